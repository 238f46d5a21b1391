"""Observation streams: the labelled presence / absence of one edge over time.

Produced by labelling (:mod:`psg_data.labeling`) and the built-in generators, consumed by the
estimators (:mod:`psg_data.estimators`) and the evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EstimatorError

__all__ = ["EdgeKey", "EdgeStream"]

EdgeKey = tuple[str, str]
"""(object_id, receptacle_id), or (door_id, state) for doors."""


@dataclass(frozen=True)
class EdgeStream:
    """Observations of one edge.

    Attributes:
        edge: the edge key.
        t_s: (N,) observation times, float64 seconds since the Unix epoch (UTC), non-decreasing.
        y: (N,) int8 observations, 1 = seen present, 0 = seen absent.
    """

    edge: EdgeKey
    t_s: NDArray[np.float64]
    y: NDArray[np.int8]
    meta: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=np.float64).reshape(-1)
        y = np.asarray(self.y).reshape(-1)
        if t.shape != y.shape:
            raise EstimatorError(f"edge {self.edge}: t_s and y differ in length ({t.size} vs {y.size})")
        if not np.all(np.isfinite(t)):
            raise EstimatorError(f"edge {self.edge}: t_s contains non-finite times")
        if t.size > 1 and np.any(np.diff(t) < 0):
            i = int(np.argmax(np.diff(t) < 0)) + 1
            raise EstimatorError(f"edge {self.edge}: t_s must be non-decreasing, got {t[i]} after {t[i - 1]} at "
                                 f"index {i}")
        if y.size and not np.all((y == 0) | (y == 1)):
            raise EstimatorError(f"edge {self.edge}: y must be 0 or 1")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "y", y.astype(np.int8))

    def __len__(self) -> int:
        return int(self.t_s.size)

    def between(self, start_s: float, end_s: float) -> EdgeStream:
        """Observations with ``start_s <= t_s < end_s``."""
        m = (self.t_s >= start_s) & (self.t_s < end_s)
        return EdgeStream(self.edge, self.t_s[m], self.y[m], dict(self.meta))
