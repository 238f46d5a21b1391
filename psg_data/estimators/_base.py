"""The estimator plugin interface: observation streams, per-edge filters and estimators.

An *edge* is one binary feature: an (object, receptacle) pair, or a (door, state) pair. Its
observations form an :class:`EdgeStream`. A :class:`PersistenceEstimator` is configured by
keyword-only settings (scikit-learn style), learns shared and per-edge parameters in
:meth:`PersistenceEstimator.fit`, and hands out one :class:`EdgeFilter` per edge, which is updated
recursively with observations and predicts P(present) at any later time.

Typical use (what ``psg-eval`` does)::

    est = get_estimator("perpetua_star", random_state=0).fit(train_streams, val_streams=val)
    f = est.make_filter(("redmug", "kitchen_table"))
    f.update_many(train.t_s, train.y)          # history up to the end of training
    belief = f.predict(test_times_s)           # predictive setting
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.schemas._streams import EdgeKey, EdgeStream

__all__ = ["EdgeKey", "EdgeStream", "EdgeFilter", "PersistenceEstimator", "streams_by_edge"]


def streams_by_edge(streams: Sequence[EdgeStream] | None) -> dict[EdgeKey, list[EdgeStream]]:
    """The streams grouped by edge, in order (an edge may have several); EstimatorError for a non-stream."""
    out: dict[EdgeKey, list[EdgeStream]] = {}
    for s in streams or ():
        if not isinstance(s, EdgeStream):
            raise EstimatorError(f"fit: expected EdgeStream objects, got {type(s).__name__}")
        out.setdefault(s.edge, []).append(s)
    return out


@runtime_checkable
class EdgeFilter(Protocol):
    """Recursive per-edge belief. Times are float64 seconds since the Unix epoch (UTC).

    ``update`` with a time earlier than the last observation raises :class:`EstimatorError`;
    ``predict`` is vectorised and defined for times >= the last observation time (earlier times
    are clamped to it or raise, as documented by the implementation); values lie in [0, 1].
    """

    @property
    def last_t_s(self) -> float | None:
        """Time (s) of the last observation applied, None before the first."""

    def update(self, t_s: float, y: int) -> None:
        """Apply one observation ``y`` (1 seen present, 0 seen absent) at ``t_s`` (s)."""

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:
        """Apply observations in time order; equal to :meth:`update` one at a time."""

    def predict(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """P(object on receptacle) at times ``t_s`` (s), same shape; does not change the filter."""

    def get_state(self) -> dict[str, Any]:
        """JSON-serialisable state; ``estimator.filter_from_state(state)`` restores the filter."""
        ...


@runtime_checkable
class PersistenceEstimator(Protocol):
    """An estimator of P(present) per edge over time.

    ``__init__`` takes keyword-only settings and stores them unchanged; learned attributes end in
    ``_``; using ``make_filter`` before ``fit`` raises :class:`psg_data.errors.NotFittedError`.
    """

    def fit(
        self,
        streams: Sequence[EdgeStream],
        *,
        val_streams: Sequence[EdgeStream] | None = None,
        timezone: str = "UTC",
    ) -> PersistenceEstimator:
        """Learn parameters from training streams (and optionally validation streams); return self."""
        ...

    def make_filter(self, edge: EdgeKey) -> EdgeFilter:
        """A fresh filter for ``edge`` with its learned parameters (defaults for unseen edges)."""
        ...

    def filter_from_state(self, state: dict[str, Any]) -> EdgeFilter:
        """Rebuild a filter from :meth:`EdgeFilter.get_state`.

        To be saved in a :class:`~psg_data.graph.PredictiveGraph`, this must work on a freshly
        constructed, *unfitted* estimator with the same settings: the state then holds everything
        the filter learned. An estimator whose filters need the fitted estimator raises
        :class:`~psg_data.errors.NotFittedError` here, and ``PredictiveGraph.save`` refuses it.
        """
        ...

    def get_params(self) -> dict[str, Any]:
        """The keyword-only settings (scikit-learn's ``get_params``)."""
        ...
