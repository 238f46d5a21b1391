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

import copy
import math
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


class _Terms:
    """What :meth:`MixtureFilter.predict` needs of a mixture's state, computed once per state.

    ``k`` and ``e`` are the dominant component and its log evidence; the state is recognised by its
    lists and arrays (the mixture replaces them at every change, never edits them in place; holding
    them here keeps their identities from being reused) and its floats.
    """

    __slots__ = ("key", "floats", "k", "e", "p1", "p2")

    def __init__(self, m: MixtureFilter) -> None:
        self.key = (m.ly, m.lsf, m.log_prior)
        self.floats = (m.l, m.origin, m.tau)
        self.k, self.e = m.dominant_evidence()
        self.p1, self.p2 = m.survival.p1[self.k], m.survival.p2[self.k]

    def holds(self, m: MixtureFilter) -> bool:
        a, b, c = self.key
        return a is m.ly and b is m.lsf and c is m.log_prior and self.floats == (m.l, m.origin, m.tau)


def _mixture_predict(m: MixtureFilter, terms: _Terms | None, t: NDArray[np.float64]) -> tuple[
        NDArray[np.float64], _Terms | None]:
    """``m.predict(t)`` (the same operations), with the state's terms cached; returns (prediction, terms)."""
    if m.origin is None:
        return (np.zeros_like(t) if m.emergence else np.ones_like(t)), terms
    if terms is None or not terms.holds(m):
        terms = _Terms(m)
    tau = np.maximum(t - m.origin, m.tau)
    if m.survival.family == "lognormal":  # SurvivalMixture.log_sf_one's operations for one component
        from scipy.special import log_ndtr

        with np.errstate(divide="ignore"):
            lt = np.log(np.maximum(tau, 0.0))
        lsf = log_ndtr((terms.p1 - lt) / terms.p2)
    else:
        lsf = m.survival.log_sf_one(tau, terms.k)
    p = np.exp(np.minimum(m.l + lsf - terms.e, 0.0))
    return (1.0 - p if m.emergence else p), terms


def _mixture_predict_one(m: MixtureFilter, terms: _Terms | None, x: float) -> tuple[float, _Terms | None]:
    """``m.predict([x])[0]`` for a log-normal mixture, as floats (IEEE arithmetic and numpy's own log and
    exp, which are what the array form computes element by element).
    """
    from scipy.special import log_ndtr

    if m.origin is None:
        return (0.0 if m.emergence else 1.0), terms
    if terms is None or not terms.holds(m):
        terms = _Terms(m)
    tau = x - m.origin
    if tau < m.tau:
        tau = m.tau
    lt = float(np.log(tau)) if tau > 0.0 else -math.inf  # np.log(0.0) = -inf
    v = m.l + float(log_ndtr((terms.p1 - lt) / terms.p2)) - terms.e
    p = float(np.exp(v if v < 0.0 else 0.0))
    return (1.0 - p if m.emergence else p), terms


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
        self._terms: dict[str, _Terms | None] = {"per": None, "emg": None}

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

    def _active_predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """The active mixture's prediction at ``t`` (its terms cached while its state lasts)."""
        which = self.active
        p, self._terms[which] = _mixture_predict(self.per if which == "per" else self.emg, self._terms[which], t)
        return p

    def _crossed(self, t: NDArray[np.float64]) -> NDArray[np.bool_]:
        p = self._active_predict(t)
        return p <= self.delta_low if self.active == "per" else p >= self.delta_high

    def _simulate(self, grid: NDArray[np.float64]) -> None:
        """Advance the state machine over sorted times (no observations)."""
        i = 0
        while i < grid.size:
            hit = np.flatnonzero(self._crossed(grid[i:]))
            if hit.size == 0:
                return
            self._switch(float(grid[i + hit[0]]))
            i += int(hit[0]) + 1

    def _simulate_each(self, times: list[float]) -> None:
        """:meth:`_simulate` one time after the other (floats: cheaper for the few times of an update)."""
        if self.per.survival.family != "lognormal" or self.emg.survival.family != "lognormal":
            self._simulate(np.asarray(times, np.float64))
            return
        for x in times:
            which = self.active
            m = self.per if which == "per" else self.emg
            p, self._terms[which] = _mixture_predict_one(m, self._terms[which], x)
            if (p <= self.delta_low) if which == "per" else (p >= self.delta_high):
                self._switch(x)

    def _sub_steps(self, a: float, b: float) -> list[float]:
        """``np.linspace(a, b, num_steps + 2)[1:-1]`` (the same operations: ``i * step + a``)."""
        div = self.num_steps + 1
        step = (b - a) / div
        if step == 0.0:  # denormal span: linspace's own handling
            return np.linspace(a, b, self.num_steps + 2)[1:-1].tolist()  # type: ignore[no-any-return]
        return [i * step + a for i in range(1, div)]

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        for ti, yi in zip(t.tolist(), y.tolist()):
            if self._last_t is not None and ti > self._last_t and self.num_steps > 0:
                self._simulate_each(self._sub_steps(self._last_t, ti))
            self.per.update(ti, yi)
            if self.emg.started:
                self.emg.update(ti, yi)
            self._simulate_each([ti])
            self._last_t = ti

    def start(self, t_s: float) -> None:
        """Start in the persistence state with the survival clock at ``t_s`` (before any observation)."""
        super().start(t_s)
        self.per.reset(float(t_s))
        self.active = "per"

    def _grid(self, t0: float, ts: NDArray[np.float64]) -> NDArray[np.float64]:
        """The simulation grid: query times plus ``num_steps`` sub-steps between consecutive distinct times."""
        if ts.size == 1:  # one query time x >= t0: the same sums as below, on floats
            x, n = float(ts[0]), self.num_steps
            if x == t0 or n == 0:
                return np.array(sorted({t0, x}))
            return np.array(sorted({t0, x, *[t0 + (x - t0) * (j / (n + 1)) for j in range(1, n + 1)]}))
        knots = np.unique(np.concatenate([[t0], ts]))
        if self.num_steps > 0 and knots.size > 1:
            frac = np.arange(1, self.num_steps + 1) / (self.num_steps + 1)
            sub = (knots[:-1, None] + np.diff(knots)[:, None] * frac).reshape(-1)
            return np.unique(np.concatenate([knots, sub]))
        return knots

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        t0 = self._last_t if self._last_t is not None else self.per.origin
        if t0 is None:  # never started: the present state
            return np.ones(t.shape)
        t = np.maximum(t, t0)
        order = np.argsort(t, kind="stable")
        ts = t[order]
        grid = self._grid(t0, ts)
        sim = self  # copied at the first switch: until then the walk only reads the state
        out_sorted = np.empty(ts.size)
        # walk the grid phase by phase; queries are answered by the model active at their time
        i = 0
        q = 0
        while q < ts.size:
            hit = np.flatnonzero(sim._crossed(grid[i:]))
            end = grid[i + hit[0]] if hit.size else np.inf
            # queries strictly before the switch time use the current model
            qe = int(np.searchsorted(ts, end, side="left"))
            out_sorted[q:qe] = sim._active_predict(ts[q:qe])
            q = qe
            if hit.size == 0:
                break
            if sim is self:
                sim = self._copy()
            sim._switch(float(end))
            i += int(hit[0]) + 1
        out = np.empty(ts.size)
        out[order] = out_sorted
        return out

    def _copy(self) -> PerpetuaFilter:
        """A copy to simulate on: the mixtures' states are replaced, never edited, so shallow copies do."""
        c = copy.copy(self)
        c.per, c.emg = copy.copy(self.per), copy.copy(self.emg)
        c._terms = dict(self._terms)
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
