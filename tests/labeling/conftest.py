"""Fixtures for the labelling tests: tiny box scenes rendered with numpy, and a small synthetic lab.

``render_boxes`` is an independent analytic ray caster (slab method in each box's frame): it
returns z-depth, the index of the box hit first and whether the hit lies on that box's top face,
which is the per-pixel ground truth the visibility tests compare against.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from psg_data.schemas import Box, CameraIntrinsics, ObjectInfo, Receptacle, Room
from psg_data.writers import DatasetWriter

T0_NS = 1_750_000_000 * 10**9


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Camera-to-world pose (OpenCV axes) at ``eye`` looking at ``target`` (world z up)."""
    ez = np.asarray(target, float) - np.asarray(eye, float)
    ez /= np.linalg.norm(ez)
    ex = np.cross(ez, [0, 0, 1.0])
    ex /= np.linalg.norm(ex)
    ey = np.cross(ez, ex)
    T = np.eye(4)
    T[:3, :3] = np.stack([ex, ey, ez], axis=1)
    T[:3, 3] = eye
    return T


def render_boxes(cam: CameraIntrinsics, T: np.ndarray, boxes: list[Box], scale: int = 1
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray-cast boxes; returns (depth_m (H, W), box index (-1 none), on_top_face bool) at ``scale`` x resolution."""
    H, W = cam.height * scale, cam.width * scale
    v, u = np.mgrid[0:H, 0:W]
    u = (u + 0.5) / scale - 0.5
    v = (v + 0.5) / scale - 0.5
    d_cam = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], -1).reshape(-1, 3)
    d_w = d_cam @ T[:3, :3].T
    o_w = T[:3, 3]
    best = np.full(len(d_w), np.inf)
    idx = np.full(len(d_w), -1)
    top = np.zeros(len(d_w), bool)
    for k, b in enumerate(boxes):
        R = np.asarray(b.rotation, float)
        o = (o_w - b.center_m) @ R
        d = d_w @ R
        h = np.asarray(b.extent_m) / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - o) / d
            t2 = (h - o) / d
        tmin = np.nanmax(np.minimum(t1, t2), axis=1)
        tmax = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (tmax >= tmin) & (tmin > 0)
        nearer = hit & (tmin < best)
        best[nearer] = tmin[nearer]
        idx[nearer] = k
        pz = o[2] + tmin * d[:, 2]
        top[nearer] = (np.abs(pz - h[2]) < 1e-6 * max(1.0, h[2]))[nearer]
    depth = np.where(np.isfinite(best), best, 0.0)  # d_cam has z = 1, so t is the z-depth
    return depth.reshape(H, W), idx.reshape(H, W), top.reshape(H, W)


FLOOR = Box(np.array([0.0, 0.0, -0.05]), np.array([30.0, 30.0, 0.1]))


def box_scene_dataset(root: Path, receptacles: list[Receptacle], poses: list[list[np.ndarray]],
                      cam: CameraIntrinsics, *, extra_boxes: list[Box] = (), schedule: list[dict] | None = None,
                      objects: list[str] = ("mug", "book")) -> Path:
    """Write a dataset whose depth images are analytic renders of the receptacles (+ floor, extra boxes)."""
    boxes = [r.box for r in receptacles] + [FLOOR, *extra_boxes]
    with DatasetWriter(root, name="boxes", timezone="UTC", extra={"generator": "tests.labeling"}) as w:
        w.add_camera(cam)
        w.set_rooms([Room("room", "Room")])
        w.set_receptacles(receptacles)
        w.set_objects([ObjectInfo(o, o) for o in objects])
        for s, scan_poses in enumerate(poses):
            with w.scan(f"scan_{s:02d}") as sw:
                for i, T in enumerate(scan_poses):
                    depth, _, _ = render_boxes(cam, T, boxes)
                    mm = np.clip(np.rint(depth * 1000), 0, 65535).astype(np.uint16)
                    col = np.full((cam.height, cam.width, 3), 128, np.uint8)
                    sw.add_frame(T0_NS + s * 3600 * 10**9 + i * 10**8, T, col, mm, cam.camera_id)
        if schedule is not None:
            w.set_table("schedule", schedule)
    return root


@pytest.fixture
def small_cam() -> CameraIntrinsics:
    return CameraIntrinsics("cam", 96, 72, 80.0, 80.0, 47.5, 35.5)


@pytest.fixture
def make_box_scene(tmp_path: Path) -> Callable[..., Path]:
    def factory(name: str = "boxes", **kwargs: object) -> Path:
        return box_scene_dataset(tmp_path / name, **kwargs)  # type: ignore[arg-type]

    return factory


# -- a small synthetic lab (the synth helper's renderer) -----------------------------------------
SMALL_LAB = dict(seed=1, days=2, frames_per_scan=4, width=96, height=72)


@pytest.fixture(scope="session")
def lab_model():  # type: ignore[no-untyped-def]
    from psg_data.synth import LabConfig, LabModel

    return LabModel(LabConfig(**SMALL_LAB))


@pytest.fixture(scope="session")
def lab_path(tmp_path_factory: pytest.TempPathFactory, lab_model) -> Path:  # type: ignore[no-untyped-def]
    from psg_data.synth import build_lab

    return build_lab(tmp_path_factory.mktemp("lab") / "lab", lab_model.config, lab=lab_model)


@pytest.fixture
def lab_copy(tmp_path: Path, lab_path: Path) -> Path:
    """A private copy of the small lab (tests that write labels into it)."""
    import shutil

    dst = tmp_path / "lab"
    shutil.copytree(lab_path, dst)
    return dst
