"""A* and the Dijkstra fields against an independent solver (networkx) on random grids."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import EvaluationError
from psg_data.navigation import OccupancyGrid, PlanningCache, astar, grid_graph, path_length_m


def nx_graph(free: np.ndarray, res: float) -> nx.Graph:
    """The 8-connected grid graph built cell by cell (independent of grid_graph)."""
    H, W = free.shape
    G = nx.Graph()
    for i in range(H):
        for j in range(W):
            if not free[i, j]:
                continue
            G.add_node((i, j))
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    if (di, dj) == (0, 0):
                        continue
                    a, b = i + di, j + dj
                    if not (0 <= a < H and 0 <= b < W) or not free[a, b]:
                        continue
                    if di and dj and not (free[i + di, j] and free[i, j + dj]):
                        continue  # no corner cutting
                    G.add_edge((i, j), (a, b), weight=res * (math.sqrt(2) if di and dj else 1.0))
    return G


def random_free(rng: np.random.Generator, H: int, W: int, p: float) -> np.ndarray:
    return rng.random((H, W)) > p


@pytest.mark.parametrize("case", range(25))
def test_astar_matches_networkx_on_random_grids(case):
    rng = np.random.default_rng(case)
    H, W = int(rng.integers(3, 25)), int(rng.integers(3, 25))
    free = random_free(rng, H, W, float(rng.uniform(0.0, 0.45)))
    res = float(rng.choice([0.05, 0.1, 1.0]))
    G = nx_graph(free, res)
    cells = np.argwhere(free)
    if len(cells) < 2:
        return
    for _ in range(6):
        s = tuple(int(x) for x in cells[rng.integers(len(cells))])
        g = tuple(int(x) for x in cells[rng.integers(len(cells))])
        r = astar(free, s, g, res)
        try:
            expect = nx.dijkstra_path_length(G, s, g, weight="weight")
        except nx.NetworkXNoPath:
            expect = math.inf
        if math.isinf(expect):
            assert math.isinf(r.length_m) and r.cells.shape == (0, 2)
            continue
        assert r.length_m == pytest.approx(expect, rel=1e-12, abs=1e-12)
        # the returned path is valid: free cells, 8-connected, its length is the reported one
        assert tuple(r.cells[0]) == s and tuple(r.cells[-1]) == g
        assert free[r.cells[:, 0], r.cells[:, 1]].all()
        assert path_length_m(r.cells, res) == pytest.approx(expect, rel=1e-12)
        for a, b in zip(r.cells[:-1], r.cells[1:]):
            assert G.has_edge(tuple(a), tuple(b))


@settings(max_examples=30, deadline=None)
@given(st.integers(2, 14), st.integers(2, 14), st.floats(0.0, 0.5), st.integers(0, 2**31 - 1))
def test_grid_graph_distances_match_networkx(H, W, p, seed):
    from scipy.sparse.csgraph import dijkstra

    rng = np.random.default_rng(seed)
    free = random_free(rng, H, W, p)
    cells = np.argwhere(free)
    if len(cells) == 0:
        return
    s = tuple(int(x) for x in cells[rng.integers(len(cells))])
    d = dijkstra(grid_graph(free, 0.5), indices=s[0] * W + s[1])
    expect = nx.single_source_dijkstra_path_length(nx_graph(free, 0.5), s, weight="weight")
    for i in range(H):
        for j in range(W):
            if (i, j) in expect:
                assert d[i * W + j] == pytest.approx(expect[(i, j)], rel=1e-12)
            else:
                assert math.isinf(d[i * W + j])


def test_no_corner_cutting():
    free = np.array([[True, False], [False, True]])
    assert math.isinf(astar(free, (0, 0), (1, 1), 1.0).length_m)
    free = np.array([[True, True], [False, True]])
    assert astar(free, (0, 0), (1, 1), 1.0).length_m == pytest.approx(2.0)  # around the corner, not sqrt(2)
    free = np.ones((2, 2), dtype=bool)
    assert astar(free, (0, 0), (1, 1), 1.0).length_m == pytest.approx(math.sqrt(2))


def test_astar_rejects_blocked_ends_and_handles_start_equals_goal():
    free = np.ones((3, 3), dtype=bool)
    free[1, 1] = False
    assert math.isinf(astar(free, (1, 1), (0, 0), 1.0).length_m)
    assert math.isinf(astar(free, (0, 0), (5, 5), 1.0).length_m)
    r = astar(free, (0, 0), (0, 0), 1.0)
    assert r.length_m == 0.0 and r.cells.tolist() == [[0, 0]]


def test_path_length_rejects_jumps():
    with pytest.raises(EvaluationError):
        path_length_m(np.array([[0, 0], [0, 2]]), 1.0)


@pytest.mark.parametrize("case", range(8))
def test_field_distance_equals_min_over_approach_cells(case):
    """The multi-source field equals the minimum networkx distance to any approach cell, and its
    predecessor walk is a shortest path."""
    rng = np.random.default_rng(100 + case)
    H, W = 20, 26
    obs = rng.random((H, W)) < 0.2
    rec = np.zeros((H, W), dtype=bool)
    ri, rj = int(rng.integers(2, H - 2)), int(rng.integers(2, W - 2))
    rec[ri:ri + 2, rj:rj + 1] = True
    obs |= rec
    grid = OccupancyGrid(obs, np.zeros(2), 0.25, 0.0, {}, {"r": rec})
    cache = PlanningCache(grid, reach_m=0.75)
    free = grid.free(())
    app = cache.approach("r", ())
    assert app.any() or not free.any()
    # approach cells: free, within 0.75 m (3 cells) of the footprint
    ii, jj = np.nonzero(app)
    fi, fj = np.nonzero(rec)
    dmin = np.sqrt((ii[:, None] - fi[None]) ** 2 + (jj[:, None] - fj[None]) ** 2).min(axis=1) * 0.25
    assert np.all(dmin <= 0.75 + 1e-9) and free[ii, jj].all()
    G = nx_graph(free, 0.25)
    dist, _ = cache.field("r", ())
    srcs = [tuple(c) for c in np.argwhere(app)]
    expect = nx.multi_source_dijkstra_path_length(G, srcs, weight="weight") if srcs else {}
    for c in np.argwhere(free)[:60]:
        k = int(c[0] * W + c[1])
        if tuple(c) in expect:
            assert dist[k] == pytest.approx(expect[tuple(c)], rel=1e-12)
            p = cache.path("r", (), k)
            assert p is not None and app.ravel()[p[-1]]
            assert cache.step_lengths(p)[-1] == pytest.approx(dist[k], rel=1e-12)
        else:
            assert math.isinf(dist[k]) and cache.path("r", (), k) is None
