"""Canonical output of the synthetic lab: tables, determinism, and renderer/geometry agreement."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from psg_data.loaders import backproject
from psg_data.schemas._records import Frame
from psg_data.synth import RECEPTACLE_ID0, ID_FLOOR, LabConfig, LabModel, build_lab, rerender_frame


def test_tables(small_dataset, small_lab: LabModel) -> None:  # type: ignore[no-untyped-def]
    ds = small_dataset
    # 3 receptacle keyframes and one door keyframe per door in every scan (the corridor layout)
    assert len(ds.scan_ids) == 8 and ds.table("frames").num_rows == 8 * (3 + 2)
    # three lab rooms and the corridor (default layout), which holds no receptacles
    assert sorted(ds.rooms) == ["corridor", "room_a", "room_b", "room_c"]
    assert len(ds.doors) == 2 and len(ds.objects) == 21 and len(ds.openings) == 3
    assert sorted(Counter(r.room_id for r in ds.receptacles.values()).values()) == [8, 10, 10]
    assert all(r.floor_polygon_m is not None and len(r.floor_polygon_m) == 4 for r in ds.rooms.values())
    splits = [ds.scan(s).split for s in ds.scan_ids]
    assert splits == ["train"] * 4 + ["test"] * 4
    extra = ds.info.extra
    assert extra["seed"] == 3 and extra["days"] == 2 and extra["resolution"] == [80, 60]
    assert ds.info.timezone == "America/Toronto"
    cam = next(iter(ds.cameras.values()))
    assert (cam.width, cam.height) == (80, 60) and cam.fx == pytest.approx(cam.fy)
    # door states and schedule are the dense ground truth at the scan start
    sched = ds.table("schedule").to_pandas().astype(object).where(lambda df: df.notna(), None)
    doors = ds.df("door_states")
    assert len(sched) == 8 * 21 and len(doors) == 8 * 2
    for plan in small_lab.scans:
        gt = small_lab.schedule.objects_at(plan.start_ns)
        rows = sched[sched.scan_id == plan.scan_id]
        assert {r.object_id: r.receptacle_id for r in rows.itertuples()} == gt
        dgt = small_lab.schedule.doors_at(plan.start_ns)
        drows = doors[doors.scan_id == plan.scan_id]
        assert {r.door_id: r.state == "open" for r in drows.itertuples()} == dgt
        assert ds.scan(plan.scan_id).start_stamp_ns >= plan.start_ns


def test_same_seed_identical_tables(tmp_path: Path, small_dataset_path: Path, small_config: LabConfig) -> None:
    again = build_lab(tmp_path / "again", small_config)
    for name in ("frames", "schedule", "door_states", "receptacles", "doors", "rooms", "objects", "files"):
        a = pq.read_table(small_dataset_path / "tables" / f"{name}.parquet")
        b = pq.read_table(again / "tables" / f"{name}.parquet")
        assert a.equals(b), name


def test_trajectory_respects_closed_doors(small_lab: LabModel) -> None:
    # the chain layout: a closed door hides the room behind it
    lab = LabModel(LabConfig(seed=0, days=7, frames_per_scan=6, width=32, height=24, layout="chain"))
    seen_closed = 0
    for p in lab.scans:
        rooms = {lab.layout.room_of_point(T[:2, 3]) for T in p.poses}
        assert rooms <= set(p.reachable_rooms)
        for d in lab.layout.doors:
            if not p.state.doors_open[d.door_id]:
                seen_closed += 1
                far = d.room_a if d.room_b == lab.layout.dock_room else d.room_b
                assert far not in rooms
    assert seen_closed > 0


def test_two_route_scans_reach_every_room() -> None:
    # the two-route lab: the open passages reach every room whatever the doors
    lab = LabModel(LabConfig(seed=0, days=7, frames_per_scan=6, width=32, height=24))
    closed = 0
    for p in lab.scans:
        assert sorted(p.reachable_rooms) == sorted(lab.layout.room_ids)
        closed += sum(not o for o in p.state.doors_open.values())
    assert closed > 0


def _ray_box_t(o: np.ndarray, d: np.ndarray, box) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Entry parameter of rays o + t d into an oriented box (inf if missed); slab method."""
    R = np.asarray(box.rotation)
    ol = (o - np.asarray(box.center_m)) @ R
    dl = d @ R
    h = np.asarray(box.extent_m) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-h - ol) / dl, (h - ol) / dl
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((tmax >= tmin) & (tmax > 0), tmin, np.inf)


