"""The Persistence Filter estimator (Rosen et al. 2016) and the baselines.

- ``persistence_filter``: one persistence filter per edge started at its first observation, with an
  exponential, log-normal, Weibull or log-logistic survival prior fitted (maximum likelihood) to
  the training present-run durations;
- ``last_seen``: the last observation (0.5 before any);
- ``always_present``: 1;
- ``always_absent``: 0 (a constant belief: chance level for balanced accuracy, F1 0);
- ``time_of_week_frequency``: fraction of present observations in the same local hour of the week
  (Laplace smoothed), from the training data.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._common import BaseEstimator, BaseFilter, streams_by_edge
from psg_data.estimators._fremen import WEEK_S, LocalClock
from psg_data.estimators._fremen_estimator import training_clock
from psg_data.estimators._mixture import MixtureFilter
from psg_data.estimators._params import Options, Pair, Real
from psg_data.estimators._survival import SURVIVAL_FAMILIES, SurvivalMixture
from psg_data.estimators._training import collect_durations

__all__ = ["PersistenceFilterEstimator", "PersistenceFilterFilter", "LastSeenEstimator", "AlwaysPresentEstimator",
           "AlwaysAbsentEstimator", "TimeOfWeekFrequencyEstimator", "fit_single_survival"]


def fit_single_survival(family: str, d: NDArray[np.float64]) -> SurvivalMixture:
    """Maximum-likelihood single-component survival prior for durations ``d`` (s)."""
    d = np.asarray(d, dtype=np.float64)
    d = d[d > 0]
    if d.size < 2:
        raise EstimatorError(f"fit_single_survival({family}): need >= 2 positive durations, got {d.size}")
    if family == "exponential":
        return SurvivalMixture.single("exponential", 1.0 / float(d.mean()))
    if family == "lognormal":
        x = np.log(d)
        return SurvivalMixture.single("lognormal", float(x.mean()), max(float(x.std()), 0.05))
    from scipy import stats

    if family == "weibull":
        c, _, scale = stats.weibull_min.fit(d, floc=0)
        return SurvivalMixture.single("weibull", float(c), float(scale))
    if family == "loglogistic":
        c, _, scale = stats.fisk.fit(d, floc=0)
        return SurvivalMixture.single("loglogistic", float(c), float(scale))
    raise EstimatorError(f"unknown survival family {family!r}; valid: {', '.join(SURVIVAL_FAMILIES)}")


class PersistenceFilterFilter(BaseFilter):
    def __init__(self, edge: EdgeKey, surv: SurvivalMixture, p_m: float, p_f: float,
                 name: str = "persistence_filter") -> None:
        super().__init__(edge)
        self.mix = MixtureFilter(surv, p_m, p_f, escape=0.0, escape_first=0.0)  # Rosen's exact recursion
        self._name = name

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        self.mix.update_many(t, y)

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.mix.predict(t)

    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t,
                "survival": self.mix.survival.to_dict(), "p_m": self.mix.p_m, "p_f": self.mix.p_f,
                "mix": self.mix.get_state()}


class PersistenceFilterEstimator(BaseEstimator):
    """Rosen et al.'s Persistence Filter.

    Args:
        survival: prior family: "exponential", "lognormal", "weibull" or "loglogistic".
        survival_params: (p1, p2) to fix the prior (see :data:`SURVIVAL_FAMILIES`); None fits it per
            edge by maximum likelihood on the training present-run durations.
        p_m, p_f: detector error rates; None estimates them from the training data.
        durations: "segments", "ground_truth" or "auto" (see :func:`collect_durations`).
    """

    name = "persistence_filter"
    _parameters = {
        "survival": Options(*SURVIVAL_FAMILIES, help="survival prior family"),
        "survival_params": Pair(none_ok=True, help="fixed prior parameters (p1, p2); none: fitted per edge"),
        "p_m": Real(0.0, 0.5, none_ok=True, help="P(seen absent | present); none: estimated"),
        "p_f": Real(0.0, 0.5, none_ok=True, help="P(seen present | absent); none: estimated"),
        "durations": Options("segments", "ground_truth", "auto", help="where training run durations come from"),
    }

    def __init__(self, *, survival: str = "exponential", survival_params: tuple[float, float] | None = None,
                 p_m: float | None = None, p_f: float | None = None, durations: str = "segments") -> None:
        self.survival = survival
        self.survival_params = survival_params
        self.p_m = p_m
        self.p_f = p_f
        self.durations = durations

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> PersistenceFilterEstimator:
        """Fit per-edge models to the training streams (times in s, UTC); returns self."""
        self.validate_params()
        durs, (pm, pf) = collect_durations(list(streams), source=self.durations)
        self.p_m_ = float(self.p_m) if self.p_m is not None else pm
        self.p_f_ = float(self.p_f) if self.p_f is not None else pf
        self.survivals_: dict[EdgeKey, SurvivalMixture] = {}
        if self.survival_params is not None:
            p1, p2 = self.survival_params
            self.default_ = SurvivalMixture.single(self.survival, float(p1), float(p2))
        else:
            pooled = np.concatenate([d.present for d in durs.values()] or [np.zeros(0)])
            self.default_ = (fit_single_survival(self.survival, pooled) if pooled.size >= 2
                             else fit_single_survival(self.survival, np.array([3600.0, 7200.0])))
            for e, d in durs.items():
                if d.present.size >= 2:
                    self.survivals_[e] = fit_single_survival(self.survival, d.present)
                elif d.mostly_present:
                    long = max(4 * d.span_s, 86400.0)
                    self.survivals_[e] = fit_single_survival(self.survival, np.array([0.5 * long, 2.0 * long]))
        self.fitted_ = True
        return self

    def make_filter(self, edge: EdgeKey) -> PersistenceFilterFilter:
        """A new filter for ``edge`` (object_id, receptacle_id) with the fitted models, before any observation."""
        self._check_fitted()
        return PersistenceFilterFilter(edge, self.survivals_.get(edge, self.default_), self.p_m_, self.p_f_, self.name)

    def filter_from_state(self, state: dict[str, Any]) -> PersistenceFilterFilter:
        """The filter that :meth:`get_state` of one of this estimator's filters described."""
        edge = self._check_state(state)
        f = PersistenceFilterFilter(edge, SurvivalMixture.from_dict(state["survival"]), state["p_m"], state["p_f"],
                                    self.name)
        f.mix.set_state(state["mix"])
        f._last_t = state["last_t_s"]
        return f


