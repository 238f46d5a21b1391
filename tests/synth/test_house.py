"""Procedural houses: geometry (rooms, area, doors and routes around them), catalogue and affinities,
schedules, the test-time shift (a stored regime, exact inference across it, chi-square) and the
house dataset (valid, gt and privileged labels, the occupancy grid)."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import networkx as nx
import numpy as np
import pytest

from psg_data.estimators import EdgeStream, get_estimator
from psg_data.schemas._generator_model import EntityProcess, Regime, StepProcess
from psg_data.synth import HouseConfig, HouseModel, HouseParams, HouseProcessParams, build_house, make_house
from psg_data.synth import transition_test
from psg_data.synth._house_catalog import COMPATIBLE, PROCTHOR_P, ROOM_RECEPTACLES, affinity
from psg_data.synth._house_layout import MIN_SHARED_M
from psg_data.synth._house_process import TEST_DAY, _perturbed

SEEDS = range(15)
TINY = HouseConfig(seed=3, geometry=HouseParams(n_objects=6))


# -- geometry ----------------------------------------------------------------------------------------
def _rect(room) -> tuple[float, float, float, float]:  # type: ignore[no-untyped-def]
    p = np.asarray(room.floor_polygon_m)
    return p[:, 0].min(), p[:, 0].max(), p[:, 1].min(), p[:, 1].max()


def _adjacency(house) -> nx.Graph:  # type: ignore[no-untyped-def]
    """Rooms sharing at least MIN_SHARED_M of wall, computed from the polygons alone."""
    g = nx.Graph()
    g.add_nodes_from(house.room_ids)
    rects = {r.room_id: _rect(r) for r in house.rooms}
    for a, ra in rects.items():
        for b, rb in rects.items():
            if a < b:
                touch_x = min(abs(ra[1] - rb[0]), abs(rb[1] - ra[0])) < 1e-9
                touch_y = min(abs(ra[3] - rb[2]), abs(rb[3] - ra[2])) < 1e-9
                ov_y = min(ra[3], rb[3]) - max(ra[2], rb[2])
                ov_x = min(ra[1], rb[1]) - max(ra[0], rb[0])
                if (touch_x and ov_y >= MIN_SHARED_M) or (touch_y and ov_x >= MIN_SHARED_M):
                    g.add_edge(a, b)
    return g


@pytest.mark.parametrize("seed", SEEDS)
def test_rooms_area_doors_and_routes_around_closed_doors(seed: int) -> None:
    h = make_house(seed)
    assert 5 <= len(h.rooms) <= 8
    assert 100.0 <= h.navigable_m2 <= 150.0
    kinds = set(h.kinds.values())
    assert {"kitchen", "living_room", "bedroom", "bathroom"} <= kinds <= set(ROOM_RECEPTACLES)
    adj = _adjacency(h)
    doors = nx.Graph()
    doors.add_nodes_from(h.room_ids)
    doors.add_edges_from((d.room_a, d.room_b) for d in h.doors)
    assert set(map(frozenset, doors.edges)) == set(map(frozenset, adj.edges))  # a door on every shared wall
    assert nx.is_connected(doors)  # every room reachable with all doors open
    assert set(h.reachable_rooms()) == set(h.room_ids)
    bridges = {frozenset(e) for e in nx.bridges(adj)}
    assert {frozenset((d.room_a, d.room_b)) for d in h.doors if d.door_id in h.bridges()} == bridges
    assert len(h.semi_static) == 3 and set(h.semi_static) <= set(h.door_ids)


def _grid_distance(grid, door_open, a_xy, b_xy) -> float:  # type: ignore[no-untyped-def]
    """Cells on the shortest 4-connected free path between two points (inf if none)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import shortest_path

    free = grid.free(door_open)
    H, W = free.shape
    idx = np.arange(H * W).reshape(H, W)
    rows, cols = [], []
    for di, dj in ((0, 1), (1, 0)):
        m = free[: H - di, : W - dj] & free[di:, dj:]
        rows.append(idx[: H - di, : W - dj][m])
        cols.append(idx[di:, dj:][m])
    r, c = np.concatenate(rows), np.concatenate(cols)
    g = coo_matrix((np.ones(r.size), (r, c)), shape=(H * W, H * W))
    i, j = (idx[tuple(grid.world_to_cell(p))] for p in (a_xy, b_xy))
    return float(shortest_path(g, directed=False, unweighted=True, indices=[i])[0, j])


