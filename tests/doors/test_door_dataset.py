"""Doors on a dataset's own map: the world built from the dataset, the no-path policies, the CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.errors import EvaluationError
from psg_data.loaders import open_dataset
from psg_data.navigation import (
    DoorQuery,
    DoorTaskOptions,
    DoorWorld,
    PlanningCache,
    grid_from_dataset,
    points_in_polygon,
    run_door_episode,
    run_door_navigation,
    run_door_task,
)
from tests.navigation.conftest import door_grid


@pytest.fixture(scope="module")
def labelled_lab(tmp_path_factory):  # type: ignore[no-untyped-def]
    """The door lab with lab seed 4: its test day has doors open at some query times and closed at
    others (with seed 0 both doors stay closed all of the last day, so no door goal is reachable)."""
    from psg_data.labeling import label_dataset
    from psg_data.synth import LabConfig, LabModel, build_lab
    from tests.doors.conftest import DOOR_LAB

    lab = LabModel(LabConfig(**{**DOOR_LAB, "seed": 4}))
    dst = build_lab(tmp_path_factory.mktemp("doorworld") / "lab", lab.config, lab=lab)
    label_dataset(dst, "observed")
    return dst


def test_world_from_a_dataset(labelled_lab) -> None:  # type: ignore[no-untyped-def]
    ds = open_dataset(labelled_lab)
    world = DoorWorld.from_dataset(ds, labels="observed")
    ref = grid_from_dataset(ds)
    assert np.array_equal(world.grid.static_obstacle, ref.static_obstacle)
    assert world.door_ids == tuple(sorted(ds.doors))
    for d in ds.doors:
        assert np.array_equal(world.grid.door_cells[d], ref.door_cells[d])
    # truth: the door_states row of the latest scan starting at or before t
    scans = ds.df("scans").sort_values("start_stamp_ns")
    states = ds.df("door_states")
    for sid, t0 in zip(scans["scan_id"], scans["start_stamp_ns"]):
        want = {r.door_id: r.state != "closed" for r in states[states.scan_id == sid].itertuples()}
        assert world.doors_at(t0 / 1e9 + 60.0) == want
    # training streams: the observed door rows of the train scans only
    train = set(scans.loc[scans["split"] == "train", "scan_id"])
    t_train = {int(t) for s, t in zip(scans["scan_id"], scans["start_stamp_ns"]) if s in train}
    lab = ds.table("labels").to_pandas()
    obs = lab[(lab.source == "observed") & (lab.receptacle_id == "open") & lab.code.isin([0, 1])]
    for s in world.train_streams:
        o = obs[(obs.object_id == s.edge[0]) & obs.stamp_ns.isin(t_train)].sort_values("stamp_ns")
        assert s.edge[1] == "open" and s.y.tolist() == o.code.tolist()
        assert np.allclose(s.t_s, o.stamp_ns / 1e9)
    assert np.all(np.concatenate([s.t_s for s in world.train_streams]) < world.t_train_end_s)
    # starts lie in their room, goals are the room's receptacles
    W = world.grid.shape[1]
    for rid, cells in world.start_cells.items():
        xy = world.grid.cell_to_world(cells)
        assert points_in_polygon(xy, ds.rooms[rid].floor_polygon_m).all()
        assert set(world.goals[rid]) <= {r for r, rec in ds.receptacles.items() if rec.room_id == rid}
        assert world.grid.free({d: False for d in world.door_ids}).ravel()[cells[:, 0] * W + cells[:, 1]].all()
    # a synthetic lab: its scoring windows (the bi-hourly steps 9-11, ..., 15-17), and its physical door states
    assert world.hours == (9.0, 17.0) and world.info["truth"] == "physical state (generator)"


def test_door_table_on_the_dataset(labelled_lab) -> None:  # type: ignore[no-untyped-def]
    world = DoorWorld.from_dataset(labelled_lab, labels="observed")
    r = run_door_navigation(world, ["time_of_week_frequency"], n_queries=60, seed=1)
    t = r.table.set_index("estimator")
    unreachable = sum(not math.isfinite(e.shortest_m) for e in r.episodes["oracle"])
    # the planner that knows the doors never meets a closed one and never sets off in vain
    assert t.loc["oracle", "blocked_first_plans"] == 0 and t.loc["oracle", "wasted_m"] == 0.0
    assert t.loc["oracle", "declined"] == unreachable and t.loc["oracle", "declined_reachable"] == 0
    assert t.loc["oracle", "SR"] == 1.0 and t.loc["all_open", "SR"] == 1.0
    # all-open: every query whose goal no route reaches starts with a blocked plan (a chain of rooms)
    assert t.loc["all_open", "blocked_first_plans"] >= unreachable and t.loc["all_open", "declined"] == 0
    assert (t["n_reachable"] == 60 - unreachable).all()
    for q in r.queries:
        assert 9.0 <= _local_hour(q.t_s, world.timezone) < 17.0 and q.t_s >= world.t_train_end_s


def _local_hour(t_s: float, tz: str) -> float:
    import datetime as dt
    from zoneinfo import ZoneInfo

    d = dt.datetime.fromtimestamp(t_s, ZoneInfo(tz))
    return d.hour + d.minute / 60


def test_no_path_policies() -> None:
    g = door_grid()
    g.static_obstacle[6, 10] = True  # close the gap: the door is the only way
    cache = PlanningCache(g)
    q_open = DoorQuery(0, 0.0, (1, 2), "T", {"d": True})
    q_closed = DoorQuery(1, 0.0, (1, 2), "T", {"d": False})
    ep = run_door_episode(cache, q_open, {"d": 0.2})  # default: decline a goal believed unreachable
    assert ep.declined and not ep.success and ep.walked_m == 0.0 and not ep.first_plan_blocked
    ep = run_door_episode(cache, q_closed, {"d": 0.2})
    assert ep.declined and ep.walked_m == 0.0 and math.isnan(ep.shortest_m)  # correct: nothing wasted
    ep = run_door_episode(cache, q_closed, {"d": 0.9})
    assert not ep.declined and ep.first_plan_blocked and ep.walked_m > 0
    with pytest.raises(EvaluationError):
        run_door_episode(cache, q_open, {"d": 0.2}, no_path="hope")


def test_door_task_and_objects_behind_doors(labelled_lab) -> None:  # type: ignore[no-untyped-def]
    opts = DoorTaskOptions(labels="gt", seeds=(0, 1), n_queries=30)
    res = run_door_task(labelled_lab, [("tow", "time_of_week_frequency")], opts)
    s = res.summary.set_index("estimator")
    assert list(s.index) == ["all_open", "oracle", "tow", "tow (expected cost)"]
    assert (s["queries"] == 60).all() and (s["seeds"] == 2).all()
    assert set(res.records["rule"]) == {"threshold", "expected_cost"}
    # the headroom table comes first, with the two reference rows
    from psg_data.evaluation import door_results

    tables = door_results(res).tables
    assert [t.name for t in tables[:2]] == ["door_headroom", "doors"]
    assert [r.method for r in tables[0].rows] == ["oracle", "all_open"] and "headroom" in tables[0].notes[0]
    assert np.isclose(s.loc["tow", "blocked_rate"], res.per_seed[res.per_seed.estimator == "tow"].blocked_rate.mean())
    # the objects table scores reachability both ways too: every query, an unreachable present target
    # counts like an absent one (aborting is right, walking is a failure); recomputed from the records
    objt = tables[-1]
    assert objt.name == "objects" and objt.groups[-1] == (f"Both ways ({len(res.objects.records) // 4})",
                                                          ["overall_sr_both"])
    recs = res.objects.records
    assert (~recs.reachable & (recs.category != "absent")).any()  # the chain lab cuts some targets off
    for row in objt.rows:
        d = recs[recs.method == row.method]
        ok = np.where((d.category == "absent") | ~d.reachable, d.aborted, d.success)
        assert row.values["overall_sr_both"].mean == pytest.approx(ok.mean())
    objs = res.objects.summary.set_index("method")
    assert list(objs.index) == ["oracle", "tow [doors all open]", "tow [doors predicted]", "tow [doors known]"]
    rec = res.objects.records
    assert rec[rec.method == "tow [doors known]"]["doors_believed"].isna().all()
    assert {json.loads(x)["door_ab"] for x in rec[rec.method == "tow [doors all open]"]["doors_believed"]} == {True}
    # the three door modes share one fit of the object filters: identical beliefs at the query time
    a = rec[rec.method == "tow [doors all open]"]["best_belief"].to_numpy()
    b = rec[rec.method == "tow [doors known]"]["best_belief"].to_numpy()
    assert np.array_equal(a, b)
    assert "declined" in res.format_table()
    # the walking summary, recomputed from the records
    from psg_data.navigation import walk_summary

    w = walk_summary(res.objects).set_index("method")
    for m, df in rec.groupby("method"):
        assert w.loc[m, "walked_m"] == pytest.approx(df.path_m.mean())
        assert w.loc[m, "found"] == df.success.sum()
    a = rec[rec.method == "tow [doors all open]"].set_index(["seed", "query_id"]).success
    p = rec[rec.method == "tow [doors predicted]"].set_index(["seed", "query_id"]).success
    assert w.loc["tow [doors predicted]", "lost_vs_all_open"] == int((a & ~p).sum())
    assert w.loc["tow [doors predicted]", "won_vs_all_open"] == int((~a & p).sum())


def test_cli_doors_on_a_dataset(labelled_lab, tmp_path) -> None:  # type: ignore[no-untyped-def]
    from psg_data.cli.psg_eval_cmd import main

    out = tmp_path / "doors"
    r = CliRunner().invoke(main, ["--task", "doors", "--dataset", str(labelled_lab), "-e", "time_of_week_frequency",
                                  "--no-references", "--seeds", "1", "--queries", "40", "--labels", "observed",
                                  "--out", str(out), "-q"])
    assert r.exit_code == 0, r.output
    assert "blocked %" in r.output and "Objects behind predicted-closed doors" in r.output
    for f in ("results.json", "results.csv", "records.csv", "table.txt", "door_plan_time_of_week_frequency.png"):
        assert (out / f).is_file(), f
    info = json.loads((out / "results.json").read_text())["info"]
    assert info["task"] == "doors" and info["labels"] == "observed" and info["world"]["doors"]["from"].startswith("labels")
    png = out / "door_plan_time_of_week_frequency.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    r = CliRunner().invoke(main, ["--task", "doors", "--dataset", "door-loop", "-e", "time_of_week_frequency",
                                  "--out", str(tmp_path / "x")])
    assert r.exit_code == 1 and "unit-test world" in r.output
