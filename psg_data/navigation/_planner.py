"""Shortest paths on an occupancy grid: A* and cached multi-source Dijkstra distance fields.

Motion model (both solvers): 8-connected moves between free cells; an orthogonal step costs
``res`` and a diagonal step ``sqrt(2) * res`` metres. **No corner cutting**: a diagonal step from
``(i, j)`` to ``(i + di, j + dj)`` is allowed only when both orthogonal neighbours ``(i + di, j)``
and ``(i, j + dj)`` are free, so a path never squeezes between two obstacle cells touching at a
corner. A* uses the octile distance, which is admissible and consistent for these costs, so its
lengths are exact.

For evaluation many queries ask for the distance from some cell to a receptacle's *approach set*
(cells from which the receptacle is within reach and in sight). :class:`PlanningCache` computes,
per receptacle and door configuration, one multi-source Dijkstra field
(``scipy.sparse.csgraph.dijkstra`` with ``min_only=True``) on the grid graph and keeps it; after
that a path length is one array lookup and a path is a walk along the predecessor array.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.navigation._grid import DoorConfig, OccupancyGrid, bresenham_many

__all__ = ["PathResult", "astar", "octile_distance", "grid_graph", "path_length_m", "PlanningCache", "SQRT2"]

log = logging.getLogger(__name__)

SQRT2 = math.sqrt(2.0)
_MOVES = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


@dataclass(frozen=True)
class PathResult:
    """A grid path.

    Attributes:
        length_m: path length, metres (``math.inf`` when there is no path).
        cells: (n, 2) cells (row, col) from start to goal, empty when there is no path.
    """

    length_m: float
    cells: NDArray[np.int64]

    @property
    def found(self) -> bool:
        return math.isfinite(self.length_m)


def octile_distance(a: tuple[int, int], b: tuple[int, int], resolution_m: float) -> float:
    """Octile distance between cells, metres (the 8-connected length without obstacles)."""
    di, dj = abs(a[0] - b[0]), abs(a[1] - b[1])
    return resolution_m * (max(di, dj) + (SQRT2 - 1.0) * min(di, dj))


def path_length_m(cells: NDArray[np.int64], resolution_m: float) -> float:
    """Length of a path of 8-connected cells, metres."""
    c = np.asarray(cells).reshape(-1, 2)
    if c.shape[0] < 2:
        return 0.0
    a = np.abs(np.diff(c, axis=0))
    if np.any(a.max(axis=1) != 1):
        raise EvaluationError("path_length_m: cells are not an 8-connected path without repeats")
    d = a.sum(axis=1)
    return float(resolution_m * (np.count_nonzero(d == 1) + SQRT2 * np.count_nonzero(d == 2)))


def astar(free: NDArray[np.bool_], start: tuple[int, int], goal: tuple[int, int], resolution_m: float) -> PathResult:
    """A* shortest path between two free cells (8-connected, octile costs, no corner cutting).

    Args:
        free: (H, W) bool, True = traversable.
        start, goal: (row, col) cells.
        resolution_m: cell size, metres.

    Returns:
        The path; ``length_m = inf`` when the goal is unreachable or either end is not free.
    """
    H, W = free.shape
    s, g = (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1]))
    empty = PathResult(math.inf, np.zeros((0, 2), dtype=np.int64))
    for c in (s, g):
        if not (0 <= c[0] < H and 0 <= c[1] < W) or not free[c]:
            return empty
    fr = free.tolist()
    gcost: dict[tuple[int, int], float] = {s: 0.0}
    parent: dict[tuple[int, int], tuple[int, int]] = {}
    closed: set[tuple[int, int]] = set()
    heap: list[tuple[float, float, tuple[int, int]]] = [(octile_distance(s, g, resolution_m), 0.0, s)]
    diag = SQRT2 * resolution_m
    while heap:
        _, gc, cur = heapq.heappop(heap)
        if cur in closed:
            continue
        if cur == g:
            path = [cur]
            while cur in parent:
                cur = parent[cur]
                path.append(cur)
            return PathResult(gc, np.asarray(path[::-1], dtype=np.int64))
        closed.add(cur)
        i, j = cur
        for di, dj in _MOVES:
            ni, nj = i + di, j + dj
            if not (0 <= ni < H and 0 <= nj < W) or not fr[ni][nj]:
                continue
            if di and dj:
                if not (fr[i + di][j] and fr[i][j + dj]):
                    continue
                step = diag
            else:
                step = resolution_m
            nb = (ni, nj)
            ng = gc + step
            if nb not in closed and ng < gcost.get(nb, math.inf):
                gcost[nb] = ng
                parent[nb] = cur
                heapq.heappush(heap, (ng + octile_distance(nb, g, resolution_m), ng, nb))
    return empty


def grid_graph(free: NDArray[np.bool_], resolution_m: float) -> Any:
    """Sparse (H*W, H*W) CSR adjacency of the free cells (symmetric, both directions stored).

    Node ``i * W + j`` is cell ``(i, j)``; weights are metres; same motion model as :func:`astar`.
    """
    from scipy.sparse import csr_matrix

    H, W = free.shape
    idx = np.arange(H * W, dtype=np.int64).reshape(H, W)
    rows, cols, wts = [], [], []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        i0, i1 = 0, H - di
        j0, j1 = max(0, -dj), W - max(0, dj)
        a = free[i0:i1, j0:j1] & free[i0 + di:i1 + di, j0 + dj:j1 + dj]
        if di and dj:
            a &= free[i0 + di:i1 + di, j0:j1] & free[i0:i1, j0 + dj:j1 + dj]
            w = SQRT2 * resolution_m
        else:
            w = float(resolution_m)
        u = idx[i0:i1, j0:j1][a]
        v = idx[i0 + di:i1 + di, j0 + dj:j1 + dj][a]
        rows += [u, v]
        cols += [v, u]
        wts.append(np.full(2 * u.size, w))
    r = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    c = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    data = np.concatenate(wts) if wts else np.zeros(0)
    return csr_matrix((data, (r, c)), shape=(H * W, H * W))


class PlanningCache:
    """Per door configuration: free cells, grid graph, receptacle approach sets and distance fields.

    The approach set of a receptacle holds the free cells within ``reach_m`` of its footprint
    (cell centre to the nearest footprint cell centre) whose Bresenham line to that footprint cell
    crosses no obstacle cell (walls, closed doors, other receptacles): standing there, an object on
    the receptacle is within reach and visible. A receptacle is *visited* when the robot stands in
    its approach set.

    Args:
        grid: the occupancy grid.
        reach_m: success radius around the receptacle, metres (the paper's 1 m).
    """

    def __init__(self, grid: OccupancyGrid, *, reach_m: float = 1.0) -> None:
        self.grid = grid
        self.reach_m = float(reach_m)
        self._graph: dict[DoorConfig, Any] = {}
        self._free_flat: dict[DoorConfig, NDArray[np.bool_]] = {}
        self._approach: dict[tuple[str, DoorConfig], NDArray[np.bool_]] = {}
        self._fields: dict[tuple[str, DoorConfig], tuple[NDArray[np.float64], NDArray[np.int32]]] = {}
        self._near: dict[str, tuple[tuple[int, int, int, int], NDArray[np.float64], NDArray[np.int64]]] = {}
        self.n_fields_computed = 0

    def key(self, door_open: Mapping[str, bool] | DoorConfig | None) -> DoorConfig:
        return door_open if isinstance(door_open, tuple) else self.grid.door_config(door_open)

    def free_flat(self, cfg: DoorConfig) -> NDArray[np.bool_]:
        if cfg not in self._free_flat:
            self._free_flat[cfg] = self.grid.free(cfg).ravel()
        return self._free_flat[cfg]

    def graph(self, cfg: DoorConfig) -> Any:
        if cfg not in self._graph:
            self._graph[cfg] = grid_graph(self.grid.free(cfg), self.grid.resolution_m)
        return self._graph[cfg]

    # -- approach sets ------------------------------------------------------------------------
    def _nearest_footprint(self, rec: str) -> tuple[tuple[int, int, int, int], NDArray[np.float64], NDArray[np.int64]]:
        """Window around the footprint, distance (cells) to it and the nearest footprint cell."""
        if rec not in self._near:
            from scipy.ndimage import distance_transform_edt

            fp = self.grid.receptacle_cells.get(rec)
            if fp is None:
                raise EvaluationError(f"receptacle {rec!r} is not in the occupancy grid")
            H, W = fp.shape
            ii, jj = np.nonzero(fp)
            m = int(math.ceil(self.reach_m / self.grid.resolution_m)) + 2
            win = (max(int(ii.min()) - m, 0), min(int(ii.max()) + m + 1, H),
                   max(int(jj.min()) - m, 0), min(int(jj.max()) + m + 1, W))
            sub = fp[win[0]:win[1], win[2]:win[3]]
            dist, ind = distance_transform_edt(~sub, return_indices=True)
            ind = ind + np.array([win[0], win[2]])[:, None, None]
            self._near[rec] = (win, dist, ind)
        return self._near[rec]

    def approach(self, rec: str, cfg: DoorConfig) -> NDArray[np.bool_]:
        """(H, W) approach cells of receptacle ``rec`` under door configuration ``cfg``."""
        k = (rec, cfg)
        if k not in self._approach:
            win, dist, ind = self._nearest_footprint(rec)
            i0, i1, j0, j1 = win
            free = self.grid.free(cfg)[i0:i1, j0:j1]
            cand = free & (dist * self.grid.resolution_m <= self.reach_m + 1e-9)
            ci, cj = np.nonzero(cand)
            out = np.zeros(self.grid.shape, dtype=bool)
            if ci.size:
                tgt = np.stack([ind[0][ci, cj], ind[1][ci, cj]], axis=1)
                src = np.stack([ci + i0, cj + j0], axis=1)
                blocked = self.grid.obstacles(cfg) & ~self.grid.receptacle_cells[rec]
                rows, cols, valid = bresenham_many(src, tgt)
                n = valid.sum(axis=1) - 1
                kk = np.arange(valid.shape[1])[None, :]
                inner = valid & (kk >= 1) & (kk < n[:, None])
                ok = ~np.any(inner & blocked[rows, cols], axis=1)
                out[src[ok, 0], src[ok, 1]] = True
            out.setflags(write=False)
            self._approach[k] = out
        return self._approach[k]

    # -- distance fields -----------------------------------------------------------------------
    def field(self, rec: str, cfg: DoorConfig) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
        """Distance (metres, inf = unreachable) from every cell to ``rec``'s approach set, and the
        predecessor array (next cell towards the set; -9999 at the set and unreachable cells)."""
        k = (rec, cfg)
        if k not in self._fields:
            from scipy.sparse.csgraph import dijkstra

            src = np.flatnonzero(self.approach(rec, cfg).ravel())
            n = self.grid.shape[0] * self.grid.shape[1]
            if src.size == 0:
                dist = np.full(n, np.inf)
                pred = np.full(n, -9999, dtype=np.int32)
            else:
                dist, pred, _ = dijkstra(self.graph(cfg), directed=True, indices=src, min_only=True,
                                         return_predecessors=True)
                pred = pred.astype(np.int32)
            self._fields[k] = (dist, pred)
            self.n_fields_computed += 1
        return self._fields[k]

    def distance(self, rec: str, cfg: DoorConfig, cell: int) -> float:
        """Shortest path length from flat cell index ``cell`` to ``rec``'s approach set, metres (inf if none)."""
        return float(self.field(rec, cfg)[0][cell])

    def path(self, rec: str, cfg: DoorConfig, cell: int) -> NDArray[np.int64] | None:
        """Flat cell indices of a shortest path from ``cell`` to ``rec``'s approach set (None if unreachable)."""
        dist, pred = self.field(rec, cfg)
        if not math.isfinite(dist[cell]):
            return None
        out = [int(cell)]
        p = int(pred[cell])
        while p >= 0:
            out.append(p)
            p = int(pred[p])
        return np.asarray(out, dtype=np.int64)

    def step_lengths(self, cells: NDArray[np.int64]) -> NDArray[np.float64]:
        """(n,) cumulative path length at each cell of a flat-index path, metres (0 at the start)."""
        W = self.grid.shape[1]
        if cells.size < 2:
            return np.zeros(cells.size)
        i, j = np.divmod(cells, W)
        d = np.abs(np.diff(i)) + np.abs(np.diff(j))
        step = np.where(d == 2, SQRT2, 1.0) * self.grid.resolution_m
        return np.concatenate([[0.0], np.cumsum(step)])
