"""The agent's plan from a predictive graph: ranked targets, predicted door states, a path on the map.

:func:`ranked_candidates` and :func:`~psg_data.graph.doors_believed_open` are the navigation
agent's own rules (:mod:`psg_data.navigation._agent`, :mod:`psg_data.navigation._doors`).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import GraphError
from psg_data.graph._snapshot import doors_believed_open

if TYPE_CHECKING:  # pragma: no cover
    from psg_data.graph._graph import PredictiveGraph

__all__ = ["Plan", "ranked_candidates", "make_plan"]

OUTCOMES = ("go", "abort", "no_path")


def ranked_candidates(beliefs: Mapping[str, float], delta: float, exclude: Collection[str] = ()) -> list[str]:
    """Receptacles with belief >= ``delta`` not in ``exclude``, most believed first (ties by id)."""
    return sorted((r for r in beliefs if r not in exclude and beliefs[r] >= delta), key=lambda r: (-beliefs[r], r))


@dataclass(frozen=True)
class Plan:
    """Where to look for an object and how to get there (:meth:`PredictiveGraph.plan`).

    Attributes:
        object_id: the target object.
        t_s: planning time, Unix seconds (UTC).
        outcome: ``go`` (a target is reachable), ``abort`` (no receptacle has P >= delta: the object
            is believed absent) or ``no_path`` (no candidate is reachable under the planned doors).
        candidates: receptacles with P >= delta, ranked (the agent tries them in this order).
        p: (K,) their P(object on receptacle), clipped to [0, 1].
        distances_m: (K,) shortest path lengths from the start to each candidate's approach set under
            the planned doors, metres (inf: unreachable); with the ``expected_cost`` door rule the
            expected walked distance of that rule's policy (inf: no route with non-negligible P(open)).
        target: the first reachable candidate (None unless ``go``).
        path_xy: (N, 2) world (x, y) of the path's cell centres to ``target``, metres (empty unless ``go``).
        path_m: its length, metres (NaN unless ``go``).
        p_open: door_id -> predicted P(open) (NaN: no door model).
        doors_open: door_id -> planned open.
        start_cell: the grid cell the plan starts from (``start_xy``'s, or the nearest free one).
        delta: the belief threshold used.
    """

    object_id: str
    t_s: float
    outcome: str
    candidates: tuple[str, ...]
    p: NDArray[np.float64]
    distances_m: NDArray[np.float64]
    target: str | None
    path_xy: NDArray[np.float64] = field(repr=False)
    path_m: float
    p_open: dict[str, float]
    doors_open: dict[str, bool]
    start_cell: tuple[int, int]
    delta: float

    def to_pandas(self) -> Any:
        """One row per candidate: rank, receptacle_id, p, distance_m, target (bool)."""
        import pandas as pd

        return pd.DataFrame({"rank": np.arange(1, len(self.candidates) + 1), "receptacle_id": list(self.candidates),
                             "p": self.p, "distance_m": self.distances_m,
                             "target": [r == self.target for r in self.candidates]})


def _start_cell(cache: Any, cfg: Any, start_xy: Sequence[float]) -> int:
    """Flat index of the free cell at ``start_xy`` (or the nearest free one under ``cfg``)."""
    grid = cache.grid
    H, W = grid.shape
    ij = grid.world_to_cell(np.asarray(start_xy, np.float64)[:2])
    if not (0 <= ij[0] < H and 0 <= ij[1] < W):
        x0, x1, y0, y1 = grid.extent_m
        raise GraphError(f"plan: start ({start_xy[0]:.2f}, {start_xy[1]:.2f}) m lies outside the map "
                         f"(x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f} m)")
    free = cache.free_flat(cfg)
    flat = int(ij[0] * W + ij[1])
    if free[flat]:
        return flat
    cand = np.flatnonzero(free)
    if cand.size == 0:
        raise GraphError("plan: the map has no free cell")
    d2 = (cand // W - ij[0]) ** 2 + (cand % W - ij[1]) ** 2
    return int(cand[int(np.argmin(d2))])


def make_plan(graph: PredictiveGraph, start_xy: Sequence[float], object_id: str, t_s: float, *, delta: float,
              threshold: float, exclude: Iterable[str], reach_m: float, door_rule: str = "threshold") -> Plan:
    """:meth:`PredictiveGraph.plan` (see there)."""
    if not 0.0 <= delta <= 1.0:
        raise GraphError(f"delta must be in [0, 1], got {delta}")
    if door_rule not in ("threshold", "expected_cost"):
        raise GraphError(f"door_rule: expected 'threshold' or 'expected_cost', got {door_rule!r}")
    cache = graph.planning_cache(reach_m)
    grid = cache.grid
    raw = {r: float(v[0]) for r, v in graph.object_probabilities(object_id, [t_s]).items()}
    bad = {r: v for r, v in raw.items() if not math.isfinite(v)}
    if bad:
        raise GraphError(f"plan: filters of {object_id!r} predicted non-finite beliefs {bad}")
    bel = {r: min(max(v, 0.0), 1.0) for r, v in raw.items() if r in grid.receptacle_cells}
    p_open = {str(d): float(v) for d, v in zip(graph.doors, graph.door_probabilities([t_s])[0])}
    doors_open = doors_believed_open(p_open, threshold)
    cfg = cache.key(doors_open)
    start = _start_cell(cache, cfg, start_xy)
    cands = ranked_candidates(bel, delta, set(exclude))
    routes: dict[str, Any] = {}
    if door_rule == "expected_cost":
        from psg_data.maps._door_risk import expected_cost_route

        routes = {r: expected_cost_route(cache, r, start, p_open) for r in cands}
        dist = np.array([math.inf if routes[r] is None else routes[r].expected_m for r in cands], np.float64)
    else:
        dist = np.array([cache.distance(r, cfg, start) for r in cands], np.float64)
    reach = np.flatnonzero(np.isfinite(dist))
    target = cands[int(reach[0])] if reach.size else None
    path_xy, path_m = np.zeros((0, 2)), float("nan")
    if target is not None and routes:
        doors_open = dict(routes[target].assumed_open)
    if target is not None:
        cells = routes[target].path if routes else cache.path(target, cfg, start)
        W = grid.shape[1]
        path_xy = grid.cell_to_world(np.stack(np.divmod(cells, W), axis=1))
        path_m = float(cache.step_lengths(cells)[-1])
    outcome = "abort" if not cands else ("go" if target is not None else "no_path")
    W = grid.shape[1]
    return Plan(object_id, float(t_s), outcome, tuple(cands), np.array([bel[r] for r in cands], np.float64), dist,
                target, path_xy, path_m, p_open, doors_open, (start // W, start % W), float(delta))
