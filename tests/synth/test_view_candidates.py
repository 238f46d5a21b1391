"""The scan planner's view scores: the batched computation (all candidates of a room in one ray cast)
against the definition evaluated one candidate at a time, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.synth import LabConfig, LabModel
from psg_data.synth._model import camera_pose
from psg_data.synth._render import LabRenderer, SceneState, d435_intrinsics


def _scores_one_by_one(lab: LabModel, C: np.ndarray) -> np.ndarray:
    """Each candidate's pose from camera_pose, its own inverse, projection and ray cast (the planner
    before the batching): the share of each target's 5 points in the image, 0.4-6 m ahead, unoccluded."""
    L = lab.layout
    rend = LabRenderer(L, SceneState({}, {d: False for d in L.door_ids}))
    cam = d435_intrinsics(160, 120)
    tops, ids = lab._view_targets()
    pts = tops.reshape(-1, 3)
    out = np.zeros((len(C), len(ids)))
    for ci, (x, y, yaw) in enumerate(C):
        T = camera_pose(x, y, yaw)
        Tinv = np.linalg.inv(T)
        pc = pts @ Tinv[:3, :3].T + Tinv[:3, 3]
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = cam.fx * pc[:, 0] / z + cam.cx
            v = cam.fy * pc[:, 1] / z + cam.cy
        inimg = (z > 0.4) & (z < 6.0) & (u > 2) & (u < cam.width - 3) & (v > 2) & (v < cam.height - 3)
        d = pts - T[:3, 3]
        t, iid, _ = rend.cast(np.broadcast_to(T[:3, 3], d.shape), d)
        out[ci] = (inimg & (iid == np.repeat(ids, 5)) & (t > 0.97)).reshape(-1, 5).mean(axis=1)
    return out


@pytest.mark.parametrize(("layout", "seed"), [("corridor", 0), ("two_routes", 3), ("chain", 5)])
def test_batched_view_scores_equal_one_candidate_at_a_time(layout: str, seed: int) -> None:
    lab = LabModel(LabConfig(seed=seed, layout=layout))
    cands = lab._view_candidates()
    rooms_with_receptacles = sorted({r.room_id for r in lab.layout.receptacles})
    assert sorted(cands) == rooms_with_receptacles
    seen_any = 0
    for room, (C, S) in cands.items():
        assert C.shape[1] == 3 and S.shape == (len(C), len(lab._view_targets()[1]))
        assert np.array_equal(C, lab._room_candidates(room))
        rows = np.arange(0, len(C), 5)  # every 5th candidate: all 24 yaws occur (24 and 5 are coprime)
        assert np.array_equal(S[rows], _scores_one_by_one(lab, C[rows]))
        seen_any += int(np.count_nonzero(S[rows]))
    assert seen_any > 0  # the comparison covers seen targets, not only zeros


def test_a_room_without_a_free_spot_gets_no_candidates(monkeypatch: pytest.MonkeyPatch) -> None:
    lab = LabModel(LabConfig(seed=0, layout="chain"))
    full = lab._room_candidates
    empty_room = lab.layout.receptacles[0].room_id
    monkeypatch.setattr(lab, "_room_candidates", lambda room: full(room)[:0] if room == empty_room else full(room))
    cands = lab._view_candidates()
    n_targets = len(lab._view_targets()[1])
    assert cands[empty_room][0].shape == (0, 3) and cands[empty_room][1].shape == (0, n_targets)
    assert all(len(C) > 0 and S.shape == (len(C), n_targets) for r, (C, S) in cands.items() if r != empty_room)
