"""The simulation navigation protocols: the adaptive agent (looks, updates, switches), the queries (last
map update inside the test week), what reaches the filters, the scene scoring, the CLI (tiny houses)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from .conftest import corridor_grid, make_query

from psg_data.navigation import AgentConfig, PlanningCache, run_episode
from psg_data.navigation._sim_agent import HouseSight, run_adaptive_episode


class ObsFilter:
    """Belief = the last observation if there is one, else a fixed prior; records its updates."""

    def __init__(self, edge: tuple[str, str], prior: float) -> None:
        self.edge, self.prior = edge, prior
        self.updates: list[tuple[float, int]] = []

    @property
    def last_t_s(self) -> float | None:
        return self.updates[-1][0] if self.updates else None

    def update(self, t_s: float, y: int) -> None:
        self.updates.append((float(t_s), int(y)))

    def update_many(self, t_s: Any, y: Any) -> None:
        for a, b in zip(np.asarray(t_s).reshape(-1), np.asarray(y).reshape(-1)):
            self.update(float(a), int(b))

    def predict(self, t_s: Any) -> np.ndarray:
        v = float(self.updates[-1][1]) if self.updates else self.prior
        return np.full(np.asarray(t_s, np.float64).shape, v)

    def get_state(self) -> dict[str, Any]:
        return {}


class OpenLayout:
    """No walls: everything within the range is in sight."""

    def visible(self, points: Any, targets: Any, door_open: Any) -> np.ndarray:
        P, T = np.asarray(points, float).reshape(-1, 2), np.asarray(targets, float).reshape(-1, 2)
        return np.ones((len(P), len(T)), bool)


@pytest.fixture
def corridor() -> PlanningCache:
    return PlanningCache(corridor_grid(), reach_m=1.0)


def sight(cache: PlanningCache, range_m: float) -> HouseSight:
    g = cache.grid
    xy = {r: tuple(float(v) for v in g.cell_to_world(tuple(np.argwhere(m)[0]))) for r, m in g.receptacle_cells.items()}
    return HouseSight(OpenLayout(), xy, range_m)


def beliefs(**b: float) -> dict[str, ObsFilter]:
    return {r: ObsFilter(("obj", r), v) for r, v in b.items()}


# Corridor (tests/navigation/conftest.py): 5 x 30 cells of 1 m, A at (2, 0), B at (2, 29), C at (0, 15).
def test_object_seen_on_the_way_switches_target(corridor: PlanningCache) -> None:
    q = make_query(corridor.grid, (2, 10), "C")
    fs = beliefs(B=0.9, C=0.3)
    ep, switches = run_adaptive_episode(corridor, q, fs, AgentConfig(), sight(corridor, 2.5))
    assert ep.success and ep.outcome == "found" and switches == 1 and ep.n_attempts == 0
    assert ep.path_m < 4.0 + 2.0  # C comes into view at (2, 14) (2.24 m away): one step to its approach set
    assert fs["C"].updates and fs["C"].updates[0][1] == 1 and not fs["B"].updates  # B was never in view
    base = run_episode(corridor, q, beliefs(B=0.9, C=0.3), AgentConfig())  # the predictive agent walks to B first
    assert base.success and base.n_attempts == 2 and base.path_m > 18.0


def test_receptacle_seen_empty_costs_no_attempt(corridor: PlanningCache) -> None:
    q = make_query(corridor.grid, (2, 14), "A")
    fs = beliefs(C=0.9, A=0.6, B=0.1)
    ep, switches = run_adaptive_episode(corridor, q, fs, AgentConfig(), sight(corridor, 2.5))
    assert fs["C"].updates[0][1] == 0  # seen empty from the start cell, before any step
    assert ep.success and ep.n_attempts == 0 and switches == 0 and ep.visited == []
    assert ep.path_m == pytest.approx(13.0)  # straight to A's approach (2, 1)
    base = run_episode(corridor, q, beliefs(C=0.9, A=0.6, B=0.1), AgentConfig())
    assert base.success and base.n_attempts == 2 and base.path_m > 13.0 + 1.0


def test_absent_object_aborts_once_everything_seen_is_empty(corridor: PlanningCache) -> None:
    q = make_query(corridor.grid, (2, 14), None)
    fs = beliefs(C=0.9, A=0.1)
    ep, _ = run_adaptive_episode(corridor, q, fs, AgentConfig(delta=0.2), sight(corridor, 2.5))
    assert ep.outcome == "abort" and ep.aborted and ep.path_m == 0.0
    assert [len(f.updates) for f in fs.values()] == [1, 0]  # one look at C; A out of sight


def test_attempts_are_failed_arrivals(corridor: PlanningCache) -> None:
    q = make_query(corridor.grid, (2, 14), "B")
    fs = beliefs(A=0.9, C=0.8, B=0.5)  # A first (13 m west), empty: with one attempt the agent gives up
    ep, _ = run_adaptive_episode(corridor, q, fs, AgentConfig(max_attempts=1), sight(corridor, 1.5))
    assert ep.outcome == "exhausted" and not ep.success and ep.n_attempts == 1 and ep.visited == ["A"]
    assert all(len(f.updates) <= 1 for f in fs.values())  # one look per receptacle per episode
    ep2, _ = run_adaptive_episode(corridor, q, beliefs(A=0.9, C=0.8, B=0.5), AgentConfig(max_attempts=3),
                                  sight(corridor, 1.5))
    assert ep2.success and ep2.visited[0] == "A" and ep2.n_attempts == len(ep2.visited) >= 1


def test_updates_are_timed_by_the_walk(corridor: PlanningCache) -> None:
    q = make_query(corridor.grid, (2, 10), "B")
    fs = beliefs(A=0.9, B=0.1)
    ep, _ = run_adaptive_episode(corridor, q, fs, AgentConfig(speed_mps=0.5), sight(corridor, 1.5))
    assert ep.outcome == "abort" and ep.path_m == pytest.approx(9.0)  # to A's approach (2, 1), empty, B < delta
    assert fs["A"].updates == [(pytest.approx(q.t_s + 9.0 / 0.5), 0)] and not fs["B"].updates


def fremen_filters(**means: float) -> dict[str, Any]:
    """Real FreMEn filters of edges (obj, r) fitted on one week of hourly observations with mean ``means[r]``
    (under 1.5 weeks and no validation week: order 0, the mean); FreMEn does not move on an update.
    """
    from psg_data.estimators import EdgeStream
    from psg_data.graph._fit import resolve_estimator

    t = 1_700_000_000.0 + 3600.0 * np.arange(168)
    streams = [EdgeStream(("obj", r), t, (np.arange(168) % 10 < round(10 * m)).astype(np.int8)) for r, m in
               means.items()]
    est = resolve_estimator("fremen").fit(streams)
    return {r: est.make_filter(("obj", r)) for r in means}


def test_absence_by_delta_aborts_only_when_no_belief_reaches_delta(corridor: PlanningCache) -> None:
    """--absence delta: an agent that has reached every candidate but still believes one at or above delta
    stops without declaring absence; list-exhausted declares it; an estimator that learns aborts either way.
    """
    q = make_query(corridor.grid, (2, 14), None)  # the object is not in the house
    cfg = AgentConfig(delta=0.2)
    fs = fremen_filters(A=0.9, B=0.1)
    assert fs["A"].predict(np.array([q.t_s]))[0] == pytest.approx(0.9, abs=0.02)
    ep, _ = run_adaptive_episode(corridor, q, fs, cfg, sight(corridor, 1.5), absence="delta")
    assert ep.visited == ["A"] and ep.outcome == "exhausted" and not ep.aborted  # A is still at 0.9
    ep, _ = run_adaptive_episode(corridor, q, fremen_filters(A=0.9, B=0.1), cfg, sight(corridor, 1.5),
                                 absence="list-exhausted")
    assert ep.visited == ["A"] and ep.outcome == "abort" and ep.aborted
    ep, _ = run_adaptive_episode(corridor, q, beliefs(A=0.9, B=0.1), cfg, sight(corridor, 1.5), absence="delta")
    assert ep.outcome == "abort" and ep.aborted and ep.path_m == pytest.approx(13.0)  # A seen empty: 0 < delta


def test_estimator_memory_lets_fremen_return_to_a_checked_receptacle(corridor: PlanningCache) -> None:
    """--agent-memory estimator: the beliefs are the only memory; FreMEn's do not move, so the agent goes back
    to the empty A (its second attempt) instead of B; with visits it tries B; an estimator that learns does too.
    """
    q = make_query(corridor.grid, (2, 14), "B")
    cfg = AgentConfig(delta=0.2, max_attempts=2)
    ep, _ = run_adaptive_episode(corridor, q, fremen_filters(A=0.9, B=0.5), cfg, sight(corridor, 1.5),
                                 memory="estimator")
    assert ep.visited == ["A", "A"] and ep.n_attempts == 2 and not ep.success and ep.outcome == "exhausted"
    ep, _ = run_adaptive_episode(corridor, q, fremen_filters(A=0.9, B=0.5), cfg, sight(corridor, 1.5),
                                 memory="visits")
    assert ep.visited[0] == "A" and ep.success and ep.path_m == pytest.approx(13.0 + 27.0)  # to A, then to B
    ep, _ = run_adaptive_episode(corridor, q, beliefs(A=0.9, B=0.5), cfg, sight(corridor, 1.5), memory="estimator")
    assert ep.visited == ["A"] and ep.success
    with pytest.raises(Exception, match="memory / absence"):
        run_adaptive_episode(corridor, q, beliefs(A=0.9), cfg, sight(corridor, 1.5), memory="none")


def test_readings_are_every_distinct_combination_the_protocols_own_first() -> None:
    from dataclasses import replace

    from psg_data.navigation._sim_benchmark import SIM_PROTOCOLS

    ad = SIM_PROTOCOLS["paper-sim-adaptive"]
    assert ad.reading == ("end-of-validation", "visits", "delta") and ad.queries_per_scene == 25
    rs = ad.readings()
    assert rs[0] == ad.reading and len(rs) == len(set(rs)) == 6  # estimator has no list: one absence rule
    assert {r for r in rs if r[1] == "estimator"} == {("end-of-validation", "estimator", "delta"),
                                                       ("test-week", "estimator", "delta")}
    other = replace(ad, last_map="test-week", agent_memory="estimator", absence="list-exhausted")
    assert other.readings()[0] == other.reading and len(other.readings()) == 6
    assert SIM_PROTOCOLS["paper-sim-predictive"].readings() == [SIM_PROTOCOLS["paper-sim-predictive"].reading]
    with pytest.raises(Exception, match="last_map"):
        replace(ad, last_map="now")


# ---------------------------------------------------------------------------------------------------
# Tiny houses: the harness (queries, what the filters see, scoring) and the CLI.

@pytest.fixture(scope="module")
def house(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from psg_data.labeling import label_dataset
    from psg_data.synth import HouseConfig, HouseParams, build_house

    root = build_house(tmp_path_factory.mktemp("simnav") / "scene_00", HouseConfig(seed=3, geometry=HouseParams(
        n_objects=6)))
    label_dataset(root, "privileged")
    return root


def _protocol(adaptive: bool, n: int = 8) -> Any:
    from psg_data.navigation._sim_benchmark import SimProtocol

    return SimProtocol("test", (3,), n, None, adaptive)


def test_adaptive_queries_sit_in_the_test_week(house: Path) -> None:
    from psg_data.loaders import open_dataset
    from psg_data.navigation import NavigationEnv
    from psg_data.navigation._sim_benchmark import _adaptive_queries, scene_split_ids

    ds = open_dataset(house)
    ids = scene_split_ids(ds)
    env = NavigationEnv.from_dataset(ds, map_scans=ids["train"] + ids["val"])
    starts = ds.df("scans").set_index("scan_id")["start_stamp_ns"]
    test = np.array([float(starts[s]) / 1e9 for s in ids["test"]])
    pairs = _adaptive_queries(env, test, 40, 3, _protocol(True))
    assert [q.query_id for q, _ in pairs] == list(range(40)) and {q.seed for q, _ in pairs} == {3}
    for q, t_m in pairs:
        assert t_m in set(test[:-1])  # a test-week patrol step, not the last one
        assert t_m < q.t_s <= min(t_m + 7 * 86400.0, env.t_end_s)
        cat = "absent" if q.gt_receptacle is None else ("static" if q.gt_receptacle == env.gt_at(q.object_id, t_m)
                                                         else "dynamic")
        assert q.category == cat and q.gt_receptacle == env.gt_at(q.object_id, q.t_s)
    assert len({t for _, t in pairs}) > 10
    ev = _adaptive_queries(env, test, 40, 3, _protocol(True), "end-of-validation")
    assert all(t_m == env.t_map_s < q.t_s <= env.t_map_s + 7 * 86400.0 for q, t_m in ev)  # the end of week 3
    assert [(q.object_id, q.start_cell) for q, _ in ev] == [(q.object_id, q.start_cell) for q, _ in pairs]
    assert [q.object_id for q, _ in _adaptive_queries(env, test, 12, 3, _protocol(True))] == [
        q.object_id for q, _ in pairs[:12]]  # more queries per scene: the first draws are the same


class Spy:
    """An estimator that records what it is fitted on."""

    def __init__(self) -> None:
        self.fit_args: dict[str, Any] = {}

    def fit(self, streams: Any, *, val_streams: Any = None, timezone: str = "UTC") -> Spy:
        self.fit_args = {"train": list(streams), "val": list(val_streams or [])}
        return self

    def make_filter(self, edge: tuple[str, str]) -> ObsFilter:
        return ObsFilter(edge, 0.5)


def test_fit_sees_train_weeks_and_the_validation_week_only_as_val_streams(house: Path) -> None:
    from psg_data.loaders import open_dataset
    from psg_data.navigation import NavigationEnv
    from psg_data.navigation._sim_benchmark import method_filters, scene_split_ids

    ds = open_dataset(house)
    ids = scene_split_ids(ds)
    env = NavigationEnv.from_dataset(ds, map_scans=ids["train"] + ids["val"])
    starts = ds.df("scans").set_index("scan_id")["start_stamp_ns"] / 1e9
    spy = Spy()
    fs = method_filters(env, "spy", spy, None, float(starts[ids["val"][0]]))  # type: ignore[arg-type]
    train_t = np.concatenate([s.t_s for s in spy.fit_args["train"]])
    val_t = np.concatenate([s.t_s for s in spy.fit_args["val"]])
    assert train_t.max() < float(starts[ids["val"][0]]) <= val_t.min()
    assert val_t.max() == float(starts[ids["val"][-1]]) < float(starts[ids["test"][0]])
    last = max(f.updates[-1][0] for f in fs.values())
    assert last == float(starts[ids["val"][-1]])  # the map ends with the validation week; no test step


@pytest.mark.parametrize("adaptive,last_map", [(False, "end-of-validation"), (True, "end-of-validation"),
                                               (True, "test-week")])
def test_filters_see_the_test_week_only_up_to_the_last_map_update(house: Path, monkeypatch: Any,
                                                                   adaptive: bool, last_map: str) -> None:
    from dataclasses import replace

    import psg_data.navigation._sim_agent as agent
    import psg_data.navigation._sim_benchmark as bench

    seen: dict[int, tuple[float, float]] = {}
    real = agent.run_adaptive_episode

    def spy_episode(cache: Any, q: Any, fs: Any, cfg: Any, sight: Any, **kw: Any) -> Any:
        ts = [t for f in fs.values() for t, _ in f.updates]
        seen[q.query_id] = (max(ts), q.t_s)
        return real(cache, q, fs, cfg, sight, **kw)

    monkeypatch.setattr(agent, "run_adaptive_episode", spy_episode)

    def filled(env: Any, name: str, spec: Any, s: Any, v: float) -> Any:  # the map streams, as method_filters
        fs = {e: ObsFilter(e, 0.5) for e in env.edges}
        for st in env.map_streams:
            fs[st.edge].update_many(st.t_s, st.y)
        return fs

    monkeypatch.setattr(bench, "method_filters", filled)
    proto = replace(_protocol(adaptive, 10), last_map=last_map)
    out = bench.run_sim_scene(house, 3, {"spy": "spy"}, {}, proto, labels="gt")
    recs = out["records"]
    assert len(recs) == 10 and {r["last_map"] for r in recs} == {last_map}
    if adaptive:
        for r in recs:
            last, t_q = seen[r["query_id"]]
            assert last <= r["t_map_s"] < t_q == r["t_s"]  # nothing after the last map update reaches them
            if last_map == "test-week":
                assert last == r["t_map_s"]  # gt labels: every edge observed at every step up to it
        assert (len({r["t_map_s"] for r in recs}) == 1) == (last_map == "end-of-validation")
    else:
        assert not seen and all(r["t_map_s"] < r["t_s"] for r in recs)


@pytest.mark.parametrize("adaptive", [False, True])
def test_oracle_finds_every_reachable_object_and_scores_add_up(house: Path, adaptive: bool) -> None:
    import pandas as pd

    from psg_data.evaluation._sim_navigation_report import sim_summary
    from psg_data.navigation._sim_benchmark import run_sim_scene

    methods = {"oracle": "oracle", "last_seen_map": "last_seen_map", "random_receptacle": "random_receptacle"}
    out = run_sim_scene(house, 3, methods, {}, _protocol(adaptive, 12), labels="privileged")
    df = pd.DataFrame(out["records"])
    o = df[df["method"] == "oracle"]
    reach = o[o["reachable"] & (o["category"] != "absent")]
    assert reach["success"].all()
    assert o[o["category"] == "absent"]["aborted"].all()
    # two scenes (the same one twice under two labels) -> the std across scenes is 0, the mean the pooled ratio
    two = pd.concat([df, df.assign(seed=4)])
    per, summ = sim_summary(two, list(methods))
    for m in methods:
        row = summ[summ["method"] == m].iloc[0]
        d = df[df["method"] == m]
        sel = ((d["category"] != "absent") & d["reachable"]) | (d["category"] == "absent")
        s = np.where(d["category"] == "absent", d["aborted"], d["success"])[sel.to_numpy()]
        assert row["overall_sr_mean"] == pytest.approx(float(np.mean(s)))
        assert row["overall_sr_std"] == pytest.approx(0.0)


def test_std_is_across_scenes(house: Path) -> None:
    import pandas as pd

    from psg_data.evaluation._sim_navigation_report import sim_summary

    rows = []
    for scene, wins in ((0, [1, 1, 1, 0]), (1, [1, 0, 0, 0]), (2, [1, 1, 0, 0])):
        for k, w in enumerate(wins):
            rows.append({"method": "m", "seed": scene, "query_id": k, "category": "static", "reachable": True,
                         "success": bool(w), "aborted": False, "path_m": 1.0, "shortest_path_m": 1.0})
    per, summ = sim_summary(pd.DataFrame(rows), ["m"])
    r = summ.iloc[0]
    assert r["overall_sr_mean"] == pytest.approx(6 / 12)
    assert r["overall_sr_std"] == pytest.approx(float(np.std([0.75, 0.25, 0.5], ddof=1)))
    assert r["overall_sr_ci_low"] <= r["overall_sr_mean"] <= r["overall_sr_ci_high"]


def test_paper_rows_are_the_paper_tables() -> None:
    from psg_data.evaluation._sim_navigation_report import PAPER_SIM_COUNTS, PAPER_SIM_ROWS

    assert sum(PAPER_SIM_COUNTS["paper-sim-predictive"]) == 250 and sum(PAPER_SIM_COUNTS["paper-sim-adaptive"]) == 125
    ad = {(p, m): v for p, m, v in PAPER_SIM_ROWS["paper-sim-adaptive"]}
    assert ad[("Privileged", "Ours (Perpetua*)")][-2] == (83.2, 4.3) and ad[("Privileged", "Ours (FreMEn)")][-2] == (
        72.0, 3.6)
    for rows in PAPER_SIM_ROWS.values():
        assert all(len(v) == 8 and all(0 <= x <= 100 and s >= 0 for x, s in v) for _, _, v in rows)


def test_cli_refuses_sim_protocols_elsewhere_and_quick_alone() -> None:
    from click.testing import CliRunner

    from psg_data.cli.psg_eval_cmd import main

    r = CliRunner().invoke(main, ["--task", "navigation", "--protocol", "paper-sim-adaptive", "-e", "fremen"])
    assert r.exit_code == 1 and "--dataset navigation-benchmark" in r.output
    r = CliRunner().invoke(main, ["--quick", "-e", "fremen"])
    assert r.exit_code == 1 and "--quick" in r.output
    r = CliRunner().invoke(main, ["--task", "navigation", "--dataset", "navigation-benchmark", "-e", "fremen"])
    assert r.exit_code == 1 and "paper-sim-predictive" in r.output
    r = CliRunner().invoke(main, ["--task", "navigation", "--dataset", "navigation-benchmark", "--protocol",
                                  "paper-sim-predictive", "--queries", "10", "--delta", "0.3", "-e", "fremen"])
    assert r.exit_code == 1 and "--queries, --delta with --protocol paper-sim-predictive" in r.output
    r = CliRunner().invoke(main, ["--task", "navigation", "--dataset", "navigation-benchmark", "--protocol",
                                  "paper-sim-predictive", "--agent-memory", "estimator", "-e", "fremen"])
    assert r.exit_code == 1 and r.output.startswith("error: --agent-memory: only with --task navigation")
    r = CliRunner().invoke(main, ["--absence", "delta", "--queries-per-scene", "5", "-e", "fremen"])
    assert r.exit_code == 1 and "--absence, --queries-per-scene: only with" in r.output
    r = CliRunner().invoke(main, ["--task", "navigation", "--dataset", "navigation-benchmark", "--protocol",
                                  "paper-sim-adaptive", "--last-map", "yesterday", "-e", "fremen"])
    assert r.exit_code == 2 and "yesterday" in r.output


def test_sim_protocol_takes_the_reading_options() -> None:
    from psg_data.cli._eval_sim_navigation import sim_protocol

    p = sim_protocol("paper-sim-adaptive", True, {"agent_memory": "estimator", "absence": None,
                                                  "last_map": "test-week", "queries_per_scene": 40})
    assert p.reading == ("test-week", "estimator", "delta") and p.queries_per_scene == 40 and p.scenes == (10, 11)
    assert sim_protocol("paper-sim-adaptive", False, {}).reading == ("end-of-validation", "visits", "delta")


def test_paired_gap_and_the_readings_grid_score_like_the_table() -> None:
    """Overall SR per query (success, a correct abort, unreachable left out), the gap paired over queries."""
    import pandas as pd

    from psg_data.evaluation._sim_navigation_report import elapsed_text, paired_gap, readings_text

    rows = []
    # 6 queries: 4 present reachable, 1 absent, 1 unreachable (left out of both)
    cats = ["static", "dynamic", "dynamic", "static", "absent", "static"]
    reach = [True, True, True, True, False, False]
    wins = {"perpetua_star": [1, 1, 0, 1, 1, 1], "fremen": [1, 0, 0, 0, 0, 0]}
    for m, w in wins.items():
        for k in range(6):
            rows.append({"method": m, "seed": 10, "query_id": k, "category": cats[k], "reachable": reach[k],
                         "success": bool(w[k]) and cats[k] != "absent", "aborted": cats[k] == "absent" and bool(w[k]),
                         "path_m": 1.0, "shortest_path_m": 1.0, "t_s": 3600.0 * (k * 20 + 0.5), "t_map_s": 0.0,
                         "shift": "shift 0.5", "last_map": "end-of-validation", "agent_memory": "visits",
                         "absence": "delta"})
    df = pd.DataFrame(rows)
    g, lo, hi, n = paired_gap(df, "perpetua_star", "fremen")
    assert n == 5 and g == pytest.approx(100 * (4 - 1) / 5)  # 4 of 5 against 1 of 5; the unreachable one left out
    assert lo <= g <= hi
    text = readings_text(df, ["perpetua_star", "fremen"], {}, [("end-of-validation", "visits", "delta")],
                         ("end-of-validation", "visits", "delta"), ["shift 0.5"])
    assert "shift 0.5 *" in text and "80.0" in text and "20.0" in text and "+60.0 [" in text
    assert "100 (1)" in text and "0 (1)" in text  # absent AR of each method on its one absent query
    el = elapsed_text(df, ["perpetua_star", "fremen"], {})
    # 0.5, 20.5, 40.5, 60.5, 80.5 h (the unreachable query at 100.5 h left out)
    assert "0-1 h (1)" in el and "1-6 h (0)" in el and "6-24 h (1)" in el and "24-72 h (2)" in el and "> 72 h (1)" in el


@pytest.mark.slow
def test_cli_quick_adaptive(tmp_path: Path, monkeypatch: Any) -> None:
    """The CI form end to end: builds two houses into an empty cache, runs every reference row and FreMEn."""
    import json

    import pandas as pd
    from click.testing import CliRunner

    from psg_data.cli.psg_eval_cmd import main

    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["--task", "navigation", "--dataset", "navigation-benchmark", "--protocol",
                                  "paper-sim-adaptive", "--quick", "-e", "fremen", "--labels", "privileged",
                                  "--out", str(out), "--quiet"])
    assert r.exit_code == 0, r.output
    assert "paper: Ours (Perpetua*) [Privileged]" in r.output and "process_oracle:model=train" in r.output
    assert "headroom (overall SR): process_oracle" in r.output and "adaptation gap" in r.output
    assert "process_oracle:model=train - fremen" in r.output and "by time since the last map update" in r.output
    grid = r.output.split("Every reading of the open choices")[1]
    assert "shift 0.5 *  end-of-validation     visits           delta" in grid and "shift 0 " in grid  # the control
    assert grid.count("\nshift ") == 12  # 6 readings on the shifted houses and on the shift-0 control
    allrec = pd.read_parquet(out / "readings.parquet")
    n_methods = allrec["method"].nunique()
    assert set(allrec["shift"]) == {"shift 0.5", "shift 0"} and n_methods >= 7 and len(allrec) == 12 * 12 * n_methods
    res = json.loads((out / "results.json").read_text())
    rows = {row["method"]: row for row in res["tables"][0]["rows"]}
    assert {"oracle", "process_oracle", "process_oracle:model=train", "fremen", "random_receptacle"} <= set(rows)
    cfg = json.loads((out / "sim_config.json").read_text())
    assert cfg["scenes"] == [10, 11] and cfg["queries_per_scene"] == 6 and cfg["adaptive"]
    built = sorted((p.parent.name.split("-")[3], p.name)
                   for p in (tmp_path / "cache").glob("navigation-benchmark-*/scene_*"))
    assert built == [("shift0", "scene_10"), ("shift0", "scene_11"), ("shift0.5", "scene_10"),
                     ("shift0.5", "scene_11")]  # the shifted houses and the shift-0 control's
    assert (out / "scene_sr.png").is_file()
    oracle = rows["oracle"]["values"]["overall_sr"]["mean"]
    assert math.isfinite(oracle) and oracle == pytest.approx(1.0)


def test_both_process_oracle_readings_agree_without_a_shift(tmp_path: Path) -> None:
    """At shift 0 the training model is the generating model: the two ceiling rows are the same walks."""
    import pandas as pd

    from psg_data.navigation._sim_benchmark import run_sim_scene
    from psg_data.synth import HouseConfig, HouseParams, HouseProcessParams, build_house

    root = build_house(tmp_path / "scene_05", HouseConfig(seed=5, geometry=HouseParams(n_objects=5),
                                                          schedules=HouseProcessParams(shift=0.0)))
    methods = {"process_oracle": "process_oracle", "process_oracle:model=train": "process_oracle"}
    out = run_sim_scene(root, 5, methods, {"process_oracle:model=train": {"model": "train"}}, _protocol(True, 10))
    df = pd.DataFrame(out["records"])
    a, b = (df[df["method"] == m].reset_index(drop=True) for m in methods)
    cols = ["query_id", "outcome", "success", "path_m", "visited", "best_belief"]
    pd.testing.assert_frame_equal(a[cols], b[cols])
    assert out["settings"]["process_oracle:model=train"]["model"] == "train"
    assert out["settings"]["process_oracle"]["share_updates"] is True
