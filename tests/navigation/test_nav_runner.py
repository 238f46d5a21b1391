"""The harness on a small generated dataset: queries, baselines, scoring, storage and plots."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psg_data.errors import EvaluationError, UnsafeOutputError
from psg_data.navigation import (
    METRICS,
    NavigationEnv,
    build_filters,
    load_queries,
    make_queries,
    plot_query,
    run_navigation,
    save_queries,
    score_records,
)
from tests.contract import files_in, interrupt_partway, snapshot


def test_env_from_dataset(nav_env):
    env = nav_env
    assert set(env.object_ids) == {"mug", "book", "keys"}
    # edges: the receptacles each object was seen on in the 16 training scans
    assert sorted(env.edges) == [("book", "k_shelf"), ("book", "o_desk"), ("keys", "o_bench"), ("mug", "k_table")]
    s = {st.edge: st for st in env.map_streams}
    assert len(s[("mug", "k_table")]) == 16 and s[("mug", "k_table")].y.all()
    # book alternates every two scans between shelf and desk
    assert s[("book", "k_shelf")].y.tolist() == [1 if (k // 2) % 2 == 0 else 0 for k in range(16)]
    # last map scan is scan 15: book on the desk ((15 // 2) % 2 == 1), keys on the bench (15 % 4 == 3)
    assert env.map_state == {"mug": "k_table", "book": "o_desk", "keys": "o_bench"}
    assert env.map_doors == {"door1": True}  # 15 % 3 == 0
    # ground truth: latest scan starting at or before t
    t17 = env.t_map_s + 2 * 7200 + 1.0  # t_map is scan 15's (single-frame) stamp; scan k starts at T0 + 7200 k
    assert env.gt_at("keys", t17) is None and env.gt_at("book", t17) is not None
    assert env.doors_at(t17) == {"door1": False}  # 17 % 3 == 2


def test_queries_are_deterministic_stored_and_categorised(nav_env, tmp_path):
    a = make_queries(nav_env, 40, seed=3)
    b = make_queries(nav_env, 40, seed=3)
    c = make_queries(nav_env, 40, seed=4)
    assert a == b and a != c
    for q in a:
        assert nav_env.t_map_s < q.t_s <= nav_env.t_end_s
        assert nav_env.grid.free({d: False for d in nav_env.grid.door_ids})[q.start_cell]
        gt = nav_env.gt_at(q.object_id, q.t_s)
        expect = "absent" if gt is None else ("static" if gt == nav_env.map_state[q.object_id] else "dynamic")
        assert q.category == expect and q.gt_receptacle == gt
        assert q.doors_open == nav_env.doors_at(q.t_s)
    assert {q.category for q in a} == {"static", "dynamic", "absent"}
    for suffix in (".parquet", ".json"):
        p = save_queries(a, tmp_path / f"q{suffix}")
        assert load_queries(p) == a


def test_oracle_is_perfect_and_unreachable_targets_are_counted(nav_dataset, tmp_path):
    res = run_navigation(nav_dataset, ["oracle", "last_seen_map"], seed=[0, 1], n_queries=60, out_dir=tmp_path / "out",
                         robot_radius_m=0.2)
    rec = res.records
    orc = rec[rec["method"] == "oracle"]
    present = orc[(orc["category"] != "absent") & orc["reachable"]]
    assert len(present) > 0 and present["success"].all()
    assert np.allclose(present["path_m"], present["shortest_path_m"])
    absent = orc[orc["category"] == "absent"]
    assert len(absent) > 0 and absent["aborted"].all() and (absent["path_m"] == 0).all()
    row = res.summary.set_index("method").loc["oracle"]
    for m in ("static_sr", "static_spl", "dynamic_sr", "dynamic_spl", "absent_ar", "overall_sr", "overall_spl"):
        assert row[f"{m}_mean"] == pytest.approx(1.0)
    assert row["absent_dist_m_mean"] == 0.0
    # the door is closed in a third of the scans: some present targets are out of reach
    unreach = orc[(orc["category"] != "absent") & ~orc["reachable"]]
    assert row["n_unreachable"] == len(unreach) > 0
    assert unreach["shortest_path_m"].isna().all() and np.isfinite(unreach["path_m"]).all()
    # no inf or NaN in the table (every category has queries here)
    vals = res.summary[[c for c in res.summary.columns if c.endswith(("_mean", "_std"))]].to_numpy(float)
    assert np.all(np.isfinite(vals))
    # every method saw the same queries
    a = rec[rec["method"] == "oracle"][["seed", "query_id", "object_id", "t_s"]].to_numpy()
    b = rec[rec["method"] == "last_seen_map"][["seed", "query_id", "object_id", "t_s"]].to_numpy()
    assert (a == b).all()
    # files: queries stored and reused; results saved
    qfiles = sorted((tmp_path / "out" / "queries").glob("*.parquet"))
    assert len(qfiles) == 2
    assert (tmp_path / "out" / "results.json").is_file() and (tmp_path / "out" / "table.txt").is_file()
    from psg_data.evaluation import load_results

    loaded = load_results(tmp_path / "out")
    assert loaded.task == "navigation" and loaded.table().row("oracle").values["overall_sr"].mean == pytest.approx(1.0)
    res2 = run_navigation(nav_dataset, ["oracle"], seed=[0, 1], n_queries=60, out_dir=tmp_path / "out",
                          robot_radius_m=0.2)
    assert res2.queries == res.queries
    assert "Static presence" in res.format_table()


def test_last_seen_map_baseline(nav_env):
    res = run_navigation(nav_env, ["last_seen_map"], seed=0, n_queries=60)
    rec = res.records
    st = rec[(rec["category"] == "static") & rec["reachable"]]
    assert st["success"].all()  # static objects are where they were last seen
    dyn = rec[(rec["category"] == "dynamic") & rec["reachable"]]
    assert len(dyn) and not dyn["success"].any()  # it only ever tries the last-seen receptacle
    assert (rec["n_attempts"] <= 1).all()
    # the map belief is the last observation: 1 on the receptacle of the last map scan
    f = build_filters(nav_env, "last_seen_map")
    assert f[("book", "o_desk")].predict([nav_env.t_map_s + 10])[0] == 1.0
    assert f[("book", "k_shelf")].predict([nav_env.t_map_s + 10])[0] == 0.0


def test_estimator_object_and_callable_specs(nav_env):
    class Frequency:
        """Minimal estimator: belief = training frequency of the edge (constant in time)."""

        def fit(self, streams, *, val_streams=None, timezone="UTC"):
            self.freq_ = {s.edge: float(np.mean(s.y)) for s in streams}
            return self

        def make_filter(self, edge):
            from psg_data.errors import NotFittedError
            from psg_data.navigation import LastSeenFilter

            if not hasattr(self, "freq_"):
                raise NotFittedError("not fitted")
            f = LastSeenFilter(edge)
            f.update_many = lambda t, y: None  # keep the frequency
            f.value = self.freq_.get(edge, 0.0)
            return f

    res = run_navigation(nav_env, {"freq": Frequency(), "oracle_fn": lambda env: build_filters(env, "oracle")},
                         seed=0, n_queries=30)
    bel = res.beliefs[("freq", 0, 0)]
    q = res.queries[0][0]
    assert bel == {r: pytest.approx(v) for r, v in
                   {"book": {"k_shelf": 0.5, "o_desk": 0.5}, "keys": {"o_bench": 0.5}, "mug": {"k_table": 1.0}}[
                       q.object_id].items()}
    row = res.summary.set_index("method").loc["oracle_fn"]
    assert row["static_sr_mean"] == 1.0


def test_registry_estimator_runs(nav_env):
    pytest.importorskip("psg_data.estimators._registry")
    res = run_navigation(nav_env, ["fremen"], seed=0, n_queries=20, estimator_settings={"fremen": {"n_periods": 4}})
    assert len(res.records) == 20 and res.records["path_m"].map(math.isfinite).all()


def test_score_records_hand_computed():
    df = pd.DataFrame({
        "category": ["static", "static", "dynamic", "dynamic", "absent", "absent", "dynamic"],
        "reachable": [True, True, True, True, False, False, False],
        "success": [True, False, True, False, False, False, False],
        "aborted": [False, True, False, False, True, False, False],
        "path_m": [4.0, 0.0, 10.0, 6.0, 3.0, 8.0, 2.0],
        "shortest_path_m": [4.0, 5.0, 5.0, 2.0, np.nan, np.nan, np.nan],
    })
    s = score_records(df)
    assert s["static_sr"] == 0.5 and s["static_spl"] == 0.5
    assert s["dynamic_sr"] == 0.5 and s["dynamic_spl"] == pytest.approx(0.25)
    assert s["absent_ar"] == 0.5 and s["absent_dist_m"] == pytest.approx(5.5)
    # overall over 4 reachable present + 2 absent; the correct abort counts as success with efficiency 1
    assert s["overall_sr"] == pytest.approx(3 / 6)
    assert s["overall_spl"] == pytest.approx((1 + 0 + 0.5 + 0 + 1 + 0) / 6)
    assert (s["n_static"], s["n_dynamic"], s["n_absent"], s["n_unreachable"], s["n_queries"]) == (2, 2, 2, 1, 7)
    s2 = score_records(df, absent_in_overall="abort_is_success_spl_path")
    assert s2["overall_sr"] == pytest.approx(3 / 6)
    assert s2["overall_spl"] == pytest.approx((1 + 0 + 0.5 + 0 + 0 + 0) / 6)  # the abort walked 3 m
    s3 = score_records(df, absent_in_overall="exclude")
    assert s3["overall_sr"] == pytest.approx(2 / 4)
    s4 = score_records(df, unreachable="failure")
    assert s4["dynamic_sr"] == pytest.approx(1 / 3) and math.isfinite(s4["dynamic_spl"])
    with pytest.raises(EvaluationError):
        score_records(df, absent_in_overall="maybe")


def test_empty_category_is_nan_with_zero_count():
    df = pd.DataFrame({"category": ["static"], "reachable": [True], "success": [True], "aborted": [False],
                       "path_m": [1.0], "shortest_path_m": [1.0]})
    s = score_records(df)
    assert math.isnan(s["dynamic_sr"]) and s["n_dynamic"] == 0 and math.isnan(s["absent_ar"])
    assert s["overall_sr"] == 1.0 and set(METRICS) <= set(s)


def test_plot_query_png(nav_env, tmp_path):
    import matplotlib.image as mpimg

    res = run_navigation(nav_env, ["oracle"], seed=0, n_queries=15)
    rec = res.records
    qid = int(rec.loc[rec["path_m"] > 0.5, "query_id"].iloc[0])
    p = tmp_path / "q.png"
    res.plot("oracle", qid, p)
    img = mpimg.imread(p)
    assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 400
    assert float(img[..., :3].std()) > 0.05  # not blank
    # the path is drawn: pixels of matplotlib's tab:blue are present
    blue = np.array([0x1F, 0x77, 0xB4]) / 255
    assert np.any(np.all(np.abs(img[..., :3] - blue) < 0.03, axis=-1))
    q = res.queries[0][qid]
    plot_query(nav_env, q, tmp_path / "bare.png")  # no beliefs, no path
    assert mpimg.imread(tmp_path / "bare.png").size > 0


def test_bad_arguments(nav_env):
    with pytest.raises(EvaluationError):
        run_navigation(nav_env, ["oracle"], seed=0, n_queries=5, setting="psychic")
    with pytest.raises(EvaluationError):
        run_navigation(nav_env, ["oracle", "oracle"], seed=0, n_queries=5)
    with pytest.raises(EvaluationError):
        run_navigation(nav_env, [object()], seed=0, n_queries=5)
    with pytest.raises(EvaluationError):
        make_queries(nav_env, 0)


def test_door_belief_last_map_discovers_closed_doors(nav_env):
    res = run_navigation(nav_env, ["oracle"], seed=0, n_queries=60, door_belief="last_map")
    rec = res.records
    present = rec[(rec["category"] != "absent") & rec["reachable"]]
    assert present["success"].all()  # the oracle still finds every reachable target
    assert (present["path_m"] >= present["shortest_path_m"] - 1e-9).all()


def test_chance_row_plans_with_open_doors_when_doors_are_predicted(nav_env):
    """random_receptacle has no door model; predicted doors (the CLI's default) must not send its name to
    the estimator registry, and it plans as with every door open."""
    pred = run_navigation(nav_env, ["random_receptacle"], seed=0, n_queries=30, door_belief="predicted").records
    open_ = run_navigation(nav_env, ["random_receptacle"], seed=0, n_queries=30, door_belief="all_open").records
    cols = ["query_id", "outcome", "success", "path_m"]
    assert len(pred) == 30 and pred[cols].equals(open_[cols])


def test_reachable_only_queries(nav_env):
    win = nav_env.windows.intervals(nav_env.t_map_s, nav_env.t_end_s)
    qs = make_queries(nav_env, 60, seed=0, reachable_only=True, windows=win)
    res = run_navigation(nav_env, ["oracle"], seed=0, n_queries=60, reachable_only=True)
    assert res.summary["n_unreachable"].iloc[0] == 0
    assert res.queries[0] == qs


def test_queries_are_drawn_inside_the_scoring_windows(nav_env):
    res = run_navigation(nav_env, ["oracle"], seed=0, n_queries=80)
    t = np.array([q.t_s for q in res.queries[0]])
    assert nav_env.windows is not None and nav_env.windows.contains(t).all()
    narrow = run_navigation(nav_env, ["oracle"], seed=0, n_queries=40, windows="10-11")
    hours = pd.to_datetime([q.t_s for q in narrow.queries[0]], unit="s", utc=True).tz_convert(nav_env.timezone).hour
    assert set(hours) == {10}
    anytime = run_navigation(nav_env, ["oracle"], seed=0, n_queries=40, windows="none")
    hours = pd.to_datetime([q.t_s for q in anytime.queries[0]], unit="s", utc=True).tz_convert(nav_env.timezone).hour
    assert len(set(hours)) > 5


def test_env_coerce_from_path(nav_dataset):
    env = NavigationEnv.coerce(str(nav_dataset))
    assert env.name == "navtest" and env.grid.door_ids == ("door1",)


def test_door_belief_from_filters(nav_env, scripted):
    from psg_data.navigation import door_belief_from_filters

    t = nav_env.t_map_s + 100.0
    hook = door_belief_from_filters({("door1", "open"): scripted(("door1", "open"), 0.8, 0.1, t + 50)})
    assert hook(t) == {"door1": True} and hook(t + 60) == {"door1": False}
    hook = door_belief_from_filters({("door1", "open"): scripted(("door1", "open"), 0.3),
                                     ("door1", "closed"): scripted(("door1", "closed"), 0.6)})
    assert hook(t) == {"door1": False}
    with pytest.raises(EvaluationError):
        door_belief_from_filters({("door1", "ajar"): scripted(("door1", "ajar"), 0.3)})
    # plugged into the harness: believing the only door closed, the oracle cannot plan into the other
    # room (outcome 'no_path', nothing walked) but still succeeds in its own room
    res = run_navigation(nav_env, ["oracle"], seed=0, n_queries=40,
                         door_belief=door_belief_from_filters({("door1", "open"): scripted(("door1", "open"), 0.0)}))
    rec = res.records
    reach = rec[(rec["category"] != "absent") & rec["reachable"]]
    room = {r: nav_env.receptacles[r].room_id for r in nav_env.receptacles}
    start_room = np.where(reach["start_x_m"] < 4.0, "kitchen", "office")
    same = start_room == reach["gt_receptacle"].map(room).to_numpy()
    assert same.any() and (~same).any()
    assert reach[same]["success"].all()
    other = reach[~same]
    assert not other["success"].any() and (other["outcome"] == "no_path").all() and (other["path_m"] == 0).all()


def test_plot_query_returns_a_figure_and_leaves_the_backend(nav_env, user_backend):  # type: ignore[no-untyped-def]
    from matplotlib.figure import Figure

    res = run_navigation(nav_env, ["oracle"], seed=0, n_queries=3)
    q = res.queries[0][0]
    fig = plot_query(nav_env, q)
    assert isinstance(fig, Figure) and fig.axes[0].get_xlabel() == "x (m)"
    assert isinstance(res.plot("oracle", q.query_id), Figure)


# -- nothing is lost: outputs are replaced atomically, never inside the input dataset ----------------------

def test_run_navigation_never_writes_into_its_input_dataset(nav_dataset, tmp_path):
    before = snapshot(nav_dataset)
    for out in (nav_dataset, nav_dataset / "results"):
        with pytest.raises(UnsafeOutputError, match="lies inside the input") as err:
            run_navigation(nav_dataset, ["oracle"], seed=0, n_queries=5, out_dir=out)
        assert str(out) in str(err.value) and "expected a path outside" in str(err.value)
    assert snapshot(nav_dataset) == before


def test_navigation_result_save_never_writes_into_the_input_dataset(nav_dataset):
    from psg_data.evaluation import write_navigation_results

    before = snapshot(nav_dataset)
    res = run_navigation(nav_dataset, ["oracle"], seed=0, n_queries=5)
    with pytest.raises(UnsafeOutputError, match="lies inside the input"):
        res.save(nav_dataset)
    with pytest.raises(UnsafeOutputError, match="lies inside the input"):
        write_navigation_results(res, nav_dataset / "sub")
    assert snapshot(nav_dataset) == before


def test_run_navigation_out_dir_replaces_each_file_atomically(nav_dataset, tmp_path, monkeypatch):
    out = tmp_path / "out"
    run_navigation(nav_dataset, ["oracle"], seed=0, n_queries=5, out_dir=out)
    before = snapshot(out)
    interrupt_partway(monkeypatch, pd.DataFrame, "to_parquet", only="records")
    with pytest.raises(KeyboardInterrupt):
        run_navigation(nav_dataset, ["oracle", "last_seen_map"], seed=0, n_queries=5, out_dir=out)
    after = snapshot(out)
    assert after["records.parquet"] == before["records.parquet"] and set(after) == set(before)


def test_navigation_result_save_replaces_each_file_atomically(nav_env, tmp_path, monkeypatch):
    from psg_data.evaluation import write_navigation_results

    res = run_navigation(nav_env, ["oracle", "last_seen_map"], seed=0, n_queries=5)
    run_navigation(nav_env, ["oracle"], seed=0, n_queries=5).save(tmp_path)
    before = snapshot(tmp_path)
    interrupt_partway(monkeypatch, pd.DataFrame, "to_csv", only="per_seed")
    with pytest.raises(KeyboardInterrupt):
        res.save(tmp_path)
    assert snapshot(tmp_path)["per_seed.csv"] == before["per_seed.csv"]
    monkeypatch.undo()
    interrupt_partway(monkeypatch, pd.DataFrame, "to_csv", only="results.csv")
    with pytest.raises(KeyboardInterrupt):
        write_navigation_results(res, tmp_path)
    after = snapshot(tmp_path)
    assert after["results.csv"] == before["results.csv"] and set(after) == set(before)


def test_save_queries_replaces_the_file_atomically(nav_env, tmp_path, monkeypatch):
    a, b = make_queries(nav_env, 5, seed=0), make_queries(nav_env, 8, seed=1)
    out = tmp_path / "out"
    for suffix, owner, name, arg in ((".json", Path, "write_text", 0), (".parquet", pd.DataFrame, "to_parquet", 1)):
        p = save_queries(a, out / f"q{suffix}")
        before = p.read_bytes()
        with monkeypatch.context() as m:
            interrupt_partway(m, owner, name, path_arg=arg)
            with pytest.raises(KeyboardInterrupt):
                save_queries(b, p)
        assert p.read_bytes() == before
    assert files_in(out) == ["q.json", "q.parquet"]


def test_plot_query_replaces_the_file_atomically(nav_env, tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    res = run_navigation(nav_env, ["oracle"], seed=0, n_queries=3)
    q = res.queries[0][0]
    p = tmp_path / "out" / "map.png"
    plot_query(nav_env, q, p)
    before = p.read_bytes()
    interrupt_partway(monkeypatch, Figure, "savefig")
    with pytest.raises(KeyboardInterrupt):
        plot_query(nav_env, q, p, title="another title")
    with pytest.raises(KeyboardInterrupt):
        res.plot("oracle", q.query_id, p)
    assert p.read_bytes() == before and files_in(p.parent) == ["map.png"]
