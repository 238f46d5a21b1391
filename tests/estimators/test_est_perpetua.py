"""Perpetua (the predecessor baseline): its switching filter, prediction and simulation, pinned by an
independent model.

The reference below is written from the description of Perpetua in
``../shared/notes/perpetua_reference.md`` and the paper's eqs. 1-8, not from the code: each mixture
component's evidence p(Y | c_l) is the brute-force sum over the interval in which the filtered state
ended (plus the term "it still holds"), in plain probabilities with scipy's survival functions; the
prediction is the dominant component's posterior (eq. 8); the state machine is a plain loop over the
check times (num_steps equally spaced sub-steps between consecutive observations / query times).
The escape floors of the change probability (``escape`` per interval, ``escape_first`` for the
interval ending at the first observation after a (re)start) are part of the model being pinned.
"""

from __future__ import annotations

import copy
import logging
import math
import warnings
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy import stats

from psg_data.errors import EstimatorError
from psg_data.estimators import EdgeStream, SurvivalMixture, get_estimator
from psg_data.estimators._perpetua import PerpetuaEstimator, PerpetuaFilter
from psg_data.estimators._perpetua_star import PerpetuaStarEstimator

H = 3600.0
T0 = 1.7e9


# ---------------------------------------------------------------------------------------------- reference
def _sf(family: str, p1: float, p2: float, tau: float) -> float:
    """S(tau) = P(T > tau) of one component (tau in s, from the mixture's origin)."""
    tau = max(tau, 0.0)
    if family == "exponential":
        return math.exp(-p1 * tau)
    if family == "lognormal":
        return float(stats.lognorm.sf(tau, s=p2, scale=math.exp(p1)))
    return float(stats.weibull_min.sf(tau, p1, scale=p2))


class RefMixture:
    """A mixture of persistence (or emergence) filters, evaluated by brute force."""

    def __init__(self, family: str, w: list[float], p1: list[float], p2: list[float], p_m: float, p_f: float,
                 emergence: bool, esc: float, esc1: float, log: list[float]) -> None:
        """Components (w, p1, p2) of ``family``; ``log`` collects decision margins (see :func:`_compare`)."""
        self.family, self.p1, self.p2 = family, list(p1), list(p2)
        self.w0 = np.asarray(w, dtype=float) / float(np.sum(w))
        present, absent = (p_m, 1.0 - p_m), (1.0 - p_f, p_f)  # p(y = 0), p(y = 1)
        # an emergence filter filters the absence state (its "own" state)
        self.own, self.other = (absent, present) if emergence else (present, absent)
        self.emergence, self.esc, self.esc1, self.log = emergence, esc, esc1, log
        self.prior = self.w0.copy()
        self.origin: float | None = None
        self.obs: list[tuple[float, int]] = []

    def reset(self, origin: float | None, prior: np.ndarray) -> None:
        """Forget the observations; survival clock at ``origin``; component weights ``prior``."""
        self.origin, self.obs, self.prior = origin, [], np.asarray(prior, dtype=float)

    @property
    def started(self) -> bool:
        """Whether the survival clock runs."""
        return self.origin is not None

    def update(self, t: float, y: int) -> None:
        """Record one observation (the first one starts the clock if nothing did)."""
        if self.origin is None:
            self.origin = t
        self.obs.append((t, y))

    def _taus(self) -> list[float]:
        assert self.origin is not None
        out, prev = [], 0.0
        for t, _ in self.obs:
            prev = max(prev, t - self.origin)
            out.append(prev)
        return out

    def evidences(self) -> np.ndarray:
        """p(Y | c_l) per component: sum over the interval (tau_{j-1}, tau_j] in which the state ended."""
        taus, ys = self._taus(), [y for _, y in self.obs]
        n = len(ys)
        out = []
        for l in range(len(self.w0)):
            s = [1.0] + [_sf(self.family, self.p1[l], self.p2[l], tau) for tau in taus]
            total = s[n] * math.prod(self.own[y] for y in ys)
            for j in range(1, n + 1):
                change = max(s[j - 1] - s[j], self.esc1 if j == 1 else self.esc)
                total += (change * math.prod(self.own[y] for y in ys[:j - 1])
                          * math.prod(self.other[y] for y in ys[j - 1:]))
            out.append(total)
        return np.array(out)

    def posterior(self) -> np.ndarray:
        """Component posterior weights (eq. 7)."""
        v = self.prior * self.evidences()
        return v / v.sum()

    def predict(self, t: float) -> float:
        """P(present at t) from the dominant component (eq. 8)."""
        if self.origin is None:
            return 0.0 if self.emergence else 1.0
        e = self.evidences()
        v = self.prior * e
        top = np.sort(v)[::-1]
        if top.size > 1:  # how clearly the dominant component dominates (rounding could flip a near tie)
            self.log.append((top[0] - top[1]) / top[0])
        k = int(np.argmax(v))
        taus = self._taus()
        tau = max(t - self.origin, taus[-1] if taus else 0.0)
        own = math.prod(self.own[y] for _, y in self.obs)
        p = min(own * _sf(self.family, self.p1[k], self.p2[k], tau) / e[k], 1.0)
        return 1.0 - p if self.emergence else p


