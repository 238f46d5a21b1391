"""Perpetua*: persistence and emergence mixtures combined by Bayesian model selection (eqs. 9-14).

Per edge, a mixture of persistence filters (M_per) and a mixture of emergence filters (M_emg) are
both updated with every observation. The model posterior at t >= t_N is (eq. 13)

    logit p(M_emg | Y) = alpha(t) * (L_emg - L_per) + logit f(t),   alpha(t) = exp(-alpha0 (t - t_N))

with f(t) the switching prior (FreMEn, schedule, oracle or constant) clipped to
[prior_floor, 1 - prior_floor], and the prediction is the posterior-weighted average of the two
models' dominant-component predictions (eq. 14).

Model log likelihoods with forgetting. L_m is the marginal log evidence of model m (denominator
of eq. 7) accumulated with forgetting: by the chain rule log p(Y_1:N | m) = sum_i
log p(y_i | Y_1:i-1, m), and each increment (the change of the mixture's log evidence) is
discounted, L_m <- g_N L_m + [log p(Y_1:N | m) - log p(Y_1:N-1 | m)]. The factor is either the
paper's forgetting factor per observation (g_N = gamma) or, by default, a half-life in time
(g_N = 0.5 ** ((t_N - t_N-1) / half_life_s)), so that sparse scans and dense streams forget on the
same clock (see :mod:`~psg_data.estimators._cadence`). With g = 1 this is exactly the paper's model
likelihood.

Eq. 14 far from the data (kept as the paper writes it). As t - t_N grows, alpha(t) -> 0 and the
model posterior tends to the prior f(t), so the prediction tends to f(t) p_emg(t) +
(1 - f(t)) p_per(t). For an edge last seen absent p_per is near 0 and p_emg(t) = P(emerged by t),
so the belief is about f(t) x P(emerged by t): *below* the prior f(t) itself. The variant
``perpetua_star_annealed`` (:class:`PerpetuaStarAnnealedEstimator`) anneals the prediction too,
p = alpha(t) p_eq14 + (1 - alpha(t)) f(t), so that without data the belief is the prior; it is not
the paper's estimator and is reported beside it.

Survival clocks (a choice the paper leaves open, documented here): a persistence model's survival
time counts from the appearance of the feature, an emergence model's from its disappearance. After
each observation the filtered state s_N = [p(x_tN | Y) >= 0.5] (eq. 14 at alpha = 1) is computed;
when it turns to present the persistence mixture restarts at t_N, when it turns to absent the
emergence mixture restarts at t_N. There is no threshold heuristic and no simulation between
observations; predictions are closed form.

Batches are processed speculatively: both mixtures are scanned over a chunk assuming no restart
(vectorised), the first change of s is located, the state is committed up to it, the restarted
model re-reads that observation, and the scan continues (chunk sizes adapt to the change rate).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._cadence import Cadence, training_cadence
from psg_data.estimators._common import (
    TRAINING_PARAMETERS,
    BaseEstimator,
    BaseFilter,
    escape_floors,
    fit_training,
    log_fit_summary,
    streams_by_edge,
)
from psg_data.estimators._fremen_estimator import (
    fit_fremen_edge,
    fremen_order_parameters,
    order_selection_summary,
    training_clock,
)
from psg_data.estimators._mixture import ESCAPE, ESCAPE_FIRST, MixtureFilter, ScanResult
from psg_data.estimators._params import Integral, MappingParam, Options, Real
from psg_data.estimators._priors import (
    PROFILE_DAYS,
    ConstantPrior,
    FremenPrior,
    OraclePrior,
    ProfilePrior,
    SchedulePrior,
    SwitchingPrior,
    parse_llm_schedule,
    prior_from_dict,
)
from psg_data.estimators._survival import SurvivalMixture

__all__ = ["PerpetuaStarEstimator", "PerpetuaStarAnnealedEstimator", "PerpetuaStarFilter", "discounted_cumsum",
           "discounted_cumsum_log"]

log = logging.getLogger(__name__)

PRIOR_KINDS = ("fremen", "profile", "oracle", "schedule", "none")


def discounted_cumsum(l0: float, inc: NDArray[np.float64], gamma: float) -> NDArray[np.float64]:
    """L_i = gamma * L_{i-1} + inc_i with L_{-1} = l0, vectorised (len(inc) must keep gamma^-n finite)."""
    n = inc.size
    if gamma >= 1.0:
        return l0 + np.cumsum(inc)
    if gamma <= 0.0:
        return inc.copy()
    j = np.arange(n, dtype=np.float64)
    lg = math.log(gamma)
    return np.exp(lg * j) * (gamma * l0 + np.cumsum(inc * np.exp(-lg * j)))


def discounted_cumsum_log(l0: float, inc: NDArray[np.float64], log_g: NDArray[np.float64]) -> NDArray[np.float64]:
    """L_i = g_i * L_{i-1} + inc_i with L_{-1} = l0 and per-step factors g_i = exp(log_g_i) <= 1.

    Vectorised in stretches over which the cumulative factor stays above e^-300 (so that its
    inverse is finite); a factor of 0 (log -inf) restarts the sum.
    """
    n = inc.size
    out = np.empty(n)
    prev, a = float(l0), 0
    while a < n:
        c = np.cumsum(log_g[a:])
        ok = c > -300.0
        m = n - a if ok.all() else int(np.argmin(ok))
        if m == 0:
            prev = math.exp(float(log_g[a])) * prev + float(inc[a])
            out[a] = prev
            a += 1
            continue
        seg = c[:m]
        out[a:a + m] = np.exp(seg) * (prev + np.cumsum(inc[a:a + m] * np.exp(-seg)))
        prev = float(out[a + m - 1])
        a += m
    return out


def _logit(p: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.log(p) - np.log1p(-p)


def _sigmoid(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


_SCALAR_MAX = 6  # batches up to this size take the scalar path
_STEPS_AFTER_RESTART = 4  # scalar steps of a model right after it restarts
_FIRST_CHUNK = 128  # rows of a model's first scan (after its scalar steps)
_GROWTH = 4  # a model's next scan is this many times longer than its previous one
_MAX_CHUNK = 512  # rows per scan (short scans waste less work when the model restarts)


class _Track:
    """One model's scanned rows [a, h) of the current batch and its state after row h - 1."""

    __slots__ = ("a", "h", "res", "L", "p", "n0", "c")

    def __init__(self, a: int, h: int, res: ScanResult, L: NDArray[np.float64], p: NDArray[np.float64], n0: int,
                 c: int) -> None:
        self.a, self.h, self.res, self.L, self.p, self.n0, self.c = a, h, res, L, p, n0, c