# ---------------------------------------------------------------------------------------- baselines
class ConstantFilter(BaseFilter):
    """Predicts ``value`` at every time, or the last observation (0.5 before any) when ``value`` is None."""

    def __init__(self, edge: EdgeKey, name: str, value: float | None) -> None:
        super().__init__(edge)
        self._name = name
        self.value = value  # None: last observation
        self.last_y: int | None = None

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        self.last_y = int(y[-1])

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        if self.value is not None:
            return np.full(t.shape, self.value)
        return np.full(t.shape, 0.5 if self.last_y is None else float(self.last_y))

    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t, "last_y": self.last_y}


class _NoFitEstimator(BaseEstimator):
    value: float | None = None

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> _NoFitEstimator:
        streams_by_edge(streams)
        self.fitted_ = True
        return self

    def make_filter(self, edge: EdgeKey) -> ConstantFilter:
        self._check_fitted()
        return ConstantFilter(edge, self.name, self.value)

    def filter_from_state(self, state: dict[str, Any]) -> ConstantFilter:
        edge = self._check_state(state)
        f = ConstantFilter(edge, self.name, self.value)
        f.last_y = state["last_y"]
        f._last_t = state["last_t_s"]
        return f


class LastSeenEstimator(_NoFitEstimator):
    """Predicts the last observation (0.5 before any)."""

    name = "last_seen"

    def __init__(self) -> None:
        pass


