"""Simulated RealSense D435 and the Open3D ray-casting renderer of the synthetic lab.

The renderer casts one ray per pixel through the pinhole model into an
``open3d.t.geometry.RaycastingScene`` holding the walls, floor, ceiling, door leaves, receptacles
and present objects, and returns colour, depth and the per-pixel instance id (see the ``*_ID0``
constants of :mod:`psg_data.synth._layout`). Ray directions are ``R @ [(u-cx)/fx, (v-cy)/fy, 1]``,
so the hit distance is the z-depth directly.

Depth noise model (:class:`DepthNoise`): Gaussian with ``sigma = k * z**2`` (axial RMS error of
active-stereo sensors), then invalid (0) outside ``[min_range_m, max_range_m]``, random dropouts
with probability ``dropout``, and dropouts with probability 0.5 at grazing angles
(``|cos| < grazing_cos``). Colour: per-instance albedo, Lambert shading from a fixed light, a
0.5 m checker on the floor and a small Gaussian sensor noise.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.schemas._records import Box, CameraIntrinsics
from psg_data.synth._layout import (
    DOOR_ID0,
    ID_CEILING,
    ID_FLOOR,
    ID_NONE,
    OBJECT_ID0,
    RECEPTACLE_ID0,
    WALL_HEIGHT_M,
    WALL_ID0,
    LabLayout,
)

__all__ = ["DepthNoise", "RenderedFrame", "SceneState", "LabRenderer", "d435_intrinsics", "D435_BASE"]

log = logging.getLogger(__name__)

D435_BASE = {"width": 1280, "height": 720, "fx": 920.0, "fy": 920.0}
"""D435 colour stream at 1280x720: fx = fy = 920 px, i.e. about 69 x 42 deg field of view."""

_WALL_RGB = np.array([0.86, 0.84, 0.78])
_FLOOR_RGB = (np.array([0.45, 0.45, 0.48]), np.array([0.58, 0.58, 0.60]))
_CEIL_RGB = np.array([0.95, 0.95, 0.95])
_DOOR_RGB = np.array([0.45, 0.25, 0.12])
_LIGHT = np.array([0.35, 0.55, 0.76]) / np.linalg.norm([0.35, 0.55, 0.76])


def d435_intrinsics(width: int = 160, height: int = 120, camera_id: str = "d435") -> CameraIntrinsics:
    """Intrinsics of the simulated D435 (registered colour + depth) at ``width`` x ``height``.

    Square pixels, the vertical field of view of the 1280x720 stream (42 deg) is kept: a 16:9 image
    has the full 69 deg horizontal field of view, a 4:3 image crops the sides (as the sensor's
    640x480 mode does, about 55 deg).
    """
    f = D435_BASE["fy"] * height / D435_BASE["height"]
    return CameraIntrinsics(camera_id, int(width), int(height), f, f, (width - 1) / 2.0, (height - 1) / 2.0,
                            "none", (), 0.001, "camera_color_optical_frame")


@dataclass(frozen=True)
class DepthNoise:
    """Depth noise of the simulated sensor (see the module docstring).

    Attributes:
        k_per_m: axial noise coefficient, ``sigma = k_per_m * z**2`` (metres).
        min_range_m: closer surfaces read as invalid (D435 minimum depth ~0.28 m).
        max_range_m: farther surfaces read as invalid.
        dropout: probability that a valid pixel reads invalid.
        grazing_cos: below this |cos(incidence)| half the pixels drop out.
        color_sigma: colour noise, 8-bit levels.
    """

    k_per_m: float = 0.004
    min_range_m: float = 0.28
    max_range_m: float = 8.0
    dropout: float = 0.01
    grazing_cos: float = 0.08
    color_sigma: float = 2.0

    def sigma_m(self, z_m: NDArray[np.float64] | float) -> NDArray[np.float64]:
        """Standard deviation of the depth noise at true depth ``z_m``, metres."""
        return self.k_per_m * np.asarray(z_m, float) ** 2


@dataclass(frozen=True)
class SceneState:
    """Dynamic state of the lab during a scan: object placement and door states."""

    objects: dict[str, str | None]
    doors_open: dict[str, bool]


@dataclass
class RenderedFrame:
    """One rendered RGB-D frame with the renderer's ground truth.

    Attributes:
        color: (H, W, 3) uint8 RGB.
        depth_mm: (H, W) uint16 millimetres with sensor noise, 0 = invalid.
        depth_true_m: (H, W) float32 noise-free z-depth, metres, 0 = no hit.
        instance_ids: (H, W) int32 instance hit by each pixel's ray (0 = none; see ``LabLayout.instances``).
        T_world_camera: (4, 4) pose used for rendering (camera-to-world, OpenCV axes).
        camera: intrinsics.
        normals: (H, W, 3) float32 world surface normals at the hits.
    """

    color: NDArray[np.uint8]
    depth_mm: NDArray[np.uint16]
    depth_true_m: NDArray[np.float32]
    instance_ids: NDArray[np.int32]
    T_world_camera: NDArray[np.float64]
    camera: CameraIntrinsics
    normals: NDArray[np.float32] = field(repr=False, default_factory=lambda: np.zeros((0, 0, 3), np.float32))


def _box_mesh(o3d: Any, box: Box) -> Any:
    ext = np.asarray(box.extent_m, float)
    m = o3d.geometry.TriangleMesh.create_box(*ext)
    m.translate(-ext / 2)
    return _place(m, box)


def _place(mesh: Any, box: Box) -> Any:
    T = np.eye(4)
    T[:3, :3] = np.asarray(box.rotation, float)
    T[:3, 3] = np.asarray(box.center_m, float)
    mesh.transform(T)
    return mesh


def _object_mesh(o3d: Any, shape: str, box: Box) -> Any:
    sx, sy, sz = np.asarray(box.extent_m, float)
    if shape == "cylinder":
        m = o3d.geometry.TriangleMesh.create_cylinder(radius=sx / 2, height=sz, resolution=12, split=1)
    elif shape == "sphere":
        m = o3d.geometry.TriangleMesh.create_sphere(radius=0.5, resolution=8)
        v = np.asarray(m.vertices) * np.array([sx, sy, sz])
        m.vertices = o3d.utility.Vector3dVector(v)
    else:
        return _box_mesh(o3d, box)
    return _place(m, box)


class LabRenderer:
    """Ray-casting scene of the lab in one :class:`SceneState`.

    Args:
        layout: the lab geometry.
        state: object placement and door states.
    """

    def __init__(self, layout: LabLayout, state: SceneState) -> None:
        from psg_data.open3d_import import import_open3d

        o3d = import_open3d()
        self._o3d = o3d
        self.layout = layout
        self.state = state
        self.scene = o3d.t.geometry.RaycastingScene()
        self._gid_to_iid: dict[int, int] = {}
        self._albedo: dict[int, NDArray[np.float64]] = {}
        x0 = min(np.asarray(r.floor_polygon_m)[:, 0].min() for r in layout.rooms) - 1.0
        x1 = max(np.asarray(r.floor_polygon_m)[:, 0].max() for r in layout.rooms) + 1.0
        y0 = min(np.asarray(r.floor_polygon_m)[:, 1].min() for r in layout.rooms) - 1.0
        y1 = max(np.asarray(r.floor_polygon_m)[:, 1].max() for r in layout.rooms) + 1.0
        self._add(ID_FLOOR, _box_mesh(o3d, Box(np.array([(x0 + x1) / 2, (y0 + y1) / 2, -0.05]),
                                               np.array([x1 - x0, y1 - y0, 0.1]))), _FLOOR_RGB[0])
        self._add(ID_CEILING, _box_mesh(o3d, Box(np.array([(x0 + x1) / 2, (y0 + y1) / 2, WALL_HEIGHT_M + 0.05]),
                                                 np.array([x1 - x0, y1 - y0, 0.1]))), _CEIL_RGB)
        for k, w in enumerate(layout.walls):
            self._add(WALL_ID0 + k, _box_mesh(o3d, w.box), _WALL_RGB)
        for i, d in enumerate(layout.doors):
            leaf = layout.door_leaf_box(i, state.doors_open.get(d.door_id, True))
            self._add(DOOR_ID0 + i, _box_mesh(o3d, leaf), _DOOR_RGB)
        for i, r in enumerate(layout.receptacles):
            self._add(RECEPTACLE_ID0 + i, _box_mesh(o3d, r.box), np.asarray(layout.receptacle_colors[i]))
        self.object_boxes = layout.object_boxes(state.objects)
        for j, o in enumerate(layout.objects):
            if o.name in self.object_boxes:
                self._add(OBJECT_ID0 + j, _object_mesh(o3d, o.shape, self.object_boxes[o.name]), np.asarray(o.color))
        n = max(self._gid_to_iid) + 1
        self._lut = np.zeros(n + 1, np.int32)
        for g, iid in self._gid_to_iid.items():
            self._lut[g] = iid
        self._albedo_lut = np.zeros((int(self._lut.max()) + 1, 3))
        for iid, c in self._albedo.items():
            self._albedo_lut[iid] = c

    def _add(self, iid: int, legacy_mesh: Any, rgb: NDArray[np.float64]) -> None:
        gid = self.scene.add_triangles(self._o3d.t.geometry.TriangleMesh.from_legacy(legacy_mesh))
        self._gid_to_iid[int(gid)] = iid
        self._albedo[iid] = np.asarray(rgb, float)

    def cast(self, origins: NDArray[np.float64], dirs: NDArray[np.float64]
             ) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.float32]]:
        """Cast rays; returns hit parameter t (inf = none), instance ids (0 = none), world normals."""
        o3c = self._o3d.core
        rays = np.concatenate([origins, dirs], axis=1).astype(np.float32)
        ans = self.scene.cast_rays(o3c.Tensor(rays))
        t = ans["t_hit"].numpy().astype(np.float64)
        gid = ans["geometry_ids"].numpy().astype(np.int64)
        hit = np.isfinite(t) & (gid < self._lut.size - 1)
        iid = np.where(hit, self._lut[np.where(hit, gid, self._lut.size - 1)], ID_NONE).astype(np.int32)
        t[~hit] = np.inf
        return t, iid, ans["primitive_normals"].numpy()

    def render(self, T_world_camera: NDArray[np.float64], camera: CameraIntrinsics, *,
               noise: DepthNoise | None = DepthNoise(), rng: np.random.Generator | None = None) -> RenderedFrame:
        """Render one frame from ``T_world_camera`` (camera-to-world, OpenCV axes).

        Args:
            T_world_camera: (4, 4) pose.
            camera: pinhole intrinsics (no distortion).
            noise: depth/colour noise model, or None for noise-free images.
            rng: random generator of the noise (default: seeded with 0).
        """
        rng = rng if rng is not None else np.random.default_rng(0)
        T = np.asarray(T_world_camera, float)
        H, W = camera.height, camera.width
        v, u = np.mgrid[0:H, 0:W]
        d_cam = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones_like(u, float)],
                         axis=-1).reshape(-1, 3)
        d_w = d_cam @ T[:3, :3].T
        o_w = np.broadcast_to(T[:3, 3], d_w.shape)
        t, iid, nrm = self.cast(o_w, d_w)
        hit = np.isfinite(t)
        z = np.where(hit, t, 0.0)
        pts = o_w + d_w * z[:, None]
        # colour
        alb = self._albedo_lut[iid]
        floor = iid == ID_FLOOR
        if floor.any():
            chk = (np.floor(pts[floor, 0] / 0.5) + np.floor(pts[floor, 1] / 0.5)).astype(int) % 2
            alb[floor] = np.where(chk[:, None] == 0, _FLOOR_RGB[0], _FLOOR_RGB[1])
        nrm64 = nrm.astype(np.float64)
        lam = np.abs(nrm64 @ _LIGHT)
        shade = (0.35 + 0.65 * lam) / (1.0 + 0.04 * z)
        col = alb * shade[:, None] * 255.0
        if noise is not None and noise.color_sigma > 0:
            col = col + rng.normal(0.0, noise.color_sigma, col.shape)
        col[~hit] = 0.0
        color = np.clip(np.rint(col), 0, 255).astype(np.uint8).reshape(H, W, 3)
        # depth
        zn = z.copy()
        if noise is not None:
            zn = z + rng.normal(0.0, 1.0, z.shape) * noise.sigma_m(z)
            ray_n = d_w / np.linalg.norm(d_w, axis=1, keepdims=True)
            cos = np.abs(np.sum(ray_n * nrm64, axis=1))
            bad = (z < noise.min_range_m) | (z > noise.max_range_m) | (rng.random(z.shape) < noise.dropout)
            bad |= (cos < noise.grazing_cos) & (rng.random(z.shape) < 0.5)
            zn[bad] = 0.0
        zn[~hit] = 0.0
        depth_mm = np.clip(np.rint(zn * 1000.0), 0, 65535).astype(np.uint16).reshape(H, W)
        return RenderedFrame(color, depth_mm, z.astype(np.float32).reshape(H, W), iid.reshape(H, W), T.copy(),
                             camera, nrm.reshape(H, W, 3))
