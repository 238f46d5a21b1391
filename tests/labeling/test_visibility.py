"""Visibility of receptacle top surfaces against an independent per-pixel computation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from psg_data.errors import LabelingError
from psg_data.labeling import VisibilityParams, compute_visibility, surface_visibility, top_face_samples
from psg_data.labeling._geometry import pixel_rays, project_points
from psg_data.loaders import open_dataset
from psg_data.schemas import Box, CameraIntrinsics, Frame, Receptacle

from .conftest import FLOOR, look_at, render_boxes, rot_z

TABLE = Receptacle("table", "table", "room", Box(np.array([2.0, 0.0, 0.375]), np.array([1.2, 0.8, 0.75]), rot_z(0.3)))
HIDDEN = Receptacle("hidden", "hidden table", "room", Box(np.array([5.0, 0.0, 0.375]), np.array([1.0, 0.8, 0.75])))
TALL = Receptacle("tall", "tall shelf", "room", Box(np.array([3.0, -1.2, 1.0]), np.array([0.8, 0.4, 2.0])))
STOOL = Receptacle("stool", "stool", "room", Box(np.array([1.6, 1.0, 0.3]), np.array([0.4, 0.4, 0.6])))
WALL = Box(np.array([3.6, 0.0, 1.0]), np.array([0.1, 4.0, 2.0]))
RECS = [TABLE, HIDDEN, TALL, STOOL]


def _per_pixel(cam: CameraIntrinsics, poses: list[np.ndarray], boxes: list[Box], recs: list[Receptacle],
               p: VisibilityParams, scale: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Independent reference: top-face pixels of a supersampled analytic render, mapped to the sample grid."""
    n = len(recs)
    cells = [np.zeros(int(np.clip(np.ceil(r.box.extent_m[0] / p.spacing_m - 1e-9), 2, 40))
                      * int(np.clip(np.ceil(r.box.extent_m[1] / p.spacing_m - 1e-9), 2, 40)), bool) for r in recs]
    pixels = np.zeros(n)
    for T in poses:
        depth, idx, top = render_boxes(cam, T, boxes, scale)
        H, W = depth.shape
        v, u = np.mgrid[0:H, 0:W]
        u = (u + 0.5) / scale - 0.5
        v = (v + 0.5) / scale - 0.5
        pc = np.stack([(u - cam.cx) / cam.fx * depth, (v - cam.cy) / cam.fy * depth, depth], -1)
        pw = pc.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
        for k, r in enumerate(recs):
            m = ((idx == k) & top & (depth > p.min_range_m) & (depth < p.max_range_m)).ravel()
            if not m.any():
                continue
            e = r.box.extent_m
            local = (pw[m] - r.box.center_m) @ r.box.rotation
            # incidence: cos between the ray and the top normal
            ray = pw[m] - T[:3, 3]
            cos = np.abs(ray @ r.box.rotation[:, 2]) / np.linalg.norm(ray, axis=1)
            ok = cos >= p.min_cos
            nu = int(np.clip(np.ceil(e[0] / p.spacing_m - 1e-9), 2, 40))
            nv = int(np.clip(np.ceil(e[1] / p.spacing_m - 1e-9), 2, 40))
            iu = np.clip(((local[ok, 0] / e[0] + 0.5) * nu).astype(int), 0, nu - 1)
            iv = np.clip(((local[ok, 1] / e[1] + 0.5) * nv).astype(int), 0, nv - 1)
            cells[k][iu * nv + iv] = True
            pixels[k] = max(pixels[k], ok.sum() / scale**2)
    return np.array([c.mean() for c in cells]), pixels


def _frames(cam: CameraIntrinsics, poses: list[np.ndarray], boxes: list[Box], noise: float = 0.0,
            seed: int = 0) -> list[Frame]:
    rng = np.random.default_rng(seed)
    out = []
    for i, T in enumerate(poses):
        d, _, _ = render_boxes(cam, T, boxes)
        if noise:
            d = d + rng.normal(0, 1, d.shape) * noise * d**2
            d[rng.random(d.shape) < 0.01] = 0.0
        out.append(Frame("s", i, i, np.zeros((0, 0, 3), np.uint8), d.astype(np.float32), cam, T))
    return out


