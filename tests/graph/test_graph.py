"""PredictiveGraph against the estimators themselves: snapshots, rankings, online updates, save / load, plans."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from psg_data.errors import GraphError, NotFittedError
from psg_data.estimators import get_estimator
from psg_data.graph import DatasetTimeline, PredictiveGraph, source_observations
from psg_data.loaders import open_dataset
from tests.graph.conftest import T0_S

ESTIMATORS = ["perpetua_star", "fremen", "time_of_week_frequency", "persistence_filter", "perpetua"]
T_QUERY = T0_S + 17 * 7200 + 1234.5  # after the 16 training scans (every 2 h)


def _by_hand(ds: Any, name: str) -> tuple[dict, dict]:
    """Edge filters and door filters fitted and filtered directly with the estimator (no graph code)."""
    tl = DatasetTimeline.from_dataset(ds, None, need_schedule=False)
    src = source_observations(ds, "gt", tl.map_ids)
    est = get_estimator(name).fit(src.object_streams, timezone="UTC")
    edges = {}
    for s in src.object_streams:
        f = est.make_filter(s.edge)
        f.update_many(s.t_s, s.y)
        edges[s.edge] = f
    dest = get_estimator(name).fit(src.door_streams, timezone="UTC")
    doors = {}
    for s in src.door_streams:
        f = dest.make_filter(s.edge)
        f.update_many(s.t_s, s.y)
        doors[s.edge[0]] = f
    return edges, doors


@pytest.mark.parametrize("name", ESTIMATORS)
def test_at_and_locate_are_the_filters_own_predictions(graph_dataset: Path, name: str) -> None:
    ds = open_dataset(graph_dataset)
    g = PredictiveGraph.from_dataset(ds, name)
    edges, doors = _by_hand(ds, name)
    assert g.edges == list(edges)
    for t in (T_QUERY, T_QUERY + 86400.0 * 3.3):
        snap = g.at(t)
        want = np.array([float(edges[e].predict(np.array([t]))[0]) for e in g.edges])
        np.testing.assert_array_equal(snap.p, want)
        assert list(snap.doors) == ["door1"]
        assert snap.p_open[0] == float(doors["door1"].predict(np.array([t]))[0])
        for obj in ("mug", "book", "keys"):
            mine = {r: float(f.predict(np.array([t]))[0]) for (o, r), f in edges.items() if o == obj}
            order = sorted(mine, key=lambda r: (-mine[r], r))
            rk = g.locate(obj, t, top=1)
            assert rk.receptacles == tuple(order[:1]) and rk.p[0] == mine[order[0]]
            full = g.locate(obj, t)
            assert full.receptacles == tuple(order)
            np.testing.assert_array_equal(full.p, [mine[r] for r in order])
            np.testing.assert_array_equal(full.xyz[0], ds.receptacles[order[0]].box.center_m)
    many = g.edge_probabilities([T_QUERY, T_QUERY + 3600.0])
    np.testing.assert_array_equal(many[0], g.at(T_QUERY).p)


def test_times_in_every_form_agree(graph_dataset: Path) -> None:
    g = PredictiveGraph.from_dataset(graph_dataset, "fremen")
    t = dt.datetime.fromtimestamp(T_QUERY, dt.timezone.utc)
    ref = g.at(T_QUERY).p
    np.testing.assert_array_equal(g.at(t).p, ref)
    np.testing.assert_array_equal(g.at(t.strftime("%Y-%m-%d %H:%M:%S.%f")).p, ref)  # site time (UTC here)
    np.testing.assert_array_equal(g.at(np.datetime64(int(T_QUERY * 1e6), "us")).p, ref)
    with pytest.raises(GraphError, match="without a zone"):
        g.at(t.replace(tzinfo=None))
    with pytest.raises(GraphError, match="ISO 8601"):
        g.at("next tuesday")
    with pytest.raises(GraphError, match="not in the graph"):
        g.locate("unicorn", T_QUERY)


def _new_scan(t0: float) -> list[tuple[float, str, str, int]]:
    return [(t0, "book", "o_desk", 0), (t0, "book", "k_shelf", 1), (t0, "keys", "o_bench", 0),
            (t0, "door1", "open", 0), (t0 + 7200.0, "mug", "o_desk", 1),  # a new edge: the mug seen on the desk
            (t0 + 7200.0, "book", "k_shelf", 0), (t0 + 7200.0, "keys", "k_table", 0)]  # absent, no edge: skipped


@pytest.mark.parametrize("name", ["perpetua_star", "persistence_filter"])
def test_update_then_at_equals_filtering_by_hand(graph_dataset: Path, name: str) -> None:
    ds = open_dataset(graph_dataset)
    g = PredictiveGraph.from_dataset(ds, name)
    edges, doors = _by_hand(ds, name)
    t0 = T0_S + 16 * 7200 + 60.0
    assert g.update(_new_scan(t0)) == 6
    edges[("book", "o_desk")].update(t0, 0)
    edges[("book", "k_shelf")].update(t0, 1)
    edges[("keys", "o_bench")].update(t0, 0)
    edges[("book", "k_shelf")].update(t0 + 7200.0, 0)
    doors["door1"].update(t0, 0)
    assert ("mug", "o_desk") in g.edges and ("keys", "k_table") not in g.edges
    est = get_estimator(name).fit(source_observations(ds, "gt", DatasetTimeline.from_dataset(
        ds, None, need_schedule=False).map_ids).object_streams, timezone="UTC")
    new = est.make_filter(("mug", "o_desk"))
    new.update(t0 + 7200.0, 1)
    edges[("mug", "o_desk")] = new
    t = t0 + 3 * 3600.0
    snap = g.at(t)
    np.testing.assert_array_equal(snap.p, [float(edges[e].predict(np.array([t]))[0]) for e in g.edges])
    assert snap.p_open[0] == float(doors["door1"].predict(np.array([t]))[0])


def test_label_rows_update_like_tuples(graph_dataset: Path) -> None:
    import pandas as pd

    a = PredictiveGraph.from_dataset(graph_dataset, "perpetua_star")
    b = a.copy()
    t0 = T0_S + 16 * 7200 + 60.0
    obs = _new_scan(t0)
    rows = pd.DataFrame({"scan_id": "x", "object_id": [o for _, o, _, _ in obs], "receptacle_id": [r for _, _, r, _ in obs],
                         "stamp_ns": [int(round(t * 1e9)) for t, _, _, _ in obs], "code": [y for *_, y in obs]})
    rows = pd.concat([rows, pd.DataFrame({"scan_id": "x", "object_id": ["mug", "door1"], "receptacle_id": ["k_table", "closed"],
                                          "stamp_ns": [int(t0 * 1e9)] * 2, "code": [-1, 1]})])  # unobserved; door twice
    assert a.update(rows) == b.update([(round(t * 1e9) / 1e9, o, r, y) for t, o, r, y in obs])
    t = t0 + 5 * 3600.0
    np.testing.assert_array_equal(a.at(t).p, b.at(t).p)
    np.testing.assert_array_equal(a.at(t).p_open, b.at(t).p_open)


def test_update_in_the_past_is_refused_and_applies_nothing(graph_dataset: Path) -> None:
    g = PredictiveGraph.from_dataset(graph_dataset, "perpetua_star")
    before = g.at(T_QUERY).p.copy()
    with pytest.raises(GraphError, match="earlier than its last observation"):
        g.update([(T_QUERY, "book", "o_desk", 1), (T0_S, "mug", "k_table", 0)])
    np.testing.assert_array_equal(g.at(T_QUERY).p, before)
    with pytest.raises(GraphError, match="unknown receptacle"):
        g.update([(T_QUERY, "book", "fridge", 1)])


@pytest.mark.parametrize("name", ESTIMATORS)
def test_save_load_round_trip_is_identical(graph_dataset: Path, tmp_path: Path, name: str) -> None:
    g = PredictiveGraph.from_dataset(graph_dataset, name)
    path = g.save(tmp_path / "g.json")
    d = json.loads(path.read_text())
    assert d["format"] == "psg-predictive-graph" and d["version"] == 1 and d["estimator"]["name"] == name
    h = PredictiveGraph.load(path)
    assert h.edges == g.edges and h.doors == g.doors
    ts = T_QUERY + np.array([0.0, 3600.0, 86400.0 * 4.5])
    np.testing.assert_array_equal(h.edge_probabilities(ts), g.edge_probabilities(ts))
    np.testing.assert_array_equal(h.door_probabilities(ts), g.door_probabilities(ts))
    t0 = T0_S + 16 * 7200 + 60.0
    g.update(_new_scan(t0))
    h.update(_new_scan(t0))  # the loaded graph makes the new edge from the saved new-edge state
    np.testing.assert_array_equal(h.edge_probabilities(ts + 86400), g.edge_probabilities(ts + 86400))
    p, q = g.plan((1.5, 1.5), "book", t0 + 7200), h.plan((1.5, 1.5), "book", t0 + 7200)
    assert p.candidates == q.candidates and p.target == q.target and p.path_m == q.path_m


class _NeedsFit:
    """A plugin whose filters need the fitted estimator to be rebuilt (like ``process_oracle``)."""

    name = "needs_fit"

    def __init__(self) -> None:
        self.fitted_ = False

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {}

    def fit(self, streams: Any, *, val_streams: Any = None, timezone: str = "UTC") -> _NeedsFit:
        self.fitted_ = True
        return self

    def make_filter(self, edge: Any) -> Any:
        if not self.fitted_:
            raise NotFittedError("needs_fit is not fitted")
        from psg_data.estimators._simple import ConstantFilter

        return ConstantFilter(edge, self.name, 0.25)

    def filter_from_state(self, state: dict[str, Any]) -> Any:
        return self.make_filter(tuple(state["edge"]))


def test_save_refuses_filters_that_need_the_fitted_estimator(graph_dataset: Path, tmp_path: Path) -> None:
    g = PredictiveGraph.from_dataset(graph_dataset, _NeedsFit(), door_estimator=None)
    assert g.at(T_QUERY).p.tolist() == [0.25] * len(g)
    with pytest.raises(GraphError, match="cannot rebuild its filters from their state alone"):
        g.save(tmp_path / "g.json")
    assert not list(tmp_path.iterdir())  # nothing written


def test_load_refuses_other_files_and_newer_versions(graph_dataset: Path, tmp_path: Path) -> None:
    path = PredictiveGraph.from_dataset(graph_dataset, "fremen").save(tmp_path / "g.json")
    d = json.loads(path.read_text())
    (tmp_path / "new.json").write_text(json.dumps({**d, "version": 99}))
    with pytest.raises(GraphError, match="version: 99"):
        PredictiveGraph.load(tmp_path / "new.json")
    (tmp_path / "other.json").write_text('{"format": "psg-dataset"}')
    with pytest.raises(GraphError, match="format: expected"):
        PredictiveGraph.load(tmp_path / "other.json")
    del d["filters"]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(GraphError, match="malformed"):
        PredictiveGraph.load(tmp_path / "bad.json")


def test_plan_is_the_agents_ranking_and_a_shortest_path(graph_dataset: Path) -> None:
    from psg_data.graph import ranked_candidates
    from psg_data.maps import astar

    g = PredictiveGraph.from_dataset(graph_dataset, "perpetua_star")
    t = T_QUERY
    plan = g.plan((1.5, 1.5), "book", t, delta=0.0)
    bel = {r: min(max(v, 0.0), 1.0) for r, v in g.at(t).beliefs("book").items()}
    assert plan.candidates == tuple(ranked_candidates(bel, 0.0))
    assert list(plan.candidates) == sorted(bel, key=lambda r: (-bel[r], r))
    assert plan.outcome == "go" and plan.target == plan.candidates[int(np.flatnonzero(np.isfinite(plan.distances_m))[0])]
    cache = g.planning_cache()
    cfg = cache.key(plan.doors_open)
    assert plan.path_m == pytest.approx(plan.distances_m[list(plan.candidates).index(plan.target)])
    end = tuple(g.grid.world_to_cell(plan.path_xy[-1]))
    assert cache.approach(plan.target, cfg)[end]
    ref = astar(cache.free_flat(cfg).reshape(g.grid.shape), plan.start_cell, end, g.grid.resolution_m)
    assert ref.length_m == pytest.approx(plan.path_m)  # the independent A* finds the same length
    assert plan.doors_open == {"door1": bool(plan.p_open["door1"] >= 0.5)}
    nothing = g.plan((1.5, 1.5), "book", t, delta=0.0, exclude=plan.candidates)
    assert nothing.outcome == "abort" and nothing.target is None and nothing.path_xy.shape == (0, 2)
    shut = g.with_door_filters({"door1": _Const(0.0)}).plan((1.5, 1.5), "book", t, delta=0.0, exclude=("k_shelf",))
    assert shut.doors_open == {"door1": False}
    office = [r for r in shut.candidates if r.startswith("o_")]
    assert office and all(np.isinf(shut.distances_m[list(shut.candidates).index(r)]) for r in office)


def test_plan_with_the_expected_cost_door_rule(graph_dataset: Path) -> None:
    """door1 at P(open) 0.2 is the only way to the office: the threshold rule finds no route there, the
    expected-cost rule plans through it, at the expected walked distance of psg_data.maps.expected_cost_route."""
    from psg_data.maps import expected_cost_route

    g = PredictiveGraph.from_dataset(graph_dataset, "perpetua_star").with_door_filters({"door1": _Const(0.2)})
    t = T_QUERY
    kept = [r for r in g.plan((1.5, 1.5), "book", t, delta=0.0).candidates if not r.startswith("o_")]
    thr = g.plan((1.5, 1.5), "book", t, delta=0.0, exclude=kept)
    assert thr.outcome == "no_path"
    exp = g.plan((1.5, 1.5), "book", t, delta=0.0, exclude=kept, door_rule="expected_cost")
    assert exp.outcome == "go" and exp.target is not None and exp.doors_open["door1"]
    cache = g.planning_cache()
    W = g.grid.shape[1]
    start = exp.start_cell[0] * W + exp.start_cell[1]
    for r, d in zip(exp.candidates, exp.distances_m):
        route = expected_cost_route(cache, r, start, {"door1": 0.2})
        assert route is not None and d == pytest.approx(route.expected_m)
    end = tuple(g.grid.world_to_cell(exp.path_xy[-1]))
    assert cache.approach(exp.target, cache.key({"door1": True}))[end]
    with pytest.raises(GraphError, match="door_rule"):
        g.plan((1.5, 1.5), "book", t, door_rule="guess")


class _Const:
    def __init__(self, v: float) -> None:
        self.v, self.last_t_s = v, None

    def predict(self, t: Any) -> np.ndarray:
        return np.full(np.asarray(t).shape, self.v)


def test_conversions_carry_the_snapshot(graph_dataset: Path, tmp_path: Path) -> None:
    g = PredictiveGraph.from_dataset(graph_dataset, "perpetua_star")
    snap = g.at(T_QUERY)
    df = snap.to_pandas()
    assert list(zip(df["object_id"], df["receptacle_id"])) == g.edges
    np.testing.assert_array_equal(df["p"].to_numpy(), snap.p)
    assert snap.doors_to_pandas()["p_open"].tolist() == snap.p_open.tolist()
    G = snap.to_networkx()
    for (o, r), p in zip(g.edges, snap.p):
        assert G.edges[("object", o), ("receptacle", r)] == {"kind": "on", "p": p}
    assert G.nodes[("door", "door1")]["p_open"] == snap.p_open[0]
    assert G.nodes[("receptacle", "o_desk")]["pos"] == (7.0, 0.5, 0.4)
    assert {k for _, k in G.nodes(data="kind")} == {"room", "receptacle", "door", "object"}


def test_spark_dsg_export_round_trips(graph_dataset: Path, tmp_path: Path) -> None:
    import spark_dsg as sd  # [dev] installs psg-data[graph]: a missing extra fails loudly
    g = PredictiveGraph.from_dataset(graph_dataset, "perpetua_star")
    snap = g.at(T_QUERY)
    snap.to_spark_dsg().save(str(tmp_path / "dsg.json"), include_mesh=False)
    H = sd.DynamicSceneGraph.load(str(tmp_path / "dsg.json"))
    assert H.metadata.get()["t_s"] == snap.t_s
    ids = {(n.attributes.metadata.get()["kind"], n.attributes.metadata.get()["id"]): n.id for n in H.nodes}
    assert sum(1 for k in ids if k[0] == "object") == 3 and sum(1 for k in ids if k[0] == "receptacle") == 4
    for (o, r), p in zip(g.edges, snap.p):
        e = H.get_edge(ids[("object", o)], ids[("receptacle", r)])
        assert e.info.weight == p and e.info.metadata.get()["p"] == p
    door = H.get_node(ids[("door", "door1")])
    assert door.attributes.metadata.get()["p_open"] == snap.p_open[0]
    np.testing.assert_allclose(H.get_node(ids[("receptacle", "o_desk")]).attributes.position, (7.0, 0.5, 0.4))


def test_a_missing_conversion_library_names_the_extra(graph_dataset: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from psg_data.errors import PsgDataError

    snap = PredictiveGraph.from_dataset(graph_dataset, "fremen").at(T_QUERY)
    for module, call in (("networkx", snap.to_networkx), ("spark_dsg", snap.to_spark_dsg)):
        monkeypatch.setitem(sys.modules, module, None)  # import fails as if not installed
        with pytest.raises(PsgDataError, match=r"pip install 'psg-data\[graph\]'"):
            call()
