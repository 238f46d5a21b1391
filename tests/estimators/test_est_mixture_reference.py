"""MixtureFilter (paper eqs. 1-8) against an independent 40-digit evaluation of the same model.

The reference below does not run the recursion: it sums the evidence of eq. 6 directly over the
disjoint intervals in which the survival time T can fall (linear space, mpmath, survival functions
written from their closed forms, not from ``SurvivalMixture``), with the escape floors as the module
docstring states them (the change probability of the interval ending at the first observation after
a (re)start at least ``escape_first``, of every later interval at least ``escape``), and error rates
kept at >= 1e-9.
Both paths of the filter (the vectorised ``scan`` and the scalar ``step``), the state they leave,
the posterior weights (eq. 7), the dominant component's prediction (eq. 8) and the serialised
state are compared with it.
"""

from __future__ import annotations

import json
import math

import mpmath
import numpy as np
import pytest

from psg_data.errors import EstimatorError
from psg_data.estimators import MixtureFilter, SurvivalMixture
from psg_data.estimators._mixture import ScanResult, clip_error_rate, decode_floats, encode_floats

mpmath.mp.dps = 40


def ref_sf(family: str, p1: float, p2: float, t: float) -> mpmath.mpf:
    """S(t) of one component from its closed form (t in s, t <= 0 counts as 0)."""
    t = mpmath.mpf(max(t, 0.0))
    if family == "exponential":
        return mpmath.exp(-mpmath.mpf(p1) * t)
    if t == 0:
        return mpmath.mpf(1)
    if family == "lognormal":  # p1 = mean of ln T, p2 = sigma of ln T
        z = (mpmath.log(t) - p1) / (p2 * mpmath.sqrt(2))
        if abs(z) > 1e4:  # erfc(z) is 0 or 2 to within exp(-1e8): mpmath's series overflows there
            return mpmath.mpf(0) if z > 0 else mpmath.mpf(1)
        return mpmath.erfc(z) / 2
    if family == "weibull":  # p1 = shape k, p2 = scale s
        return mpmath.exp(-((t / p2) ** p1))
    return 1 / (1 + (t / p2) ** p1)  # log-logistic: p1 = beta, p2 = alpha


