"""The ``ground_truth`` ceiling row: a pseudo-estimator that predicts the task's own ground truth.

Used where a dataset has no generator model (nothing better than the truth is defined); it is not
in the estimator registry (it reads the test ground truth, which no estimator may).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.estimators._base import EdgeKey, EdgeStream

__all__ = ["GroundTruthEstimator", "TruthFactory"]


class _TruthFilter:
    def __init__(self, edge: EdgeKey, t: NDArray[np.float64], y: NDArray[np.int64]) -> None:
        self.edge = edge
        self._t, self._y = t, (y == 1).astype(np.float64)
        self.last_t_s: float | None = None

    def update(self, t_s: float, y: int) -> None:
        self.last_t_s = float(t_s)

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        if t.size:
            self.last_t_s = float(t[-1])

    def predict(self, t_s: ArrayLike) -> NDArray[np.float64]:
        t = np.asarray(t_s, dtype=np.float64)
        if self._t.size == 0:
            return np.zeros(t.shape)
        i = np.clip(np.searchsorted(self._t, t.reshape(-1), side="right") - 1, 0, self._t.size - 1)
        return self._y[i].reshape(t.shape)

    def get_state(self) -> dict[str, Any]:
        return {"estimator": "ground_truth", "edge": list(self.edge), "last_t_s": self.last_t_s}


class GroundTruthEstimator:
    """Predicts the ground truth grid (a step function) of every edge it was given."""

    name = "ground_truth"
    fit_depends_on_seed = False

    def __init__(self, truth: Mapping[EdgeKey, tuple[Any, Any]]) -> None:
        self.truth = {k: (np.asarray(t, np.float64), np.asarray(y, np.int64)) for k, (t, y) in truth.items()}

    def fit(self, streams: Sequence[EdgeStream], *, val_streams: Any = None,
            timezone: str = "UTC") -> GroundTruthEstimator:
        return self

    def make_filter(self, edge: EdgeKey) -> _TruthFilter:
        t, y = self.truth.get(edge, (np.zeros(0), np.zeros(0, np.int64)))
        return _TruthFilter(edge, t, y)

    def filter_from_state(self, state: dict[str, Any]) -> _TruthFilter:
        return self.make_filter(tuple(state["edge"]))  # type: ignore[arg-type]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {}


@dataclass(frozen=True)
class TruthFactory:
    """Picklable ``factory(random_state=)`` of a :class:`GroundTruthEstimator` for one task's truth."""

    truth: Mapping[EdgeKey, tuple[Any, Any]]

    def __call__(self, *, random_state: int = 0) -> GroundTruthEstimator:
        return GroundTruthEstimator(self.truth)