@pytest.mark.parametrize("seed", [0, 5, 12])
def test_occupancy_grid_a_closed_door_lengthens_the_way(seed: int, tmp_path: Path) -> None:
    from psg_data.loaders import open_dataset
    from psg_data.navigation import grid_from_dataset

    h = make_house(seed)
    m = HouseModel(HouseConfig(seed=seed))
    build_house(tmp_path / "h", model=m)
    grid = grid_from_dataset(open_dataset(tmp_path / "h"))
    pts = h.patrol_points
    base = {d: _grid_distance(grid, {}, pts[h.dock_room], pts[r]) for r, d in zip(h.room_ids, h.room_ids)}
    assert all(np.isfinite(v) for v in base.values())  # every patrol point reachable on the grid, doors open
    for d in h.doors:
        closed = _grid_distance(grid, {d.door_id: False}, pts[d.room_a], pts[d.room_b])
        opened = _grid_distance(grid, {}, pts[d.room_a], pts[d.room_b])
        assert np.isfinite(closed) and closed > opened  # no bridge: a longer way around, never cut off


def test_line_of_sight_agrees_with_the_occupancy_grid(tmp_path: Path) -> None:
    from psg_data.loaders import open_dataset
    from psg_data.navigation import grid_from_dataset, line_of_sight

    h = make_house(1)
    build_house(tmp_path / "h", model=HouseModel(HouseConfig(seed=1)))
    grid = grid_from_dataset(open_dataset(tmp_path / "h"))
    rec_cells = np.zeros(grid.shape, bool)
    for c in grid.receptacle_cells.values():
        rec_cells |= c
    agree = total = 0
    for closed in [(), tuple(h.semi_static)]:
        door_open = {d: d not in closed for d in h.door_ids}
        blocked = grid.obstacles(door_open) & ~rec_cells  # walls, closed doorways, outside
        pts = np.array(list(h.patrol_points.values()))
        tgt = np.array([r.box.center_m[:2] for r in h.receptacles])
        ours = h.visible(pts, tgt, door_open)
        p0 = np.repeat(grid.world_to_cell(pts), len(tgt), axis=0)
        p1 = np.tile(grid.world_to_cell(tgt), (len(pts), 1))
        near = np.linalg.norm(np.repeat(pts, len(tgt), 0) - np.tile(tgt, (len(pts), 1)), axis=1) <= h.view_range_m
        theirs = (line_of_sight(blocked, p0, p1) & near).reshape(ours.shape)
        agree += int((ours == theirs).sum())
        total += ours.size
    assert agree / total >= 0.97


# -- catalogue and schedules --------------------------------------------------------------------------
def test_affinity_table_rule_and_its_use() -> None:
    for o in COMPATIBLE:
        for c in ("Sofa", "Desk", "CounterTop", "Toilet", "Bed"):
            want = PROCTHOR_P[o].get(c, 0.0) + (0.01 if c in COMPATIBLE[o] else 0.0)
            assert affinity(o, c) == pytest.approx(want)
    m = HouseModel(HouseConfig(seed=2))
    cat = {r.receptacle_id: r.category for r in m.layout.receptacles}
    for o in m.layout.objects:
        e = m.process.entities[o.object_id]
        w = np.array([affinity(o.object_type, cat[s]) if s is not None else np.nan for s in e.states])
        assert np.all(w[np.isfinite(w)] > 0)  # only receptacles the table allows
        if o.role == "dynamic":  # jumps proportional to the table's weights
            np.testing.assert_allclose(e.jump[0, 0], w / w.sum(), rtol=1e-12)
    got = {s for o in m.layout.object_ids for s in m.state(o)}
    assert got - {None} <= set(cat)


def test_hourly_schedules_follow_the_model() -> None:
    """Empirical state frequencies of sampled paths against the exact prior marginals (steps-v2)."""
    from psg_data.synth._process import ForwardBelief, sample_entity

    m = HouseModel(TINY)
    p = m.process
    assert p.step_hours == tuple(float(h) for h in range(24)) and p.n_steps == 672
    eid = next(o.object_id for o in m.layout.objects if o.role == "dynamic")
    e = p.entities[eid]
    steps = np.arange(24 * 8, 24 * 9)
    b = ForwardBelief(p, e).start()
    marg = b.forecast(steps)
    n = 300
    counts = np.zeros_like(marg)
    for k in range(n):
        s = sample_entity(p, e, int(steps[-1]) + 1, np.random.default_rng([99, k])).states[steps]
        counts[np.arange(steps.size), s] += 1
    assert np.abs(counts / n - marg).max() < 0.12  # 300 paths: 4.5 standard errors at p = 0.5