class RefPerpetua:
    """The state machine of the reference notes, one check time at a time."""

    def __init__(self, per: RefMixture, emg: RefMixture, dl: float, dh: float, eps: float, num_steps: int) -> None:
        """Starts in the persistence state."""
        self.per, self.emg = per, emg
        self.dl, self.dh, self.eps, self.num_steps = dl, dh, eps, num_steps
        self.active = "per"
        self.last_t: float | None = None
        self.log = per.log

    def model(self) -> RefMixture:
        """The active mixture."""
        return self.per if self.active == "per" else self.emg

    def check(self, g: float) -> None:
        """One check time: switch if the active belief crossed its threshold."""
        p = self.model().predict(g)
        if self.active == "per":
            self.log.append(abs(p - self.dl))
            if p <= self.dl:  # persistence belief dropped to delta_low: a fresh emergence mixture
                self._restart(self.emg, g)
                self.active = "emg"
        else:
            self.log.append(abs(p - self.dh))
            if p >= self.dh:
                self._restart(self.per, g)
                self.active = "per"

    def _restart(self, m: RefMixture, g: float) -> None:
        w = (1.0 - self.eps) * m.posterior() + self.eps * m.w0 if m.started else m.w0
        m.reset(g, w)

    def start(self, t_s: float) -> None:
        """Start the persistence clock at ``t_s``."""
        self.per.reset(t_s, self.per.prior)

    def update(self, t: float, y: int) -> None:
        """Sub-steps since the last observation, then both mixtures (emergence once started), then a check."""
        if self.last_t is not None and t > self.last_t:
            a = self.last_t
            for k in range(1, self.num_steps + 1):
                self.check(a + (t - a) * k / (self.num_steps + 1))
        self.per.update(t, y)
        if self.emg.started:
            self.emg.update(t, y)
        self.check(t)
        self.last_t = t

    def predict(self, q: np.ndarray) -> np.ndarray:
        """Beliefs at query times >= the last observation, simulated on a copy."""
        t0 = self.last_t if self.last_t is not None else self.per.origin
        if t0 is None:
            return np.ones(len(q))
        q = [max(float(x), t0) for x in q]
        knots = sorted({t0, *q})
        grid: list[float] = []
        for a, b in zip(knots[:-1], knots[1:]):
            grid += [a] + [a + (b - a) * k / (self.num_steps + 1) for k in range(1, self.num_steps + 1)]
        grid.append(knots[-1])
        sim = copy.deepcopy(self, memo={id(self.log): self.log})
        belief: dict[float, float] = {}
        for g in grid:
            sim.check(g)
            belief[g] = sim.model().predict(g)
        return np.array([belief[x] for x in q])


def _mixture(family: str, comps: list[tuple[float, float, float]]) -> SurvivalMixture:
    w, p1, p2 = (np.array([c[i] for c in comps], dtype=float) for i in range(3))
    return SurvivalMixture(family, w, p1, p2)


