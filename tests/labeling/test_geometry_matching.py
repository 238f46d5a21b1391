"""Oriented-box IoU, Hungarian matching (vs brute force) and object-receptacle association."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import LabelingError
from psg_data.labeling import (
    AssociationParams,
    associate_objects,
    box_iou,
    convex_polygon_intersection,
    is_yaw_only,
    match_boxes,
    max_weight_matching,
    polygon_area,
)
from psg_data.schemas import Box

from .conftest import rot_z


def _mc_iou(a: Box, b: Box, n: int = 60_000, seed: int = 0) -> float:
    """Monte Carlo IoU over the union of both boxes' bounding boxes (independent of the implementation)."""
    rng = np.random.default_rng(seed)
    corners = np.vstack([a.corners(), b.corners()])
    lo, hi = corners.min(0), corners.max(0)
    p = rng.uniform(lo, hi, (n, 3))
    ia, ib = a.contains(p), b.contains(p)
    union = (ia | ib).sum()
    return float((ia & ib).sum() / union) if union else 0.0


def test_iou_closed_form_axis_aligned() -> None:
    a = Box(np.array([0.0, 0, 0]), np.array([2.0, 2, 2]))
    b = Box(np.array([1.0, 0, 0]), np.array([2.0, 2, 2]))
    assert box_iou(a, b) == pytest.approx(4 / 12)  # overlap 1x2x2, union 8 + 8 - 4
    assert box_iou(a, a) == pytest.approx(1.0)
    assert box_iou(a, Box(np.array([5.0, 0, 0]), np.array([1.0, 1, 1]))) == 0.0
    # a 45-degree rotated unit square inside a 2x2 square: the xy intersection is the diamond (area 2)
    c = Box(np.array([0.0, 0, 0]), np.array([np.sqrt(2), np.sqrt(2), 2.0]), rot_z(np.pi / 4))
    assert box_iou(a, c) == pytest.approx((2 * 2) / (8 + 4 - 4))
    with pytest.raises(LabelingError, match="positive volume"):
        box_iou(a, Box(np.zeros(3), np.array([1.0, 0.0, 1.0])))


@settings(max_examples=25, deadline=None)
@given(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6), st.floats(-0.3, 0.3), st.floats(0, np.pi),
       st.floats(0.3, 1.5), st.floats(0.3, 1.5), st.floats(0.2, 1.0))
def test_iou_yaw_only_matches_monte_carlo(dx: float, dy: float, dz: float, yaw: float, sx: float, sy: float,
                                          sz: float) -> None:
    a = Box(np.array([0.0, 0.0, 0.5]), np.array([1.0, 0.7, 0.8]), rot_z(0.2))
    b = Box(np.array([dx, dy, 0.5 + dz]), np.array([sx, sy, sz]), rot_z(yaw))
    iou = box_iou(a, b)
    assert 0.0 <= iou <= 1.0
    assert iou == pytest.approx(box_iou(b, a), abs=1e-12)
    assert iou == pytest.approx(_mc_iou(a, b), abs=0.015)


def test_iou_general_rotation_estimate() -> None:
    from scipy.spatial.transform import Rotation

    R = Rotation.from_euler("xyz", [0.4, -0.3, 0.8]).as_matrix()
    a = Box(np.array([0.0, 0, 0]), np.array([1.0, 0.8, 0.6]), R)
    b = Box(np.array([0.2, 0.1, -0.1]), np.array([1.0, 1.0, 1.0]))
    assert not is_yaw_only(R) and is_yaw_only(rot_z(1.0)) and is_yaw_only(np.diag([1.0, -1.0, -1.0]))
    assert box_iou(a, b) == pytest.approx(_mc_iou(a, b), abs=0.03)


def test_polygon_intersection_brute_force() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        a = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * rng.uniform(0.3, 1.5, 2)
        a = a @ rot_z(rng.uniform(0, np.pi))[:2, :2].T + rng.uniform(-0.5, 0.5, 2)
        b = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * rng.uniform(0.3, 1.5, 2)
        b = b @ rot_z(rng.uniform(0, np.pi))[:2, :2].T
        inter = polygon_area(convex_polygon_intersection(a, b))
        # grid estimate: points inside both convex polygons (half-plane tests)
        g = np.mgrid[-3:3:500j, -3:3:500j].reshape(2, -1).T

        def inside(poly: np.ndarray, p: np.ndarray) -> np.ndarray:
            e = np.roll(poly, -1, 0) - poly
            s = e[None, :, 0] * (p[:, None, 1] - poly[None, :, 1]) - e[None, :, 1] * (p[:, None, 0] - poly[None, :, 0])
            return np.all(s >= 0, 1) | np.all(s <= 0, 1)

        est = (inside(a, g) & inside(b, g)).mean() * 36
        assert inter == pytest.approx(est, abs=0.04)


