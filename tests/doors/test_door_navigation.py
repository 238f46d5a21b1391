"""Door-aware planning: replanning at closed doors, the comparison table, unseen doors and the figure."""

from __future__ import annotations

import math

import numpy as np
import pytest

from psg_data.estimators import EdgeStream
from psg_data.navigation import (
    DoorQuery,
    PlanningCache,
    door_open_probabilities,
    fit_door_filters,
    plot_door_query,
    run_door_episode,
    run_door_navigation,
)
from tests.contract import files_in, interrupt_partway
from tests.navigation.conftest import door_grid


def _q(doors_open: dict[str, bool]) -> DoorQuery:
    return DoorQuery(0, 0.0, (1, 0 + 2), "T", doors_open)


def test_episode_on_a_hand_built_grid() -> None:
    """Wall in column 10 with door 'd' at row 1 and a gap at row 6; start (1, 2), goal T at (1, 18)."""
    cache = PlanningCache(door_grid())
    # door open, believed open: straight through, not blocked, walked == shortest
    ep = run_door_episode(cache, _q({"d": True}), {"d": 0.9})
    assert ep.success and not ep.first_plan_blocked and math.isclose(ep.walked_m, ep.shortest_m)
    # door closed, believed open: walks to the door, discovers it, replans through the gap
    ep = run_door_episode(cache, _q({"d": False}), {"d": 0.9})
    assert ep.success and ep.first_plan_blocked and ep.doors_discovered == ["d"] and ep.n_replans == 1
    # brute force: walked = start -> cell before the door + that cell -> goal under the true doors
    W = cache.grid.shape[1]
    stop = int(ep.first_plan[np.flatnonzero(~cache.free_flat(cache.key({"d": False}))[ep.first_plan])[0] - 1])
    d1 = cache.step_lengths(ep.first_plan[: list(ep.first_plan).index(stop) + 1])[-1]
    d2 = cache.distance("T", cache.key({"d": False}), stop)
    assert math.isclose(ep.walked_m, d1 + d2)
    assert ep.extra_m > 0 and math.isclose(ep.extra_m, ep.walked_m - ep.shortest_m)
    # door closed, predicted closed: takes the gap directly, no extra distance
    ep = run_door_episode(cache, _q({"d": False}), {"d": 0.1})
    assert ep.success and not ep.first_plan_blocked and ep.extra_m == 0.0
    # door open but predicted closed: longer route, never blocked
    ep = run_door_episode(cache, _q({"d": True}), {"d": 0.1})
    assert ep.success and not ep.first_plan_blocked and ep.extra_m > 0
    assert ep.trail[0] == 1 * W + 2


def test_fallback_when_every_route_is_believed_closed() -> None:
    g = door_grid()
    g.static_obstacle[6, 10] = True  # close the gap: the door is the only way
    cache = PlanningCache(g)
    ep = run_door_episode(cache, _q({"d": True}), {"d": 0.2}, no_path="optimistic")
    assert ep.success and ep.fallback and not ep.first_plan_blocked and not ep.declined
    ep = run_door_episode(cache, _q({"d": False}), {"d": 0.2}, no_path="optimistic")
    assert not ep.success and ep.first_plan_blocked and math.isnan(ep.shortest_m)


def test_unseen_door_gets_the_prior_never_nan() -> None:
    t = np.arange(20) * 7200.0 + 1.74e9
    streams = [EdgeStream(("seen", "open"), t, (np.arange(20) % 3 > 0).astype(np.int8)),
               EdgeStream(("empty", "open"), np.zeros(0), np.zeros(0, np.int8))]
    for name in ("perpetua_star", "time_of_week_frequency", "last_seen"):
        filters, kind = fit_door_filters(name, streams, ["seen", "empty", "never"], timezone="UTC")
        assert kind == {"seen": "estimator", "empty": "prior", "never": "prior"}
        p = door_open_probabilities(filters, t[-1] + 3600.0, ["seen", "empty", "never", "no_filter"])
        assert all(math.isfinite(v) and 0 <= v <= 1 for v in p.values())
        assert p["empty"] == p["never"] == p["no_filter"] == 0.5