class Ref:
    """The filter's quantities after observations (t_i, y_i), evaluated by direct summation."""

    def __init__(self, surv: SurvivalMixture, p_m: float, p_f: float, t, y, *, emergence: bool = False,
                 origin: float | None = None, escape: float = 1e-10, escape_first: float = 1e-6,
                 log_prior=None) -> None:
        p_m, p_f = max(p_m, 1e-9), max(p_f, 1e-9)
        # P(y | own state), P(y | other state); own = present for persistence, absent for emergence
        pres = {1: mpmath.mpf(1) - p_m, 0: mpmath.mpf(p_m)}
        absn = {1: mpmath.mpf(p_f), 0: mpmath.mpf(1) - p_f}
        self.own, self.other = (absn, pres) if emergence else (pres, absn)
        self.emergence = emergence
        self.fam, self.p1, self.p2 = surv.family, surv.p1.tolist(), surv.p2.tolist()
        self.k = len(self.p1)
        lp = surv.log_weights if log_prior is None else np.asarray(log_prior, dtype=float)
        self.prior = [mpmath.exp(v) if v > -math.inf else mpmath.mpf(0) for v in lp.tolist()]
        self.t = [float(v) for v in t]
        self.y = [int(v) for v in y]
        self.origin = self.t[0] if origin is None else float(origin)
        self.taus = []
        tau = 0.0
        for ti in self.t:
            tau = max(ti - self.origin, tau)
            self.taus.append(tau)
        self.escape, self.escape_first = escape, escape_first

    def sf(self, c: int, tau: float) -> mpmath.mpf:
        return ref_sf(self.fam, self.p1[c], self.p2[c], tau)

    def parts(self, c: int, n: int) -> tuple[mpmath.mpf, mpmath.mpf, mpmath.mpf]:
        """(H, L, S(tau_n)) after the first n observations: eq. 6's accumulator (T in one of the
        intervals (tau_{j-1}, tau_j]: own state before observation j, the other from j on), the
        likelihood of 'own state at every observation' and the survival at the last one."""
        tail = [mpmath.mpf(1)] * (n + 1)  # tail[j] = prod_{i >= j} P(y_i | other)
        for j in range(n - 1, -1, -1):
            tail[j] = tail[j + 1] * self.other[self.y[j]]
        lik = mpmath.mpf(1)
        h = mpmath.mpf(0)
        s_prev = mpmath.mpf(1)
        for j in range(n):
            s = self.sf(c, self.taus[j])
            mass = max(s_prev - s, mpmath.mpf(self.escape_first if j == 0 else self.escape))
            h += mass * lik * tail[j]
            lik *= self.own[self.y[j]]
            s_prev = s
        return h, lik, s_prev

    def comp_evidence(self, n: int | None = None) -> list[mpmath.mpf]:
        n = len(self.t) if n is None else n
        out = []
        for c in range(self.k):
            h, lik, s = self.parts(c, n)
            out.append(h + lik * s)
        return out

    def log_evidence(self, n: int | None = None) -> float:
        return float(mpmath.log(sum(p * e for p, e in zip(self.prior, self.comp_evidence(n)))))

    def weights(self) -> list[float]:
        v = [p * e for p, e in zip(self.prior, self.comp_evidence())]
        return [float(x / sum(v)) for x in v]

    def dominant(self, n: int | None = None) -> int:
        v = [p * e for p, e in zip(self.prior, self.comp_evidence(n))]
        return max(range(self.k), key=lambda c: v[c])

    def p_own(self, tq: float, n: int | None = None) -> float:
        """Eq. 8: P(own state at tq | Y_1:n, dominant component), tq >= t_n."""
        n = len(self.t) if n is None else n
        c = self.dominant(n)
        _, lik, _ = self.parts(c, n)
        e = self.comp_evidence(n)[c]
        tau = max(tq - self.origin, self.taus[n - 1])
        return float(min(lik * self.sf(c, tau) / e, 1))

    def p_own_of(self, c: int, tq: float) -> float:
        """Eq. 8's posterior of component c after all observations."""
        _, lik, _ = self.parts(c, len(self.t))
        return float(lik * self.sf(c, max(tq - self.origin, self.taus[-1])) / self.comp_evidence()[c])

    def predict(self, tq: float) -> float:
        p = self.p_own(tq)
        return 1.0 - p if self.emergence else p

    def log_l(self, n: int | None = None) -> float:
        n = len(self.t) if n is None else n
        return float(sum(mpmath.log(self.own[v]) for v in self.y[:n]))

    def log_h(self, n: int | None = None) -> list[float]:
        n = len(self.t) if n is None else n
        out = []
        for c in range(self.k):
            h = self.parts(c, n)[0]
            out.append(float(mpmath.log(h)) if h > 0 else -math.inf)
        return out

    def log_sf(self, n: int | None = None) -> list[float]:
        n = len(self.t) if n is None else n
        return [float(mpmath.log(self.sf(c, self.taus[n - 1]))) for c in range(self.k)]


MIX3 = SurvivalMixture("lognormal", np.array([0.2, 0.5, 0.3]), np.log([600.0, 3000.0, 20000.0]),
                       np.array([0.4, 0.7, 1.1]))
FAMS = {
    "exponential": SurvivalMixture("exponential", np.array([0.6, 0.4]), np.array([1 / 900.0, 1 / 8000.0]),
                                   np.ones(2)),
    "lognormal": MIX3,
    "weibull": SurvivalMixture("weibull", np.array([0.5, 0.5]), np.array([0.8, 2.5]), np.array([1500.0, 5000.0])),
    "loglogistic": SurvivalMixture("loglogistic", np.array([0.3, 0.7]), np.array([1.5, 4.0]),
                                   np.array([1200.0, 6000.0])),
}
T = 1.7e9 + np.array([0.0, 250.0, 700.0, 1300.0, 1300.0, 2100.0, 3500.0, 3600.0, 5200.0, 7000.0])
Y = np.array([1, 1, 0, 1, 1, 0, 0, 1, 0, 0], dtype=np.int8)