def _pair(per: tuple[str, list], emg: tuple[str, list], p_m: float, p_f: float, dl: float, dh: float, eps: float,
          num_steps: int, esc: float = 1e-10, esc1: float = 1e-6) -> tuple[PerpetuaFilter, RefPerpetua]:
    """The filter under test and the reference with the same settings; comps are (weight, p1, p2)."""
    f = PerpetuaFilter(("o", "r"), _mixture(per[0], per[1]), _mixture(emg[0], emg[1]), p_m, p_f, delta_low=dl,
                       delta_high=dh, eps=eps, num_steps=num_steps, escape=esc, escape_first=esc1)
    log: list[float] = []
    mix = [RefMixture(fam, [c[0] for c in comps], [c[1] for c in comps], [c[2] for c in comps], p_m, p_f, e, esc,
                      esc1, log) for (fam, comps), e in ((per, False), (emg, True))]
    return f, RefPerpetua(mix[0], mix[1], dl, dh, eps, num_steps)


def _ln(median_h: float, sigma: float, w: float = 1.0) -> tuple[float, float, float]:
    return (w, math.log(median_h * H), sigma)


# two components each, clearly different, so the restart weights and the dominant component matter
PER2 = ("lognormal", [_ln(1.0, 0.4, 0.6), _ln(6.0, 0.5, 0.4)])
EMG2 = ("lognormal", [_ln(0.5, 0.5, 0.3), _ln(3.0, 0.4, 0.7)])


# ---------------------------------------------------------------------------------------------- closed forms
def test_never_started_filter_predicts_present_everywhere() -> None:
    """Docs: a filter that was never started or updated predicts the present state."""
    f, _ = _pair(PER2, EMG2, 0.1, 0.1, 0.05, 0.95, 0.1, 1)
    np.testing.assert_array_equal(f.predict(np.array([T0, T0 + 5 * H, T0 + 50 * H])), [1.0, 1.0, 1.0])
    assert f.predict(np.array([[T0, T0 + H]])).shape == (1, 2)


@pytest.mark.parametrize("num_steps", [0, 1, 3])
def test_started_filter_before_any_observation_is_the_prior_survival_then_switches(num_steps: int) -> None:
    """One exponential component each: before it crosses delta_low the belief is S_per(t - t_s) = exp(-r t)."""
    r_per, r_emg = 1.0 / H, 0.5 / H
    f = PerpetuaFilter(("o", "r"), SurvivalMixture.single("exponential", r_per),
                       SurvivalMixture.single("exponential", r_emg), 0.1, 0.1, delta_low=0.05, delta_high=0.95,
                       eps=0.1, num_steps=num_steps)
    f.start(T0)
    assert f.last_t_s is None and f.active == "per"
    t_cross = math.log(1 / 0.05) / r_per  # exp(-r t) = delta_low at 3.0 h
    q = T0 + np.array([0.0, 0.5, 1.0, 2.0, 2.9]) * H
    np.testing.assert_allclose(f.predict(q), np.exp(-r_per * (q - T0)), rtol=1e-12)
    # a query time after the crossing: the emergence mixture started at the first check time at or
    # after the crossing: with no sub-steps that is the query itself (predicts 0 at its origin)
    tq = T0 + 4.0 * H
    got = float(f.predict(np.array([tq]))[0])
    grid = T0 + (tq - T0) * np.arange(1, num_steps + 2) / (num_steps + 1)
    t_sw = grid[np.argmax(grid >= T0 + t_cross)]
    assert got == pytest.approx(1.0 - math.exp(-r_emg * (tq - t_sw)), abs=1e-12)
    assert f.active == "per"  # prediction simulates on a copy


def test_start_after_an_observation_is_refused_and_start_sets_the_clock() -> None:
    """``start`` sets the persistence clock only, and only before the first observation."""
    f, _ = _pair(PER2, EMG2, 0.1, 0.1, 0.05, 0.95, 0.1, 1)
    f.start(T0 - 2 * H)
    assert f.per.origin == T0 - 2 * H and f.per.started and not f.emg.started
    f.update(T0, 1)
    with pytest.raises(EstimatorError, match="before the first observation"):
        f.start(T0 + H)