def test_renderer_agrees_with_stored_boxes(small_dataset) -> None:  # type: ignore[no-untyped-def]
    """Pixel rays intersected analytically with the stored boxes give the rendered ids and depths."""
    ds = small_dataset
    recs = list(ds.receptacles.values())
    lab = LabModel.from_dataset(ds)
    checked = 0
    for sid in ds.scan_ids[:4]:
        scan = ds.scan(sid)
        for i in range(len(scan)):
            fr = rerender_frame(ds, sid, i, noise=False, lab=lab)
            cam = ds.cameras[next(iter(ds.cameras))]
            T = scan.poses[i]
            v, u = np.mgrid[0:cam.height, 0:cam.width]
            dc = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones(u.shape)], -1).reshape(-1, 3)
            dw = dc @ T[:3, :3].T
            o = np.broadcast_to(T[:3, 3], dw.shape)
            ids = fr.instance_ids.reshape(-1)
            z = fr.depth_true_m.reshape(-1).astype(float)
            for k, r in enumerate(recs):
                t = _ray_box_t(o, dw, r.box)
                mine = ids == RECEPTACLE_ID0 + k
                # every pixel attributed to the receptacle hits its stored box at the rendered depth
                assert np.all(np.isfinite(t[mine]))
                np.testing.assert_allclose(t[mine], z[mine], atol=2e-3)
                # pixels whose ray meets the box first (nothing rendered in front) are attributed to it
                front = np.isfinite(t) & (np.abs(z - t) < 1e-3)
                assert np.mean(ids[front] == RECEPTACLE_ID0 + k) > 0.97 if front.any() else True
                checked += int(mine.sum())
    assert checked > 500


def test_projected_top_surfaces_land_on_their_receptacle(small_dataset) -> None:  # type: ignore[no-untyped-def]
    ds = small_dataset
    lab = LabModel.from_dataset(ds)
    cam = next(iter(ds.cameras.values()))
    hits = total = 0
    for sid in ds.scan_ids:
        scan = ds.scan(sid)
        for i in range(len(scan)):
            fr = rerender_frame(ds, sid, i, noise=False, lab=lab)
            Tinv = np.linalg.inv(scan.poses[i])
            for k, r in enumerate(ds.receptacles.values()):
                e, c, R = r.box.extent_m, r.box.center_m, r.box.rotation
                g = np.linspace(-0.35, 0.35, 5)
                loc = np.array([[a * e[0], b * e[1], e[2] / 2] for a in g for b in g])
                pw = loc @ np.asarray(R).T + c
                pc = pw @ Tinv[:3, :3].T + Tinv[:3, 3]
                ok = pc[:, 2] > 0.3
                u = np.rint(cam.fx * pc[ok, 0] / pc[ok, 2] + cam.cx).astype(int)
                vv = np.rint(cam.fy * pc[ok, 1] / pc[ok, 2] + cam.cy).astype(int)
                zin = pc[ok, 2]
                inside = (u >= 0) & (u < cam.width) & (vv >= 0) & (vv < cam.height)
                u, vv, zin = u[inside], vv[inside], zin[inside]
                # points not hidden by something nearer (objects on top, other furniture, walls)
                unocc = fr.depth_true_m[vv, u] > zin - 0.05
                total += int(unocc.sum())
                # within one pixel of rounding: the pixel or one of its 8 neighbours shows the receptacle
                pad = np.pad(fr.instance_ids, 1, constant_values=-1)
                near = np.stack([pad[vv[unocc] + 1 + a, u[unocc] + 1 + b] for a in (-1, 0, 1) for b in (-1, 0, 1)])
                hits += int(np.sum((near == RECEPTACLE_ID0 + k).any(axis=0)))
    assert total > 100
    assert hits / total > 0.98


def test_rerender_reproduces_stored_images_and_backprojection_on_surfaces(small_dataset) -> None:  # type: ignore[no-untyped-def]
    ds = small_dataset
    lab = LabModel.from_dataset(ds)
    noise = lab.config.noise
    recs = list(ds.receptacles.values())
    n_rec_pts = 0
    for sid in ds.scan_ids[::3]:
        for i in range(len(ds.scan(sid))):
            stored = ds.scan(sid).frame(i)
            fr = rerender_frame(ds, sid, i, lab=lab)
            np.testing.assert_array_equal(fr.color, stored.color)
            np.testing.assert_array_equal(fr.depth_mm.astype(np.float32) * np.float32(0.001), stored.depth_m)
            clean = rerender_frame(ds, sid, i, noise=False, lab=lab)
            ok = stored.depth_m > 0
            err = np.abs(stored.depth_m[ok] - clean.depth_true_m[ok])
            assert np.all(err <= 5 * noise.sigma_m(clean.depth_true_m[ok]) + 6e-4)
            assert (stored.depth_m[ok] >= noise.min_range_m - 0.05).all()
            # loader back-projection of the stored frame: points on the surfaces the renderer hit
            pts, _ = backproject(stored)
            ids = clean.instance_ids[ok]
            zt = clean.depth_true_m[ok].astype(float)
            tol = 5 * noise.sigma_m(zt) + 2e-3
            floor = ids == ID_FLOOR
            assert np.all(np.abs(pts[floor, 2]) <= tol[floor] + 1e-9)
            for k, r in enumerate(recs):
                m = ids == RECEPTACLE_ID0 + k
                if m.any():
                    local = (pts[m] - r.box.center_m) @ np.asarray(r.box.rotation)
                    out = np.abs(local) - np.asarray(r.box.extent_m) / 2
                    assert np.all(out.max(axis=1) <= tol[m])
                    n_rec_pts += int(m.sum())
    assert n_rec_pts > 200


def test_frame_record_shape(small_dataset) -> None:  # type: ignore[no-untyped-def]
    fr = small_dataset.scan(small_dataset.scan_ids[0]).frame(0)
    assert isinstance(fr, Frame) and fr.color.shape == (60, 80, 3) and fr.depth_m.shape == (60, 80)
    assert 0.8 < (fr.depth_m > 0).mean() <= 1.0
