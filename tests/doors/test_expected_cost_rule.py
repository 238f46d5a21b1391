"""The expected-cost door rule against brute-force enumeration of door states on small worlds."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from psg_data.maps import OccupancyGrid, PlanningCache, expected_cost_route
from psg_data.navigation import DoorQuery, run_door_episode


def _world(seed: int) -> tuple[OccupancyGrid, tuple[int, int]]:
    """9 x 25 cells of 1 m: walls in columns 6, 12, 18; each wall has one or two doors and maybe a gap
    (without a gap the wall's doors are the only way); receptacle T at the east end. Start at column 1."""
    rng = np.random.default_rng(seed)
    H, W = 9, 25
    obs = np.zeros((H, W), dtype=bool)
    doors: dict[str, np.ndarray] = {}
    for k, col in enumerate((6, 12, 18)):
        obs[:, col] = True
        rows = rng.choice(np.arange(1, H - 1), size=3, replace=False)
        n_doors = 1 if k == 1 else int(rng.integers(1, 3))
        for m in range(n_doors):
            if len(doors) >= 4:
                break
            cell = np.zeros((H, W), dtype=bool)
            cell[rows[m], col] = True
            doors[f"d{col}_{m}"] = cell
            obs[rows[m], col] = False
        if rng.random() < 0.5:
            obs[rows[2], col] = False  # an open gap
    rec = np.zeros((H, W), dtype=bool)
    rec[int(rng.integers(H)), W - 1] = True
    obs |= rec
    start = (int(rng.integers(H)), 1)
    return OccupancyGrid(obs, np.array([0.0, 0.0]), 1.0, 0.0, doors, {"T": rec}, "test"), start


def _walk(cache: PlanningCache, path: np.ndarray, world: dict[str, bool]) -> tuple[float, int | None, set[str]]:
    """Walk ``path`` in ``world``: (metres, cell of the first blocked step or None, doors closed there)."""
    free = cache.free_flat(cache.key(world))
    bad = np.flatnonzero(~free[path])
    if not bad.size:
        return float(cache.step_lengths(path)[-1]), None, set()
    kb = int(bad[0])
    cell = int(path[kb])
    culprits = {d for d, o in world.items() if not o and cache.grid.door_cells[d].ravel()[cell]}
    return float(cache.step_lengths(path[:kb])[-1]), int(path[kb - 1]), culprits


def _brute(cache: PlanningCache, cur: int, known: dict[str, bool], p: dict[str, float]) -> float:
    """Min over every policy (a route under any guess of the unknown doors, then recursively) of the
    expected walked distance, by enumerating the door states consistent with what is known."""
    doors = cache.grid.door_ids
    unknown = [d for d in doors if d not in known]
    if cache.path("T", cache.key({**known, **{d: True for d in unknown}}), cur) is None:
        return 0.0  # the goal is unreachable in every world still possible: stop
    best = math.inf
    for guess in itertools.product((True, False), repeat=len(unknown)):
        path = cache.path("T", cache.key({**known, **dict(zip(unknown, guess))}), cur)
        if path is None:
            continue
        total = 0.0
        for states in itertools.product((True, False), repeat=len(unknown)):
            world = {**known, **dict(zip(unknown, states))}
            w = math.prod(p[d] if s else 1.0 - p[d] for d, s in zip(unknown, states))
            if w == 0.0:
                continue
            walked, stop, culprits = _walk(cache, path, world)
            if stop is not None:
                seg = path[: list(path).index(stop) + 1]
                passed = {d for d in unknown if world[d] and cache.grid.door_cells[d].ravel()[seg].any()}
                walked += _brute(cache, stop, {**known, **{d: False for d in culprits}, **{d: True for d in passed}}, p)
            total += w * walked
        best = min(best, total)
    return best


@pytest.mark.parametrize("seed", range(12))
def test_expected_cost_route_equals_brute_force(seed: int) -> None:
    grid, start = _world(seed)
    cache = PlanningCache(grid, reach_m=1.0)
    rng = np.random.default_rng(100 + seed)
    doors = grid.door_ids
    p = {d: float(rng.uniform(0.05, 0.95)) for d in doors}
    W = grid.shape[1]
    s = start[0] * W + start[1]
    brute = _brute(cache, s, {}, p)
    route = expected_cost_route(cache, "T", s, p)
    if route is None:  # only when no route exists even with every door open
        assert cache.path("T", cache.key({d: True for d in doors}), s) is None
        return
    assert math.isclose(route.expected_m, brute, rel_tol=1e-9, abs_tol=1e-9)
    # the agent walking in every world, weighted by its probability, walks that expectation
    mean = 0.0
    for states in itertools.product((True, False), repeat=len(doors)):
        world = dict(zip(doors, states))
        w = math.prod(p[d] if o else 1.0 - p[d] for d, o in world.items())
        ep = run_door_episode(cache, DoorQuery(0, 0.0, start, "T", world), p, rule="expected_cost")
        reachable = cache.path("T", cache.key(world), s) is not None
        assert ep.success == reachable  # never gives up on a goal some route reaches
        mean += w * ep.walked_m
    assert math.isclose(mean, brute, rel_tol=1e-9, abs_tol=1e-9)


def _wall_world(H: int, door_row: int, gap_row: int | None) -> OccupancyGrid:
    """H x 11 cells of 1 m: a wall in column 5 with door 'd' at ``door_row`` and maybe an open gap;
    receptacle T at (``door_row``, 10)."""
    W = 11
    obs = np.zeros((H, W), dtype=bool)
    obs[:, 5] = True
    door = np.zeros((H, W), dtype=bool)
    door[door_row, 5] = True
    obs[door_row, 5] = False
    if gap_row is not None:
        obs[gap_row, 5] = False
    rec = np.zeros((H, W), dtype=bool)
    rec[door_row, 10] = True
    return OccupancyGrid(obs | rec, np.array([0.0, 0.0]), 1.0, 0.0, {"d": door}, {"T": rec}, "test")


def test_expected_cost_weighs_risk_where_the_threshold_declines() -> None:
    """Only route through a door of P(open) 0.2: the threshold rule declines, the expected-cost rule goes."""
    cache = PlanningCache(_wall_world(5, 2, None))
    q = DoorQuery(0, 0.0, (2, 0), "T", {"d": True})
    assert run_door_episode(cache, q, {"d": 0.2}).declined
    ep = run_door_episode(cache, q, {"d": 0.2}, rule="expected_cost")
    assert ep.success and not ep.declined and ep.walked_m == ep.shortest_m
    # negligible P(open): the door counts as closed, the rule gives up without walking
    ep = run_door_episode(cache, q, {"d": 0.001}, rule="expected_cost")
    assert ep.declined and ep.walked_m == 0.0


def test_expected_cost_takes_the_detour_when_the_door_is_likely_closed() -> None:
    """A door on the short route and an open gap on a long one: the choice flips where
    p * L_door + (1 - p) * (to the door and round by the gap) = L_gap."""
    cache = PlanningCache(_wall_world(12, 1, 11))  # the gap far south
    W = 11
    s = 1 * W + 1
    direct = cache.distance("T", cache.key({"d": True}), s)
    gap = cache.distance("T", cache.key({"d": False}), s)
    r = expected_cost_route(cache, "T", s, {"d": 0.5})
    assert r is not None
    stop = 1 * W + 4
    fail = cache.step_lengths(np.arange(s, stop + 1))[-1] + cache.distance("T", cache.key({"d": False}), stop)
    for p in (0.05, 0.3, 0.6, 0.95):
        r = expected_cost_route(cache, "T", s, {"d": p})
        assert r is not None
        want = min(p * direct + (1 - p) * fail, gap)
        assert math.isclose(r.expected_m, want, rel_tol=1e-9)
        assert r.assumed_open["d"] == (p * direct + (1 - p) * fail < gap)


def test_probabilities_outside_the_unit_interval_are_rejected() -> None:
    grid, start = _world(0)
    cache = PlanningCache(grid)
    with pytest.raises(Exception, match="P\\(open\\)"):
        expected_cost_route(cache, "T", start[0] * grid.shape[1] + start[1], {grid.door_ids[0]: 1.5})


def test_reachability_scored_both_ways() -> None:
    """SR all: a reachable goal counts when reached, an unreachable one when the robot did not set off;
    extra blocked m: only the queries whose all-doors-open route meets a closed door."""
    import pandas as pd

    from psg_data.evaluation._door_report import door_terms

    nan = float("nan")
    df = pd.DataFrame({
        "shortest_m": [5.0, 5.0, nan, nan, 8.0],
        "walked_m": [5.0, 0.0, 0.0, 3.0, 10.0],
        "success": [True, False, False, False, True],
        "extra_m": [0.0, nan, nan, nan, 2.0],
        "first_plan_blocked": [False, False, False, True, True],
        "open_plan_blocked": [False, False, True, True, True],
    })
    t = door_terms(df)
    num, den = t["SR_all"]
    # reached / declined a reachable goal (failure) / correct decline / walked towards an unreachable goal / reached
    assert num.tolist() == [1.0, 0.0, 1.0, 0.0, 1.0] and den.sum() == 5
    num, den = t["SR"]
    assert num.sum() / den.sum() == pytest.approx(2 / 3)
    num, den = t["wasted_m"]
    assert num.sum() / den.sum() == pytest.approx(1.5)
    num, den = t["extra_blocked_m"]
    assert den.tolist() == [0.0, 0.0, 0.0, 0.0, 1.0] and num.sum() == pytest.approx(2.0)


def test_figure_query_is_the_papers_case() -> None:
    """The door figure prefers a query whose all-open plan met a closed door that the estimator predicted
    closed, and which the estimator reached by another route (the longest saving first)."""
    from types import SimpleNamespace as NS

    from psg_data.evaluation._door_report import pick_blocked_door_query

    def ep(blocked: bool, success: bool, walked: float, p: float = 1.0, found: tuple[str, ...] = ()) -> NS:
        return NS(first_plan_blocked=blocked, success=success, declined=False, walked_m=walked,
                  p_open={"d": p}, doors_discovered=list(found))

    base = [ep(False, True, 5.0), ep(True, True, 12.0, found=("d",)), ep(True, True, 20.0, found=("d",)),
            ep(True, True, 15.0, found=("d",))]
    est = [ep(False, True, 5.0, 0.9), ep(False, True, 8.0, 0.6), ep(False, True, 9.0, 0.2), ep(False, True, 9.0, 0.3)]
    res = NS(first=NS(episodes={"est": est, "all_open": base}))
    # queries 2 and 3: predicted closed, went around; query 2 saves more (20 - 9 > 15 - 9)
    assert pick_blocked_door_query(res, "est") == 2
    est[2] = ep(True, True, 21.0, 0.2)
    est[3] = ep(True, True, 16.0, 0.3)
    assert pick_blocked_door_query(res, "est") == 1  # planned around without predicting it closed