def test_two_observations_enumerated_by_hand() -> None:
    """One exponential component per mixture, P_M = P_F = 0.1, observations 1 then 0 an hour apart.

    Persistence evidence (origin at the first observation, floors e1 = 1e-6, e = 1e-10):
      ended in (0, 0]:  max(0, e1) * p(1|abs) p(0|abs) = e1 * 0.1 * 0.9
      ended in (0, 1h]: (1 - S(1h)) * p(1|pres) p(0|abs) = (1 - e^-r) * 0.9 * 0.9
      still present:    S(1h) * p(1|pres) p(0|pres) = e^-r * 0.9 * 0.1
    belief at t >= 1h: e^-r(t) * 0.9 * 0.1 / evidence; it falls below delta_low at once, so the
    emergence mixture starts at the second observation (never updated): 1 - exp(-r_e (t - t_2)).
    """
    r, r_e = 0.2 / H, 1.0 / H
    f = PerpetuaFilter(("o", "r"), SurvivalMixture.single("exponential", r), SurvivalMixture.single("exponential", r_e),
                       0.1, 0.1, delta_low=0.35, delta_high=0.95, eps=0.1, num_steps=0)
    f.update(T0, 1)
    ev1 = 1e-6 * 0.1 + 1.0 * 0.9  # one observation: ended before it, or still present
    assert float(f.predict(np.array([T0 + H]))[0]) == pytest.approx(0.9 * math.exp(-r * H) / ev1, rel=1e-12)
    ev = 1e-6 * 0.1 * 0.9 + (1 - math.exp(-r * H)) * 0.81 + math.exp(-r * H) * 0.09
    p2 = math.exp(-r * H) * 0.09 / ev
    assert 0.9 * math.exp(-r * H) / ev1 > 0.35 >= p2  # no switch after the first, one after the second
    f.update(T0 + H, 0)
    assert f.active == "emg" and f.emg.origin == T0 + H
    q = T0 + H + np.array([0.0, 0.5, 2.0]) * H
    np.testing.assert_allclose(f.predict(q), 1.0 - np.exp(-r_e * (q - T0 - H)), rtol=1e-12, atol=1e-15)
    # the emergence belief reaches 0.95 at ln(20) / r_e = 3.0 h: with no sub-steps the query itself is
    # the first check time after it and a fresh persistence mixture starts there (belief 1)
    assert float(f.predict(np.array([T0 + H + 3.5 * H]))[0]) == 1.0


def _exact_half_at(median_s: float) -> SurvivalMixture:
    """A log-normal whose median is a power of two seconds: S(median) = 1/2 exactly in floating point."""
    return SurvivalMixture("lognormal", np.ones(1), np.array([float(np.log(np.float64(median_s)))]), np.ones(1))


def test_switching_thresholds_are_inclusive() -> None:
    """Docs: switch when the persistence belief drops to <= delta_low, the emergence one reaches >= delta_high."""
    m_per, m_emg = 2.0 ** 12, 2.0 ** 13  # 4096 s, 8192 s
    f = PerpetuaFilter(("o", "r"), _exact_half_at(m_per), _exact_half_at(m_emg), 0.1, 0.1, delta_low=0.5,
                       delta_high=0.5 + 1e-12, eps=0.1, num_steps=0)
    f.start(T0)
    assert float(f.per.predict(np.array([T0 + m_per]))[0]) == 0.5  # S(median) = 1/2: the boundary is met
    assert float(f.predict(np.array([T0 + m_per]))[0]) == 0.0  # switched there: fresh emergence belief 0
    g = PerpetuaFilter(("o", "r"), _exact_half_at(m_per), _exact_half_at(m_emg), 0.1, 0.1, delta_low=0.4,
                       delta_high=0.5, eps=0.1, num_steps=0)
    g.start(T0)
    t_sw = T0 + 2 * m_per  # S_per = Phi(-ln 2) = 0.244 <= 0.4: switch here
    assert float(g.per.predict(np.array([t_sw]))[0]) < 0.4
    q = np.array([t_sw, t_sw + m_emg])
    # at t_sw + median the emergence belief is exactly 1/2 = delta_high: back to persistence (belief 1)
    np.testing.assert_array_equal(g.predict(q), [0.0, 1.0])