POSES = [look_at(np.array([0.0, 0.0, 1.5]), np.array([2.0, 0.0, 0.75])),
         look_at(np.array([0.3, 1.5, 1.4]), np.array([2.0, 0.2, 0.6])),
         look_at(np.array([0.0, -0.5, 1.3]), np.array([3.0, -1.2, 1.0]))]


@pytest.mark.parametrize("noise", [0.0, 0.004])
def test_visibility_matches_per_pixel_reference(small_cam: CameraIntrinsics, noise: float) -> None:
    boxes = [r.box for r in RECS] + [FLOOR, WALL]
    p = VisibilityParams()
    res = surface_visibility(_frames(small_cam, POSES, boxes, noise), top_face_samples([r.box for r in RECS]), p)
    ref_frac, ref_px = _per_pixel(small_cam, POSES, boxes, RECS, p)
    # the scene's facts: table and stool seen, the table behind the wall and the shelf above the camera not
    assert ref_frac[0] > 0.8 and ref_frac[3] > 0.5
    assert ref_frac[1] == 0 and ref_frac[2] == 0
    np.testing.assert_allclose(res.seen_fraction, ref_frac, atol=0.12)
    np.testing.assert_allclose(res.pixels, ref_px, rtol=0.25, atol=3.0)
    vis = (res.seen_fraction >= p.min_fraction) & (res.pixels >= p.min_pixels)
    ref_vis = (ref_frac >= p.min_fraction) & (ref_px >= p.min_pixels)
    assert vis.tolist() == ref_vis.tolist() == [True, False, False, True]


def test_range_and_occluder_rules(small_cam: CameraIntrinsics) -> None:
    boxes = [TABLE.box, FLOOR]
    frames = _frames(small_cam, POSES[:1], boxes)
    s = top_face_samples([TABLE.box])
    seen = surface_visibility(frames, s).seen_fraction[0]
    assert seen > 0.8
    # everything beyond max range is unseen
    assert surface_visibility(frames, s, VisibilityParams(max_range_m=1.5)).seen_fraction[0] == 0.0
    # a box standing on the table hides the samples under it (its depth is nearer than the face)
    block = Box(np.array([2.0, 0.0, 0.95]), np.array([0.5, 0.5, 0.4]), rot_z(0.3))
    frames_b = _frames(small_cam, POSES[:1], [TABLE.box, FLOOR, block])
    seen_b = surface_visibility(frames_b, s).seen_fraction[0]
    hidden_area = 0.25 / (1.2 * 0.8)  # the block's footprint, plus what it hides behind it
    assert seen_b <= seen - hidden_area + 0.05
    # missing depth (0) is not seen
    empty = [Frame(f.scan_id, f.index, f.stamp_ns, f.color, np.zeros_like(f.depth_m), f.camera, f.T_world_camera)
             for f in frames]
    assert surface_visibility(empty, s).seen_fraction[0] == 0.0


