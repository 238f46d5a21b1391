"""Geometry for labelling: surface samples of boxes, camera projection, oriented-box 3D IoU.

Frames: boxes and samples are in the world frame (metres); ``T_world_camera`` is camera-to-world
with OpenCV camera axes (x right, y down, z forward).

3D IoU of oriented boxes (:func:`box_iou`) is exact when both boxes are rotated about the world z
axis only ("yaw-only": the box's z axis is the world z axis, up to sign): the intersection volume is
then the area of the intersection of the two footprint rectangles (``cv2.intersectConvexConvex``)
times the overlap of their z intervals. For general rotations it is estimated
by testing a regular grid of ``GENERAL_IOU_GRID**3`` points of the smaller box against the other box
(error about 1/GENERAL_IOU_GRID of the smaller box's volume).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from psg_data._geometry import box_footprint, convex_polygon_intersection, polygon_area
from psg_data.errors import LabelingError
from psg_data.schemas._records import Box, CameraIntrinsics

__all__ = [
    "SurfaceSamples",
    "top_face_samples",
    "box_surface_samples",
    "is_yaw_only",
    "box_iou",
    "box_iou_matrix",
    "polygon_area",
    "convex_polygon_intersection",
    "project_points",
    "pixel_rays",
    "GENERAL_IOU_GRID",
]

GENERAL_IOU_GRID = 24
"""Grid points per axis of the IoU estimate for boxes that are not yaw-only."""

_YAW_TOL = 1e-6


class SurfaceSamples:
    """Sample points on planar faces, grouped by owner (receptacle or object index).

    Attributes:
        points: (N, 3) world points, metres.
        normals: (N, 3) outward unit face normals, world frame.
        area_m2: (N,) area of the face cell each sample stands for, square metres.
        owner: (N,) int index of the box the sample belongs to.
        n_owners: number of boxes.
    """

    def __init__(self, points: NDArray[np.float64], normals: NDArray[np.float64], area_m2: NDArray[np.float64],
                 owner: NDArray[np.int64], n_owners: int) -> None:
        self.points = points
        self.normals = normals
        self.area_m2 = area_m2
        self.owner = owner
        self.n_owners = int(n_owners)

    def __len__(self) -> int:
        return int(self.owner.size)

    @property
    def counts(self) -> NDArray[np.int64]:
        """(n_owners,) number of samples per box."""
        return np.bincount(self.owner, minlength=self.n_owners)

    @staticmethod
    def concat(parts: list[SurfaceSamples]) -> SurfaceSamples:
        """Concatenate samples of disjoint owner sets (owners are renumbered consecutively)."""
        off = 0
        pts, nrm, area, own = [], [], [], []
        for p in parts:
            pts.append(p.points)
            nrm.append(p.normals)
            area.append(p.area_m2)
            own.append(p.owner + off)
            off += p.n_owners
        if not parts:
            z = np.zeros((0, 3))
            return SurfaceSamples(z, z.copy(), np.zeros(0), np.zeros(0, np.int64), 0)
        return SurfaceSamples(np.concatenate(pts), np.concatenate(nrm), np.concatenate(area),
                              np.concatenate(own), off)


def _face_grid(n_u: int, n_v: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Cell centres of an n_u x n_v grid on [-0.5, 0.5]^2 (flattened u, v)."""
    gu = (np.arange(n_u) + 0.5) / n_u - 0.5
    gv = (np.arange(n_v) + 0.5) / n_v - 0.5
    U, V = np.meshgrid(gu, gv, indexing="ij")
    return U.ravel(), V.ravel()


def _cells(length_m: float, spacing_m: float, max_per_axis: int) -> int:
    return int(np.clip(np.ceil(length_m / spacing_m - 1e-9), 2, max_per_axis))