def test_restart_weights_with_a_zero_prior_weight_raise_no_warning() -> None:
    """A component of prior weight 0 stays at weight 0 after the restart (log 0 = -inf, no warning)."""
    emg = SurvivalMixture("exponential", np.array([1.0, 0.0]), np.array([1.0 / H, 10.0 / H]), np.ones(2))
    f = PerpetuaFilter(("o", "r"), SurvivalMixture.single("exponential", 1.0 / H), emg, 0.1, 0.1, delta_low=0.3,
                       delta_high=0.95, eps=0.0, num_steps=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f.update_many(np.array([T0, T0 + H]), np.array([1, 0]))
        assert f.active == "emg"
        np.testing.assert_array_equal(f.emg.log_prior, [0.0, -np.inf])
        # the emergence belief follows the weight-1 component (rate 1/h), not the rate-10/h one
        assert float(f.predict(np.array([T0 + 2 * H]))[0]) == pytest.approx(1 - math.exp(-1.0), rel=1e-12)


# ---------------------------------------------------------------------------------------------- the reference
def _run(f: PerpetuaFilter, r: RefPerpetua, t_s: float | None, t: np.ndarray, y: np.ndarray, split: int) -> None:
    if t_s is not None:
        f.start(t_s)
        r.start(t_s)
    f.update_many(t[:split], y[:split])
    for i in range(split, t.size):
        f.update(float(t[i]), int(y[i]))
    for ti, yi in zip(t.tolist(), y.tolist()):
        r.update(ti, yi)


def _compare(f: PerpetuaFilter, r: RefPerpetua, q: np.ndarray, drawn: bool = True) -> None:
    want = r.predict(np.maximum(q, f.last_t_s if f.last_t_s is not None else -np.inf))
    got = f.predict(q)
    clear = min(r.log, default=1.0) > 1e-7  # no decision within rounding of a threshold or a tie
    if drawn:
        assume(clear)
    else:
        assert clear
    assert r.active == f.active
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-10)
    # the component weights after the restarts: (1 - eps) * posterior + eps * initial prior
    for m, rm in ((f.per, r.per), (f.emg, r.emg)):
        np.testing.assert_allclose(np.exp(m.log_prior), rm.prior, rtol=1e-9, atol=1e-300)
        assert m.origin == rm.origin


def test_a_long_gap_cycles_per_emg_per_with_restart_weights() -> None:
    """Absence then a long gap: several switches between two observations and inside one prediction."""
    f, r = _pair(PER2, EMG2, 0.1, 0.15, 0.1, 0.9, 0.3, 6)
    t = T0 + np.array([0.0, 0.5, 1.0, 1.5, 9.0, 9.5, 10.0]) * H
    y = np.array([1, 1, 0, 0, 1, 1, 0])
    _run(f, r, None, t, y, 4)
    q = t[-1] + np.array([20.0, 0.0, 3.0, 0.25, 3.0, 12.0, 7.5]) * H
    _compare(f, r, q, drawn=False)
    # the reference passed through both states in this prediction
    sim = copy.deepcopy(r, memo={id(r.log): r.log})
    states = set()
    for g in t[-1] + np.linspace(0, 20 * H, 200):
        sim.check(float(g))
        states.add(sim.active)
    assert states == {"per", "emg"}