def _run(f: MixtureFilter, t, y, path: str) -> list[tuple[float, float]]:
    """Feed (t, y) through one path; per observation (log evidence, p_own) where the path gives them."""
    if path == "step":
        return [f.step(float(ti), int(yi)) for ti, yi in zip(t, y)]
    if path == "update":
        for ti, yi in zip(t, y):
            f.update(ti, yi)
        return []
    if path == "chunks":
        f.update_many(t, y, chunk=3)
        return []
    res = f.scan(t, y)
    f.commit(res, len(t) - 1)
    return list(zip(res.log_evidence.tolist(), res.p_own.tolist()))


def _check_state(f: MixtureFilter, r: Ref) -> None:
    n = len(r.t)
    assert (f.n, f.origin, f.last_t) == (n, r.origin, r.t[-1])
    assert f.tau == pytest.approx(r.taus[-1], abs=0)
    assert f.l == pytest.approx(r.log_l(), rel=1e-12)
    np.testing.assert_allclose(f.ly, r.log_h(), rtol=1e-11)
    np.testing.assert_allclose(f.lsf, r.log_sf(), rtol=1e-11, atol=1e-13)
    want = [float(mpmath.log(e)) for e in r.comp_evidence()]
    np.testing.assert_allclose(f.component_log_evidence(), want, rtol=1e-11)
    assert f.log_evidence() == pytest.approx(r.log_evidence(), rel=1e-11)
    np.testing.assert_allclose(f.posterior_weights(), r.weights(), rtol=1e-10, atol=1e-300)
    assert f.dominant() == r.dominant()