def test_nan_prediction_falls_back_to_the_prior() -> None:
    class NanFilter:
        def predict(self, t):  # type: ignore[no-untyped-def]
            return np.full(np.shape(t), np.nan)

    assert door_open_probabilities({"d": NanFilter()}, 0.0, ["d"], prior=0.3) == {"d": 0.3}  # type: ignore[dict-item]


def test_loop_world_truth_follows_a_weekly_pattern(loop_world) -> None:  # type: ignore[no-untyped-def]
    import datetime as dt
    from zoneinfo import ZoneInfo

    tz = ZoneInfo(loop_world.timezone)
    t0 = loop_world.t_train_end_s
    for day in range(7):
        for h in (10, 12, 14):
            t = t0 + day * 86400 + h * 3600
            wd = dt.datetime.fromtimestamp(t, tz).weekday()
            if wd >= 5:
                assert loop_world.doors_at(t)["door_ab"] is False
            assert loop_world.doors_at(t)["door_a_hall"] and loop_world.doors_at(t)["door_b_hall"]
    s = {x.edge[0]: x for x in loop_world.train_streams}
    assert np.all(s["door_ab"].t_s < t0) and 0 < s["door_ab"].y.mean() < 1


def test_predictive_planner_beats_all_open(loop_world, tmp_path) -> None:  # type: ignore[no-untyped-def]
    r = run_door_navigation(loop_world, ("perpetua_star", "time_of_week_frequency"), n_queries=120, seed=3)
    t = r.table.set_index("estimator")
    assert list(r.table.columns[:7]) == ["estimator", "queries", "blocked_first_plans", "blocked_rate",
                                         "mean_extra_distance_m", "SR", "SPL"]
    assert (t.queries == 120).all()
    assert t.loc["oracle", "blocked_first_plans"] == 0 and t.loc["oracle", "mean_extra_distance_m"] == 0.0
    assert t.loc["all_open", "blocked_first_plans"] > 0
    for est in ("perpetua_star", "time_of_week_frequency"):
        assert t.loc[est, "blocked_first_plans"] < t.loc["all_open", "blocked_first_plans"]
        assert t.loc[est, "mean_extra_distance_m"] < t.loc["all_open", "mean_extra_distance_m"]
        assert t.loc[est, "SR"] == t.loc["all_open", "SR"] == 1.0  # the hallway is always open
    # a blocked first plan always means door_ab (the only door ever closed) was closed at the query time
    for est in ("all_open", "perpetua_star"):
        rec = r.records[r.records.estimator == est]
        assert (~rec.first_plan_blocked | ~rec["open:door_ab"]).all()
        assert (rec.extra_m >= 0).all()
    # the same queries for every method
    ids = r.records.groupby("estimator").query_id.apply(list)
    assert all(v == ids.iloc[0] for v in ids)
    # the figure
    q = next(q for q, e in zip(r.queries, r.episodes["perpetua_star"]) if not q.doors_open["door_ab"]
             and e.p_open["door_ab"] < 0.5)
    out = tmp_path / "doors.png"
    plot_door_query(loop_world, q, r.episodes["perpetua_star"][q.query_id], out)
    assert out.stat().st_size > 10_000 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_door_plot_returns_a_figure_and_leaves_the_backend(loop_world, user_backend) -> None:  # type: ignore[no-untyped-def]
    from matplotlib.figure import Figure

    r = run_door_navigation(loop_world, ["last_seen"], n_queries=3)
    q = r.queries[0]
    fig = plot_door_query(loop_world, q, r.episodes["last_seen"][q.query_id])
    assert isinstance(fig, Figure) and fig.axes


def test_door_plot_replaces_the_file_atomically(loop_world, tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    from matplotlib.figure import Figure

    r = run_door_navigation(loop_world, ["last_seen"], n_queries=3)
    q = r.queries[0]
    out = tmp_path / "doors.png"
    plot_door_query(loop_world, q, r.episodes["last_seen"][q.query_id], out)
    before = out.read_bytes()
    interrupt_partway(monkeypatch, Figure, "savefig")
    with pytest.raises(KeyboardInterrupt):
        plot_door_query(loop_world, q, r.episodes["last_seen"][q.query_id], out, title="another title")
    assert out.read_bytes() == before and files_in(tmp_path) == ["doors.png"]
