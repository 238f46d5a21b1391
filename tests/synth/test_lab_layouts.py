"""The lab layouts: in ``corridor`` and ``two_routes`` a closed door lengthens the way and never isolates a
room; the chain stays as it was; the corridor lab's scans see the doors."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from psg_data.loaders import open_dataset
from psg_data.maps import PlanningCache, grid_from_dataset, grid_from_geometry
from psg_data.synth import LabConfig, LabModel, build_lab, make_layout


def _room_cells(grid, layout):  # type: ignore[no-untyped-def]
    """Flat index of a free cell near each room's centre (free with every door closed)."""
    free = grid.free({d: False for d in grid.door_ids}).ravel()
    W = grid.shape[1]
    out = {}
    for r in layout.rooms:
        c = np.asarray(r.floor_polygon_m).mean(axis=0)
        cand = np.flatnonzero(free)
        ij = np.stack(np.divmod(cand, W), axis=1)
        d = np.linalg.norm(grid.cell_to_world(ij) - c, axis=1)
        out[r.room_id] = int(cand[int(np.argmin(d))])
    return out


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4, 5, 6, 7])
@pytest.mark.parametrize("layout", ["corridor", "two_routes"])
def test_every_room_reachable_with_both_doors_closed(seed: int, layout: str) -> None:
    L = make_layout(seed, layout)
    lab_rooms = sorted({r.room_id for r in L.receptacles})
    assert lab_rooms == ["room_a", "room_b", "room_c"] and len(L.doors) == 2
    assert [sum(r.room_id == x for r in L.receptacles) for x in lab_rooms] == [10, 10, 8]
    assert len(L.rooms) == (4 if layout == "corridor" else 3)
    assert len(L.openings) == (3 if layout == "corridor" else 2)
    grid = grid_from_geometry(L.rooms, L.receptacles, L.doors, openings=L.openings)
    planner = PlanningCache(grid)
    cells = _room_cells(grid, L)
    W = grid.shape[1]
    lengths = {}
    for cfg in itertools.product([True, False], repeat=2):
        p = planner.planner(cfg)
        for a, b in itertools.combinations(sorted(cells), 2):
            r = p.path(divmod(cells[a], W), divmod(cells[b], W))
            assert r.found, f"{a} -> {b} cut with doors {cfg}"
            lengths[(cfg, a, b)] = r.length_m
    # a closed door never shortens the way, and for the rooms it joins it lengthens it (a detour)
    for a, b in itertools.combinations(sorted(cells), 2):
        assert lengths[((False, False), a, b)] >= lengths[((True, True), a, b)] - 1e-9
    for k, d in enumerate(grid.door_ids):
        door = next(x for x in L.doors if x.door_id == d)
        cfg = tuple(j != k for j in range(2))
        detour = lengths[(cfg, *sorted((door.room_a, door.room_b)))] - lengths[((True, True),
                                                                                 *sorted((door.room_a, door.room_b)))]
        # the corridor detour is longer by design (out of the room, along the hallway, back in)
        assert (0.5 <= detour < 16.0) if layout == "corridor" else (0.0 <= detour < 12.0)


@pytest.mark.parametrize("seed", [0, 1, 4])
def test_corridor_openings_lead_out_of_every_room_clear_of_furniture(seed: int) -> None:
    L = make_layout(seed, "corridor")
    corridor = next(r for r in L.rooms if r.room_id == "corridor")
    assert not any(r.room_id == "corridor" for r in L.receptacles)
    assert sorted(o.room_a for o in L.openings) == ["room_a", "room_b", "room_c"]
    assert all(o.room_b == "corridor" for o in L.openings)
    y_wall = np.asarray(corridor.floor_polygon_m)[:, 1].min()
    for o in L.openings:
        c = np.asarray(o.box.center_m)
        assert c[1] == pytest.approx(y_wall)
        assert L.room_of_point(c[:2] - [0.0, 0.3]) == o.room_a  # the room's side of its north wall
        # nothing stands in front of the opening (1.3 m wide, 0.9 m deep)
        front = np.array([[c[0] + dx, c[1] - dy, 0.3] for dx in np.linspace(-0.6, 0.6, 7) for dy in (0.1, 0.5, 0.85)])
        assert not any(r.box.contains(front, margin_m=0.0).any() for r in L.receptacles)
    # the end rooms open at the end of the wall away from their door
    doors = {d.room_a: d for d in L.doors}
    xa = next(o for o in L.openings if o.room_a == "room_a").box.center_m[0]
    assert abs(xa - doors["room_a"].box.center_m[0]) > 4.0


@pytest.mark.parametrize("seed", [0, 3])
def test_chain_layout_isolates_rooms_as_before(seed: int) -> None:
    L = make_layout(seed, "chain")
    assert L.openings == []
    grid = grid_from_geometry(L.rooms, L.receptacles, L.doors, openings=L.openings)
    cells = _room_cells(grid, L)
    W = grid.shape[1]
    p = PlanningCache(grid).planner({d: False for d in grid.door_ids})
    assert not p.path(divmod(cells["room_a"], W), divmod(cells["room_b"], W)).found