# -- the shift: a stored regime, exact inference, chi-square ----------------------------------------------
def test_regime_round_trip_and_checks() -> None:
    m = HouseModel(HouseConfig(seed=4))
    p = m.process
    assert p.regimes and p.regimes[0].start_day == TEST_DAY and p.to_dict()["version"] == 2
    q = StepProcess.from_dict(p.to_dict())
    assert [r.to_dict() for r in q.regimes] == [r.to_dict() for r in p.regimes]
    assert q.base_model().regimes == () and q.base_model().to_dict()["version"] == 1
    changed = set(p.parameters["shifted_objects"])
    moving = [o.object_id for o in m.layout.objects if o.role != "static"]
    assert len(changed) == round(0.5 * len(moving)) and set(p.regimes[0].entities) == changed
    for eid in changed:  # routines moved and preferences changed; states, patterns, dwell range kept
        a, b = p.entities[eid], p.regimes[0].entities[eid]
        assert a.states == b.states and not np.array_equal(a.routine, b.routine)
    no_shift = HouseModel(HouseConfig(seed=4, schedules=HouseProcessParams(shift=0.0))).process
    assert no_shift.regimes == () and no_shift.to_dict()["version"] == 1
    bad = Regime(TEST_DAY, "x", {"nope": next(iter(p.entities.values()))})
    assert any("not an entity" in s for s in StepProcess(p.timezone, p.start_date, p.days, p.step_hours,
                                                         p.entities, regimes=(bad,)).problems())


def _tiny_shifted(seed: int) -> StepProcess:
    """A tiny house-like model (K = 2, 3 states, affinity jumps) whose day 2 on is the house shift of it."""
    rng = np.random.default_rng(seed)
    S, D, K = 3, 2, 2
    w = rng.dirichlet(np.ones(S))
    ent = EntityProcess("obj", "object", "dynamic", ("r0", "r1", None), ("p0", "p1"), np.ones((7, D), bool),
                        rng.dirichlet(np.ones(D)), rng.dirichlet(np.ones(D), size=D), rng.dirichlet(np.ones(S)),
                        rng.integers(0, S, size=(D, K)), np.full((D, K), 0.55), np.broadcast_to(w, (D, S, S)).copy(),
                        np.stack([np.ones((D, S), np.int64), rng.integers(1, 3, size=(D, S))], axis=-1))
    shifted = _perturbed(ent, np.random.default_rng(seed + 100))
    return StepProcess("America/Toronto", dt.date(2025, 3, 3), 3, (9.0, 15.0), {"obj": ent},
                       regimes=(Regime(2, "test-shift", {"obj": shifted}),))


