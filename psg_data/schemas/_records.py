"""Typed records of the format (one row of a table) shared by writers, loaders and producers."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["CameraIntrinsics", "Box", "Room", "Receptacle", "Door", "Opening", "ObjectInfo", "Frame"]


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole camera of registered colour + depth images (OpenCV conventions).

    Pixel (u, v) has its centre at integer coordinates; x right, y down, z forward.
    """

    camera_id: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion_model: str = "none"
    distortion_coeffs: tuple[float, ...] = ()
    depth_scale_m: float = 0.001
    frame_id: str | None = None

    @property
    def K(self) -> NDArray[np.float64]:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class Box:
    """Oriented box in the world frame (metres).

    Attributes:
        center_m: (3,) centre.
        extent_m: (3,) full side lengths along the box axes.
        rotation: (3, 3) world-from-box rotation.
    """

    center_m: NDArray[np.float64]
    extent_m: NDArray[np.float64]
    rotation: NDArray[np.float64] = field(default_factory=lambda: np.eye(3))

    def corners(self) -> NDArray[np.float64]:
        """(8, 3) corners in the world frame."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        local = signs * (np.asarray(self.extent_m, float) / 2.0)
        return local @ np.asarray(self.rotation, float).T + np.asarray(self.center_m, float)

    def contains(self, points_m: NDArray[np.float64], margin_m: float = 0.0) -> NDArray[np.bool_]:
        """Whether each of the (N, 3) world points lies inside the box grown by ``margin_m``."""
        local = (np.asarray(points_m, float) - np.asarray(self.center_m, float)) @ np.asarray(self.rotation, float)
        return np.all(np.abs(local) <= np.asarray(self.extent_m, float) / 2.0 + margin_m, axis=-1)


@dataclass(frozen=True)
class Room:
    room_id: str
    name: str
    floor_polygon_m: NDArray[np.float64] | None = None
    """(N, 2) floor outline in the world frame, metres, or None."""


@dataclass(frozen=True)
class Receptacle:
    receptacle_id: str
    name: str
    room_id: str
    box: Box
    category: str | None = None


@dataclass(frozen=True)
class Door:
    door_id: str
    name: str
    room_a: str
    room_b: str
    box: Box


@dataclass(frozen=True)
class Opening:
    """A doorless passage between two rooms (an archway, an open doorway): always traversable.

    ``box`` is the passage as an oriented box in the world frame (metres), like a door's doorway;
    maps cut it out of the wall between the rooms for good.
    """

    opening_id: str
    name: str
    room_a: str
    room_b: str
    box: Box


@dataclass(frozen=True)
class ObjectInfo:
    object_id: str
    name: str
    description: str | None = None


@dataclass(frozen=True)
class Frame:
    """One RGB-D frame as the loader returns it.

    Attributes:
        scan_id: scan of the frame.
        index: frame index within the scan.
        stamp_ns: capture time, int64 UTC nanoseconds.
        color: (H, W, 3) uint8 RGB.
        depth_m: (H, W) float32 metres, 0 where invalid.
        camera: intrinsics.
        T_world_camera: (4, 4) camera-to-world pose, OpenCV camera axes.
    """

    scan_id: str
    index: int
    stamp_ns: int
    color: NDArray[np.uint8]
    depth_m: NDArray[np.float32]
    camera: CameraIntrinsics
    T_world_camera: NDArray[np.float64]
