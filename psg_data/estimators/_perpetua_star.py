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
from numpy.typing import NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._common import BaseEstimator, BaseFilter, fit_survivals, streams_by_edge
from psg_data.estimators._fremen_estimator import fit_fremen_edge, training_clock
from psg_data.estimators._mixture import MixtureFilter, ScanResult
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
        self.L = np.zeros(2)  # discounted log evidence [per, emg]
        self.E = np.zeros(2)  # current mixture log evidence [per, emg]
        self.phase = -1  # filtered state after the last observation (-1: none yet)
        self.n_restarts = 0

    # ------------------------------------------------------------------ update
    def _prior_logit(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        f = np.clip(self.prior(t), self.prior_floor, 1.0 - self.prior_floor)
        return _logit(f)

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        n = t.size
        pos = 0
        cmax = _chunk_limit(self.gamma)
        c = min(256, cmax)
        while pos < n:
            j = min(n, pos + c)
            tt, yy = t[pos:j], y[pos:j]
            rp = self.per.scan(tt, yy)
            re = self.emg.scan(tt, yy)
            inc_p = np.diff(rp.log_evidence, prepend=self.E[0])
            inc_e = np.diff(re.log_evidence, prepend=self.E[1])
            lp = discounted_cumsum(self.L[0], inc_p, self.gamma)
            le = discounted_cumsum(self.L[1], inc_e, self.gamma)
            w = _sigmoid((le - lp) + self._prior_logit(tt))
            p = w * (1.0 - re.p_own) + (1.0 - w) * rp.p_own
            s = (p >= 0.5).astype(np.int8)
            if self.phase < 0:
                self.phase = int(s[0])
            prev = np.concatenate([[self.phase], s[:-1]])
            ch = np.flatnonzero(s != prev)
            k = (j - pos - 1) if ch.size == 0 else int(ch[0])
            self._commit(rp, re, lp, le, k)
            if ch.size:
                self.phase = int(s[k])
                self._restart(1 if self.phase == 1 else 0, float(tt[k]), int(yy[k]))
                c = max(16, min(cmax, 2 * (k + 1)))
            else:
                self.phase = int(s[-1])
                c = min(cmax, 2 * c)
            pos += k + 1

    def _commit(self, rp: ScanResult, re: ScanResult, lp: NDArray[np.float64], le: NDArray[np.float64], k: int) -> None:
        self.per.commit(rp, k)
        self.emg.commit(re, k)
        self.L[:] = (lp[k], le[k])
        self.E[:] = (rp.log_evidence[k], re.log_evidence[k])

    def _restart(self, model_per: int, t: float, y: int) -> None:
        """Restart the persistence (model_per=1) or emergence (0) mixture at t with observation y."""
        m = self.per if model_per else self.emg
        m.reset(t)
        m.update_many(np.array([t]), np.array([y]))
        self.E[0 if model_per else 1] = m.log_evidence()
        self.n_restarts += 1

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
        f.L = np.asarray(s["L"], dtype=np.float64)
        f.E = np.asarray(s["E"], dtype=np.float64)
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

    def __init__(self, *, prior: str = "fremen", gamma: float = 0.99, alpha0: float = 0.01, time_unit_s: float = 60.0,
                 max_components: int = 5, p_m: float | None = None, p_f: float | None = None,
                 durations: str = "segments", n_periods: int = 1000, max_order: int | None = None,
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
        if self.prior not in PRIOR_KINDS:
            raise EstimatorError(f"{self.name}: prior must be one of {', '.join(PRIOR_KINDS)}, got {self.prior!r}")
        if not (0.0 <= float(self.gamma) <= 1.0):
            raise EstimatorError(f"{self.name}: gamma must be in [0, 1], got {self.gamma}")
        if float(self.alpha0) < 0 or float(self.time_unit_s) <= 0:
            raise EstimatorError(f"{self.name}: alpha0 must be >= 0 and time_unit_s > 0")
        if not (0.0 < float(self.prior_floor) < 0.5):
            raise EstimatorError(f"{self.name}: prior_floor must be in (0, 0.5), got {self.prior_floor}")
        if self.prior == "schedule" and not self.schedules:
            raise EstimatorError(f"{self.name}: prior='schedule' needs schedules={{(object, receptacle): llm_answer}}")

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> PerpetuaStarEstimator:
        self._validate()
        streams = list(streams)
        tr = streams_by_edge(streams)
        va = streams_by_edge(val_streams)
        durs, (pm, pf) = collect_durations(streams, source=self.durations)
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
