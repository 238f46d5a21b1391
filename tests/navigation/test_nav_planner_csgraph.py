"""The csgraph planner (GridPlanner, astar, PlanningCache.shortest_path) against the pure-Python
A* reference on random grids with walls and switchable doors."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.navigation import GridPlanner, OccupancyGrid, PlanningCache, astar, astar_reference, path_length_m


def random_door_grid(rng: np.random.Generator) -> OccupancyGrid:
    """Random clutter plus 1-3 vertical walls, each with 1-2 doorways (and sometimes a gap)."""
    H, W = int(rng.integers(6, 40)), int(rng.integers(8, 48))
    obs = rng.random((H, W)) < float(rng.uniform(0.0, 0.3))
    doors: dict[str, np.ndarray] = {}
    cols = rng.choice(np.arange(2, W - 2), size=min(int(rng.integers(1, 4)), W - 4), replace=False)
    for k, c in enumerate(sorted(int(x) for x in cols)):
        obs[:, c] = True
        if rng.random() < 0.3:
            obs[int(rng.integers(H)), c] = False  # a gap that is always open
        for m in range(int(rng.integers(1, 3))):
            r0 = int(rng.integers(0, H - 1))
            cells = np.zeros((H, W), dtype=bool)
            cells[r0:r0 + int(rng.integers(1, 3)), c] = True
            obs &= ~cells
            doors[f"d{k}{m}"] = cells
    radius = float(rng.choice([0.0, 0.0, 1.0]))  # inflation in cells of 1 m (0: the raw mask)
    return OccupancyGrid(obs, np.zeros(2), 1.0, radius, doors, {}, "test")


def _check_path(free: np.ndarray, r, s, g, res: float) -> None:  # type: ignore[no-untyped-def]
    assert tuple(r.cells[0]) == s and tuple(r.cells[-1]) == g
    assert free[r.cells[:, 0], r.cells[:, 1]].all()
    d = np.diff(r.cells, axis=0)
    assert np.all(np.abs(d).max(axis=1) == 1)
    diag = (d[:, 0] != 0) & (d[:, 1] != 0)
    a = r.cells[:-1][diag]
    assert free[a[:, 0] + d[diag, 0], a[:, 1]].all() and free[a[:, 0], a[:, 1] + d[diag, 1]].all()  # no corner cut
    assert math.isclose(path_length_m(r.cells, res), r.length_m, rel_tol=0, abs_tol=1e-9)


@pytest.mark.parametrize("case", range(30))
def test_csgraph_lengths_equal_the_reference_on_random_grids_with_doors(case: int) -> None:
    rng = np.random.default_rng([case, 19])
    grid = random_door_grid(rng)
    cache = PlanningCache(grid)
    configs = list(itertools.product([True, False], repeat=len(grid.door_ids)))
    for cfg in configs[:4]:
        free = grid.free(cfg)
        cells = np.argwhere(free)
        if len(cells) < 2:
            continue
        for _ in range(8):
            s = tuple(int(x) for x in cells[rng.integers(len(cells))])
            g = tuple(int(x) for x in cells[rng.integers(len(cells))])
            ref = astar_reference(free, s, g, grid.resolution_m)
            got = cache.shortest_path(s, g, cfg)
            if math.isinf(ref.length_m):
                assert math.isinf(got.length_m) and got.cells.shape == (0, 2)
                continue
            assert abs(got.length_m - ref.length_m) <= 1e-9
            _check_path(free, got, s, g, grid.resolution_m)


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 18), st.integers(2, 18), st.floats(0.0, 0.6), st.sampled_from([0.05, 0.1, 0.25, 1.0]),
       st.integers(0, 2**31 - 1))
def test_astar_equals_the_reference(H: int, W: int, p: float, res: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    free = rng.random((H, W)) >= p
    pts = [(int(rng.integers(H)), int(rng.integers(W))) for _ in range(2)]
    planner = GridPlanner(free, res)
    ref = astar_reference(free, pts[0], pts[1], res)
    for got in (astar(free, pts[0], pts[1], res), planner.path(pts[0], pts[1])):
        if math.isinf(ref.length_m):
            assert math.isinf(got.length_m)
        else:
            assert abs(got.length_m - ref.length_m) <= 1e-9
            _check_path(free, got, pts[0], pts[1], res)


def test_direct_octile_paths_and_detours() -> None:
    free = np.ones((10, 10), dtype=bool)
    r = astar(free, (0, 0), (3, 9), 0.5)
    assert r.length_m == pytest.approx(0.5 * (6 + 3 * math.sqrt(2)))
    free[0:9, 5] = False  # a wall with a gap at the bottom row
    ref = astar_reference(free, (0, 0), (0, 9), 0.5)
    got = astar(free, (0, 0), (0, 9), 0.5)
    assert got.length_m == pytest.approx(ref.length_m, abs=1e-12) and got.length_m > 4.5
    free[9, 5] = False
    assert math.isinf(astar(free, (0, 0), (0, 9), 0.5).length_m)
    # the blocked corner: the diagonal through two touching obstacle cells is not allowed
    free = np.array([[True, False], [False, True]])
    assert math.isinf(GridPlanner(free, 1.0).path((0, 0), (1, 1)).length_m)


def test_planner_does_not_keep_a_writable_alias() -> None:
    free = np.ones((4, 4), dtype=bool)
    p = GridPlanner(free, 1.0)
    free[:, 2] = False  # the caller changes its array afterwards: the planner keeps its copy
    assert p.path((0, 0), (0, 3)).length_m == pytest.approx(3.0)
