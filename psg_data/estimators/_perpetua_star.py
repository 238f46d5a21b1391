"""Perpetua*: persistence and emergence mixtures combined by Bayesian model selection (eqs. 9-14).

Per edge, a mixture of persistence filters (M_per) and a mixture of emergence filters (M_emg) are
both updated with every observation. The model posterior at t >= t_N is (eq. 13)

    logit p(M_emg | Y) = alpha(t) * (L_emg - L_per) + logit f(t),   alpha(t) = exp(-alpha0 (t - t_N))

with f(t) the switching prior (FreMEn, schedule, oracle or constant) clipped to
[prior_floor, 1 - prior_floor], and the prediction is the posterior-weighted average of the two
models' dominant-component predictions (eq. 14).

Model log likelihoods with forgetting factor gamma. L_m is the marginal log evidence of model m
(denominator of eq. 7) accumulated with forgetting: by the chain rule
log p(Y_1:N | m) = sum_i log p(y_i | Y_1:i-1, m), and each increment (the change of the mixture's
log evidence) is discounted, L_m <- gamma L_m + [log p(Y_1:N | m) - log p(Y_1:N-1 | m)]. With
gamma = 1 this is exactly the paper's model likelihood.

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
from psg_data.estimators._common import TRAINING_PARAMETERS, BaseEstimator, BaseFilter, fit_survivals, streams_by_edge
from psg_data.estimators._fremen_estimator import fit_fremen_edge, training_clock
from psg_data.estimators._mixture import MixtureFilter, ScanResult
from psg_data.estimators._params import Integral, MappingParam, Options, Real
from psg_data.estimators._priors import (
    ConstantPrior,
    FremenPrior,
    OraclePrior,
    SchedulePrior,
    SwitchingPrior,
    parse_llm_schedule,
    prior_from_dict,
)
from psg_data.estimators._survival import SurvivalMixture
from psg_data.estimators._training import collect_durations

__all__ = ["PerpetuaStarEstimator", "PerpetuaStarFilter", "discounted_cumsum"]

log = logging.getLogger(__name__)

PRIOR_KINDS = ("fremen", "oracle", "schedule", "none")


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


def _chunk_limit(gamma: float) -> int:
    if gamma >= 1.0 or gamma <= 0.0:
        return 32768
    return int(max(1, min(32768, math.floor(600.0 / -math.log(gamma)))))


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


class PerpetuaStarFilter(BaseFilter):
    """One edge of Perpetua*. See the module docstring for the equations."""

    def __init__(self, edge: EdgeKey, per: SurvivalMixture, emg: SurvivalMixture, p_m: float, p_f: float,
                 prior: SwitchingPrior, *, gamma: float, alpha0_per_s: float, prior_floor: float,
                 name: str = "perpetua_star") -> None:
        super().__init__(edge)
        self.per = MixtureFilter(per, p_m, p_f, emergence=False)
        self.emg = MixtureFilter(emg, p_m, p_f, emergence=True)
        self.prior = prior
        self.gamma = float(gamma)
        self.alpha0_per_s = float(alpha0_per_s)
        self.prior_floor = float(prior_floor)
        self._name = name
        self._Ls = [0.0, 0.0]  # discounted log evidence [per, emg]
        self._Es = [0.0, 0.0]  # current mixture log evidence [per, emg]
        self.phase = -1  # filtered state after the last observation (-1: none yet)
        self.n_restarts = 0
        self._const_logit: float | None = None
        if isinstance(prior, ConstantPrior):
            f = min(max(float(np.clip(prior.value, 0.0, 1.0)), self.prior_floor), 1.0 - self.prior_floor)
            self._const_logit = math.log(f) - math.log1p(-f)

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
    def _prior_logit(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        if self._const_logit is not None:
            return np.full(t.shape, self._const_logit)
        f = np.clip(self.prior(t), self.prior_floor, 1.0 - self.prior_floor)
        return _logit(f)

    def _prior_logit_one(self, t: float) -> float:
        if self._const_logit is not None:
            return self._const_logit
        return float(self._prior_logit(np.array([t]))[0])

    def update(self, t_s: float, y: int) -> None:
        """One observation through the scalar path (same equations as :meth:`update_many`)."""
        t = float(t_s)
        if not math.isfinite(t):
            raise EstimatorError(f"edge {self.edge}: observation times must be finite")
        if y not in (0, 1):
            raise EstimatorError(f"edge {self.edge}: observations must be 0 or 1")
        if self._last_t is not None and t < self._last_t:
            raise EstimatorError(f"edge {self.edge}: observation at t={t} is earlier than the last one at t={self._last_t}")
        self._step(t, int(y))
        self._last_t = t

    def _step(self, t: float, y: int) -> None:
        e_p, pp = self.per.step(t, y)
        e_e, po = self.emg.step(t, y)
        g = self.gamma
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
            for ti, yv in zip(t.tolist(), y.tolist()):
                self._step(ti, yv)
            return
        yi = y.astype(np.intp)
        plogit = self._prior_logit(t)
        models = (self.per, self.emg)
        cmax = min(_MAX_CHUNK, _chunk_limit(self.gamma))
        gamma = self.gamma
        Ls, Es = self._Ls, self._Es

        def scan(j: int, a: int, c: int, st: tuple[Any, ...]) -> _Track:
            origin, tau0, l0, ly0, lsf0, e0, l_0, n0 = st
            b = min(n, a + c)
            origin = float(t[a]) if origin is None else origin
            res = models[j].scan_from(origin, tau0, l0, ly0, lsf0, t[a:b], yi[a:b])
            ev = res.log_evidence
            inc = np.empty(b - a)
            inc[0] = ev[0] - e0
            np.subtract(ev[1:], ev[:-1], out=inc[1:])
            L = discounted_cumsum(l_0, inc, gamma)
            p = res.p_own if j == 0 else 1.0 - res.p_own
            return _Track(a, b, res, L, p, n0, min(cmax, c * _GROWTH))

        def live(j: int) -> tuple[Any, ...]:
            m = models[j]
            return (m.origin, m.tau, m.l, m.ly, m.lsf, Es[j], Ls[j], m.n)

        def last_state(tr: _Track) -> tuple[Any, ...]:
            r, i = tr.res, tr.h - tr.a - 1
            return (r.origin, float(r.tau[i]), float(r.l[i]), r.ly[:, i], r.lsf[:, i], float(r.log_evidence[i]),
                    float(tr.L[i]), tr.n0 + i + 1)

        c0 = min(cmax, _FIRST_CHUNK)
        tracks: list[_Track | None] = [scan(0, 0, c0, live(0)), scan(1, 0, c0, live(1))]
        left = [0, 0]  # scalar steps left before a stepped model is scanned again
        pos = 0
        phase = self.phase
        while pos < n:
            for j in (0, 1):
                tr = tracks[j]
                if tr is None:
                    if left[j] <= 0:
                        tracks[j] = scan(j, pos, _FIRST_CHUNK, live(j))
                elif tr.h <= pos:
                    tracks[j] = scan(j, pos, tr.c, last_state(tr))
            tp, te = tracks
            if tp is not None and te is not None:
                h = min(tp.h, te.h)
                ip, ie = pos - tp.a, pos - te.a
                m = h - pos
                z = te.L[ie:ie + m] - tp.L[ip:ip + m]
                z += plogit[pos:h]
                w = _sigmoid(z)
                s = (w * te.p[ie:ie + m] + (1.0 - w) * tp.p[ip:ip + m]) >= 0.5
                if phase < 0:
                    phase = int(s[0])
                ch = s != bool(phase)
                if not ch.any():
                    pos = h
                    continue
                k = pos + int(np.argmax(ch))
            else:  # one observation, stepping the models without rows
                k = pos
                tk, yk = float(t[k]), int(yi[k])
                lv, pv = [0.0, 0.0], [0.0, 0.0]
                for j in (0, 1):
                    tr = tracks[j]
                    if tr is None:
                        e, po = models[j].step(tk, yk)
                        Ls[j] = gamma * Ls[j] + (e - Es[j])
                        Es[j] = e
                        left[j] -= 1
                        lv[j], pv[j] = Ls[j], (po if j == 0 else 1.0 - po)
                    else:
                        r = k - tr.a
                        lv[j], pv[j] = float(tr.L[r]), float(tr.p[r])
                w1 = 0.5 * (1.0 + math.tanh(0.5 * ((lv[1] - lv[0]) + float(plogit[k]))))
                s1 = int(w1 * pv[1] + (1.0 - w1) * pv[0] >= 0.5)
                pos = k + 1
                if phase < 0:
                    phase = s1
                if s1 == phase:
                    continue
            # the filtered state changes at k: the model of the new state restarts at t_k
            phase = 1 - phase
            j = 0 if phase == 1 else 1
            tr = tracks[j]
            if tr is not None:
                r = k - tr.a
                Ls[j] = float(tr.L[r])
                tracks[j] = None
            mj = models[j]
            mj.reset(float(t[k]))
            Es[j] = mj.step(float(t[k]), int(yi[k]))[0]
            left[j] = _STEPS_AFTER_RESTART
            self.n_restarts += 1
            pos = k + 1
        self.phase = phase
        for j, mj in enumerate(models):
            tr = tracks[j]
            if tr is not None:
                i = n - 1 - tr.a
                mj.commit(tr.res, i)
                mj.n = tr.n0 + i + 1
                Es[j] = float(tr.res.log_evidence[i])
                Ls[j] = float(tr.L[i])

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
        return w * self.emg.predict(t) + (1.0 - w) * self.per.predict(t)

    # ------------------------------------------------------------------ state
    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t,
                "per": self.per.get_state(), "emg": self.emg.get_state(), "L": self.L.tolist(),
                "E": self.E.tolist(), "phase": self.phase, "n_restarts": self.n_restarts,
                "per_survival": self.per.survival.to_dict(), "emg_survival": self.emg.survival.to_dict(),
                "p_m": self.per.p_m, "p_f": self.per.p_f, "prior": self.prior.to_dict(), "gamma": self.gamma,
                "alpha0_per_s": self.alpha0_per_s, "prior_floor": self.prior_floor}

    @classmethod
    def from_state(cls, s: dict[str, Any]) -> PerpetuaStarFilter:
        f = cls((s["edge"][0], s["edge"][1]), SurvivalMixture.from_dict(s["per_survival"]),
                SurvivalMixture.from_dict(s["emg_survival"]), s["p_m"], s["p_f"], prior_from_dict(s["prior"]),
                gamma=s["gamma"], alpha0_per_s=s["alpha0_per_s"], prior_floor=s["prior_floor"], name=s["estimator"])
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

    Args:
        prior: switching prior: "fremen" (default), "oracle" (needs ground truth in the training
            streams' ``meta['gt_t_s']`` / ``meta['gt_state']`` or ``ground_truth``), "schedule" (needs
            ``schedules``) or "none" (f = 0.5).
        gamma: forgetting factor on the model likelihoods (0.99).
        alpha0: annealing decay rate per ``time_unit_s`` (0.01 per minute by default).
        time_unit_s: the time unit of alpha0, seconds.
        max_components: largest number of log-normal components tried by AIC (5).
        p_m, p_f: detector error rates; None estimates them from the training data.
        durations: where training durations come from: "segments" (change points of the
            observations), "ground_truth" or "auto".
        min_segment, segment_penalty: change-point segmentation of the training streams (PELT with
            a Bernoulli cost; the reference's 5 observations and 3 nats). With sparse observations
            (a few scans a day) short visits give fewer than ``min_segment`` observations and are
            then treated as detector noise: lower both (e.g. 1 and 1) for such data.
        n_periods, max_order, order_tol: FreMEn prior settings (1000 periods, order on validation).
        schedules: for prior="schedule": mapping edge -> LLM answer text (the prompt's list format)
            or list of 'Day: HH:MM - Day: HH:MM' strings; keys (object, receptacle) or 'object/receptacle'.
        schedule_inside, schedule_outside: prior value inside / outside the scheduled intervals.
        ground_truth: for prior="oracle": mapping edge -> (t_s, state) dense grid (optional when
            the streams carry it in ``meta``).
        prior_floor: the prior is clipped to [prior_floor, 1 - prior_floor] inside the logit.
        random_state: seed of the EM restarts.
    """

    name = "perpetua_star"
    _parameters = {
        "prior": Options(*PRIOR_KINDS, help="switching prior"),
        "gamma": Real(0.0, 1.0, help="forgetting factor on the model likelihoods, per observation"),
        "alpha0": Real(0.0, None, help="annealing decay rate per time_unit_s"),
        "time_unit_s": Real(0.0, None, closed="right", help="time unit of alpha0, seconds"),
        **TRAINING_PARAMETERS,
        "n_periods": Integral(0, None, help="FreMEn prior: candidate periods one week / k"),
        "max_order": Integral(0, None, none_ok=True, help="FreMEn prior: largest order tried"),
        "order_tol": Real(0.0, None, help="FreMEn prior: MAE tolerance favouring smaller orders"),
        "schedules": MappingParam(help="schedule prior: edge -> LLM-format schedule"),
        "schedule_inside": Real(0.0, 1.0, help="schedule prior value inside the scheduled intervals"),
        "schedule_outside": Real(0.0, 1.0, help="schedule prior value outside them"),
        "ground_truth": MappingParam(help="oracle prior: edge -> (t_s, state)"),
        "prior_floor": Real(0.0, 0.5, closed="neither", help="prior clipped to [floor, 1 - floor]"),
    }

    def __init__(self, *, prior: str = "fremen", gamma: float = 0.99, alpha0: float = 0.01, time_unit_s: float = 60.0,
                 max_components: int = 5, p_m: float | None = None, p_f: float | None = None,
                 durations: str = "segments", min_segment: int = 5, segment_penalty: float = 3.0,
                 n_periods: int = 1000, max_order: int | None = None,
                 order_tol: float = 1e-3, schedules: Mapping[Any, Any] | None = None, schedule_inside: float = 0.9,
                 schedule_outside: float = 0.1, ground_truth: Mapping[Any, Any] | None = None,
                 prior_floor: float = 1e-3, random_state: int = 0) -> None:
        self.prior = prior
        self.gamma = gamma
        self.alpha0 = alpha0
        self.time_unit_s = time_unit_s
        self.max_components = max_components
        self.p_m = p_m
        self.p_f = p_f
        self.durations = durations
        self.min_segment = min_segment
        self.segment_penalty = segment_penalty
        self.n_periods = n_periods
        self.max_order = max_order
        self.order_tol = order_tol
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

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> PerpetuaStarEstimator:
        self._validate()
        streams = list(streams)
        tr = streams_by_edge(streams)
        va = streams_by_edge(val_streams)
        durs, (pm, pf) = collect_durations(streams, source=self.durations, min_size=int(self.min_segment),
                                           penalty=float(self.segment_penalty))
        self.p_m_ = float(self.p_m) if self.p_m is not None else pm
        self.p_f_ = float(self.p_f) if self.p_f is not None else pf
        self.survivals_, self.default_survivals_ = fit_survivals(
            durs, max_components=int(self.max_components), seed=int(self.random_state))
        self.timezone_ = timezone
        self.clock_ = training_clock(streams, timezone)
        self.priors_: dict[EdgeKey, SwitchingPrior] = {}
        self.fit_info_: dict[EdgeKey, dict[str, Any]] = {}
        for e, ss in tr.items():
            self.priors_[e] = self._fit_prior(e, ss, va.get(e))
        self._extra_schedule_priors()
        self.fitted_ = True
        return self

    def _fit_prior(self, e: EdgeKey, ss: list[EdgeStream], val: list[EdgeStream] | None) -> SwitchingPrior:
        if self.prior == "fremen":
            comps, info = fit_fremen_edge(ss, val, self.clock_, n_periods=int(self.n_periods),
                                          order_tol=self.order_tol, max_order=self.max_order)
            self.fit_info_[e] = info
            return FremenPrior(comps, self.clock_)
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
        self._check_fitted()
        edge = (str(edge[0]), str(edge[1]))
        per, emg = self.survivals_.get(edge, self.default_survivals_)
        return PerpetuaStarFilter(edge, per, emg, self.p_m_, self.p_f_, self._prior_for(edge), gamma=float(self.gamma),
                                  alpha0_per_s=float(self.alpha0) / float(self.time_unit_s),
                                  prior_floor=float(self.prior_floor), name=self.name)

    def filter_from_state(self, state: dict[str, Any]) -> PerpetuaStarFilter:
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
