"""The agent on hand-built maps whose path lengths are known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from .conftest import T0_S, corridor_grid, door_grid, make_query

from psg_data.errors import EvaluationError
from psg_data.navigation import AgentConfig, PlanningCache, run_episode

S2 = math.sqrt(2.0)


def filters(scripted, **beliefs):
    return {r: scripted(("obj", r), b) for r, b in beliefs.items()}


# Corridor: 5 x 30 cells of 1 m, A at (2, 0), B at (2, 29), C at (0, 15); reach 1 m means the
# 4-neighbours of a receptacle cell. Start (2, 10): 9 m to A's approach (2, 1), 18 m to B's (2, 28).
@pytest.fixture
def corridor():
    return PlanningCache(corridor_grid(), reach_m=1.0)


def test_best_receptacle_first_try(corridor, scripted):
    q = make_query(corridor.grid, (2, 10), "B")
    ep = run_episode(corridor, q, filters(scripted, A=0.3, B=0.9), AgentConfig())
    assert ep.success and ep.outcome == "found" and ep.n_attempts == 1
    assert ep.path_m == pytest.approx(18.0) and ep.shortest_path_m == pytest.approx(18.0)
    assert ep.predicted_receptacle == "B" and ep.best_belief == pytest.approx(0.9)


def test_second_attempt_spl_one_half(corridor, scripted):
    q = make_query(corridor.grid, (2, 10), "B")
    ep = run_episode(corridor, q, filters(scripted, A=0.9, B=0.5), AgentConfig())
    assert ep.success and ep.n_attempts == 2 and ep.visited == ["A"]
    assert ep.path_m == pytest.approx(9.0 + 27.0)  # to A, then A's approach (2, 1) -> (2, 28)
    from psg_data.metrics import spl

    assert spl([ep.success], [ep.shortest_path_m], [ep.path_m]) == pytest.approx(0.5)


def test_low_beliefs_abort_present_target(corridor, scripted):
    q = make_query(corridor.grid, (2, 10), "B")
    ep = run_episode(corridor, q, filters(scripted, A=0.15, B=0.19), AgentConfig(delta=0.2))
    assert ep.outcome == "abort" and ep.aborted and not ep.success and ep.path_m == 0.0
    ep = run_episode(corridor, q, filters(scripted, A=0.15, B=0.19), AgentConfig(delta=0.1))
    assert ep.success  # a lower threshold lets it try B (the best) first


def test_absent_target_abort_and_distance(corridor, scripted):
    q = make_query(corridor.grid, (2, 10), None)
    ep = run_episode(corridor, q, filters(scripted, A=0.1, B=0.05), AgentConfig())
    assert ep.aborted and ep.path_m == 0.0 and not ep.reachable and math.isnan(ep.shortest_path_m)
    ep = run_episode(corridor, q, filters(scripted, A=0.9, B=0.05), AgentConfig())
    assert ep.aborted and ep.path_m == pytest.approx(9.0) and ep.visited == ["A"]
    ep = run_episode(corridor, q, filters(scripted, A=0.9, B=0.5), AgentConfig())
    assert ep.aborted and ep.path_m == pytest.approx(36.0)  # both candidates above delta visited
    ep = run_episode(corridor, q, filters(scripted, A=0.9, B=0.5, C=0.4), AgentConfig())
    assert ep.outcome == "exhausted" and not ep.aborted and ep.n_attempts == 2


def test_en_route_detection(scripted):
    # object on C (top row, column 15): approach cells (1, 15), (0, 14), (0, 16). Rows 2-4 are blocked
    # in columns 12-18, so every path from (1, 10) to B runs along row 1 and passes (1, 15) after 5 m.
    grid = corridor_grid()
    grid.static_obstacle[2:, 12:19] = True
    corridor = PlanningCache(grid, reach_m=1.0)
    q = make_query(corridor.grid, (1, 10), "C")
    ep = run_episode(corridor, q, filters(scripted, B=0.9), AgentConfig())
    assert ep.success and ep.path_m == pytest.approx(5.0) and ep.visited == []
    ep = run_episode(corridor, q, filters(scripted, B=0.9), AgentConfig(detect_en_route=False))
    assert not ep.success and ep.visited == ["B"]


def test_adaptive_time_dependent_belief(corridor, scripted):
    """B's belief drops below delta 10 s after the query; walking to A takes 9 m / 0.5 m/s = 18 s."""
    q = make_query(corridor.grid, (2, 10), None)
    t_q = q.t_s
    fs = {"A": scripted(("obj", "A"), 0.9), "B": scripted(("obj", "B"), 0.5, 0.1, t_q + 10.0)}
    pred = run_episode(corridor, q, fs, AgentConfig(setting="predictive"))
    ada = run_episode(corridor, q, fs, AgentConfig(setting="adaptive", speed_mps=0.5))
    assert pred.aborted and pred.path_m == pytest.approx(36.0)
    assert ada.aborted and ada.path_m == pytest.approx(9.0)
    assert fs["A"].updates == []  # the caller's filters are untouched (the agent updates copies)