def test_several_switches_between_two_observations_enumerated_by_hand() -> None:
    """Exponential priors, 9 sub-steps (one per hour) in a 10 h gap after one "present" observation.

    Persistence belief after the observation at 0: e^(-ln2 t/h) (times 1 / (1 + 1e-7)), emergence belief
    of a mixture started at t_e: 1 - 10^(-(t - t_e) / 2.5 h). With delta_low 0.6 and delta_high 0.9 the
    check times 1, 2, ..., 9 h switch at 1 h (0.5), 4 h (emergence 0.937 three hours after 1 h), 5 h
    (fresh persistence 0.5), 8 h and 9 h; the observation at 10 h meets the emergence mixture of 9 h.
    """
    per = SurvivalMixture.single("exponential", math.log(2) / H)
    emg = SurvivalMixture.single("exponential", math.log(10) / (2.5 * H))
    f = PerpetuaFilter(("o", "r"), per, emg, 0.1, 0.1, delta_low=0.6, delta_high=0.9, eps=0.1, num_steps=9)
    f.update(T0, 1)
    assert (f.active, f.per.origin, f.emg.started) == ("per", T0, False)
    f.update(T0 + 10 * H, 0)
    assert (f.active, f.per.origin, f.emg.origin) == ("emg", T0 + 8 * H, T0 + 9 * H)
    assert (f.per.n, f.emg.n) == (1, 1)  # both mixtures took the observation at 10 h
    # the same with the gap's checks made by a prediction instead of an update
    g = PerpetuaFilter(("o", "r"), per, emg, 0.1, 0.1, delta_low=0.6, delta_high=0.9, eps=0.1, num_steps=0)
    g.update(T0, 1)
    q = T0 + np.arange(11) * H
    b = g.predict(q)
    sw = [1, 4, 5, 8, 9]  # the prediction at a switch time is the fresh mixture's: 0 (emergence) or 1
    np.testing.assert_allclose(b[sw], [0.0, 1.0, 0.0, 1.0, 0.0], atol=1e-15)
    e1, e2 = 1 - 10 ** -0.4, 1 - 10 ** -0.8  # emergence beliefs 1 h and 2 h after its start
    np.testing.assert_allclose(b[[2, 3, 6, 7, 10]], [e1, e2, e1, e2, e1], rtol=1e-12)


_FAMILY = st.sampled_from(["lognormal", "exponential"])


@st.composite
def _components(draw: Any, family: str) -> list[tuple[float, float, float]]:
    k = draw(st.integers(1, 3))
    out = []
    for _ in range(k):
        w = draw(st.floats(0.1, 1.0))
        med_h = draw(st.floats(0.3, 8.0))
        if family == "lognormal":
            out.append((w, math.log(med_h * H), draw(st.floats(0.3, 1.2))))
        else:
            out.append((w, math.log(2) / (med_h * H), 1.0))
    return out


@st.composite
def _scenario(draw: Any) -> dict[str, Any]:
    fp, fe = draw(_FAMILY), draw(_FAMILY)
    n = draw(st.integers(1, 6))
    gaps = draw(st.lists(st.sampled_from([0.0, 0.25, 0.5, 1.0, 2.0, 3.5, 6.0]), min_size=n, max_size=n))
    return {
        "per": (fp, draw(_components(fp))), "emg": (fe, draw(_components(fe))),
        "p_m": draw(st.floats(0.02, 0.3)), "p_f": draw(st.floats(0.02, 0.3)),
        "dl": draw(st.floats(0.03, 0.4)), "dh": draw(st.floats(0.6, 0.97)),
        "eps": draw(st.sampled_from([0.0, 0.1, 0.5, 1.0])), "num_steps": draw(st.integers(0, 4)),
        "esc": draw(st.sampled_from([0.0, 1e-10, 1e-4])), "esc1": draw(st.sampled_from([0.0, 1e-6, 1e-3])),
        "t_s": draw(st.one_of(st.none(), st.sampled_from([0.0, 0.5, 2.0]))),
        "t": T0 + np.cumsum(gaps) * H, "y": np.array(draw(st.lists(st.integers(0, 1), min_size=n, max_size=n))),
        "split": draw(st.integers(0, n)),
        "q": np.array(draw(st.lists(st.sampled_from([-1.0, 0.0, 0.0, 0.3, 1.0, 2.5, 5.0, 9.0, 16.0]),
                                    min_size=1, max_size=6))) * H,
    }


def _same_state(a: dict[str, Any], b: dict[str, Any]) -> None:
    """Equal states; the survival weights up to rounding (SurvivalMixture normalises them again on load)."""
    keys = ("per_survival", "emg_survival")
    assert {k: v for k, v in a.items() if k not in keys} == {k: v for k, v in b.items() if k not in keys}
    for k in keys:
        np.testing.assert_allclose(a[k]["weights"], b[k]["weights"], rtol=1e-14)
        assert {**a[k], "weights": None} == {**b[k], "weights": None}


