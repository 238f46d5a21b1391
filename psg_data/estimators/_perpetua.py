"""Perpetua (Saavedra et al. 2025), the predecessor: mixtures coupled by a heuristic state machine.

Starts in the persistence state. Between observations (``num_steps`` simulated sub-steps per
interval) and after each update: in the persistence state, when the dominant persistence prediction
drops to <= delta_low a fresh emergence mixture starts at that time and becomes active; in the
emergence state, when the dominant emergence prediction reaches >= delta_high a fresh persistence
mixture starts. Restarted mixtures get component weights (1 - eps) * posterior of the previous
instance + eps * initial prior. The belief is the active mixture's prediction. Both mixtures are
updated with every observation (the emergence one once started).

Training (shared with Perpetua*): interval-censored EM on the runs of the training states; the
states come from the reference's own segmentation by default (``segmentation="reference"``: the
L2 PELT the public code really runs, see :mod:`~psg_data.estimators._segmentation`), error rates
from the disagreement of the observations with those segments. As the reference, each filter
starts in the persistence state (its survival clock at :meth:`PerpetuaFilter.start`, or at the
first observation) and never predicts 0.5 before its first observation; the mixtures' change
probabilities have the escape floor of :class:`~psg_data.estimators.MixtureFilter`.

Predictions simulate the state machine on the grid of query times (plus ``num_steps`` sub-steps
between consecutive ones); within one state the active prediction is monotone, so each state's
switching time is found with one vectorised pass.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._common import (
    TRAINING_PARAMETERS,
    BaseEstimator,
    BaseFilter,
    escape_floors,
    fit_training,
    log_fit_summary,
)
from psg_data.estimators._mixture import ESCAPE, ESCAPE_FIRST, MixtureFilter
from psg_data.estimators._params import Integral, Real
from psg_data.estimators._survival import SurvivalMixture

__all__ = ["PerpetuaEstimator", "PerpetuaFilter"]


class PerpetuaFilter(BaseFilter):
    def __init__(self, edge: EdgeKey, per: SurvivalMixture, emg: SurvivalMixture, p_m: float, p_f: float, *,
                 delta_low: float, delta_high: float, eps: float, num_steps: int, escape: float = ESCAPE,
                 escape_first: float = ESCAPE_FIRST, name: str = "perpetua") -> None:
        super().__init__(edge)
        self.per = MixtureFilter(per, p_m, p_f, escape=escape, escape_first=escape_first)
        self.emg = MixtureFilter(emg, p_m, p_f, emergence=True, escape=escape, escape_first=escape_first)
        self.delta_low = float(delta_low)
        self.delta_high = float(delta_high)
        self.eps = float(eps)
        self.num_steps = int(num_steps)
        self.active = "per"
        self._name = name

    def _reset_weights(self, m: MixtureFilter) -> NDArray[np.float64]:
        w0 = m.survival.weights
        w = (1 - self.eps) * m.posterior_weights() + self.eps * w0 if m.started else w0
        with np.errstate(divide="ignore"):
            return np.log(w)

    def _switch(self, t: float) -> None:
        if self.active == "per":
            lp = self._reset_weights(self.emg)
            self.emg.reset(t)
            self.emg.log_prior = lp
            self.active = "emg"
        else:
            lp = self._reset_weights(self.per)
            self.per.reset(t)
            self.per.log_prior = lp
            self.active = "per"

    def _crossed(self, m: MixtureFilter, t: NDArray[np.float64]) -> NDArray[np.bool_]:
        p = m.predict(t)
        return p <= self.delta_low if self.active == "per" else p >= self.delta_high

    def _simulate(self, grid: NDArray[np.float64]) -> None:
        """Advance the state machine over sorted times (no observations)."""
        i = 0
        while i < grid.size:
            m = self.per if self.active == "per" else self.emg
            hit = np.flatnonzero(self._crossed(m, grid[i:]))
            if hit.size == 0:
                return
            self._switch(float(grid[i + hit[0]]))
            i += int(hit[0]) + 1

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        for ti, yi in zip(t.tolist(), y.tolist()):
            if self._last_t is not None and ti > self._last_t and self.num_steps > 0:
                sub = np.linspace(self._last_t, ti, self.num_steps + 2)[1:-1]
                self._simulate(sub)
            self.per.update(ti, yi)
            if self.emg.started:
                self.emg.update(ti, yi)
            self._simulate(np.array([ti]))
            self._last_t = ti

    def start(self, t_s: float) -> None:
        """Start in the persistence state with the survival clock at ``t_s`` (before any observation)."""
        super().start(t_s)
        self.per.reset(float(t_s))
        self.active = "per"

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        t0 = self._last_t if self._last_t is not None else self.per.origin
        if t0 is None:  # never started: the present state
            return np.ones(t.shape)
        t = np.maximum(t, t0)
        order = np.argsort(t, kind="stable")
        ts = t[order]
        # simulation grid: query times plus num_steps sub-steps between consecutive distinct times
        knots = np.unique(np.concatenate([[t0], ts]))
        if self.num_steps > 0 and knots.size > 1:
            frac = np.arange(1, self.num_steps + 1) / (self.num_steps + 1)
            sub = (knots[:-1, None] + np.diff(knots)[:, None] * frac).reshape(-1)
            grid = np.unique(np.concatenate([knots, sub]))
        else:
            grid = knots
        sim = self._copy()
        out_sorted = np.empty(ts.size)
        # walk the grid phase by phase; queries are answered by the model active at their time
        i = 0
        q = 0
        while q < ts.size:
            m = sim.per if sim.active == "per" else sim.emg
            hit = np.flatnonzero(sim._crossed(m, grid[i:]))
            end = grid[i + hit[0]] if hit.size else np.inf
            # queries strictly before the switch time use the current model
            qe = int(np.searchsorted(ts, end, side="left"))
            out_sorted[q:qe] = m.predict(ts[q:qe])
            q = qe
            if hit.size == 0:
                break
            sim._switch(float(end))
            i += int(hit[0]) + 1
        out = np.empty(ts.size)
        out[order] = out_sorted
        return out

    def _copy(self) -> PerpetuaFilter:
        c = PerpetuaFilter(self.edge, self.per.survival, self.emg.survival, self.per.p_m, self.per.p_f,
                           delta_low=self.delta_low, delta_high=self.delta_high, eps=self.eps,
                           num_steps=self.num_steps, escape=self.per.escape, escape_first=self.per.escape_first,
                           name=self._name)
        c.per.set_state(self.per.get_state())
        c.emg.set_state(self.emg.get_state())
        c.active = self.active
        c._last_t = self._last_t
        return c

    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t, "active": self.active,
                "per": self.per.get_state(), "emg": self.emg.get_state(),
                "per_survival": self.per.survival.to_dict(), "emg_survival": self.emg.survival.to_dict(),
                "p_m": self.per.p_m, "p_f": self.per.p_f, "delta_low": self.delta_low, "delta_high": self.delta_high,
                "eps": self.eps, "num_steps": self.num_steps, "escape": [self.per.escape, self.per.escape_first]}

    @classmethod
    def from_state(cls, s: dict[str, Any]) -> PerpetuaFilter:
        f = cls((s["edge"][0], s["edge"][1]), SurvivalMixture.from_dict(s["per_survival"]),
                SurvivalMixture.from_dict(s["emg_survival"]), s["p_m"], s["p_f"], delta_low=s["delta_low"],
                delta_high=s["delta_high"], eps=s["eps"], num_steps=s["num_steps"], escape=s["escape"][0],
                escape_first=s["escape"][1], name=s["estimator"])
        f.per.set_state(s["per"])
        f.emg.set_state(s["emg"])
        f.active = s["active"]
        f._last_t = s["last_t_s"]
        return f


class PerpetuaEstimator(BaseEstimator):
    """Perpetua (the predecessor of Perpetua*), with the reference's defaults.

    Args:
        delta_low, delta_high: switching thresholds (0.05, 0.95).
        eps: weight of the initial component prior after a restart (0.1).
        num_steps: simulated sub-steps between observations / query times (1).
        max_components, survival, p_m, p_f, segmentation, durations, min_segment, segment_penalty,
            pool_weight, sigma_min, escape, random_state: training and filter settings shared with
            Perpetua* (``segmentation`` defaults to "reference", the public code's L2 PELT).
    """

    name = "perpetua"
    survivals_: dict[EdgeKey, tuple[SurvivalMixture, SurvivalMixture]]
    default_survivals_: tuple[SurvivalMixture, SurvivalMixture]
    p_m_: float
    p_f_: float
    _parameters = {
        "delta_low": Real(0.0, 1.0, closed="neither", help="switch to emergence when the belief drops to this"),
        "delta_high": Real(0.0, 1.0, closed="neither", help="switch back to persistence at this"),
        "eps": Real(0.0, 1.0, help="weight of the initial component prior after a restart"),
        "num_steps": Integral(0, None, help="simulated sub-steps between observations"),
        **TRAINING_PARAMETERS,
    }

    def __init__(self, *, delta_low: float = 0.05, delta_high: float = 0.95, eps: float = 0.1, num_steps: int = 1,
                 max_components: int = 5, survival: str = "lognormal", p_m: float | None = None,
                 p_f: float | None = None, segmentation: str = "reference", durations: str = "segments",
                 min_segment: int = 5, segment_penalty: float = 3.0, pool_weight: float = 2.0,
                 sigma_min: float = 0.05, escape: float = ESCAPE, random_state: int = 0) -> None:
        self.delta_low = delta_low
        self.delta_high = delta_high
        self.eps = eps
        self.num_steps = num_steps
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
        self.random_state = random_state

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> PerpetuaEstimator:
        """Fit per-edge models to the training streams (times in s, UTC); returns self."""
        self.validate_params()
        if not (0.0 < float(self.delta_low) < float(self.delta_high) < 1.0):
            raise EstimatorError(f"{self.name}: need 0 < delta_low < delta_high < 1, got {self.delta_low}, "
                                 f"{self.delta_high}")
        if int(self.num_steps) < 0 or not (0.0 <= float(self.eps) <= 1.0):
            raise EstimatorError(f"{self.name}: num_steps must be >= 0 and eps in [0, 1]")
        streams = list(streams)
        self.fit_summary_ = {"estimator": self.name, **fit_training(self, streams)}
        log_fit_summary(self.name, self.fit_summary_)
        self.fitted_ = True
        return self

    def make_filter(self, edge: EdgeKey) -> PerpetuaFilter:
        """A new filter for ``edge`` (object_id, receptacle_id) with the fitted models, before any observation."""
        self._check_fitted()
        edge = (str(edge[0]), str(edge[1]))
        per, emg = self.survivals_.get(edge, self.default_survivals_)
        esc, esc1 = escape_floors(self.escape)
        return PerpetuaFilter(edge, per, emg, self.p_m_, self.p_f_, delta_low=float(self.delta_low),
                              delta_high=float(self.delta_high), eps=float(self.eps), num_steps=int(self.num_steps),
                              escape=esc, escape_first=esc1, name=self.name)

    def filter_from_state(self, state: dict[str, Any]) -> PerpetuaFilter:
        """The filter that :meth:`get_state` of one of this estimator's filters described."""
        self._check_state(state)
        return PerpetuaFilter.from_state(state)