def test_adaptive_updates_visited_edge(corridor, scripted):
    q = make_query(corridor.grid, (2, 10), "B")
    fa = scripted(("obj", "A"), 0.9)
    fa_updates = []
    orig = type(fa).update

    def spy(self, t, y):
        fa_updates.append((t, y))
        orig(self, t, y)

    type(fa).update = spy
    try:
        ep = run_episode(corridor, q, {"A": fa, "B": scripted(("obj", "B"), 0.5)}, AgentConfig(setting="adaptive"))
    finally:
        type(fa).update = orig
    assert ep.success and fa_updates == [(pytest.approx(q.t_s + 9.0 / 0.5), 0)]


def test_unreachable_candidate_is_skipped(scripted):
    grid = corridor_grid()
    grid.static_obstacle[:, 20] = True  # cut the corridor: B is unreachable from column 10
    cache = PlanningCache(grid, reach_m=1.0)
    q = make_query(grid, (2, 10), "A")
    ep = run_episode(cache, q, filters(scripted, B=0.9, A=0.5), AgentConfig(max_attempts=1))
    assert ep.success and ep.n_attempts == 1 and ep.path_m == pytest.approx(9.0)
    q = make_query(grid, (2, 10), "B")
    ep = run_episode(cache, q, filters(scripted, B=0.9), AgentConfig())
    assert ep.outcome == "no_path" and not ep.success and not ep.reachable
    assert math.isnan(ep.shortest_path_m) and ep.path_m == 0.0


# Door map: wall in column 10 with door 'd' at (1, 10) and a gap at (6, 10). Start (1, 2), target T
# at (1, 18) with approach cells (0, 18), (2, 18), (1, 17), (1, 19).
def test_door_open_vs_closed_shortest_paths(scripted):
    cache = PlanningCache(door_grid(), reach_m=1.0)
    f = filters(scripted, T=0.9)
    ep = run_episode(cache, make_query(cache.grid, (1, 2), "T", doors={"d": True}), f, AgentConfig())
    assert ep.success and ep.path_m == pytest.approx(15.0) and ep.shortest_path_m == pytest.approx(15.0)
    # closed: (1,2) -> (6,9): 5 sqrt2 + 2; through the gap (6,9)->(6,11): 2; (6,11) -> (1,17): 5 sqrt2 + 1
    ep = run_episode(cache, make_query(cache.grid, (1, 2), "T", doors={"d": False}), f, AgentConfig())
    assert ep.success and ep.path_m == pytest.approx(10 * S2 + 5) and ep.shortest_path_m == pytest.approx(10 * S2 + 5)


def test_door_discovered_closed_on_the_way(scripted):
    cache = PlanningCache(door_grid(), reach_m=1.0)
    q = make_query(cache.grid, (1, 2), "T", doors={"d": False})
    ep = run_episode(cache, q, filters(scripted, T=0.9), AgentConfig(), door_belief={"d": True})
    # walks 7 m to (1, 9), finds the door closed, then (1,9)->(6,9) 5, the gap 2, (6,11)->(1,17) 5 sqrt2 + 1
    assert ep.success and ep.doors_discovered == ["d"]
    assert ep.path_m == pytest.approx(15 + 5 * S2)
    assert ep.shortest_path_m == pytest.approx(10 * S2 + 5)


def test_door_believed_closed_takes_the_detour(scripted):
    cache = PlanningCache(door_grid(), reach_m=1.0)
    q = make_query(cache.grid, (1, 2), "T", doors={"d": True})
    ep = run_episode(cache, q, filters(scripted, T=0.9), AgentConfig(), door_belief={"d": False})
    assert ep.success and ep.path_m == pytest.approx(10 * S2 + 5) and ep.shortest_path_m == pytest.approx(15.0)


def test_all_doors_closed_target_unreachable(scripted):
    grid = door_grid()
    grid.static_obstacle[6, 10] = True  # close the gap too: only the door connects the halves
    cache = PlanningCache(grid, reach_m=1.0)
    q = make_query(grid, (1, 2), "T", doors={"d": False})
    ep = run_episode(cache, q, filters(scripted, T=0.9, S=0.5), AgentConfig(), door_belief={"d": True})
    assert not ep.reachable and not ep.success and math.isnan(ep.shortest_path_m)
    assert math.isfinite(ep.path_m) and ep.doors_discovered == ["d"]
    # it walked to the door (7 m), learnt it is closed, then tried S: (1, 9) -> (1, 1) is 8 m
    assert ep.visited == ["S"] and ep.path_m == pytest.approx(7.0 + 8.0)


def test_bad_settings_raise():
    with pytest.raises(EvaluationError):
        AgentConfig(setting="psychic")
    with pytest.raises(EvaluationError):
        AgentConfig(delta=1.5)
    with pytest.raises(EvaluationError):
        AgentConfig(max_attempts=0)


def test_non_finite_belief_raises(corridor, scripted):
    q = make_query(corridor.grid, (2, 10), "B")
    with pytest.raises(EvaluationError):
        run_episode(corridor, q, {"B": scripted(("obj", "B"), float("nan"))}, AgentConfig())


def test_start_in_sight_succeeds_without_moving(corridor, scripted):
    q = make_query(corridor.grid, (2, 28), "B", t_s=T0_S)
    ep = run_episode(corridor, q, filters(scripted, A=0.9, B=0.5), AgentConfig())
    assert ep.success and ep.path_m == 0.0 and ep.shortest_path_m == 0.0
    assert np.asarray(ep.trail).size == 1