def test_unknown_layout_rejected() -> None:
    with pytest.raises(ValueError, match="layout"):
        make_layout(0, "ring")
    with pytest.raises(Exception, match="layout"):
        LabConfig(layout="ring")


def test_openings_round_trip_through_the_dataset(tmp_path) -> None:  # type: ignore[no-untyped-def]
    cfg = LabConfig(seed=2, days=1, frames_per_scan=1, width=32, height=24)
    lab = LabModel(cfg)
    root = build_lab(tmp_path / "lab", cfg, lab=lab)
    ds = open_dataset(root)
    assert sorted(ds.openings) == sorted(o.opening_id for o in lab.layout.openings)
    assert LabModel.from_dataset(ds).config.layout == "corridor"
    grid = grid_from_dataset(ds)
    closed = {d: False for d in grid.door_ids}
    cells = _room_cells(grid, lab.layout)
    W = grid.shape[1]
    r = PlanningCache(grid).planner(closed).path(divmod(cells["room_a"], W), divmod(cells["room_c"], W))
    assert r.found and math.isfinite(r.length_m)


def test_old_manifest_without_layout_rebuilds_the_chain() -> None:
    extra = LabConfig().to_extra()
    assert extra["layout"] == "corridor"
    assert LabConfig.from_extra({**extra, "layout": "two_routes"}).layout == "two_routes"
    extra.pop("layout")
    assert LabConfig.from_extra(extra).layout == "chain"


def test_only_the_corridor_lab_aims_its_views_at_the_doors() -> None:
    from psg_data.synth._layout import DOOR_ID0, RECEPTACLE_ID0

    for layout, looks in (("corridor", True), ("two_routes", False), ("chain", False)):
        lab = LabModel(LabConfig(layout=layout, days=1))
        assert lab.layout.scans_look_at_doors is looks
        _, ids = lab._view_targets()
        assert list(ids[:28]) == [RECEPTACLE_ID0 + i for i in range(28)]
        assert list(ids[28:]) == ([DOOR_ID0, DOOR_ID0 + 1] if looks else [])


def test_corridor_scans_see_both_doors_and_read_their_state(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from psg_data.labeling import observe_doors

    cfg = LabConfig(seed=0, days=2, width=80, height=60)
    root = build_lab(tmp_path / "lab", cfg)
    ds = open_dataset(root)
    ob = observe_doors(ds)
    vis = np.asarray(ob.visible)
    assert vis.shape == (8, 2) and vis.mean() >= 0.75
    truth = ds.table("door_states").to_pandas().pivot(index="scan_id", columns="door_id", values="state")
    truth = truth.loc[list(ob.scan_ids), list(ob.door_ids)].to_numpy()
    seen = np.where(np.asarray(ob.open_fraction) >= ob.params.open_threshold, "open", "closed")
    assert (seen[vis] == truth[vis]).all()


def test_synth_command_builds_the_chain_by_name(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from click.testing import CliRunner

    from psg_data.cli.psg_data_cmd import main

    out = tmp_path / "chain"
    r = CliRunner().invoke(main, ["synth", str(out), "--layout", "chain", "--days", "1", "--frames-per-scan", "1",
                                  "--resolution", "32x24", "-q"])
    assert r.exit_code == 0, r.output
    ds = open_dataset(out)
    assert not ds.has_table("openings") and ds.openings == {}
    assert LabModel.from_dataset(ds).config.layout == "chain"


@pytest.mark.parametrize("seed", [0, 2, 5])
def test_layouts_share_doors_and_each_rooms_furniture(seed: int) -> None:
    a, b = make_layout(seed, "chain"), make_layout(seed, "two_routes")
    assert [d.door_id for d in a.doors] == [d.door_id for d in b.doors]
    assert all(np.allclose(x.box.center_m, y.box.center_m) for x, y in zip(a.doors, b.doors))
    for room in a.room_ids:
        cats_a = sorted(r.category or "" for r in a.receptacles if r.room_id == room)
        cats_b = sorted(r.category or "" for r in b.receptacles if r.room_id == room)
        assert cats_a == cats_b
    c = make_layout(seed, "corridor")
    assert all(np.allclose(x.box.center_m, y.box.center_m) for x, y in zip(a.doors, c.doors))
    assert ([sum(r.room_id == x for r in c.receptacles) for x in a.room_ids]
            == [sum(r.room_id == x for r in a.receptacles) for x in a.room_ids])
    # the passages stand in the inner walls, clear of the doors
    for o, d in zip(b.openings, b.doors):
        assert o.box.center_m[0] == d.box.center_m[0] and abs(o.box.center_m[1] - d.box.center_m[1]) > 1.2