def top_face_samples(boxes: list[Box], spacing_m: float = 0.05, max_per_axis: int = 40) -> SurfaceSamples:
    """Grid samples on the top face (box z = +extent_z / 2) of every box.

    The face is divided into ``ceil(extent / spacing_m)`` cells per axis (clipped to
    ``[2, max_per_axis]``); one sample sits at each cell centre, exactly on the face.

    Args:
        boxes: oriented boxes, world frame.
        spacing_m: target cell size, metres.
        max_per_axis: cap on cells per axis.

    Returns:
        samples with owner = index into ``boxes``; normals are the box's +z axis.
    """
    parts = []
    for b in boxes:
        e = np.asarray(b.extent_m, float)
        R = np.asarray(b.rotation, float)
        nu, nv = _cells(e[0], spacing_m, max_per_axis), _cells(e[1], spacing_m, max_per_axis)
        u, v = _face_grid(nu, nv)
        local = np.column_stack([u * e[0], v * e[1], np.full(u.size, e[2] / 2)])
        parts.append(SurfaceSamples(local @ R.T + np.asarray(b.center_m, float),
                                    np.ascontiguousarray(np.broadcast_to(R[:, 2], (u.size, 3))),
                                    np.full(u.size, e[0] * e[1] / (nu * nv)), np.zeros(u.size, np.int64), 1))
    return SurfaceSamples.concat(parts)


def box_surface_samples(boxes: list[Box], spacing_m: float = 0.02, max_per_axis: int = 12) -> SurfaceSamples:
    """Grid samples on the five visible faces (top and four sides; not the bottom) of every box."""
    parts = []
    for b in boxes:
        e = np.asarray(b.extent_m, float)
        R = np.asarray(b.rotation, float)
        pts, nrm, area = [], [], []
        # (normal axis, sign, the two in-face axes)
        for ax, sign, (a1, a2) in ((2, 1, (0, 1)), (0, 1, (1, 2)), (0, -1, (1, 2)), (1, 1, (0, 2)), (1, -1, (0, 2))):
            n1, n2 = _cells(e[a1], spacing_m, max_per_axis), _cells(e[a2], spacing_m, max_per_axis)
            u, v = _face_grid(n1, n2)
            local = np.zeros((u.size, 3))
            local[:, a1] = u * e[a1]
            local[:, a2] = v * e[a2]
            local[:, ax] = sign * e[ax] / 2
            pts.append(local @ R.T + np.asarray(b.center_m, float))
            nrm.append(np.broadcast_to(sign * R[:, ax], (u.size, 3)))
            area.append(np.full(u.size, e[a1] * e[a2] / (n1 * n2)))
        p = np.concatenate(pts)
        parts.append(SurfaceSamples(p, np.concatenate(nrm), np.concatenate(area), np.zeros(len(p), np.int64), 1))
    return SurfaceSamples.concat(parts)


# -- camera --------------------------------------------------------------------------------------
def project_points(points_cam: NDArray[np.float64], cam: CameraIntrinsics) -> NDArray[np.float64]:
    """Pixel coordinates (N, 2) of camera-frame points (N, 3) with z > 0, including distortion."""
    z = points_cam[:, 2]
    xn = points_cam[:, 0] / z
    yn = points_cam[:, 1] / z
    model = cam.distortion_model
    k = np.asarray(cam.distortion_coeffs, float)
    if model == "none" or not np.any(k):
        return np.column_stack([cam.fx * xn + cam.cx, cam.fy * yn + cam.cy])
    import cv2

    pts = np.column_stack([xn, yn, np.ones_like(xn)]).reshape(-1, 1, 3)
    if model == "equidistant":
        uv, _ = cv2.fisheye.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, k[:4].reshape(4, 1))
    else:
        uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, k)
    return np.asarray(uv, dtype=np.float64).reshape(-1, 2)


def pixel_rays(uv: NDArray[np.float64], cam: CameraIntrinsics) -> NDArray[np.float64]:
    """Camera-frame rays (N, 3) with z = 1 through the pixel positions ``uv`` (N, 2), undistorted."""
    model = cam.distortion_model
    k = np.asarray(cam.distortion_coeffs, float)
    if model == "none" or not np.any(k) or uv.size == 0:
        xn = (uv[:, 0] - cam.cx) / cam.fx
        yn = (uv[:, 1] - cam.cy) / cam.fy
    else:
        import cv2

        src = uv.reshape(-1, 1, 2).astype(np.float64)
        if model == "equidistant":
            und = cv2.fisheye.undistortPoints(src, cam.K, k[:4].reshape(4, 1))
        else:
            und = cv2.undistortPoints(src, cam.K, k)
        xn, yn = und.reshape(-1, 2).T
    return np.column_stack([xn, yn, np.ones_like(xn)])


