"""Door observation from the depth images, against the renderer's own door schedule and geometry."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.labeling import DoorParams, door_ground_truth, doorway_samples, observe_doors
from psg_data.loaders import open_dataset
from psg_data.schemas import Box, CameraIntrinsics


def test_states_read_from_images_agree_with_the_schedule(door_lab_path, door_lab_model) -> None:  # type: ignore[no-untyped-def]
    ds = open_dataset(door_lab_path)
    obs = observe_doors(ds)
    seen = obs.observed_open >= 0
    assert seen.sum() >= 6, "the small lab should see a door in several scans"
    # independent truth: the schedule of the generator at each scan start (not the door_states table)
    truth = np.array([[door_lab_model.schedule.doors_at(int(st))[d] for d in obs.door_ids] for st in obs.stamps_ns])
    assert np.array_equal(obs.observed_open[seen] == 1, truth[seen])
    # both states occur among the seen ones, so agreement is not trivial
    assert set(obs.observed_open[seen].tolist()) == {0, 1}
    # closed doors leave (almost) no free votes, open doors mostly free votes
    of = obs.open_fraction[seen]
    assert np.all(of[~truth[seen]] < 0.1) and np.all(of[truth[seen]] > 0.5)


def test_door_visibility_matches_rendered_instance_pixels(door_lab_path, door_lab_model) -> None:  # type: ignore[no-untyped-def]
    """A door counted as seen has its leaf (closed) or free space (open) in view: when it is closed,
    the renderer's instance image must show that door's leaf in some frame."""
    from psg_data.synth import DOOR_ID0

    ds = open_dataset(door_lab_path)
    obs = observe_doors(ds)
    L = door_lab_model.layout
    for s, sid in enumerate(obs.scan_ids):
        plan = door_lab_model.scan_plan(sid)
        for k, d in enumerate(obs.door_ids):
            if not obs.visible[s, k] or plan.state.doors_open[d]:
                continue
            i = L.door_ids.index(d)
            px = 0
            for T in plan.poses:
                fr = door_lab_model.render_frame(T, plan.state, noise=None)
                px += int((fr.instance_ids == DOOR_ID0 + i).sum())
            assert px > 0, f"{sid}/{d}: seen closed but its leaf is not in any rendered frame"


def _render_slab_scene(cam: CameraIntrinsics, T: np.ndarray, wall_x: float, leaf: bool, far_x: float) -> np.ndarray:
    """Analytic depth of a scene: a far wall at x = far_x and, if ``leaf``, a plane at x = wall_x."""
    v, u = np.mgrid[0:cam.height, 0:cam.width]
    d_cam = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u, float)], -1).reshape(-1, 3)
    d_w = d_cam @ T[:3, :3].T
    o = T[:3, 3]
    with np.errstate(divide="ignore"):
        t_far = (far_x - o[0]) / d_w[:, 0]
        t_leaf = (wall_x - o[0]) / d_w[:, 0]
    t = np.where(t_far > 0, t_far, 0.0)
    if leaf:
        t = np.where(t_leaf > 0, t_leaf, t)
    return t.reshape(cam.height, cam.width).astype(np.float32)


class _Frame:
    def __init__(self, depth: np.ndarray, cam: CameraIntrinsics, T: np.ndarray) -> None:
        self.depth_m, self.camera, self.T_world_camera = depth, cam, T


@pytest.mark.parametrize("leaf", [True, False])
def test_planar_scene_closed_and_open(leaf: bool) -> None:
    """A camera facing a doorway: a leaf in the doorway plane reads closed, a far wall reads open."""
    from psg_data.labeling._doors import _DoorAccumulator

    cam = CameraIntrinsics("c", 64, 48, 50.0, 50.0, 31.5, 23.5)
    T = np.eye(4)
    T[:3, :3] = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0.0]])  # camera z along world +x
    T[:3, 3] = [0.0, 0.0, 1.0]
    box = Box(np.array([2.0, 0.0, 1.0]), np.array([0.14, 0.9, 2.0]))
    depth = _render_slab_scene(cam, T, 2.0, leaf, 4.0)
    p = DoorParams()
    acc = _DoorAccumulator(doorway_samples([box], p.spacing_m, p.inset_m))
    acc.add_frame(depth, cam, T, p)
    frac, px, frames, of = acc.door_result()
    assert frames[0] == 1 and frac[0] > 0.5 and px[0] > p.min_pixels
    assert of[0] == (0.0 if leaf else 1.0)
    # an occluder in front of the doorway hides it: nothing is seen
    acc2 = _DoorAccumulator(doorway_samples([box], p.spacing_m, p.inset_m))
    acc2.add_frame(np.full_like(depth, 1.0), cam, T, p)
    assert acc2.door_result()[0][0] == 0.0 and acc2.door_result()[2][0] == 0


def test_doorway_samples_lie_on_the_mid_plane_inside_the_opening() -> None:
    R = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    box = Box(np.array([1.0, 2.0, 1.0]), np.array([0.9, 0.12, 2.0]), R)
    s = doorway_samples([box], 0.05, 0.06)
    local = (s.points - box.center_m) @ R
    assert np.allclose(local[:, 1], 0.0)  # thinnest axis (y, 0.12 m) is the normal
    assert np.all(np.abs(local[:, 0]) <= 0.45 - 0.06 + 1e-9) and np.all(np.abs(local[:, 2]) <= 1.0 - 0.06 + 1e-9)
    assert np.allclose(np.abs(s.normals @ R[:, 1]), 1.0)
    assert np.isclose(s.area_m2.sum(), (0.9 - 0.12) * (2.0 - 0.12))


def test_ground_truth_grid_is_complementary(door_lab_path) -> None:  # type: ignore[no-untyped-def]
    ds = open_dataset(door_lab_path)
    g = door_ground_truth(ds)
    assert g.receptacle_ids == ["open", "closed"] and g.object_ids == list(ds.doors)
    assert np.all(g.codes[..., 0] + g.codes[..., 1] == 1)
    rows = ds.table("door_states").to_pylist()
    for r in rows:
        assert g.codes[g.scan_ids.index(r["scan_id"]), g.object_ids.index(r["door_id"]), 0] == int(r["state"] == "open")