def test_distortion_is_used(small_cam: CameraIntrinsics) -> None:
    """With a distorted camera, projecting without the distortion would sample the wrong pixels."""
    import cv2

    dcam = CameraIntrinsics("cam", 96, 72, 80.0, 80.0, 47.5, 35.5, "plumb_bob", (-0.3, 0.1, 0.0, 0.0, 0.0))
    T = POSES[0]
    boxes = [TABLE.box, FLOOR]
    d_ideal, _, _ = render_boxes(small_cam, T, boxes, scale=1)
    # distort the ideal image: for each distorted pixel, look up the undistorted position
    v, u = np.mgrid[0:72, 0:96].astype(np.float32)
    und = cv2.undistortPoints(np.stack([u.ravel(), v.ravel()], -1).reshape(-1, 1, 2), dcam.K,
                              np.asarray(dcam.distortion_coeffs)).reshape(-1, 2)
    pu = und[:, 0] * 80.0 + 47.5
    pv = und[:, 1] * 80.0 + 35.5
    # ray-cast those exact rays instead of resampling, for exact depth
    d_cam = np.column_stack([und, np.ones(len(und))])
    d_w = d_cam @ T[:3, :3].T
    depth = np.zeros(len(d_w))
    best = np.full(len(d_w), np.inf)
    for b in boxes:
        o = (T[:3, 3] - b.center_m) @ b.rotation
        d = d_w @ b.rotation
        h = b.extent_m / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (-h - o) / d, (h - o) / d
        tmin, tmax = np.nanmax(np.minimum(t1, t2), 1), np.nanmin(np.maximum(t1, t2), 1)
        hit = (tmax >= tmin) & (tmin > 0) & (tmin < best)
        best[hit] = tmin[hit]
    depth = np.where(np.isfinite(best), best, 0).reshape(72, 96).astype(np.float32)
    assert np.isfinite(pu).all() and np.isfinite(pv).all()
    fr = [Frame("s", 0, 0, np.zeros((0, 0, 3), np.uint8), depth, dcam, T)]
    s = top_face_samples([TABLE.box])
    right = surface_visibility(fr, s).seen_fraction[0]
    ideal = surface_visibility(_frames(small_cam, [T], boxes), s).seen_fraction[0]
    assert ideal > 0.8 and abs(right - ideal) < 0.1
    assert d_ideal.shape == depth.shape
    # projection and pixel rays invert each other with distortion
    pts = np.random.default_rng(0).uniform([-1, -0.7, 1], [1, 0.7, 4], (200, 3))
    uv = project_points(pts, dcam)
    ref, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), dcam.K,
                               np.asarray(dcam.distortion_coeffs))
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-6)
    rays = pixel_rays(uv, dcam)
    np.testing.assert_allclose(rays[:, :2], pts[:, :2] / pts[:, 2:], atol=2e-3)
    np.testing.assert_allclose(project_points(pts, small_cam)[:, 0], 80.0 * pts[:, 0] / pts[:, 2] + 47.5)


def test_compute_visibility_on_dataset(make_box_scene, small_cam: CameraIntrinsics) -> None:  # type: ignore[no-untyped-def]
    root: Path = make_box_scene(receptacles=RECS, poses=[POSES, POSES[2:]], cam=small_cam, extra_boxes=[WALL])
    ds = open_dataset(root)
    t = compute_visibility(ds).to_pydict()
    vis = {(s, i): v for s, i, v in zip(t["scan_id"], t["id"], t["visible"])}
    assert vis[("scan_00", "table")] and vis[("scan_00", "stool")]
    assert not vis[("scan_00", "hidden")] and not vis[("scan_00", "tall")]
    # the second scan only looks at the shelf: its top is above the camera
    assert not vis[("scan_01", "tall")]
    # stride 2 on scan 0 drops the second pose; the per-pixel reference with poses 0 and 2 agrees
    t2 = compute_visibility(ds, VisibilityParams(frame_stride=2)).to_pydict()
    frac2 = {(s, i): f for s, i, f in zip(t2["scan_id"], t2["id"], t2["seen_fraction"])}
    ref, _ = _per_pixel(small_cam, [POSES[0], POSES[2]], [r.box for r in RECS] + [FLOOR, WALL], RECS,
                        VisibilityParams())
    got = np.array([frac2[("scan_00", r.receptacle_id)] for r in RECS])
    np.testing.assert_allclose(got, ref, atol=0.12)


def test_bad_params() -> None:
    with pytest.raises(LabelingError, match="min_fraction"):
        VisibilityParams(min_fraction=1.5)
    with pytest.raises(LabelingError, match="frame_stride"):
        VisibilityParams(frame_stride=0)
