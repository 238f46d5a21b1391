"""Navigation baselines as per-edge filters (they satisfy the :class:`~psg_data.estimators.EdgeFilter` protocol).

- ``last_seen_map`` (ConceptGraphs-like): the map is the last map state; an edge's belief is its
  last observation (1 where the object was seen at the last map update, 0 elsewhere; an object
  absent at the last update is absent from the map, so the agent aborts). An update replaces the
  belief with the new observation (a map that is refreshed by what the robot sees).
- ``oracle`` (perfect knowledge): belief = ground truth at the query time, with an edge to every
  receptacle of the environment; updates are ignored.
- ``random_receptacle`` (chance): on the object's known edges (the receptacles it was seen on), a
  belief drawn uniformly in [0, 1] per edge and query time (seeded, the same draw for the same edge
  and time in any process): the agent visits the known receptacles in a random order and aborts
  when every draw falls below delta; updates are ignored. It has no door model: with predicted doors
  it plans with every door open.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeKey, EdgeStream

__all__ = ["LastSeenFilter", "OracleFilter", "RandomFilter", "last_seen_filters", "oracle_filters", "random_filters"]


class _Clock:
    def __init__(self, edge: EdgeKey) -> None:
        self.edge = edge
        self._last: float | None = None

    @property
    def last_t_s(self) -> float | None:
        return self._last

    def _advance(self, t: NDArray[np.float64]) -> None:
        if t.size == 0:
            return
        if self._last is not None and t[0] < self._last or np.any(np.diff(t) < 0):
            raise EstimatorError(f"edge {self.edge}: update times must not decrease")
        self._last = float(t[-1])

    def update(self, t_s: float, y: int) -> None:
        self.update_many([t_s], [y])

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:  # pragma: no cover - overridden
        raise NotImplementedError


class LastSeenFilter(_Clock):
    """Belief = the last observation of the edge (0 before any observation)."""

    def __init__(self, edge: EdgeKey) -> None:
        super().__init__(edge)
        self.value = 0.0

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:
        """Keep the last observation (times must not decrease)."""
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        yy = np.asarray(y).reshape(-1)
        self._advance(t)
        if yy.size:
            self.value = float(yy[-1])

    def predict(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """The last observation at every time of ``t_s``."""
        return np.full(np.asarray(t_s, dtype=np.float64).shape, self.value)

    def get_state(self) -> dict[str, Any]:
        """The filter's state as a JSON-ready dictionary."""
        return {"estimator": "last_seen_map", "edge": list(self.edge), "last_t_s": self._last, "value": self.value}


class OracleFilter(_Clock):
    """Belief = 1 if the ground truth puts the object on the receptacle at ``t``, else 0."""

    def __init__(self, edge: EdgeKey, gt_at: Callable[[str, float], str | None]) -> None:
        super().__init__(edge)
        self._gt = gt_at

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:
        """Observations are ignored (times must not decrease)."""
        self._advance(np.asarray(t_s, dtype=np.float64).reshape(-1))

    def predict(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """1 where the ground truth puts the object on the edge's receptacle at ``t_s``, else 0."""
        t = np.asarray(t_s, dtype=np.float64)
        o, r = self.edge
        flat = [1.0 if self._gt(o, float(x)) == r else 0.0 for x in t.reshape(-1)]
        return np.asarray(flat, dtype=np.float64).reshape(t.shape)

    def get_state(self) -> dict[str, Any]:
        """The filter's state as a JSON-ready dictionary."""
        return {"estimator": "oracle", "edge": list(self.edge), "last_t_s": self._last}


class RandomFilter(_Clock):
    """Belief = a uniform draw per (edge, time), deterministic for ``seed`` (chance)."""

    def __init__(self, edge: EdgeKey, seed: int = 0) -> None:
        import zlib

        super().__init__(edge)
        self._key = (int(seed), zlib.crc32(f"{edge[0]}\x00{edge[1]}".encode()))

    def update_many(self, t_s: ArrayLike, y: ArrayLike) -> None:
        """Advance to the last time; the values are ignored (the chance agent's beliefs do not use them)."""
        self._advance(np.asarray(t_s, dtype=np.float64).reshape(-1))

    def predict(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Uniform random beliefs in [0, 1], shaped as ``t_s``: a function of (seed, edge, time in ms)."""
        t = np.asarray(t_s, dtype=np.float64)
        flat = [float(np.random.default_rng([*self._key, int(round(x * 1000))]).random()) for x in t.reshape(-1)]
        return np.asarray(flat, dtype=np.float64).reshape(t.shape)

    def get_state(self) -> dict[str, Any]:
        """JSON-serialisable state (the edge and the last time)."""
        return {"estimator": "random_receptacle", "edge": list(self.edge), "last_t_s": self._last}


def random_filters(streams: list[EdgeStream], seed: int = 0) -> dict[EdgeKey, RandomFilter]:
    """A :class:`RandomFilter` on every stream's edge."""
    return {s.edge: RandomFilter(s.edge, seed) for s in streams}


def last_seen_filters(streams: list[EdgeStream]) -> dict[EdgeKey, LastSeenFilter]:
    """One :class:`LastSeenFilter` per stream, updated with the stream."""
    out: dict[EdgeKey, LastSeenFilter] = {}
    for s in streams:
        f = out.setdefault(s.edge, LastSeenFilter(s.edge))
        f.update_many(s.t_s, s.y)
    return out


def oracle_filters(object_ids: list[str], receptacle_ids: list[str],
                   gt_at: Callable[[str, float], str | None]) -> dict[EdgeKey, OracleFilter]:
    """An :class:`OracleFilter` for every (object, receptacle) pair."""
    return {(o, r): OracleFilter((o, r), gt_at) for o in object_ids for r in receptacle_ids}