def _brute_force(w: np.ndarray) -> float:
    m, n = w.shape
    best = 0.0
    if m <= n:
        for perm in itertools.permutations(range(n), m):
            best = max(best, sum(w[i, perm[i]] for i in range(m)))
    else:
        for perm in itertools.permutations(range(m), n):
            best = max(best, sum(w[perm[j], j] for j in range(n)))
    return best


@pytest.mark.parametrize("seed", range(30))
def test_hungarian_matches_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    m, n = rng.integers(1, 6), rng.integers(1, 6)
    w = rng.uniform(0, 1, (m, n))
    w[rng.random((m, n)) < 0.4] = 0.0  # pairs below the IoU threshold
    pairs = max_weight_matching(w)
    total = sum(w[i, j] for i, j in pairs)
    assert total == pytest.approx(_brute_force(w))
    assert len({i for i, _ in pairs}) == len(pairs) == len({j for _, j in pairs})
    assert all(w[i, j] > 0 for i, j in pairs)


def test_match_boxes_threshold_and_brute_force() -> None:
    rng = np.random.default_rng(5)
    annotated = [Box(np.array([x, y, 0.4]), np.array([1.0, 0.6, 0.8]), rot_z(a))
                 for x, y, a in zip(rng.uniform(0, 3, 5), rng.uniform(0, 3, 5), rng.uniform(0, np.pi, 5))]
    detected = [Box(b.center_m + rng.normal(0, 0.15, 3), b.extent_m * rng.uniform(0.8, 1.2, 3),
                    rot_z(rng.normal(0, 0.1)) @ b.rotation) for b in annotated[:4]]
    detected.append(Box(np.array([10.0, 10, 0.4]), np.ones(3)))  # matches nothing
    pairs, iou = match_boxes(detected, annotated, min_iou=0.25)
    w = np.where(iou >= 0.25, iou, 0)
    assert sum(iou[i, j] for i, j in pairs) == pytest.approx(_brute_force(w))
    assert all(iou[i, j] >= 0.25 for i, j in pairs)
    assert 4 not in [i for i, _ in pairs]


TABLE_A = Box(np.array([0.0, 0.0, 0.375]), np.array([1.0, 0.6, 0.75]))
TABLE_B = Box(np.array([1.2, 0.0, 0.375]), np.array([1.0, 0.6, 0.75]))
SHELF = Box(np.array([3.0, 0.0, 0.5]), np.array([0.8, 0.4, 1.0]), rot_z(np.pi / 2))


def test_association_cases() -> None:
    boxes = [TABLE_A, TABLE_B, SHELF]
    c = np.array([
        [0.1, 0.1, 0.80],   # on A
        [0.58, 0.0, 0.80],  # between A and B (gap 0.2 m), within both margins, nearer to A's edge (0.08 vs 0.12)
        [0.62, 0.0, 0.80],  # nearer to B
        [0.6, 0.0, 0.80],   # exactly midway: first receptacle in order (A)
        [3.1, 0.3, 1.05],   # on the rotated shelf (its x axis is world y)
        [0.0, 0.0, 0.30],   # inside A's volume, below the top face: not on top
        [5.0, 5.0, 0.80],   # on nothing
        [0.0, 0.0, 1.60],   # far above A
    ])
    got = associate_objects(c, boxes)
    assert got.tolist() == [0, 0, 1, 0, 2, -1, -1, -1]
    # receptacle not observed in the scan: it is no candidate
    assert associate_objects(c[:1], boxes, np.array([False, True, True])).tolist() == [-1]
    assert associate_objects(c[1:4], boxes, np.array([False, True, True])).tolist() == [-1, 1, 1]
    # centroid rule: nearest centre within the distance limit
    cen = associate_objects(c, boxes, params=AssociationParams(rule="centroid", max_distance_m=1.0))
    d = np.linalg.norm(c[:, None] - np.array([b.center_m for b in boxes])[None], axis=-1)
    expect = np.where(d.min(1) <= 1.0, d.argmin(1), -1)
    assert cen.tolist() == expect.tolist()
    assert associate_objects(np.zeros((0, 3)), boxes).tolist() == []
    with pytest.raises(LabelingError, match="rule"):
        AssociationParams(rule="nearest")