def _brute_force(proc: StepProcess, n_steps: int, obs: dict[int, list[tuple[str, int]]]) -> np.ndarray:
    """P(state at step n_steps - 1 | noise-free observations) by enumerating every path, each step with
    the entity model in force on its day (independent of the forward algorithm's code)."""
    K = proc.n_slots
    e0 = proc.entities["obj"]
    post = np.zeros(e0.n_states)

    def rec(n: int, p: int, s: int, r: int, wt: float) -> None:
        if wt == 0.0:
            return
        if n == n_steps:
            post[s] += wt
            return
        day, k = divmod(n, K)
        e = proc.entity_on("obj", day)
        if k == 0:
            row = (e.pattern_initial if day == 0 else e.pattern_transition[p]) * proc.allowed(e, day)
            choices = [(q, row[q] / row.sum()) for q in range(e.n_patterns) if row[q] > 0]
        else:
            choices = [(p, 1.0)]
        for q, wq in choices:
            rho = e.routine_strength[q, k]
            s_r = int(e.routine[q, k])
            lo, hi = e.dwell[q, s_r]
            moves = [(s_r, d, rho / (hi - lo + 1)) for d in range(lo, hi + 1)]
            if r > 1:
                moves.append((s, r - 1, 1 - rho))
            else:
                for s2 in range(e.n_states):
                    lo, hi = e.dwell[q, s2]
                    moves += [(s2, d, (1 - rho) * e.jump[q, s, s2] / (hi - lo + 1)) for d in range(lo, hi + 1)]
            for s2, r2, wm in moves:
                lik = np.prod([float((e.states[s2] == lab) == bool(y)) for lab, y in obs.get(n, [])])
                rec(n + 1, q, s2, r2, wt * wq * wm * lik)

    for s0 in range(e0.n_states):
        rec(0, -1, s0, 1, float(e0.state_initial[s0]))
    return post / post.sum()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_process_oracle_exact_across_the_shift_both_readings(seed: int) -> None:
    proc = _tiny_shifted(seed)
    assert proc.problems() == []
    clock = proc.clock
    rng = np.random.default_rng(seed)
    from psg_data.synth._process import sample_entity

    path = sample_entity(proc, proc.entities["obj"], 6, rng).states
    labels = ["r0", "r1"]
    obs_steps = [0, 1, 3]  # observed steps; the prediction is for step 5 (day 2, inside the regime)
    t = {n: clock.step_start_s(n) + 60.0 for n in range(6)}
    streams = [EdgeStream(("obj", lab), np.array([t[n] for n in obs_steps]),
                          np.array([int(proc.entities["obj"].states[path[n]] == lab) for n in obs_steps], np.int8))
               for lab in labels]
    obs = {n: [(lab, int(proc.entities["obj"].states[path[n]] == lab)) for lab in labels] for n in obs_steps}
    for reading, model in (("generating", proc), ("train", proc.base_model())):
        want = _brute_force(model, 6, obs)
        est = get_estimator("process_oracle", process=proc.to_dict(), model=reading).fit(streams)
        for j, lab in enumerate(labels):
            f = est.make_filter(("obj", lab))
            f.update_many(streams[j].t_s, streams[j].y)
            got = f.predict(np.array([t[5]]))[0]
            assert abs(got - want[j]) < 1e-9, (reading, lab, got, want[j])
    gen = _brute_force(proc, 6, obs)
    assert not np.allclose(gen, _brute_force(proc.base_model(), 6, obs))  # the readings differ


def _items(shift: float, seeds: range) -> list[tuple[StepProcess, dict[str, np.ndarray]]]:
    out = []
    for s in seeds:
        m = HouseModel(HouseConfig(seed=s, schedules=HouseProcessParams(shift=shift)))
        paths = {o.object_id: m.paths[o.object_id].states for o in m.layout.objects if o.role != "static"}
        out.append((m.process.base_model(), paths))
    return out


def test_the_shift_is_real_at_the_default_knob_and_absent_at_zero() -> None:
    week4 = (TEST_DAY * 24, 28 * 24)
    shifted = transition_test(_items(HouseProcessParams().shift, range(6)), *week4)
    assert shifted.p_value < 1e-6
    plain = transition_test(_items(0.0, range(6)), *week4)
    assert plain.p_value > 0.01 and plain.n_impossible == 0
    assert 0.8 < plain.statistic / plain.df < 1.2


# -- the dataset ---------------------------------------------------------------------------------------
def test_house_dataset_is_valid_and_labelled(tmp_path: Path) -> None:
    from psg_data.evaluation import persistence_task_from_dataset
    from psg_data.labeling import ground_truth, label_dataset
    from psg_data.loaders import open_dataset
    from psg_data.schemas.validate import validate_dataset

    root = build_house(tmp_path / "tiny", TINY)
    label_dataset(root, "privileged")
    assert validate_dataset(root) == []
    ds = open_dataset(root)
    assert len(ds.scan_ids) == 672 and ds.info.extra["shift"] == 0.5
    split = ds.df("scans")["split"].value_counts().to_dict()
    assert split == {"train": 336, "val": 168, "test": 168}
    gt = ground_truth(ds)
    assert (gt.codes[:, gt.valid] >= 0).all()  # gt observes every receptacle at every step
    task = persistence_task_from_dataset(ds, labels="privileged")
    assert task.val_streams and task.estimator_hints["test_shift"] is True
    vis = ds.df("visibility")
    rec = vis[vis.kind == "receptacle"]
    assert rec.visible.mean() > 0.5
