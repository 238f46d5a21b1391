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
from psg_data.maps._grid import DoorConfig, OccupancyGrid, bresenham_many

__all__ = ["PathResult", "astar", "astar_reference", "GridPlanner", "octile_distance", "grid_graph",
           "path_length_m", "PlanningCache", "SQRT2"]

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
        """Whether a path was found."""
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


def astar_reference(free: NDArray[np.bool_], start: tuple[int, int], goal: tuple[int, int], resolution_m: float
                    ) -> PathResult:
    """Pure-Python A* (8-connected, octile costs, no corner cutting): the reference implementation.

    Kept as the test oracle of :func:`astar` / :class:`GridPlanner` and as the baseline of
    ``bench/bench_navigation.py``; about an order of magnitude slower than :func:`astar` on
    paths that detour around walls.

    Args:
        free: (H, W) bool, True = traversable.
        start: (row, col) start cell.
        goal: (row, col) goal cell.
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
    Built directly in CSR order (rows in node order, columns sorted within a row), no sort.
    """
    from scipy.sparse import csr_matrix

    fr = np.asarray(free, dtype=bool)
    H, W = fr.shape
    n = H * W
    pad = np.zeros((H + 2, W + 2), dtype=bool)
    pad[1:-1, 1:-1] = fr
    # the 8 moves in increasing flat offset (so that columns come out sorted within each row)
    ok = np.empty((H, W, 8), dtype=bool)
    for k, (di, dj) in enumerate(_MOVES):
        m = fr & pad[1 + di:H + 1 + di, 1 + dj:W + 1 + dj]
        if di and dj:
            m &= pad[1 + di:H + 1 + di, 1:W + 1] & pad[1:H + 1, 1 + dj:W + 1 + dj]
        ok[:, :, k] = m
    flat = np.flatnonzero(ok)  # row-major over (node, move): CSR order
    rows, move = np.divmod(flat, 8)
    offs = np.array([di * W + dj for di, dj in _MOVES], dtype=np.int64)
    wts = np.array([SQRT2 * resolution_m if di and dj else float(resolution_m) for di, dj in _MOVES])
    indices = (rows + offs[move]).astype(np.int32)
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.count_nonzero(ok.reshape(n, 8), axis=1), out=indptr[1:])
    return csr_matrix((wts[move], indices, indptr), shape=(n, n))


def _octile_cells(start: tuple[int, int], goal: tuple[int, int], diagonal_first: bool) -> NDArray[np.int64]:
    """Cells of the monotone 8-connected path with ``min(|di|, |dj|)`` diagonal steps and the rest
    straight (the octile-length path), diagonal steps first or last; (n + 1, 2).
    """
    di, dj = goal[0] - start[0], goal[1] - start[1]
    si, sj = int(np.sign(di)), int(np.sign(dj))
    m, M = min(abs(di), abs(dj)), max(abs(di), abs(dj))
    diag = np.array([si, sj], dtype=np.int64)
    straight = np.array([si, 0] if abs(di) > abs(dj) else [0, sj], dtype=np.int64)
    steps = [diag] * m + [straight] * (M - m)
    if not diagonal_first:
        steps = steps[::-1]
    if not steps:
        return np.array([start], dtype=np.int64)
    return np.concatenate([np.array([start], np.int64), np.asarray(start) + np.cumsum(steps, axis=0)])


def _direct_path(free: NDArray[np.bool_], start: tuple[int, int], goal: tuple[int, int]) -> NDArray[np.int64] | None:
    """An obstacle-free path of octile length (the lower bound, so a shortest path), if one of the
    two monotone octile paths is free without corner cutting; else None.
    """
    for diagonal_first in (True, False):
        c = _octile_cells(start, goal, diagonal_first)
        if not free[c[:, 0], c[:, 1]].all():
            continue
        d = np.diff(c, axis=0)
        dg = np.flatnonzero((d[:, 0] != 0) & (d[:, 1] != 0))
        if dg.size and not (free[c[dg, 0] + d[dg, 0], c[dg, 1]].all() and free[c[dg, 0], c[dg, 1] + d[dg, 1]].all()):
            continue
        return c
    return None