class AlwaysPresentEstimator(_NoFitEstimator):
    """Predicts 1 everywhere."""

    name = "always_present"
    value = 1.0

    def __init__(self) -> None:
        pass


class AlwaysAbsentEstimator(_NoFitEstimator):
    """Predicts 0 everywhere: the chance row of the thresholded metrics (B-Acc 0.5, F1 0; MAE = the
    share of time the object is present).
    """

    name = "always_absent"
    value = 0.0

    def __init__(self) -> None:
        pass


class _TowFilter(BaseFilter):
    def __init__(self, edge: EdgeKey, table: NDArray[np.float64], clock: LocalClock, bin_s: float, name: str) -> None:
        super().__init__(edge)
        self.table = table
        self.clock = clock
        self.bin_s = bin_s
        self._name = name

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        pass

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        i = np.minimum((np.mod(self.clock(t), WEEK_S) / self.bin_s).astype(np.int64), self.table.size - 1)
        return self.table[i]

    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t,
                "table": self.table.tolist(), "clock": self.clock.to_dict(), "bin_s": self.bin_s}


class TimeOfWeekFrequencyEstimator(BaseEstimator):
    """P(present) = smoothed fraction of present observations in the same local time-of-week bin.

    Args:
        bin_s: bin width in seconds (one hour).
        pseudo_count: Laplace smoothing towards the edge's overall frequency.
    """

    name = "time_of_week_frequency"
    _parameters = {
        "bin_s": Real(0.0, WEEK_S, closed="right", help="time-of-week bin width, seconds"),
        "pseudo_count": Real(0.0, None, help="Laplace smoothing towards the edge's overall frequency"),
    }

    def __init__(self, *, bin_s: float = 3600.0, pseudo_count: float = 1.0) -> None:
        self.bin_s = bin_s
        self.pseudo_count = pseudo_count

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> TimeOfWeekFrequencyEstimator:
        """Fit per-edge models to the training streams (times in s, UTC); returns self."""
        self.validate_params()
        streams = list(streams)
        self.clock_ = training_clock(streams, timezone)
        nb = int(np.ceil(WEEK_S / float(self.bin_s)))
        self.tables_: dict[EdgeKey, NDArray[np.float64]] = {}
        for e, ss in streams_by_edge(streams).items():
            t = np.concatenate([s.t_s for s in ss])
            y = np.concatenate([s.y for s in ss]).astype(np.float64)
            i = np.minimum((np.mod(self.clock_(t), WEEK_S) / float(self.bin_s)).astype(np.int64), nb - 1)
            cnt = np.bincount(i, minlength=nb)
            tot = np.bincount(i, weights=y, minlength=nb)
            base = float(y.mean()) if y.size else 0.5
            a = float(self.pseudo_count)
            raw = np.where(cnt > 0, tot / np.maximum(cnt, 1), base)
            self.tables_[e] = (tot + a * base) / (cnt + a) if a > 0 else raw
        self.default_ = np.full(nb, 0.5)
        self.fitted_ = True
        return self

    def make_filter(self, edge: EdgeKey) -> _TowFilter:
        """A new filter for ``edge`` (object_id, receptacle_id) with the fitted models, before any observation."""
        self._check_fitted()
        return _TowFilter(edge, self.tables_.get(edge, self.default_), self.clock_, float(self.bin_s), self.name)

    def filter_from_state(self, state: dict[str, Any]) -> _TowFilter:
        """The filter that :meth:`get_state` of one of this estimator's filters described."""
        edge = self._check_state(state)
        if "table" in state:  # self-contained: no fit needed
            f = _TowFilter(edge, np.asarray(state["table"], np.float64), LocalClock.from_dict(state["clock"]),
                           float(state["bin_s"]), self.name)
        else:
            f = self.make_filter(edge)
        f._last_t = state["last_t_s"]
        return f