@settings(max_examples=120, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(_scenario())
def test_filter_matches_the_reference_state_machine(s: dict[str, Any]) -> None:
    """Beliefs before and after the observations, after a state round trip and one more update."""
    f, r = _pair(s["per"], s["emg"], s["p_m"], s["p_f"], s["dl"], s["dh"], s["eps"], s["num_steps"], s["esc"],
                 s["esc1"])
    t_s = None if s["t_s"] is None else float(s["t"][0] - s["t_s"] * H)
    if t_s is not None:  # before any observation: the prior survival from t_s and its switches
        f.start(t_s)
        r.start(t_s)
        _compare(f, r, t_s + s["q"] + H)
        t_s = None
    _run(f, r, t_s, s["t"], s["y"], s["split"])
    _compare(f, r, s["t"][-1] + s["q"])
    # the state round trip (JSON-safe) keeps every prediction and the next update
    g = PerpetuaEstimator().filter_from_state(f.get_state())
    _same_state(g.get_state(), f.get_state())
    q = s["t"][-1] + s["q"]
    np.testing.assert_allclose(g.predict(q), f.predict(q), rtol=1e-12, atol=1e-15)
    t_next, y_next = float(s["t"][-1] + 2.5 * H), 1 - int(s["y"][-1])
    f.update(t_next, y_next)
    g.update(t_next, y_next)
    r.update(t_next, y_next)
    _compare(g, r, t_next + s["q"])
    np.testing.assert_allclose(g.predict(t_next + s["q"]), f.predict(t_next + s["q"]), rtol=1e-12, atol=1e-15)


# ---------------------------------------------------------------------------------------------- state and names
def test_state_keeps_edge_name_clock_and_floors() -> None:
    """A restored filter has the edge, name, clock, state and escape floors of the saved one."""
    f = PerpetuaFilter(("obj", "rec"), _mixture(*PER2), _mixture(*EMG2), 0.1, 0.2, delta_low=0.1, delta_high=0.9,
                       eps=0.2, num_steps=2, escape=1e-4, escape_first=1e-3)
    f.update_many(T0 + np.array([0.0, 1.0, 2.0]) * H, np.array([1, 0, 0]))
    s = f.get_state()
    assert s["estimator"] == "perpetua"  # the default name: the built-in estimator restores it
    g = PerpetuaEstimator().filter_from_state(s)
    assert g.edge == ("obj", "rec") and g.last_t_s == T0 + 2 * H and g.active == f.active
    assert (g.per.escape, g.per.escape_first, g.emg.escape, g.emg.escape_first) == (1e-4, 1e-3, 1e-4, 1e-3)
    _same_state(g.get_state(), s)
    assert g.emg.emergence and not g.per.emergence
    with pytest.raises(EstimatorError, match="earlier than the last"):
        g.update(T0 + H, 1)


def test_a_renamed_variant_keeps_its_name_through_make_filter_and_state() -> None:
    """A subclass registered under another name: its filters and their restored states carry that name."""

    class Variant(PerpetuaEstimator):
        name = "perpetua_variant"

    est = Variant(p_m=0.1, p_f=0.1).fit(_streams())
    f = est.make_filter(("o", "r"))
    assert f.get_state()["estimator"] == "perpetua_variant"
    g = est.filter_from_state(f.get_state())
    assert g.get_state()["estimator"] == "perpetua_variant" == PerpetuaFilter.from_state(f.get_state())._name


# ---------------------------------------------------------------------------------------------- the estimator
def test_defaults_are_the_reference_ones_and_training_is_shared_with_perpetua_star() -> None:
    """The reference's defaults; the training settings are Perpetua*'s; every setting is kept."""
    p = PerpetuaEstimator().get_params()
    # perpetua_reference.md: delta_low 0.05, delta_high 0.95, eps 0.1, num_steps 1; the L2 PELT segmentation
    assert (p["delta_low"], p["delta_high"], p["eps"], p["num_steps"], p["segmentation"]) == (
        0.05, 0.95, 0.1, 1, "reference")
    star = PerpetuaStarEstimator().get_params()
    shared = ["max_components", "survival", "p_m", "p_f", "durations", "min_segment", "segment_penalty",
              "pool_weight", "sigma_min", "escape", "random_state"]
    assert {k: p[k] for k in shared} == {k: star[k] for k in shared}
    settings_ = {"delta_low": 0.2, "delta_high": 0.7, "eps": 0.3, "num_steps": 4, "max_components": 2,
                 "survival": "exponential", "p_m": 0.07, "p_f": 0.03, "segmentation": "observations",
                 "durations": "segments", "min_segment": 3, "segment_penalty": 2.0, "pool_weight": 1.0,
                 "sigma_min": 0.1, "escape": 1e-8, "random_state": 7}
    assert {k: v for k, v in PerpetuaEstimator(**settings_).get_params().items() if k in settings_} == settings_


def _streams() -> list[EdgeStream]:
    t = T0 + np.arange(48) * H
    y = ((np.arange(48) // 6) % 2 == 0).astype(np.int8)  # 6 h present, 6 h absent
    y2 = ((np.arange(48) // 12) % 2 == 0).astype(np.int8)  # 12 h blocks
    return [EdgeStream(("o", "r"), t, y), EdgeStream(("o", "q"), t, y2)]


@pytest.mark.parametrize("bad", [{"delta_low": 0.5, "delta_high": 0.5}, {"delta_low": 0.6, "delta_high": 0.4}])
def test_fit_refuses_thresholds_out_of_order(bad: dict[str, float]) -> None:
    """0 < delta_low < delta_high < 1 (equal thresholds included in the refusal)."""
    with pytest.raises(EstimatorError, match=r"perpetua: need 0 < delta_low < delta_high < 1, got"):
        get_estimator("perpetua", p_m=0.1, p_f=0.1, **bad).fit(_streams())


def test_fit_accepts_the_closed_ends_and_builds_filters(caplog: pytest.LogCaptureFixture) -> None:
    """num_steps 0 and eps 0 / 1 are valid; the filters get the edge's models and the settings."""
    for ok in ({"num_steps": 0}, {"eps": 0.0}, {"eps": 1.0}):
        assert get_estimator("perpetua", p_m=0.1, p_f=0.1, **ok).fit(_streams()).fitted_
    with caplog.at_level(logging.INFO):
        est = get_estimator("perpetua", p_m=0.12, p_f=0.08, escape=1e-4, delta_low=0.2, delta_high=0.7, eps=0.3,
                            num_steps=2).fit(_streams())
    assert est.fit_summary_["estimator"] == "perpetua"
    assert (est.p_m_, est.p_f_) == (0.12, 0.08)
    lines = [r.getMessage() for r in caplog.records if r.levelno == logging.INFO]
    assert lines and all(m.startswith("perpetua: ") for m in lines)
    # per-edge models; an unknown edge gets the pooled default; edges are strings
    f = est.make_filter(("o", "q"))
    assert f.per.survival is est.survivals_[("o", "q")][0] and f.emg.survival is est.survivals_[("o", "q")][1]
    assert est.make_filter(("o", "r")).per.survival is est.survivals_[("o", "r")][0]
    assert est.survivals_[("o", "r")][0] is not est.survivals_[("o", "q")][0]
    d = est.make_filter((7, 8))
    assert d.edge == ("7", "8") and d.per.survival is est.default_survivals_[0]
    assert d.emg.survival is est.default_survivals_[1]
    assert (f.per.p_m, f.per.p_f, f.delta_low, f.delta_high, f.eps, f.num_steps) == (0.12, 0.08, 0.2, 0.7, 0.3, 2)
    # escape 1e-4: both floors 1e-4 (escape_first is max(1e-6, escape))
    assert (f.per.escape, f.per.escape_first, f.emg.escape, f.emg.escape_first) == (1e-4, 1e-4, 1e-4, 1e-4)