@pytest.mark.parametrize("path", ["scan", "step", "update", "chunks"])
@pytest.mark.parametrize("emergence", [False, True])
@pytest.mark.parametrize("family", list(FAMS))
def test_filter_matches_direct_summation(family: str, emergence: bool, path: str) -> None:
    """Eqs. 5-8 with the escape floors, every family, both filters, every update path."""
    surv = FAMS[family]
    f = MixtureFilter(surv, 0.1, 0.2, emergence=emergence)
    per_obs = _run(f, T, Y, path)
    r = Ref(surv, 0.1, 0.2, T, Y, emergence=emergence)
    _check_state(f, r)
    for n, (ev, p) in enumerate(per_obs, start=1):  # the per-observation outputs of scan and step
        assert ev == pytest.approx(r.log_evidence(n), rel=1e-11)
        assert p == pytest.approx(r.p_own(r.t[n - 1], n), rel=1e-10, abs=1e-15)
    q = T[-1] + np.array([0.0, 300.0, 2000.0, 9000.0])
    want = [r.predict(float(v)) for v in q]
    np.testing.assert_allclose(f.predict(q), want, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(f.predict_own(q), [r.p_own(float(v)) for v in q], rtol=1e-10, atol=1e-14)


NARROW = SurvivalMixture("lognormal", np.array([0.5, 0.5]), np.log([900.0, 40.0]), np.array([0.02, 0.6]))
T0 = 1.7e9
TN = T0 + np.array([0.0, 30.0, 60.0, 60.0, 400.0, 880.0, 905.0, 1500.0])
YN = np.array([1, 1, 0, 0, 1, 0, 0, 0], dtype=np.int8)


@pytest.mark.parametrize("path", ["scan", "step"])
@pytest.mark.parametrize("origin", [None, T0 - 400.0, T0 + 500.0])
@pytest.mark.parametrize("floors", [(0.0, 0.0), (1e-4, 0.0), (0.0, 1e-4), (1e-10, 1e-6), (1e-3, 1e-3), (1e-4, 1e-7)])
def test_escape_floors_and_origins(floors: tuple[float, float], origin: float | None, path: str) -> None:
    """Each floor alone and both, exact recursion (0, 0), an origin before the first observation and one
    after it (survival time held at 0 until the origin), on a narrow prior where the floors matter."""
    esc, esc1 = floors
    f = MixtureFilter(NARROW, 0.1, 0.1, escape=esc, escape_first=esc1)
    f.reset(origin)
    assert f.started == (origin is not None)
    per_obs = _run(f, TN, YN, path)
    r = Ref(NARROW, 0.1, 0.1, TN, YN, origin=origin, escape=esc, escape_first=esc1)
    _check_state(f, r)
    for n, (ev, p) in enumerate(per_obs, start=1):
        assert ev == pytest.approx(r.log_evidence(n), rel=1e-11)
        assert p == pytest.approx(r.p_own(r.t[n - 1], n), rel=1e-10, abs=1e-15)
    q = TN[-1] + np.array([0.0, 100.0, 1000.0])
    np.testing.assert_allclose(f.predict(q), [r.predict(float(v)) for v in q], rtol=1e-10, atol=1e-14)


def test_scan_result_rows_and_scan_from_the_fresh_state() -> None:
    """ScanResult's per-observation arrays; ``scan_from`` with ly0 = lsf0 = None is the fresh state."""
    surv = FAMS["weibull"]
    origin = T[0] - 300.0  # S(tau_1) < 1: the first change probability is not the floor
    f = MixtureFilter(surv, 0.15, 0.05)
    f.reset(origin)
    res = f.scan(T, Y)
    again = f.scan_from(origin, 0.0, 0.0, None, None, T.copy(), Y.astype(np.intp))
    r = Ref(surv, 0.15, 0.05, T, Y, origin=origin)
    for got in (res, again):
        assert isinstance(got, ScanResult) and got.origin == origin
        np.testing.assert_array_equal(got.t, T)
        np.testing.assert_array_equal(got.tau, r.taus)
        for n in range(1, len(T) + 1):
            assert got.l[n - 1] == pytest.approx(r.log_l(n), rel=1e-12)
            np.testing.assert_allclose(got.ly[:, n - 1], r.log_h(n), rtol=1e-11)
            np.testing.assert_allclose(got.lsf[:, n - 1], r.log_sf(n), rtol=1e-11, atol=1e-13)
            assert got.log_evidence[n - 1] == pytest.approx(r.log_evidence(n), rel=1e-11)
            assert got.p_own[n - 1] == pytest.approx(r.p_own(r.t[n - 1], n), rel=1e-10)
    assert (f.n, f.last_t, f.origin) == (0, None, origin)  # scan changes no state


@pytest.mark.parametrize("path", ["scan", "step"])
@pytest.mark.parametrize("surv", [SurvivalMixture.single("weibull", 1.3, 2000.0), MIX3], ids=["K1", "K3"])
def test_log_prior_overrides_the_survival_weights(surv: SurvivalMixture, path: str) -> None:
    """Perpetua's resets pass log prior weights (not necessarily normalised) instead of ``survival.weights``."""
    lp = np.log([0.25]) if surv.n_components == 1 else np.log([0.6, 0.05, 0.1])
    f = MixtureFilter(surv, 0.1, 0.2, log_prior=lp.tolist())
    assert f.log_prior.dtype == np.float64
    np.testing.assert_array_equal(f.log_prior, lp)
    per_obs = _run(f, T, Y, path)
    r = Ref(surv, 0.1, 0.2, T, Y, log_prior=lp)
    _check_state(f, r)
    for n, (ev, _) in enumerate(per_obs, start=1):
        assert ev == pytest.approx(r.log_evidence(n), rel=1e-11)


def test_constructor_checks() -> None:
    surv = FAMS["exponential"]
    for esc, esc1 in ((1e-3, 1e-3), (0.0, 0.0), (1e-3, 0.0), (0.0, 1e-3)):
        MixtureFilter(surv, 0.1, 0.1, escape=esc, escape_first=esc1)  # the closed range [0, 1e-3]
    for esc, esc1 in ((1.1e-3, 1e-6), (1e-10, 1.1e-3), (0.5, 1e-6), (1e-10, 0.5), (-1e-12, 1e-6), (1e-10, -1e-12)):
        with pytest.raises(EstimatorError, match=r"escape floors must be in \[0, 1e-3\], got "):
            MixtureFilter(surv, 0.1, 0.1, escape=esc, escape_first=esc1)
    with pytest.raises(EstimatorError, match="p_m must be in"):
        MixtureFilter(surv, 0.5, 0.1)
    with pytest.raises(EstimatorError, match=r"p_f must be in \[0, 0.5\), got 0.5"):
        MixtureFilter(surv, 0.1, 0.5)
    with pytest.raises(EstimatorError, match=r"p_f must be in \[0, 0.5\), got -0.1"):
        MixtureFilter(surv, 0.1, -0.1)
    with pytest.raises(EstimatorError, match=r"log_prior must have shape \(2,\), got \(3,\)"):
        MixtureFilter(surv, 0.1, 0.1, log_prior=np.zeros(3))
    assert clip_error_rate(0.0, "p") == 1e-9 and clip_error_rate(0.3, "p") == 0.3
    assert clip_error_rate(np.nextafter(0.5, 0.0), "p") < 0.5
    for bad in (0.5, 0.7, -1e-9):
        with pytest.raises(EstimatorError, match=r"x must be in \[0, 0.5\)"):
            clip_error_rate(bad, "x")


def test_fresh_state_and_json_round_trip() -> None:
    """get_state is strict JSON (log 0 as null); set_state continues exactly where the state was."""
    surv = MIX3
    f = MixtureFilter(surv, 0.1, 0.2)
    s0 = f.get_state()
    assert (f.n, f.l, f.tau, f.origin, f.last_t) == (0, 0.0, 0.0, None, None)
    assert s0["ly"] == [None] * 3 and s0["lsf"] == [0.0] * 3 and s0["last_t"] is None
    f.update_many(T[:4], Y[:4])
    text = json.dumps(f.get_state(), allow_nan=False)
    g = MixtureFilter(surv, 0.1, 0.2)
    g.set_state(json.loads(text))
    assert g.get_state() == f.get_state()
    g.update_many(T[4:], Y[4:])
    _check_state(g, Ref(surv, 0.1, 0.2, T, Y))
    # a filter that never saw a change: log H = -inf in every component (escape 0, observations at the origin)
    h = MixtureFilter(surv, 0.1, 0.2, escape=0.0, escape_first=0.0)
    h.update_many(np.full(3, T0), np.ones(3, dtype=np.int8))
    assert h.ly == [-math.inf] * 3
    state = json.loads(json.dumps(h.get_state(), allow_nan=False))
    assert state["ly"] == [None] * 3
    k = MixtureFilter(surv, 0.1, 0.2, escape=0.0, escape_first=0.0)
    k.set_state(state)
    assert k.ly == [-math.inf] * 3 and k.log_prior.dtype == np.float64
    np.testing.assert_array_equal(k.log_prior, surv.log_weights)


def test_encode_and_decode_floats() -> None:
    assert encode_floats([-math.inf, 0.0, -2.5]) == [None, 0.0, -2.5]
    assert encode_floats(np.array([[1.0, -np.inf], [3.0, 4.0]])) == [1.0, None, 3.0, 4.0]  # flattened
    assert encode_floats(-1.5) == [-1.5] and encode_floats(-np.inf) == [None]
    assert all(type(v) is float for v in encode_floats(np.arange(3)))
    with pytest.raises(ValueError):
        json.dumps(encode_floats([math.inf]), allow_nan=False)  # +inf is not log 0: not silently null
    d = decode_floats([None, 0, 1, -2.5])
    assert d.dtype == np.float64
    np.testing.assert_array_equal(d, [-np.inf, 0.0, 1.0, -2.5])
    assert decode_floats([0, 1]).dtype == np.float64
    np.testing.assert_array_equal(decode_floats(encode_floats([-np.inf, 7.0])), [-np.inf, 7.0])


def test_commit_counts_and_update_many_shapes() -> None:
    surv = FAMS["loglogistic"]
    r = Ref(surv, 0.1, 0.2, T, Y)
    a = MixtureFilter(surv, 0.1, 0.2)
    res = a.scan(T[:4], Y[:4])
    a.commit(res, 1)  # the state after the first two observations
    assert (a.n, a.last_t, a.tau) == (2, T[1], T[1] - T[0])
    a.update_many(T[2:], Y[2:], chunk=4)
    _check_state(a, r)
    b = MixtureFilter(surv, 0.1, 0.2)
    b.update_many(T[:, None], Y[:, None])  # any shape, flattened in time order
    _check_state(b, r)
    c = MixtureFilter(surv, 0.1, 0.2)
    c.update_many(T[0], Y[0])  # a scalar is one observation
    for ti, yi in zip(T[1:], Y[1:]):
        c.update_many(ti, yi)
    _check_state(c, r)
    d = MixtureFilter(surv, 0.1, 0.2)
    d.update_many(T.astype(np.int64), Y.astype(np.int64))  # integer seconds
    _check_state(d, r)


def test_predictions_before_any_observation_and_dtypes() -> None:
    surv = FAMS["lognormal"]
    q = np.array([5, 50, 500])
    per, emg = MixtureFilter(surv, 0.1, 0.1), MixtureFilter(surv, 0.1, 0.1, emergence=True)
    for f, want in ((per, 1.0), (emg, 0.0)):
        p = f.predict(q)  # integer times in, float probabilities out
        assert p.dtype == np.float64 and p.shape == (3,)
        np.testing.assert_array_equal(p, want)
    own = per.predict_own(q)
    assert own.dtype == np.float64 and own.shape == (3,)
    np.testing.assert_array_equal(own, 1.0)
    # started at an origin but no observation yet: the prior survival of the heaviest component
    per.reset(0.0)
    k = int(np.argmax(surv.weights))
    want = [float(ref_sf("lognormal", surv.p1[k], surv.p2[k], float(v))) for v in q]
    np.testing.assert_allclose(per.predict(q), want, rtol=1e-12)


def test_float32_times_are_computed_in_float64() -> None:
    """Times are converted to float64 before differences are taken (float32 keeps ~7 digits)."""
    surv = FAMS["lognormal"]
    t32 = np.array([0.0, 250.5, 700.25, 1300.0, 2100.75], dtype=np.float32)
    y = Y[:5]
    f = MixtureFilter(surv, 0.1, 0.2)
    f.reset(-3.3)
    r = Ref(surv, 0.1, 0.2, t32.astype(np.float64), y, origin=-3.3)
    res = f.scan(t32, y)
    assert res.t.dtype == np.float64
    for n in range(1, 6):
        assert res.log_evidence[n - 1] == pytest.approx(r.log_evidence(n), rel=1e-11)
    f.commit(res, 4)
    q = np.array([2200.3, 5000.1], dtype=np.float32)
    np.testing.assert_allclose(f.predict_own(q), [r.p_own(float(v)) for v in q.astype(np.float64)], rtol=1e-10)


@pytest.mark.parametrize("path", ["scan", "step"])
def test_survival_reaching_zero_gives_log_zero_silently(path: str) -> None:
    """A (near-)deterministic duration: S = 0 after the median, so S_prev - S = 0 - 0 between two later
    observations; the change probability is then the escape floor, without a floating-point warning."""
    step_prior = SurvivalMixture("lognormal", np.array([0.5, 0.5]), np.log([100.0, 5000.0]), np.array([1e-300, 0.5]))
    t = T0 + np.array([0.0, 50.0, 150.0, 300.0, 400.0])
    y = np.array([1, 1, 0, 0, 0], dtype=np.int8)
    f = MixtureFilter(step_prior, 0.1, 0.1)
    with np.errstate(all="raise"):
        per_obs = _run(f, t, y, path)
    assert f.lsf[0] == -math.inf
    r = Ref(step_prior, 0.1, 0.1, t, y)
    want = [float(mpmath.log(e)) for e in r.comp_evidence()]
    np.testing.assert_allclose(f.component_log_evidence(), want, rtol=1e-11)
    for n, (ev, _) in enumerate(per_obs, start=1):
        assert ev == pytest.approx(r.log_evidence(n), rel=1e-11)


def test_posterior_weights_of_a_long_stream() -> None:
    """Eq. 7 when every evidence is far below exp(-745) (weights need the max shifted out)."""
    rng = np.random.default_rng(7)
    t = T0 + np.cumsum(rng.uniform(60.0, 600.0, 700))
    y = (rng.random(700) < 0.5).astype(np.int8)
    f = MixtureFilter(MIX3, 0.3, 0.3)
    f.update_many(t, y)
    r = Ref(MIX3, 0.3, 0.3, t, y)
    assert f.log_evidence() < -400.0
    assert f.log_evidence() == pytest.approx(r.log_evidence(), rel=1e-11)
    np.testing.assert_allclose(f.posterior_weights(), r.weights(), rtol=1e-9)
    assert f.dominant() == r.dominant()


def test_step_breaks_an_exact_tie_of_the_weights_like_argmax() -> None:
    """At exactly equal posterior weights the first component is the dominant one in step, as in
    ``dominant()`` (numpy's argmax) and the batch scan."""
    surv = SurvivalMixture("weibull", np.array([0.5, 0.5]), np.array([0.9, 2.2]), np.array([2000.0, 2600.0]))
    probe = MixtureFilter(surv, 0.1, 0.2)
    probe.update_many(T, Y)
    e = probe.component_log_evidence()
    assert 0.5 < e[0] / e[1] < 2.0  # so e0 - e1 is exact (Sterbenz) and e1 + (e0 - e1) == e0
    lp = [0.0, float(e[0] - e[1])]
    f = MixtureFilter(surv, 0.1, 0.2, log_prior=lp)
    out = [f.step(float(ti), int(yi)) for ti, yi in zip(T, Y)]
    w = f.log_prior + f.component_log_evidence()
    assert w[0] == w[1]  # the tie (the precondition of this test)
    r = Ref(surv, 0.1, 0.2, T, Y, log_prior=np.array(lp))
    p0, p1 = r.p_own_of(0, T[-1]), r.p_own_of(1, T[-1])
    assert abs(p0 - p1) > 0.5 * max(p0, p1)  # the two components disagree: the tie break matters
    assert out[-1][1] == pytest.approx(p0, rel=1e-10)
    assert f.dominant() == 0
    assert float(f.predict(T[-1:])[0]) == pytest.approx(p0, rel=1e-10)
    g = MixtureFilter(surv, 0.1, 0.2, log_prior=lp)
    assert float(g.scan(T, Y).p_own[-1]) == pytest.approx(p0, rel=1e-10)


@pytest.mark.parametrize("surv", [SurvivalMixture.single("weibull", 1.5, 300.0),
                                  SurvivalMixture.lognormal_median(300.0, 0.5)], ids=["weibull", "lognormal"])
def test_prediction_never_exceeds_one(surv: SurvivalMixture) -> None:
    """Certain presence (P_F = 0, no change probability between repeated detections): the posterior is
    1 to double precision, and the scalar and numpy survival functions may differ in the last bit;
    the prediction is clipped to 1 and still matches the reference."""
    rng = np.random.default_rng(1)
    for _ in range(60):
        t = T0 + np.sort(rng.uniform(100.0, 3000.0, 3))
        t = np.append(t, [t[-1]] * 3)  # three more detections at the last time
        f = MixtureFilter(surv, 0.1, 0.0, escape=0.0, escape_first=0.0)
        f.reset(T0)
        for ti in t:
            f.update(float(ti), 1)
        p = f.predict(np.array([t[-1], t[-1] + 1e-3]))
        assert np.all(p <= 1.0)
        r = Ref(surv, 0.1, 0.0, t, np.ones(t.size, dtype=np.int8), origin=T0, escape=0.0, escape_first=0.0)
        np.testing.assert_allclose(p, [r.predict(float(t[-1])), r.predict(float(t[-1]) + 1e-3)], rtol=1e-12)
