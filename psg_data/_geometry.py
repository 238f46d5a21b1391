"""Planar geometry every package shares: yaw rotations, box footprints and convex polygons.

World frame: x east, y north, z up, metres; a yaw turns about +z, counter-clockwise seen from above.
Convex hulls come from scipy (Qhull, in float64), the intersection of two convex polygons from
OpenCV (``cv2.intersectConvexConvex``, in float32: areas agree to about 1e-7 relative).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from psg_data.schemas._records import Box

__all__ = ["yaw_rotation", "box_footprint", "convex_hull", "polygon_area", "convex_polygon_intersection",
           "points_in_polygon"]


def yaw_rotation(yaw_rad: float) -> NDArray[np.float64]:
    """3x3 rotation about +z by ``yaw_rad`` (entries below 1e-12 set to 0, so right angles are exact)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    R[np.abs(R) < 1e-12] = 0.0
    return R


def convex_hull(points: ArrayLike) -> NDArray[np.float64]:
    """Convex hull of (N, 2) points: its (V, 2) vertices counter-clockwise (the distinct points if fewer than 3
    or all on one line).
    """
    P = np.unique(np.round(np.asarray(points, float).reshape(-1, 2), 12), axis=0)
    if len(P) < 3:
        return P
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = P[ConvexHull(P).vertices]  # counter-clockwise for 2-D input
    except QhullError:  # collinear points: the segment's two ends
        return P[[0, -1]]
    return np.roll(hull, -int(np.lexsort((hull[:, 1], hull[:, 0]))[0]), axis=0)  # from the lowest-x vertex


def box_footprint(box: Box) -> NDArray[np.float64]:
    """Top-down footprint of an oriented box: the convex hull of its corners on z = 0, (V, 2), metres.

    A box turned about z only (the usual case) projects to its four bottom corners: they are returned
    directly, as the hull would order them (counter-clockwise from the lowest-x vertex), without Qhull.
    """
    R = np.asarray(box.rotation, float)
    e = np.asarray(box.extent_m, float)
    if R[2, 0] == 0.0 and R[2, 1] == 0.0 and R[0, 2] == 0.0 and R[1, 2] == 0.0 and e[0] > 0 and e[1] > 0:
        loc = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) * (e[:2] / 2.0)
        P = np.round(loc @ R[:2, :2].T + np.asarray(box.center_m, float)[:2], 12)
        if np.linalg.det(R[:2, :2]) < 0:  # a box flipped upside down: the same corners, clockwise
            P = P[::-1]
        return np.roll(P, -int(np.lexsort((P[:, 1], P[:, 0]))[0]), axis=0)
    return convex_hull(box.corners()[:, :2])


def polygon_area(poly: ArrayLike) -> float:
    """Area of a simple polygon (M, 2), square metres (shoelace formula, either orientation)."""
    p = np.asarray(poly, float).reshape(-1, 2)
    if len(p) < 3:
        return 0.0
    x, y = p[:, 0], p[:, 1]
    return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2.0)


def convex_polygon_intersection(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Intersection of two convex polygons (M, 2) and (K, 2), either orientation.

    Returns:
        the (P, 2) intersection polygon (P = 0 when they do not overlap), float32 precision.
    """
    import cv2

    pa, pb = (np.asarray(p, np.float32).reshape(-1, 1, 2) for p in (a, b))
    if len(pa) < 3 or len(pb) < 3:
        return np.zeros((0, 2))
    area, inter = cv2.intersectConvexConvex(pa, pb)
    if inter is None or area <= 0:
        return np.zeros((0, 2))
    return inter.reshape(-1, 2).astype(np.float64)


def points_in_polygon(xy: NDArray[np.float64], polygon: ArrayLike) -> NDArray[np.bool_]:
    """Even-odd point-in-polygon test, vectorised over the points.

    Args:
        xy: (N, 2) points, metres.
        polygon: (V, 2) vertices (either orientation, not repeated at the end).

    Returns:
        (N,) True for points strictly inside (points on an edge may go either way).
    """
    p = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    x, y = xy[:, 0], xy[:, 1]
    inside = np.zeros(xy.shape[0], dtype=bool)
    for k in range(p.shape[0]):
        (xa, ya), (xb, yb) = p[k], p[(k + 1) % p.shape[0]]
        crosses = (ya > y) != (yb > y)
        if not np.any(crosses):
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = xa + (y - ya) * (xb - xa) / (yb - ya)
        inside ^= crosses & (x < xc)
    return inside