class GridPlanner:
    """Exact shortest paths between cells of one free mask through ``scipy.sparse.csgraph``.

    Same motion model and lengths as :func:`astar_reference` (8-connected, octile costs, no
    corner cutting). A query is answered by, in order: (1) the octile lower bound, when one of the
    two monotone octile paths is free (then it is a shortest path); (2) the connected components
    of the grid graph (different components: no path; labelled from the planner's second search
    on, so that a one-off query does not pay for it); (3) a bidirectional Dijkstra: two searches
    from the start and from the goal, each cut at distance ``L`` (``dijkstra(..., limit=L)``); the
    shortest path length is ``mu = min_v d_s(v) + d_g(v)``, exact once ``mu + w_max <= 2 L``
    (``w_max`` the diagonal step: the shortest path then has a node within ``L`` of both ends).
    ``L`` starts just above half the octile bound; when the two searches meet without that
    guarantee, ``mu`` bounds the length and one more round at ``L = (mu + w_max) / 2`` is exact;
    when they do not meet (a long detour), one single-source search from the start finishes.

    The graph and the components are built on first use and kept; build one planner per free mask
    (:class:`PlanningCache` keeps one per door configuration).

    Args:
        free: (H, W) bool, True = traversable (not modified; copied if writable).
        resolution_m: cell size, metres.
        graph: a prebuilt :func:`grid_graph` of ``free`` (optional).
    """

    def __init__(self, free: NDArray[np.bool_], resolution_m: float, *, graph: Any = None) -> None:
        f = np.asarray(free, dtype=bool)
        if f.ndim != 2:
            raise EvaluationError(f"free: expected an (H, W) mask, got shape {f.shape}")
        if f.flags.writeable:
            f = f.copy()
            f.setflags(write=False)
        self.free = f
        self.resolution_m = float(resolution_m)
        self._graph = graph
        self._labels: NDArray[np.int32] | None = None
        self._searches = 0

    @property
    def graph(self) -> Any:
        """The 8-connected graph of the free cells (``scipy.sparse`` CSR, edge weights in metres), built once."""
        if self._graph is None:
            self._graph = grid_graph(self.free, self.resolution_m)
        return self._graph

    @property
    def components(self) -> NDArray[np.int32]:
        """(H*W,) connected-component label of every cell (free cells of one label reach each other)."""
        if self._labels is None:
            from scipy.sparse.csgraph import connected_components

            self._labels = connected_components(self.graph, directed=False)[1].astype(np.int32)
        return self._labels

    def path(self, start: tuple[int, int], goal: tuple[int, int]) -> PathResult:
        """Shortest path from ``start`` to ``goal`` (row, col); ``length_m = inf`` if there is none
        or an end is not a free cell.
        """
        H, W = self.free.shape
        s, g = (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1]))
        empty = PathResult(math.inf, np.zeros((0, 2), dtype=np.int64))
        for c in (s, g):
            if not (0 <= c[0] < H and 0 <= c[1] < W) or not self.free[c]:
                return empty
        direct = _direct_path(self.free, s, g)
        if direct is not None:
            return PathResult(path_length_m(direct, self.resolution_m), direct)
        si, gi = s[0] * W + s[1], g[0] * W + g[1]
        self._searches += 1
        if self._labels is not None or self._searches > 1:  # worth labelling once a planner is reused
            lab = self.components
            if lab[si] != lab[gi]:
                return empty
        cells = self._bidirectional(si, gi, octile_distance(s, g, self.resolution_m))
        if cells is None:
            return empty
        return PathResult(path_length_m(cells, self.resolution_m), cells)

    def _bidirectional(self, si: int, gi: int, lower_m: float) -> NDArray[np.int64] | None:
        from scipy.sparse.csgraph import dijkstra

        w_max = SQRT2 * self.resolution_m
        limit = 0.5 * (1.1 * lower_m + w_max) + self.resolution_m
        for _ in range(2):
            ds, ps = dijkstra(self.graph, indices=si, limit=limit, return_predecessors=True)
            dg, pg = dijkstra(self.graph, indices=gi, limit=limit, return_predecessors=True)
            tot = ds + dg
            v = int(np.argmin(tot))
            mu = float(tot[v])
            if math.isfinite(mu) and mu + w_max <= 2.0 * limit:
                break
            if not math.isfinite(mu):  # a long detour: one search from the start over the component
                return self._single_source(si, gi)
            limit = 0.5 * (mu + w_max) + 1e-9  # mu bounds the length: this round is exact
        flat = np.asarray(_walk_back(ps, si, v) + _walk_back(pg, gi, v)[::-1][1:], dtype=np.int64)
        return np.stack(np.divmod(flat, self.free.shape[1]), axis=1)

    def _single_source(self, si: int, gi: int) -> NDArray[np.int64] | None:
        from scipy.sparse.csgraph import dijkstra

        dist, pred = dijkstra(self.graph, indices=si, return_predecessors=True)
        if not math.isfinite(dist[gi]):
            return None
        flat = np.asarray(_walk_back(pred, si, gi), dtype=np.int64)
        return np.stack(np.divmod(flat, self.free.shape[1]), axis=1)