# -- oriented box IoU -----------------------------------------------------------------------------
def pixels_in_image(points_cam: NDArray[np.float64], cam: CameraIntrinsics, shape: tuple[int, ...],
                    border_px: int = 0) -> tuple[NDArray[np.bool_], NDArray[np.int64], NDArray[np.int64]]:
    """Project camera-frame points (OpenCV axes, metres) to their nearest pixel.

    Returns ``(inside, u, v)``: which points land at least ``border_px`` pixels inside an image of
    ``shape`` (H, W, ...), and the integer column / row of those points.
    """
    uv = project_points(points_cam, cam)
    ui, vi = np.rint(uv[:, 0]), np.rint(uv[:, 1])
    H, W = shape[:2]
    b = border_px
    inside = np.isfinite(ui) & np.isfinite(vi) & (ui >= b) & (ui <= W - 1 - b) & (vi >= b) & (vi <= H - 1 - b)
    return inside, ui[inside].astype(np.int64), vi[inside].astype(np.int64)


def is_yaw_only(R: NDArray[np.float64], tol: float = _YAW_TOL) -> bool:
    """True if rotation ``R`` (3x3, world-from-box) maps the box z axis to +-world z."""
    R = np.asarray(R, float)
    return bool(abs(abs(R[2, 2]) - 1.0) <= tol and np.all(np.abs(R[2, :2]) <= tol) and np.all(np.abs(R[:2, 2]) <= tol))


def _z_range(b: Box) -> tuple[float, float]:
    c = float(np.asarray(b.center_m, float)[2])
    h = float(np.asarray(b.extent_m, float)[2]) / 2
    return c - h, c + h


def _volume(b: Box) -> float:
    return float(np.prod(np.asarray(b.extent_m, float)))


def _intersection_volume(a: Box, b: Box) -> float:
    if is_yaw_only(a.rotation) and is_yaw_only(b.rotation):
        za, zb = _z_range(a), _z_range(b)
        dz = min(za[1], zb[1]) - max(za[0], zb[0])
        if dz <= 0:
            return 0.0
        return polygon_area(convex_polygon_intersection(box_footprint(a), box_footprint(b))) * dz
    small, big = (a, b) if _volume(a) <= _volume(b) else (b, a)
    g = (np.arange(GENERAL_IOU_GRID) + 0.5) / GENERAL_IOU_GRID - 0.5
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    local = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]) * np.asarray(small.extent_m, float)
    pts = local @ np.asarray(small.rotation, float).T + np.asarray(small.center_m, float)
    return float(big.contains(pts).mean()) * _volume(small)


def box_iou(a: Box, b: Box) -> float:
    """3D intersection over union of two oriented boxes (exact for yaw-only boxes; see module doc)."""
    va, vb = _volume(a), _volume(b)
    if va <= 0 or vb <= 0:
        raise LabelingError(f"box_iou: boxes need positive volume, got extents {np.asarray(a.extent_m).tolist()} "
                            f"and {np.asarray(b.extent_m).tolist()}")
    inter = _intersection_volume(a, b)
    return float(inter / (va + vb - inter))


def box_iou_matrix(a: list[Box], b: list[Box]) -> NDArray[np.float64]:
    """(len(a), len(b)) IoU matrix; pairs whose bounding spheres do not overlap are 0 without clipping."""
    out = np.zeros((len(a), len(b)))
    if not a or not b:
        return out
    ca = np.array([np.asarray(x.center_m, float) for x in a])
    cb = np.array([np.asarray(x.center_m, float) for x in b])
    ra = np.array([np.linalg.norm(x.extent_m) / 2 for x in a])
    rb = np.array([np.linalg.norm(x.extent_m) / 2 for x in b])
    near = np.linalg.norm(ca[:, None] - cb[None], axis=-1) < ra[:, None] + rb[None]
    for i, j in zip(*np.nonzero(near)):
        out[i, j] = box_iou(a[i], b[j])
    return out
