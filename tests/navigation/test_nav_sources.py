"""Navigation with every label source: map observations, door streams and sightings come from the
source, scoring from the schedule; noisy:0 is exactly gt; the paper-real protocol."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from psg_data.errors import EvaluationError
from psg_data.navigation import NavigationEnv, NavigationOptions, ObservationModel, make_queries, run_navigation

METHODS = ["oracle", "last_seen_map", "time_of_week_frequency"]
KEY = ["method", "seed", "query_id"]


def _records(res) -> pd.DataFrame:  # type: ignore[no-untyped-def]
    return res.records.sort_values(KEY).reset_index(drop=True)


@pytest.mark.parametrize("setting", ["predictive", "adaptive"])
def test_noisy_zero_equals_gt(nav_dataset, setting) -> None:  # type: ignore[no-untyped-def]
    runs = {}
    for labels in ("gt", "noisy:0", "noisy:0,0"):
        opts = NavigationOptions.preset("sim", labels=labels, seeds=(0, 1), n_queries=40, setting=setting,
                                        door_belief="predicted", robot_radius_m=0.2)
        runs[labels] = run_navigation(nav_dataset, METHODS, opts)
    a = _records(runs["gt"])
    for other in ("noisy:0", "noisy:0,0"):
        pd.testing.assert_frame_equal(a, _records(runs[other]))
        pd.testing.assert_frame_equal(runs["gt"].summary, runs[other].summary)
    env_gt, env_n0 = runs["gt"].env, runs["noisy:0"].env
    assert [(s.edge, s.t_s.tolist(), s.y.tolist()) for s in env_gt.map_streams] == \
        [(s.edge, s.t_s.tolist(), s.y.tolist()) for s in env_n0.map_streams]
    assert [(s.edge, s.y.tolist()) for s in env_gt.door_streams] == [(s.edge, s.y.tolist()) for s in env_n0.door_streams]
    assert env_n0.observation.exact


def test_noise_flips_the_map_and_the_sightings_but_not_the_truth(nav_dataset) -> None:  # type: ignore[no-untyped-def]
    gt = NavigationEnv.from_dataset(nav_dataset, robot_radius_m=0.2)
    nz = NavigationEnv.from_dataset(nav_dataset, robot_radius_m=0.2, labels="noisy:0.3", label_seed=4)
    # the truth (scoring) does not depend on the source
    assert gt.t_map_s == nz.t_map_s and gt.map_state == nz.map_state
    assert all(gt.gt_at(o, gt.t_map_s + 3600 * k) == nz.gt_at(o, gt.t_map_s + 3600 * k)
               for o in gt.object_ids for k in range(1, 10))
    # flips: the noisy map disagrees with the truth on about 30 % of the gt observations
    truth = {(s.edge, t): y for s in gt.map_streams for t, y in zip(s.t_s, s.y)}
    pairs = [(truth[(s.edge, t)], y) for s in nz.map_streams for t, y in zip(s.t_s, s.y) if (s.edge, t) in truth]
    flipped = np.mean([a != b for a, b in pairs])
    assert 0.15 < flipped < 0.45
    assert nz.observation == ObservationModel(0.3, 0.3, 4, "noisy:0.3")
    g = gt.door_streams[0].y
    rates = [np.mean(NavigationEnv.from_dataset(nav_dataset, labels="noisy:0.3", label_seed=k).door_streams[0].y != g)
             for k in range(8)]
    assert 0.15 < np.mean(rates) < 0.45  # door observations are flipped too (16 per seed)
    # the oracle's beliefs are the truth, but with noisy sightings it misses or mistakes some targets
    res = run_navigation(nz, ["oracle"], seed=0, n_queries=80, labels="noisy:0.3", label_seed=4)
    rec = res.records
    assert (rec["n_missed"] > 0).any() or (rec["outcome"] == "false_positive").any()
    assert res.summary.loc[0, "overall_sr_mean"] < 1.0
    # same query set whatever the labels (queries depend on the truth only)
    assert make_queries(gt, 30, seed=2) == make_queries(nz, 30, seed=2)


def test_observation_model_common_random_numbers() -> None:
    m = ObservationModel(0.25, 0.1, seed=3)
    keys = [(0, q, r, k) for q in range(40) for r in range(5) for k in range(2)]
    there = np.array([m.sees(True, k) for k in keys])
    assert np.array_equal(there, [m.sees(True, k) for k in keys])  # deterministic per key
    assert abs(there.mean() - 0.75) < 4 * math.sqrt(0.25 * 0.75 / len(keys))
    fp = np.array([m.sees(False, k) for k in keys])
    assert abs(fp.mean() - 0.1) < 4 * math.sqrt(0.1 * 0.9 / len(keys))
    exact = ObservationModel()
    assert exact.exact and exact.sees(True, (1,)) and not exact.sees(False, (1,))
    with pytest.raises(EvaluationError):
        ObservationModel(1.5, 0.0)


def test_sources_that_need_stored_labels_say_which_command(nav_dataset) -> None:  # type: ignore[no-untyped-def]
    for labels in ("privileged", "detections:dets.parquet"):
        with pytest.raises(EvaluationError, match="psg-data label"):
            NavigationEnv.from_dataset(nav_dataset, labels=labels)
    with pytest.raises(EvaluationError, match="door-only"):
        NavigationEnv.from_dataset(nav_dataset, labels="observed")
    with pytest.raises(EvaluationError, match="expected gt"):
        NavigationEnv.from_dataset(nav_dataset, labels="psychic")


def test_paper_real_protocol(nav_dataset, tmp_path) -> None:  # type: ignore[no-untyped-def]
    opts = NavigationOptions.preset("paper-real", seeds=(0, 1), robot_radius_m=0.2)
    assert opts.n_queries == 25 and opts.setting == "adaptive" and opts.delta == 0.2 and opts.max_attempts == 2
    assert opts.reach_m == 1.0 and opts.start == "fixed" and opts.door_belief == "predicted"
    res = run_navigation(nav_dataset, ["oracle", "last_seen_map"], opts, out_dir=tmp_path / "a")
    env = res.env
    start = env.start_cell()
    for sd, qs in res.queries.items():
        assert [q.category for q in qs].count("static") == 10
        assert [q.category for q in qs].count("dynamic") == 10
        assert [q.category for q in qs].count("absent") == 5
        assert {q.start_cell for q in qs} == {start}
        assert all(env.t_map_s < q.t_s <= env.t_end_s for q in qs)
    # the recordings' first pose is the origin: the start is the start cell nearest to it
    xy = env.grid.cell_to_world(np.array(start))
    assert np.linalg.norm(xy - np.array(env.start_xy)) < 0.6
    # every present target is reachable, none is excluded: the table counts all 25 per seed
    row = res.summary.set_index("method").loc["oracle"]
    assert row["n_unreachable"] == 0 and row["n_queries"] == 50
    assert row["overall_sr_mean"] == 1.0
    table = res.format_table()
    assert "Static (20)" in table and "Absent (10)" in table and "Overall (50)" in table
    # stored with the results and reused: a second run compares query by query
    files = sorted(p.name for p in (tmp_path / "a" / "queries").glob("*.parquet"))
    assert files == [f"{env.name}_seed{s}_n25_static10-dynamic10-absent5_fixedstart_reachable.parquet" for s in (0, 1)]
    again = run_navigation(nav_dataset, ["oracle"], opts, out_dir=tmp_path / "b")
    assert again.queries == res.queries
    with pytest.raises(EvaluationError):
        NavigationOptions.preset("paper-real", quotas=(("static", 2), ("moving", 1)))
    with pytest.raises(EvaluationError):
        NavigationOptions.preset("paper-fake")


def test_quotas_that_cannot_be_filled_fail_clearly(nav_env) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(EvaluationError, match="quotas"):
        make_queries(nav_env, seed=0, quotas={"absent": 5}, objects=["mug"])  # the mug is never absent


def test_predicted_doors_per_method(nav_dataset) -> None:  # type: ignore[no-untyped-def]
    """The door belief each method plans with: the oracle the truth, the last-seen map the last door
    observation, an estimator its P(open) >= 0.5."""
    import json

    opts = NavigationOptions.preset("sim", seeds=(0,), n_queries=40, door_belief="predicted", robot_radius_m=0.2)
    res = run_navigation(nav_dataset, ["oracle", "last_seen_map", "time_of_week_frequency"], opts)
    rec = res.records
    assert rec[rec.method == "oracle"]["doors_believed"].isna().all()
    last = res.env.door_streams[0].y[-1]
    assert {json.loads(x)["door1"] for x in rec[rec.method == "last_seen_map"]["doors_believed"]} == {bool(last)}
    tow = {json.loads(x)["door1"] for x in rec[rec.method == "time_of_week_frequency"]["doors_believed"]}
    assert tow <= {True, False}
    # per-method door modes with one shared fit
    res2 = run_navigation(nav_dataset, {"a": "time_of_week_frequency", "b": "time_of_week_frequency"}, opts,
                          door_modes={"a": "all_open", "b": "truth"})
    r2 = res2.records
    assert {json.loads(x)["door1"] for x in r2[r2.method == "a"]["doors_believed"]} == {True}
    assert r2[r2.method == "b"]["doors_believed"].isna().all()
    with pytest.raises(EvaluationError):
        run_navigation(nav_dataset, ["oracle"], opts, door_modes={"oracle": "psychic"})