class _Batch:
    """The arrays and the two models of one :meth:`PerpetuaStarFilter._update_many` call.

    ``Ls`` / ``Es`` are the filter's own lists (the discounted log-likelihood ratios and the last
    log evidences of the persistence and emergence models), updated in place.
    """

    def __init__(self, f: PerpetuaStarFilter, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        self.t, self.yi, self.n = t, y.astype(np.intp), int(t.size)
        self.plogit = f._prior_logit(t)
        self.models = (f.per, f.emg)
        self.log_g = f._log_g(f._last_t, t)
        self.Ls, self.Es = f._Ls, f._Es

    def scan(self, j: int, a: int, c: int, st: tuple[Any, ...]) -> _Track:
        """Rows [a, a + c) of model j from state ``st`` (:meth:`live` / :meth:`last_state`)."""
        origin, tau0, l0, ly0, lsf0, e0, l_0, n0 = st
        b = min(self.n, a + c)
        origin = float(self.t[a]) if origin is None else origin
        res = self.models[j].scan_from(origin, tau0, l0, ly0, lsf0, self.t[a:b], self.yi[a:b])
        ev = res.log_evidence
        inc = np.empty(b - a)
        inc[0] = ev[0] - e0
        np.subtract(ev[1:], ev[:-1], out=inc[1:])
        L = discounted_cumsum_log(l_0, inc, self.log_g[a:b])
        p = res.p_own if j == 0 else 1.0 - res.p_own
        return _Track(a, b, res, L, p, n0, min(_MAX_CHUNK, c * _GROWTH))

    def live(self, j: int) -> tuple[Any, ...]:
        """Model j's current state, as :meth:`scan` takes it."""
        m = self.models[j]
        return (m.origin, m.tau, m.l, m.ly, m.lsf, self.Es[j], self.Ls[j], m.n)

    @staticmethod
    def last_state(tr: _Track) -> tuple[Any, ...]:
        """The state after a track's last row, as :meth:`scan` takes it."""
        r, i = tr.res, tr.h - tr.a - 1
        return (r.origin, float(r.tau[i]), float(r.l[i]), r.ly[:, i], r.lsf[:, i], float(r.log_evidence[i]),
                float(tr.L[i]), tr.n0 + i + 1)

    def extend(self, tracks: list[_Track | None], left: list[int], pos: int) -> None:
        """Scan a stepped model whose scalar steps are used up, or a scanned one whose rows end at pos."""
        for j in (0, 1):
            tr = tracks[j]
            if tr is None:
                if left[j] <= 0:
                    tracks[j] = self.scan(j, pos, _FIRST_CHUNK, self.live(j))
            elif tr.h <= pos:
                tracks[j] = self.scan(j, pos, tr.c, self.last_state(tr))

    def first_change(self, tp: _Track, te: _Track, pos: int, phase: int) -> tuple[int, int | None]:
        """(phase, first row >= pos where the filtered state leaves it, or None) over the rows both cover."""
        h = min(tp.h, te.h)
        ip, ie = pos - tp.a, pos - te.a
        m = h - pos
        z = te.L[ie:ie + m] - tp.L[ip:ip + m]
        z += self.plogit[pos:h]
        w = _sigmoid(z)
        s = (w * te.p[ie:ie + m] + (1.0 - w) * tp.p[ip:ip + m]) >= 0.5
        if phase < 0:
            phase = int(s[0])
        ch = s != bool(phase)
        return phase, (pos + int(np.argmax(ch)) if ch.any() else None)

    def step_one(self, k: int, tracks: list[_Track | None], left: list[int]) -> int:
        """The filtered state at row k, stepping the models that have no rows there."""
        tk, yk = float(self.t[k]), int(self.yi[k])
        Ls, Es = self.Ls, self.Es
        lv, pv = [0.0, 0.0], [0.0, 0.0]
        for j in (0, 1):
            tr = tracks[j]
            if tr is None:
                e, po = self.models[j].step(tk, yk)
                Ls[j] = math.exp(float(self.log_g[k])) * Ls[j] + (e - Es[j])
                Es[j] = e
                left[j] -= 1
                lv[j], pv[j] = Ls[j], (po if j == 0 else 1.0 - po)
            else:
                r = k - tr.a
                lv[j], pv[j] = float(tr.L[r]), float(tr.p[r])
        w1 = 0.5 * (1.0 + math.tanh(0.5 * ((lv[1] - lv[0]) + float(self.plogit[k]))))
        return int(w1 * pv[1] + (1.0 - w1) * pv[0] >= 0.5)

    def restart(self, j: int, k: int, tracks: list[_Track | None], left: list[int]) -> None:
        """Model j restarts at t_k: its rows are dropped and it is stepped for the next few rows."""
        tr = tracks[j]
        if tr is not None:
            self.Ls[j] = float(tr.L[k - tr.a])
            tracks[j] = None
        mj = self.models[j]
        mj.reset(float(self.t[k]))
        self.Es[j] = mj.step(float(self.t[k]), int(self.yi[k]))[0]
        left[j] = _STEPS_AFTER_RESTART

    def commit(self, tracks: list[_Track | None]) -> None:
        """Write the scanned models' states after the last row back into the models."""
        for j, mj in enumerate(self.models):
            tr = tracks[j]
            if tr is not None:
                i = self.n - 1 - tr.a
                mj.commit(tr.res, i)
                mj.n = tr.n0 + i + 1
                self.Es[j] = float(tr.res.log_evidence[i])
                self.Ls[j] = float(tr.L[i])


class PerpetuaStarFilter(BaseFilter):
    """One edge of Perpetua*. See the module docstring for the equations."""

    def __init__(self, edge: EdgeKey, per: SurvivalMixture, emg: SurvivalMixture, p_m: float, p_f: float,
                 prior: SwitchingPrior, *, gamma: float | None, alpha0_per_s: float, prior_floor: float,
                 half_life_s: float | None = None, escape: float = ESCAPE, escape_first: float = ESCAPE_FIRST,
                 anneal_prediction: bool = False, name: str = "perpetua_star") -> None:
        super().__init__(edge)
        if (gamma is None) == (half_life_s is None):
            raise EstimatorError(f"edge {edge}: give exactly one of gamma (per observation) and half_life_s")
        self.per = MixtureFilter(per, p_m, p_f, emergence=False, escape=escape, escape_first=escape_first)
        self.emg = MixtureFilter(emg, p_m, p_f, emergence=True, escape=escape, escape_first=escape_first)
        self.prior = prior
        self.gamma = None if gamma is None else float(gamma)
        self.half_life_s = None if half_life_s is None else float(half_life_s)
        # log of the forgetting factor: constant per observation, or -ln2 / half-life per second
        self._lg_obs = None if gamma is None else (math.log(gamma) if gamma > 0 else -math.inf)
        self._lg_per_s = None if half_life_s is None else -math.log(2.0) / float(half_life_s)
        self.alpha0_per_s = float(alpha0_per_s)
        self.prior_floor = float(prior_floor)
        self.anneal_prediction = bool(anneal_prediction)
        self._name = name
        self._Ls = [0.0, 0.0]  # discounted log evidence [per, emg]
        self._Es = [0.0, 0.0]  # current mixture log evidence [per, emg]
        self.phase = -1  # filtered state after the last observation (-1: none yet)
        self.n_restarts = 0
        self._const_logit: float | None = None
        self._logit_memo: tuple[Any, float, NDArray[np.float64], NDArray[np.float64]] | None = None
        if isinstance(prior, ConstantPrior):
            f = min(max(float(np.clip(prior.value, 0.0, 1.0)), self.prior_floor), 1.0 - self.prior_floor)
            self._const_logit = math.log(f) - math.log1p(-f)

    def _log_g(self, t_prev: float | None, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n,) log forgetting factors of the steps into the times ``t`` (after ``t_prev``)."""
        if self._lg_obs is not None:
            return np.full(t.size, self._lg_obs)
        dt = np.diff(t, prepend=t[0] if t_prev is None else t_prev)
        return self._lg_per_s * np.maximum(dt, 0.0)

    def _g_one(self, t: float, t_prev: float | None) -> float:
        if self._lg_obs is not None:
            return math.exp(self._lg_obs)
        if t_prev is None:
            return 1.0
        assert self._lg_per_s is not None  # forgetting in time when not per observation
        return math.exp(self._lg_per_s * max(t - t_prev, 0.0))

    @property
    def L(self) -> NDArray[np.float64]:
        """Discounted model log likelihoods [persistence, emergence]."""
        return np.array(self._Ls)

    @L.setter
    def L(self, v: ArrayLike) -> None:
        self._Ls = [float(x) for x in np.asarray(v, dtype=np.float64).reshape(2)]

    @property
    def E(self) -> NDArray[np.float64]:
        """Current mixture log evidences [persistence, emergence]."""
        return np.array(self._Es)

    @E.setter
    def E(self, v: ArrayLike) -> None:
        self._Es = [float(x) for x in np.asarray(v, dtype=np.float64).reshape(2)]

    # ------------------------------------------------------------------ update
    def _prior_logit_of(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        f = np.clip(self.prior(t), self.prior_floor, 1.0 - self.prior_floor)
        return _logit(f)

    def _prior_logit(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Logit of the floored prior at times ``t``; remembered for the next :meth:`_prior_logit_one`."""
        if self._const_logit is not None:
            return np.full(t.shape, self._const_logit)
        out = self._prior_logit_of(t)
        self._logit_memo = (self.prior, self.prior_floor, np.array(t, dtype=np.float64, copy=True), out)
        return out

    def _prior_logit_one(self, t: float) -> float:
        """:meth:`_prior_logit` at one time; taken from the last array call when it had ``t`` (the prior is
        elementwise: the same number), as the adaptive loop's update at a time it has just predicted.
        """
        if self._const_logit is not None:
            return self._const_logit
        memo = self._logit_memo
        if memo is not None and memo[0] is self.prior and memo[1] == self.prior_floor and memo[2].ndim == 1:
            ts = memo[2]
            i = int(np.searchsorted(ts, t))
            if i < ts.size and ts[i] == t:
                return float(memo[3][i])
        return float(self._prior_logit_of(np.array([t]))[0])

    def update(self, t_s: float, y: int) -> None:
        """One observation through the scalar path (same equations as :meth:`update_many`)."""
        t = float(t_s)
        if not math.isfinite(t):
            raise EstimatorError(f"edge {self.edge}: observation times must be finite")
        if y not in (0, 1):
            raise EstimatorError(f"edge {self.edge}: observations must be 0 or 1")
        if self._last_t is not None and t < self._last_t:
            raise EstimatorError(f"edge {self.edge}: observation at t={t} is earlier than the last one at "
                                 f"t={self._last_t}")
        self._step(t, int(y), self._last_t)
        self._last_t = t

    def _step(self, t: float, y: int, t_prev: float | None) -> None:
        g = self._g_one(t, t_prev)
        e_p, pp = self.per.step(t, y)
        e_e, po = self.emg.step(t, y)
        lp = g * self._Ls[0] + (e_p - self._Es[0])
        le = g * self._Ls[1] + (e_e - self._Es[1])
        self._Ls = [lp, le]
        self._Es = [e_p, e_e]
        w = 0.5 * (1.0 + math.tanh(0.5 * ((le - lp) + self._prior_logit_one(t))))
        s = int(w * (1.0 - po) + (1.0 - w) * pp >= 0.5)
        if self.phase < 0:
            self.phase = s
        elif s != self.phase:
            self.phase = s
            j = 0 if s == 1 else 1
            m = self.per if j == 0 else self.emg
            m.reset(t)
            self._Es[j] = m.step(t, y)[0]
            self.n_restarts += 1

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        """Batch update, equal to one :meth:`_step` per observation (up to rounding).

        Each model is either *scanned* (vectorised rows ahead of the current position, computed
        from its own state only: they stay valid until that model restarts) or *stepped* (scalar,
        :meth:`MixtureFilter.step`). Where both are scanned, the filtered state s_i is evaluated
        over all the rows both cover at once and its first change located. A restarted model is
        stepped for the next few observations (the filtered state often flips straight back after
        an isolated outlier) and then scanned again with geometrically growing lookahead; the
        other model's rows are reused. Each restart therefore costs O(1) scalar work plus, for
        the restarts that stick, one short scan.
        """
        n = t.size
        if n <= _SCALAR_MAX:
            prev = self._last_t
            for ti, yv in zip(t.tolist(), y.tolist()):
                self._step(ti, yv, prev)
                prev = ti
            return
        bt = _Batch(self, t, y)
        c0 = min(_MAX_CHUNK, _FIRST_CHUNK)
        tracks: list[_Track | None] = [bt.scan(0, 0, c0, bt.live(0)), bt.scan(1, 0, c0, bt.live(1))]
        left = [0, 0]  # scalar steps left before a stepped model is scanned again
        pos, phase = 0, self.phase
        while pos < n:
            bt.extend(tracks, left, pos)
            tp, te = tracks
            if tp is not None and te is not None:
                phase, k = bt.first_change(tp, te, pos, phase)
                if k is None:
                    pos = min(tp.h, te.h)
                    continue
            else:  # one observation, stepping the models without rows
                k = pos
                s1 = bt.step_one(k, tracks, left)
                if phase < 0:
                    phase = s1
                if s1 == phase:
                    pos = k + 1
                    continue
            # the filtered state changes at k: the model of the new state restarts at t_k
            phase = 1 - phase
            bt.restart(0 if phase == 1 else 1, k, tracks, left)
            self.n_restarts += 1
            pos = k + 1
        self.phase = phase
        bt.commit(tracks)

    # ------------------------------------------------------------------ predict
    def model_posterior(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """p(M = emergence | Y) at times t (eq. 13)."""
        t = np.asarray(t, dtype=np.float64)
        if self._last_t is None:
            return np.clip(self.prior(t), 0.0, 1.0)
        alpha = np.exp(-self.alpha0_per_s * np.maximum(t - self._last_t, 0.0))
        return _sigmoid(alpha * (self.L[1] - self.L[0]) + self._prior_logit(t))

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        if self._last_t is None:
            return np.clip(self.prior(t), 0.0, 1.0)
        w = self.model_posterior(t)
        p = w * self.emg.predict(t) + (1.0 - w) * self.per.predict(t)
        if self.anneal_prediction:
            alpha = np.exp(-self.alpha0_per_s * np.maximum(t - self._last_t, 0.0))
            p = alpha * p + (1.0 - alpha) * np.clip(self.prior(t), 0.0, 1.0)
        return p

    # ------------------------------------------------------------------ state
    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t,
                "per": self.per.get_state(), "emg": self.emg.get_state(), "L": self.L.tolist(),
                "E": self.E.tolist(), "phase": self.phase, "n_restarts": self.n_restarts,
                "per_survival": self.per.survival.to_dict(), "emg_survival": self.emg.survival.to_dict(),
                "p_m": self.per.p_m, "p_f": self.per.p_f, "prior": self.prior.to_dict(), "gamma": self.gamma,
                "half_life_s": self.half_life_s, "alpha0_per_s": self.alpha0_per_s, "prior_floor": self.prior_floor,
                "escape": [self.per.escape, self.per.escape_first], "anneal_prediction": self.anneal_prediction}

    @classmethod
    def from_state(cls, s: dict[str, Any]) -> PerpetuaStarFilter:
        f = cls((s["edge"][0], s["edge"][1]), SurvivalMixture.from_dict(s["per_survival"]),
                SurvivalMixture.from_dict(s["emg_survival"]), s["p_m"], s["p_f"], prior_from_dict(s["prior"]),
                gamma=s["gamma"], half_life_s=s["half_life_s"], alpha0_per_s=s["alpha0_per_s"],
                prior_floor=s["prior_floor"], escape=s["escape"][0], escape_first=s["escape"][1],
                anneal_prediction=s["anneal_prediction"], name=s["estimator"])
        f.per.set_state(s["per"])
        f.emg.set_state(s["emg"])
        f.L = s["L"]
        f.E = s["E"]
        f.phase = int(s["phase"])
        f.n_restarts = int(s["n_restarts"])
        f._last_t = s["last_t_s"]
        return f


def _edge_key_of(k: Any) -> EdgeKey:
    if isinstance(k, str):
        for sep in ("/", "|", "@"):
            if sep in k:
                a, b = k.split(sep, 1)
                return (a.strip(), b.strip())
        raise EstimatorError(f"schedule key {k!r}: expected (object, receptacle) or 'object/receptacle'")
    return (str(k[0]), str(k[1]))


class PerpetuaStarEstimator(BaseEstimator):
    """Perpetua* (paper Sec. "Perpetua*").

    Settings left at None are derived from the training streams' cadence (the typical gap g
    between observations, :mod:`~psg_data.estimators._cadence`) and recorded with their source in
    ``fit_summary_`` (also logged at INFO); the persistence benchmark passes the paper's values.

    Args:
        prior: switching prior: "fremen" (default), "profile" (eq. 10's piecewise-constant form
            learned from the training observations: day type x step of the day), "oracle" (needs
            ground truth in the training streams' ``meta['gt_t_s']`` / ``meta['gt_state']`` or
            ``ground_truth``), "schedule" (needs ``schedules``) or "none" (f = 0.5).
        gamma: the paper's forgetting factor *per observation* (0.99 in the paper); None: forget
            in time with ``half_life_s``. Give at most one of the two.
        half_life_s: forgetting half-life in seconds (None and gamma None: g).
        alpha0: annealing decay rate per ``time_unit_s`` (the paper: 0.01 per minute); None: ln 2 / g.
        time_unit_s: the time unit of alpha0, seconds (60: per minute).
        max_components, survival, p_m, p_f, segmentation, durations, min_segment, segment_penalty,
            pool_weight, sigma_min, escape: training and filter settings shared with ``perpetua``
            (:data:`~psg_data.estimators._common.TRAINING_PARAMETERS`): the survival mixtures are fitted
            by interval-censored EM to the runs of the states given by the pooled error-rate HMM
            (``segmentation="hmm"``), which also estimates P_M and P_F.
        n_periods, max_order, order_tol, order_rule, duration_rule: FreMEn prior: candidate periods
            one week / k, k = 1..n_periods (None: the shortest period is 2 g, at most 1000), order chosen
            on validation data (``val_streams``, else each edge's last training week) by the same rules
            and defaults as the ``fremen`` estimator (:class:`~psg_data.estimators.FremenEstimator`): the
            public FreMEn code's order rule ("reference") and duration rule (on); the choice is
            reported in ``fit_summary_["order_selection"]``.
        profile_step_s, profile_days: profile prior: step length (None: g rounded to a divisor of a
            day) and day types ("workweek": Mon-Fri / Sat-Sun, "all", "weekday").
        schedules: for prior="schedule": mapping edge -> LLM answer text (the prompt's list format)
            or list of 'Day: HH:MM - Day: HH:MM' strings; keys (object, receptacle) or 'object/receptacle'.
        schedule_inside, schedule_outside: prior value inside / outside the scheduled intervals.
        ground_truth: for prior="oracle": mapping edge -> (t_s, state) dense grid (optional when
            the streams carry it in ``meta``).
        prior_floor: the prior is clipped to [prior_floor, 1 - prior_floor] inside the logit.
        random_state: seed of the EM restarts.
    """

    name = "perpetua_star"
    survivals_: dict[EdgeKey, tuple[SurvivalMixture, SurvivalMixture]]
    default_survivals_: tuple[SurvivalMixture, SurvivalMixture]
    p_m_: float
    p_f_: float
    gamma_: float | None
    half_life_s_: float | None
    anneal_prediction = False
    _parameters = {
        "prior": Options(*PRIOR_KINDS, help="switching prior"),
        "gamma": Real(0.0, 1.0, none_ok=True, help="forgetting factor per observation (paper); none: half_life_s"),
        "half_life_s": Real(0.0, None, closed="neither", none_ok=True,
                            help="forgetting half-life, seconds; none: the typical gap between observations"),
        "alpha0": Real(0.0, None, none_ok=True, help="annealing decay rate per time_unit_s; none: ln 2 / typical gap"),
        "time_unit_s": Real(0.0, None, closed="right", help="time unit of alpha0, seconds"),
        **TRAINING_PARAMETERS,
        "n_periods": Integral(1, None, none_ok=True, help="FreMEn prior: candidate periods one week / k; none: "
                              "shortest period twice the typical gap (at most 1000)"),
        **fremen_order_parameters("FreMEn prior: "),
        "profile_step_s": Real(0.0, 86400.0, closed="right", none_ok=True,
                               help="profile prior: step of the day, seconds; none: the typical gap"),
        "profile_days": Options(*PROFILE_DAYS, help="profile prior: day types"),
        "schedules": MappingParam(help="schedule prior: edge -> LLM-format schedule"),
        "schedule_inside": Real(0.0, 1.0, help="schedule prior value inside the scheduled intervals"),
        "schedule_outside": Real(0.0, 1.0, help="schedule prior value outside them"),
        "ground_truth": MappingParam(help="oracle prior: edge -> (t_s, state)"),
        "prior_floor": Real(0.0, 0.5, closed="neither", help="prior clipped to [floor, 1 - floor]"),
    }

    def __init__(self, *, prior: str = "fremen", gamma: float | None = None, half_life_s: float | None = None,
                 alpha0: float | None = None, time_unit_s: float = 60.0, max_components: int = 5,
                 survival: str = "lognormal", p_m: float | None = None, p_f: float | None = None,
                 segmentation: str = "hmm", durations: str = "segments", min_segment: int = 5,
                 segment_penalty: float = 3.0, pool_weight: float = 2.0, sigma_min: float = 0.05,
                 escape: float = ESCAPE, n_periods: int | None = None, max_order: int | None = None,
                 order_tol: float = 1e-3, order_rule: str = "reference", duration_rule: bool = True,
                 profile_step_s: float | None = None, profile_days: str = "workweek",
                 schedules: Mapping[Any, Any] | None = None, schedule_inside: float = 0.9,
                 schedule_outside: float = 0.1, ground_truth: Mapping[Any, Any] | None = None,
                 prior_floor: float = 1e-3, random_state: int = 0) -> None:
        self.prior = prior
        self.gamma = gamma
        self.half_life_s = half_life_s
        self.alpha0 = alpha0
        self.time_unit_s = time_unit_s
        self.max_components = max_components
        self.survival = survival
        self.p_m = p_m
        self.p_f = p_f
        self.segmentation = segmentation
        self.durations = durations
        self.min_segment = min_segment
        self.segment_penalty = segment_penalty
        self.pool_weight = pool_weight
        self.sigma_min = sigma_min
        self.escape = escape
        self.n_periods = n_periods
        self.max_order = max_order
        self.order_tol = order_tol
        self.order_rule = order_rule
        self.duration_rule = duration_rule
        self.profile_step_s = profile_step_s
        self.profile_days = profile_days
        self.schedules = schedules
        self.schedule_inside = schedule_inside
        self.schedule_outside = schedule_outside
        self.ground_truth = ground_truth
        self.prior_floor = prior_floor
        self.random_state = random_state

    def _validate(self) -> None:
        self.validate_params()
        if self.prior == "schedule" and not self.schedules:
            raise EstimatorError(f"{self.name}: prior='schedule' needs schedules={{(object, receptacle): llm_answer}}")
        if self.gamma is not None and self.half_life_s is not None:
            raise EstimatorError(f"{self.name}: give gamma (forgetting per observation) or half_life_s (per time), "
                                 f"not both (got gamma={self.gamma}, half_life_s={self.half_life_s})")

    def _resolve(self, cad: Cadence) -> dict[str, dict[str, Any]]:
        """Resolved forgetting, annealing and prior settings with where each value came from."""
        src = f"cadence: typical gap {cad.typical_gap_s:g} s" + ("" if cad.measured else " (fallback)")
        out: dict[str, dict[str, Any]] = {}
        if self.gamma is not None:
            self.gamma_, self.half_life_s_ = float(self.gamma), None
            out["forgetting"] = {"value": f"gamma {self.gamma:g} per observation", "source": "set"}
        else:
            self.gamma_ = None
            self.half_life_s_ = float(self.half_life_s) if self.half_life_s is not None else cad.half_life_s
            out["forgetting"] = {"value": f"half-life {self.half_life_s_:g} s",
                                 "source": "set" if self.half_life_s is not None else src}
        if self.alpha0 is not None:
            self.alpha0_per_s_ = float(self.alpha0) / float(self.time_unit_s)
            out["alpha0"] = {"value": f"{self.alpha0:g} per {self.time_unit_s:g} s ({self.alpha0_per_s_:.4g} per s)",
                             "source": "set"}
        else:
            self.alpha0_per_s_ = cad.alpha0_per_s
            out["alpha0"] = {"value": f"{self.alpha0_per_s_ * float(self.time_unit_s):.4g} per {self.time_unit_s:g} s "
                             f"({self.alpha0_per_s_:.4g} per s)", "source": src}
        self.n_periods_ = int(self.n_periods) if self.n_periods is not None else cad.n_periods
        if self.prior == "fremen":
            out["n_periods"] = {"value": self.n_periods_, "source": "set" if self.n_periods is not None else src}
        self.profile_step_s_ = float(self.profile_step_s) if self.profile_step_s is not None else cad.profile_step_s
        if self.prior == "profile":
            out["profile_step_s"] = {"value": self.profile_step_s_,
                                     "source": "set" if self.profile_step_s is not None else src}
        return out

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> PerpetuaStarEstimator:
        """Learn the mixtures, error rates and switching priors; see ``fit_summary_`` for every decision."""
        self._validate()
        streams = list(streams)
        tr = streams_by_edge(streams)
        va = streams_by_edge(val_streams)
        cad = training_cadence(streams)
        settings = self._resolve(cad)
        training = fit_training(self, streams)
        self.timezone_ = timezone
        self.clock_ = training_clock(streams, timezone)
        self.priors_: dict[EdgeKey, SwitchingPrior] = {}
        self.fit_info_: dict[EdgeKey, dict[str, Any]] = {}
        for e, ss in tr.items():
            self.priors_[e] = self._fit_prior(e, ss, va.get(e))
        self._extra_schedule_priors()
        self.fit_summary_ = {"estimator": self.name, "cadence": cad.to_dict(), "settings": settings, **training}
        if self.prior == "fremen":
            self.fit_summary_["order_selection"] = order_selection_summary(self.order_rule, self.duration_rule,
                                                                           self.order_tol, self.fit_info_)
        log_fit_summary(self.name, self.fit_summary_)
        self.fitted_ = True
        return self

    def _fit_prior(self, e: EdgeKey, ss: list[EdgeStream], val: list[EdgeStream] | None) -> SwitchingPrior:
        if self.prior == "fremen":
            comps, info = fit_fremen_edge(ss, val, self.clock_, n_periods=self.n_periods_,
                                          order_tol=self.order_tol, max_order=self.max_order,
                                          order_rule=self.order_rule, duration_rule=self.duration_rule)
            self.fit_info_[e] = info
            return FremenPrior(comps, self.clock_)
        if self.prior == "profile":
            t = np.concatenate([s.t_s for s in ss])
            y = np.concatenate([s.y for s in ss])
            return ProfilePrior.fit(t, y, step_s=self.profile_step_s_, days=self.profile_days, timezone=self.timezone_)
        if self.prior == "oracle":
            gt = self._ground_truth_for(e, ss)
            return OraclePrior.from_ground_truth(gt[0], gt[1], self.clock_)
        if self.prior == "schedule":
            sp = self._schedule_for(e)
            return sp if sp is not None else ConstantPrior(0.5)
        return ConstantPrior(0.5)

    def _ground_truth_for(self, e: EdgeKey, ss: list[EdgeStream]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if self.ground_truth:
            for k, v in self.ground_truth.items():
                if _edge_key_of(k) == e:
                    return np.asarray(v[0], dtype=np.float64), np.asarray(v[1], dtype=np.float64)
        ts, xs = [], []
        for s in ss:
            if "gt_t_s" in s.meta and "gt_state" in s.meta:
                ts.append(np.asarray(s.meta["gt_t_s"], dtype=np.float64))
                xs.append(np.asarray(s.meta["gt_state"], dtype=np.float64))
        if not ts:
            raise EstimatorError(f"{self.name}: prior='oracle' needs ground truth for edge {e}: pass ground_truth= or "
                                 "streams with meta['gt_t_s'] and meta['gt_state']")
        return np.concatenate(ts), np.concatenate(xs)

    def _schedule_for(self, e: EdgeKey) -> SchedulePrior | None:
        for k, v in (self.schedules or {}).items():
            if _edge_key_of(k) == e:
                text = v if isinstance(v, str) else repr(list(v))
                return SchedulePrior(parse_llm_schedule(text), float(self.schedule_inside),
                                     float(self.schedule_outside), self.timezone_)
        return None

    def _extra_schedule_priors(self) -> None:
        if self.prior == "schedule":
            for k in self.schedules or {}:
                e = _edge_key_of(k)
                if e not in self.priors_:
                    sp = self._schedule_for(e)
                    if sp is not None:
                        self.priors_[e] = sp

    def _prior_for(self, e: EdgeKey) -> SwitchingPrior:
        return self.priors_.get(e, ConstantPrior(0.5))

    def make_filter(self, edge: EdgeKey) -> PerpetuaStarFilter:
        """A new filter for ``edge`` (object_id, receptacle_id) with the fitted models, before any observation."""
        self._check_fitted()
        edge = (str(edge[0]), str(edge[1]))
        per, emg = self.survivals_.get(edge, self.default_survivals_)
        esc, esc1 = escape_floors(self.escape)
        return PerpetuaStarFilter(edge, per, emg, self.p_m_, self.p_f_, self._prior_for(edge), gamma=self.gamma_,
                                  half_life_s=self.half_life_s_, alpha0_per_s=self.alpha0_per_s_,
                                  prior_floor=float(self.prior_floor), escape=esc, escape_first=esc1,
                                  anneal_prediction=self.anneal_prediction, name=self.name)

    def filter_from_state(self, state: dict[str, Any]) -> PerpetuaStarFilter:
        """The filter that :meth:`get_state` of one of this estimator's filters described."""
        self._check_state(state)
        return PerpetuaStarFilter.from_state(state)


class PerpetuaStarScheduleEstimator(PerpetuaStarEstimator):
    """``perpetua_star_schedule``: Perpetua* with the LLM schedule prior (``schedules`` required)."""

    name = "perpetua_star_schedule"

    def __init__(self, *, prior: str = "schedule", **kwargs: Any) -> None:
        super().__init__(prior=prior, **kwargs)


class PerpetuaStarOracleEstimator(PerpetuaStarEstimator):
    """``perpetua_star_oracle``: Perpetua* with the oracle prior (training ground truth required)."""

    name = "perpetua_star_oracle"

    def __init__(self, *, prior: str = "oracle", **kwargs: Any) -> None:
        super().__init__(prior=prior, **kwargs)


class PerpetuaStarAnnealedEstimator(PerpetuaStarEstimator):
    """``perpetua_star_annealed``: Perpetua* whose *prediction* also anneals to the prior (not the paper's).

    p(t) = alpha(t) p_eq14(t) + (1 - alpha(t)) f(t) with alpha(t) = exp(-alpha0 (t - t_N)): near the
    last observation it is eq. 14, far from it the switching prior f(t) (which eq. 14 undershoots
    for edges last seen absent, see the module docstring). Same settings as ``perpetua_star``.
    """

    name = "perpetua_star_annealed"
    anneal_prediction = True
