"""Records of the persistence task: issues, per-edge scores, breakdown rows, prediction traces."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.estimators._base import EdgeKey

__all__ = ["TIME_METRICS", "SAMPLE_METRICS", "WEEKDAY_NAMES", "EvaluationIssue", "EdgeResult", "BreakdownRow",
           "WeekdayResult", "PredictionTrace", "clean_json"]

TIME_METRICS: tuple[str, ...] = ("mae", "balanced_accuracy", "f1")
"""Time-integrated metrics (columns of the per-edge table), weighted by scored time across edges."""
SAMPLE_METRICS: tuple[str, ...] = ("sample_mae", "sample_balanced_accuracy", "sample_f1")
"""Per-sample metrics over the evaluation times, weighted by scored points across edges."""
WEEKDAY_NAMES: tuple[str, ...] = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")


def clean_json(x: Any) -> Any:
    """JSON-able copy: NaN/inf -> None, numpy scalars -> Python, tuples -> lists."""
    if isinstance(x, dict):
        return {str(k): clean_json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [clean_json(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, (str, int, float, bool)) or x is None:
        return x
    if isinstance(x, np.ndarray):
        return clean_json(x.tolist())
    if hasattr(x, "to_dict"):
        return clean_json(x.to_dict())
    return repr(x)


@dataclass(frozen=True)
class EvaluationIssue:
    """A problem met while evaluating one estimator (for one seed and, usually, one edge).

    Attributes:
        estimator: estimator name.
        seed: the seed (``random_state``) of the run.
        object_id: object of the edge, None for a fit failure.
        receptacle_id: receptacle of the edge, None for a fit failure.
        stage: ``"fit"``, ``"history"`` (updating with training data), ``"update"`` (a test
            observation), ``"predict"`` (an exception) or ``"prediction"`` (invalid values).
        t_s: time of the (first) offending prediction or observation, seconds since the Unix
            epoch (UTC); None when not tied to a time.
        n_times: how many evaluation times were affected (invalid values only).
        message: one-line description.
    """

    estimator: str
    seed: int
    object_id: str | None
    receptacle_id: str | None
    stage: str
    t_s: float | None
    message: str
    n_times: int = 1

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        return clean_json(asdict(self))


@dataclass(frozen=True)
class EdgeResult:
    """Scores of one (estimator, seed, edge) on one dataset draw.

    Attributes:
        estimator: estimator name.
        seed: seed of the run.
        object_id: first element of the edge key.
        receptacle_id: second element of the edge key.
        status: ``"ok"``, ``"error"`` (see the issues) or ``"unscored"`` (no valid ground truth in
            the scoring windows).
        n_points: scored evaluation times (ground-truth codes excluded).
        span_s: scored time (sum of the time weights inside the scoring windows), seconds.
        n_train_obs: observations used as history before the test window.
        n_test_obs: test observations of the edge (applied only in the adaptive setting).
        metrics: metric name -> value (NaN when not scored); keys :data:`TIME_METRICS` and
            :data:`SAMPLE_METRICS`.
        draw: the dataset draw (``--lab-seeds``; 0 for a single dataset).
    """

    estimator: str
    seed: int
    object_id: str
    receptacle_id: str
    status: str
    n_points: int
    span_s: float
    n_train_obs: int
    n_test_obs: int
    metrics: dict[str, float]
    draw: int = 0

    @property
    def edge(self) -> EdgeKey:
        """(object_id, receptacle_id)."""
        return (self.object_id, self.receptacle_id)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        d = asdict(self)
        d.update(d.pop("metrics"))
        return clean_json(d)


@dataclass(frozen=True)
class BreakdownRow:
    """Scores of one (estimator, seed, edge) restricted to one group of evaluation times.

    ``by`` is ``"weekday"`` (``key`` 0 = Monday, local time) or ``"horizon"`` (``key`` the bin of
    the time since the edge's last observation the filter had: ``< 2 h``, ``2-12 h``, ``12-48 h``,
    ``> 48 h``, ``no observation yet``). ``span_s`` is the scored time of the group, seconds.
    """

    estimator: str
    seed: int
    object_id: str
    receptacle_id: str
    by: str
    key: Any
    span_s: float
    n_points: int
    metrics: dict[str, float]
    draw: int = 0

    @property
    def weekday(self) -> int:
        """The weekday of a ``by="weekday"`` row (0 = Monday)."""
        return int(self.key)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        d = asdict(self)
        if self.by == "weekday":
            d["weekday_name"] = WEEKDAY_NAMES[int(self.key)]
        d.update(d.pop("metrics"))
        return clean_json(d)


WeekdayResult = BreakdownRow
"""Former name of the weekday breakdown rows (now :class:`BreakdownRow` with ``by="weekday"``)."""


@dataclass(frozen=True)
class PredictionTrace:
    """Beliefs of one (estimator, seed, edge) at its evaluation times (kept for plots).

    Attributes:
        t_s: (N,) evaluation times, float64 seconds since the Unix epoch (UTC).
        belief: (N,) predicted P(present).
        truth: (N,) ground truth (1, 0, or an excluded code -1/-2).
        obs_t_s: the edge's test observation times (applied only in the adaptive setting).
        obs_y: the test observations.
        weight: (N,) time weights (0 outside the scoring windows), seconds.
        draw: the dataset draw.
    """

    estimator: str
    seed: int
    edge: EdgeKey
    t_s: NDArray[np.float64]
    belief: NDArray[np.float64]
    truth: NDArray[np.int64]
    obs_t_s: NDArray[np.float64]
    obs_y: NDArray[np.int8]
    weight: NDArray[np.float64] | None = None
    draw: int = 0