def _walk_back(pred: NDArray[np.int32], source: int, node: int) -> list[int]:
    """Flat nodes from ``source`` to ``node`` along a predecessor array."""
    out = [node]
    while out[-1] != source:
        out.append(int(pred[out[-1]]))
    return out[::-1]


def astar(free: NDArray[np.bool_], start: tuple[int, int], goal: tuple[int, int], resolution_m: float) -> PathResult:
    """Exact shortest path between two free cells (8-connected, octile costs, no corner cutting).

    The lengths are those of A* with the octile heuristic (:func:`astar_reference`), computed
    through ``scipy.sparse.csgraph`` by a :class:`GridPlanner` built for this call; for many
    pairs on one grid, build a :class:`GridPlanner` (or use :meth:`PlanningCache.shortest_path`)
    once and reuse it.

    Args:
        free: (H, W) bool, True = traversable.
        start: (row, col) start cell.
        goal: (row, col) goal cell.
        resolution_m: cell size, metres.

    Returns:
        The path; ``length_m = inf`` when the goal is unreachable or either end is not free.
    """
    return GridPlanner(free, resolution_m).path(start, goal)


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
        self._graph: dict[DoorConfig, GridPlanner] = {}
        self._free_flat: dict[DoorConfig, NDArray[np.bool_]] = {}
        self._approach: dict[tuple[str, DoorConfig], NDArray[np.bool_]] = {}
        self._fields: dict[tuple[str, DoorConfig], tuple[NDArray[np.float64], NDArray[np.int32]]] = {}
        self._near: dict[str, tuple[tuple[int, int, int, int], NDArray[np.float64], NDArray[np.int64]]] = {}
        self.n_fields_computed = 0

    def key(self, door_open: Mapping[str, bool] | DoorConfig | None) -> DoorConfig:
        """The :data:`DoorConfig` of door states given as a mapping (or already as a config)."""
        return door_open if isinstance(door_open, tuple) else self.grid.door_config(door_open)

    def free_flat(self, cfg: DoorConfig) -> NDArray[np.bool_]:
        """Free cells (flat, row-major) with the doors of ``cfg``, computed once per config."""
        if cfg not in self._free_flat:
            self._free_flat[cfg] = self.grid.free(cfg).ravel()
        return self._free_flat[cfg]

    def graph(self, cfg: DoorConfig) -> Any:
        """The graph of the free cells with the doors of ``cfg``."""
        return self.planner(cfg).graph

    def planner(self, cfg: Mapping[str, bool] | DoorConfig | None) -> GridPlanner:
        """The :class:`GridPlanner` of a door configuration (its graph is shared with the fields)."""
        cfg = self.key(cfg)
        if cfg not in self._graph:
            self._graph[cfg] = GridPlanner(self.grid.free(cfg), self.grid.resolution_m)
        return self._graph[cfg]

    def shortest_path(self, start: tuple[int, int], goal: tuple[int, int],
                      door_open: Mapping[str, bool] | DoorConfig | None = None) -> PathResult:
        """Exact shortest path between two cells under a door configuration (see :class:`GridPlanner`)."""
        return self.planner(door_open).path(start, goal)

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
        predecessor array (next cell towards the set; -9999 at the set and unreachable cells).
        """
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
