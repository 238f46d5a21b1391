"""The simple methods of the FreMEn authors' benchmark framework, as psg-data estimators.

``chronorobotics/framework2`` (``Mean.hs``, ``Histogram.hs``, ``DoorState.hs``) scores two simple
methods beside FreMEn; psg-data reports them as reference rows on the real benchmarks:

- ``training_mean`` (their ``Mean``): the edge's training base rate, a constant;
- ``time_of_day_histogram`` (their ``Hist``): the training mean of the same time-of-day bin (local
  time), the number of bins per day chosen per edge among (3, 4, 6, 12, 24) by the mean squared
  error on the training data itself (their ``bruteForceTrain``); an empty bin predicts 0, as their
  ``meanDivision _ 0 = 0``.

Neither adapts online: updates only record the time.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._common import BaseEstimator, BaseFilter, streams_by_edge
from psg_data.estimators._fremen import LocalClock
from psg_data.estimators._fremen_estimator import training_clock
from psg_data.estimators._params import Integral

__all__ = ["TrainingMeanEstimator", "TimeOfDayHistogramEstimator", "HIST_BINS_PER_DAY"]

DAY_S = 86400.0
HIST_BINS_PER_DAY = (3, 4, 6, 12, 24)
"""Bins per day the histogram chooses among (the authors' list)."""


def _edge_arrays(ss: Sequence[EdgeStream]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    return np.concatenate([s.t_s for s in ss]), np.concatenate([s.y for s in ss]).astype(np.float64)


class _TableFilter(BaseFilter):
    """Predicts ``table[bin(t)]`` with ``len(table)`` equal bins of a local day (one bin: a constant)."""

    def __init__(self, edge: EdgeKey, table: NDArray[np.float64], clock: LocalClock, name: str) -> None:
        super().__init__(edge)
        self.table = np.asarray(table, dtype=np.float64)
        self.clock = clock
        self._name = name

    def _update_many(self, t: NDArray[np.float64], y: NDArray[np.int8]) -> None:
        pass

    def _predict(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        nb = self.table.size
        i = np.minimum((np.mod(self.clock(t), DAY_S) * (nb / DAY_S)).astype(np.int64), nb - 1)
        return self.table[i]

    def get_state(self) -> dict[str, Any]:
        return {"estimator": self._name, "edge": list(self.edge), "last_t_s": self._last_t,
                "table": self.table.tolist(), "clock": self.clock.to_dict()}


class _TableEstimator(BaseEstimator):
    """Shared fit plumbing: one day-bin table per edge."""

    def _table(self, tau: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        raise NotImplementedError

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Sequence[EdgeStream] | None = None,
            timezone: str = "UTC") -> _TableEstimator:
        """Fit one table per edge to the training streams (times in s, UTC); returns self."""
        self.validate_params()
        streams = list(streams)
        self.clock_ = training_clock(streams, timezone)
        self.tables_: dict[EdgeKey, NDArray[np.float64]] = {}
        for e, ss in streams_by_edge(streams).items():
            t, y = _edge_arrays(ss)
            self.tables_[e] = self._table(self.clock_(t), y)
        self.fitted_ = True
        return self

    def make_filter(self, edge: EdgeKey) -> _TableFilter:
        """A new filter for ``edge`` (0.5 for an edge without training data)."""
        self._check_fitted()
        return _TableFilter(edge, self.tables_.get(edge, np.full(1, 0.5)), self.clock_, self.name)

    def filter_from_state(self, state: dict[str, Any]) -> _TableFilter:
        """The filter that :meth:`get_state` of one of this estimator's filters described."""
        edge = self._check_state(state)
        f = _TableFilter(edge, np.asarray(state["table"], np.float64), LocalClock.from_dict(state["clock"]),
                         self.name)
        f._last_t = state["last_t_s"]
        return f


class TrainingMeanEstimator(_TableEstimator):
    """The edge's training base rate everywhere (the authors' ``Mean``; 0.5 for an edge never observed)."""

    name = "training_mean"

    def __init__(self) -> None:
        pass

    def _table(self, tau: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.full(1, float(y.mean()) if y.size else 0.5)


def day_bin_means(tau: NDArray[np.float64], y: NDArray[np.float64], nb: int) -> NDArray[np.float64]:
    """(nb,) mean of ``y`` in each of ``nb`` equal bins of the local day (0 for an empty bin)."""
    i = np.minimum((np.mod(tau, DAY_S) * (nb / DAY_S)).astype(np.int64), nb - 1)
    cnt = np.bincount(i, minlength=nb)
    tot = np.bincount(i, weights=y, minlength=nb)
    return np.where(cnt > 0, tot / np.maximum(cnt, 1), 0.0)


class TimeOfDayHistogramEstimator(_TableEstimator):
    """The training mean of the same local time-of-day bin (the authors' ``Hist``).

    Args:
        bins_per_day: bins of the day; None (default): per edge the one of :data:`HIST_BINS_PER_DAY`
            with the lowest mean squared error on the training data (the first on a tie).
    """

    name = "time_of_day_histogram"
    _parameters = {"bins_per_day": Integral(1, 1440, none_ok=True, help="bins of the local day; none: chosen "
                                            "among 3, 4, 6, 12, 24 by the training mean squared error")}

    def __init__(self, *, bins_per_day: int | None = None) -> None:
        self.bins_per_day = bins_per_day

    def _table(self, tau: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        if not y.size:
            return np.full(1, 0.5)
        choices = HIST_BINS_PER_DAY if self.bins_per_day is None else (int(self.bins_per_day),)
        best, table = np.inf, np.zeros(1)
        for nb in choices:
            tab = day_bin_means(tau, y, nb)
            i = np.minimum((np.mod(tau, DAY_S) * (nb / DAY_S)).astype(np.int64), nb - 1)
            err = float(np.mean((tab[i] - y) ** 2))
            if err < best:
                best, table = err, tab
        return table
