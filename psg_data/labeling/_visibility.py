"""Visibility of receptacle top surfaces (and optionally object boxes) per scan, from the measured depth.

Method (vectorised per frame): every receptacle's top face (box z = +extent_z / 2) is covered by a
grid of samples (``spacing_m`` cells, see :func:`~psg_data.labeling._geometry.top_face_samples`).
In each frame, with the frame's pose and the camera intrinsics (including distortion), a sample is
*seen* when all of these hold:

* it is in front of the camera within range: ``min_range_m < z < max_range_m`` (camera z);
* its face points towards the camera, at an incidence with ``|cos| >= min_cos`` (grazing views of a
  surface are unreliable; a top face is never seen from below);
* it projects inside the image (pixel centre rounded to the nearest pixel, ``border_px`` from the edge);
* that pixel has a valid measured depth ``d`` and ``|d - z_face| < tolerance(z_face)``, where
  ``z_face`` is the depth at which that pixel's ray meets the face's plane (exact for planar faces,
  so steep depth gradients across a pixel at grazing angles cost nothing), and
  ``tolerance(z) = tol_m + tol_n_sigma * tol_k_per_m * z**2``: a fixed margin plus ``n`` standard
  deviations of active-stereo depth noise, whose axial sigma grows with the square of the range
  (``k * z**2``, k = 0.004 /m for a RealSense D435 class sensor). Anything nearer than the face by
  more than the tolerance occludes the sample; missing depth (0) counts as not seen.

Per scan and surface: ``seen_fraction`` = fraction of the samples seen in at least one frame (union
over frames); ``pixels`` = the largest, over frames, estimated image area of the seen part of the
surface, in pixels (each seen sample contributes its cell's projected area
``area * fx * fy * |n . p| / z**3``, the Jacobian of the pinhole projection of a plane patch at
camera point ``p`` with normal ``n``); ``frames_seen`` = frames with at least one seen sample.
A receptacle is *visible* when ``seen_fraction >= min_fraction`` and ``pixels >= min_pixels``.

Objects: the format stores no object poses. Unless per-object boxes are given (``object_boxes``,
e.g. from a simulator or a detector), an object counts as visible in a scan when its ground-truth
receptacle is visible (the object stands on that receptacle's top surface). With boxes, the samples
of the object's top and four side faces are tested the same way with the object thresholds.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import LabelingError
from psg_data.labeling._geometry import (
    SurfaceSamples,
    box_surface_samples,
    pixel_rays,
    pixels_in_image,
    top_face_samples,
)
from psg_data.schemas._records import Box, CameraIntrinsics

__all__ = ["VisibilityParams", "SurfaceVisibility", "surface_visibility", "compute_visibility", "visibility_matrix"]

log = logging.getLogger(__name__)


def check_params(p: Any, what: str, *, positive: tuple[str, ...] = (), unit: tuple[str, ...] = (),
                 non_negative: tuple[str, ...] = ()) -> None:
    """Validate a thresholds dataclass: ``positive`` > 0, ``unit`` in [0, 1], ``non_negative`` >= 0,
    ``frame_stride`` >= 1. Raises :class:`LabelingError` naming ``what`` and the field.
    """
    checks = [(n, "> 0", lambda x: x > 0) for n in positive] + [(n, "in [0, 1]", lambda x: 0 <= x <= 1) for n in unit]
    checks += [(n, ">= 0", lambda x: x >= 0) for n in non_negative] + [("frame_stride", ">= 1", lambda x: x >= 1)]
    for name, expected, ok in checks:
        if not ok(getattr(p, name)):
            raise LabelingError(f"{what} parameter {name}: {getattr(p, name)}, expected {expected}")


def depth_tolerance_m(p: Any, z_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Depth tolerance ``tol_m + tol_n_sigma * tol_k_per_m * z**2`` at depth ``z_m`` (metres)."""
    return p.tol_m + p.tol_n_sigma * p.tol_k_per_m * np.asarray(z_m, float) ** 2


@dataclass(frozen=True)
class VisibilityParams:
    """Thresholds of the visibility test (see the module docstring).

    Attributes:
        spacing_m: sample grid cell size on receptacle top faces, metres.
        min_range_m: nearer samples are not seen (sensor minimum range), metres.
        max_range_m: farther samples are not seen, metres.
        tol_m: fixed depth tolerance, metres.
        tol_k_per_m: depth noise coefficient, sigma(z) = k * z**2 (metres, z in metres).
        tol_n_sigma: noise standard deviations added to the tolerance.
        min_cos: minimum |cos| of the angle between the viewing ray and the face normal.
        border_px: samples projecting within this many pixels of the image edge are not seen.
        min_fraction: receptacle visible if at least this fraction of its top face was seen ...
        min_pixels: ... and the seen part covered at least this many pixels in one frame.
        object_spacing_m: sample grid cell size on object boxes, metres.
        object_min_fraction: object visible if this fraction of its (top + side) samples was seen ...
        object_min_pixels: ... and at least this many pixels in one frame.
        frame_stride: use every ``frame_stride``-th frame.
    """

    spacing_m: float = 0.05
    min_range_m: float = 0.3
    max_range_m: float = 6.0
    tol_m: float = 0.03
    tol_k_per_m: float = 0.004
    tol_n_sigma: float = 3.0
    min_cos: float = 0.1
    border_px: int = 0
    min_fraction: float = 0.3
    min_pixels: float = 20.0
    object_spacing_m: float = 0.02
    object_min_fraction: float = 0.15
    object_min_pixels: float = 4.0
    frame_stride: int = 1

    def __post_init__(self) -> None:
        check_params(self, "visibility", positive=("spacing_m", "max_range_m", "object_spacing_m"),
                     unit=("min_fraction", "object_min_fraction", "min_cos"))

    def tolerance_m(self, z_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Depth tolerance at depth ``z_m``, metres."""
        return depth_tolerance_m(self, z_m)

    def to_dict(self) -> dict[str, Any]:
        """The settings as a dictionary (stored with the labels)."""
        return asdict(self)


@dataclass
class SurfaceVisibility:
    """Visibility of a set of surfaces (one entry per owner box) in one scan.

    Attributes:
        seen_fraction: (K,) fraction of samples seen in at least one frame.
        pixels: (K,) largest per-frame projected area of the seen samples, pixels.
        frames_seen: (K,) frames in which at least one sample was seen.
        seen: (N,) per-sample union over frames (order of the samples).
    """

    seen_fraction: NDArray[np.float64]
    pixels: NDArray[np.float64]
    frames_seen: NDArray[np.int64]
    seen: NDArray[np.bool_]


class SampleAccumulator:
    def __init__(self, samples: SurfaceSamples) -> None:
        self.s = samples
        self.seen = np.zeros(len(samples), bool)
        self.pixels = np.zeros(samples.n_owners)
        self.frames = np.zeros(samples.n_owners, np.int64)

    def add_frame(self, depth_m: NDArray[np.float32], cam: CameraIntrinsics, T_world_camera: NDArray[np.float64],
                  p: VisibilityParams) -> None:
        s = self.s
        if len(s) == 0:
            return
        pc, z, nc, ndotp, dist = self.to_camera(T_world_camera)
        cand = (z > p.min_range_m) & (z < p.max_range_m) & (ndotp < 0) & (-ndotp >= p.min_cos * dist)
        idx, ui, vi, nd = self.in_image(pc, nc, cand, depth_m.shape, cam, p.border_px)
        if idx.size == 0:
            return
        with np.errstate(divide="ignore", invalid="ignore"):
            z_face = ndotp[idx] / nd
        d = depth_m[vi, ui].astype(np.float64)
        ok = (d > 0) & np.isfinite(z_face) & (z_face > 0) & (np.abs(d - z_face) < p.tolerance_m(z_face))
        self.mark_seen(idx[ok], ndotp, z, cam)

    # -- shared by the door observation (psg_data.labeling._doors) ----------------------------
    def to_camera(self, T_world_camera: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """Samples in the camera frame: points, z, normals, n.p (negated plane distance), range."""
        R = T_world_camera[:3, :3]
        pc = (self.s.points - T_world_camera[:3, 3]) @ R
        nc = self.s.normals @ R
        return pc, pc[:, 2], nc, np.einsum("ij,ij->i", nc, pc), np.linalg.norm(pc, axis=1)

    @staticmethod
    def in_image(pc: NDArray[np.float64], nc: NDArray[np.float64], cand: NDArray[np.bool_], shape: tuple[int, ...],
                 cam: CameraIntrinsics, border_px: int) -> tuple[NDArray[Any], ...]:
        """Candidate samples that land in the image: indices, pixel column / row, n . ray of their pixel."""
        idx = np.flatnonzero(cand)
        if idx.size == 0:
            return idx, idx, idx, np.zeros(0)
        inside, ui, vi = pixels_in_image(pc[idx], cam, shape, border_px)
        idx = idx[inside]
        if idx.size == 0:
            return idx, ui, vi, np.zeros(0)
        ray = pixel_rays(np.column_stack([ui, vi]).astype(float), cam)
        return idx, ui, vi, np.einsum("ij,ij->i", nc[idx], ray)

    def mark_seen(self, hit: NDArray[np.int64], ndotp: NDArray[np.float64], z: NDArray[np.float64],
                  cam: CameraIntrinsics) -> None:
        """Record the samples seen in one frame: union, per-owner projected pixels (max), frames."""
        if hit.size == 0:
            return
        s = self.s
        self.seen[hit] = True
        area_px = s.area_m2[hit] * cam.fx * cam.fy * np.abs(ndotp[hit]) / z[hit] ** 3
        px = np.bincount(s.owner[hit], weights=area_px, minlength=s.n_owners)
        np.maximum(self.pixels, px, out=self.pixels)
        self.frames += np.bincount(s.owner[hit], minlength=s.n_owners) > 0

    def seen_fraction(self) -> NDArray[np.float64]:
        """Fraction of each owner's samples seen in at least one frame."""
        counts = np.maximum(self.s.counts, 1)
        return np.bincount(self.s.owner, weights=self.seen.astype(float), minlength=self.s.n_owners) / counts

    def result(self) -> SurfaceVisibility:
        return SurfaceVisibility(self.seen_fraction(), self.pixels.copy(), self.frames.copy(), self.seen.copy())


def surface_visibility(frames: Any, samples: SurfaceSamples, params: VisibilityParams | None = None
                       ) -> SurfaceVisibility:
    """Visibility of ``samples`` over an iterable of :class:`~psg_data.schemas.Frame` (depth needed)."""
    p = params or VisibilityParams()
    acc = SampleAccumulator(samples)
    for fr in frames:
        acc.add_frame(fr.depth_m, fr.camera, np.asarray(fr.T_world_camera, float), p)
    return acc.result()


def compute_visibility(ds: Any, params: VisibilityParams | None = None, *,
                       object_boxes: Mapping[str, Mapping[str, Box]] | None = None,
                       progress: Callable[..., Any] | None = None, timings: dict[str, float] | None = None) -> Any:
    """Visibility of every receptacle top surface (and, with ``object_boxes``, every object) per scan.

    Args:
        ds: an opened :class:`~psg_data.loaders.Dataset`.
        params: thresholds (default :class:`VisibilityParams`).
        object_boxes: optional ``scan_id -> {object_id: Box}`` world boxes of the objects present
            in each scan; without it no object rows are produced (see the module docstring).
        progress: called as ``progress(1)`` after each scan.
        timings: if given, seconds spent are added under ``visibility.read_depth`` and
            ``visibility.project``.

    Returns:
        an Arrow table with the ``visibility`` label-table schema, rows ordered by scan (start
        time), kind ('receptacle' then 'object') and id (table order).
    """
    import pyarrow as pa

    from psg_data.schemas._tables import TABLES

    p = params or VisibilityParams()
    rec_ids = list(ds.receptacles)
    rec_samples = top_face_samples([ds.receptacles[r].box for r in rec_ids], p.spacing_m)
    cols: dict[str, list[Any]] = {k: [] for k in TABLES["visibility"].schema.names}
    t_read = t_proj = 0.0
    for sid in ds.scan_ids:
        scan = ds.scan(sid)
        obj_ids: list[str] = []
        samples = rec_samples
        if object_boxes is not None:
            boxes = dict(object_boxes.get(sid, {}))
            unknown = sorted(set(boxes) - set(ds.objects))
            if unknown:
                raise LabelingError(f"object_boxes: scan {sid}: unknown object ids {unknown[:5]}, expected ids from "
                                    "tables/objects.parquet")
            obj_ids = [o for o in ds.objects if o in boxes]
            obj_samples = box_surface_samples([boxes[o] for o in obj_ids], p.object_spacing_m)
            samples = SurfaceSamples.concat([rec_samples, obj_samples])
        acc = SampleAccumulator(samples)
        it = scan.frames(color=False, stride=p.frame_stride)
        while True:
            t0 = time.perf_counter()
            fr = next(it, None)
            t1 = time.perf_counter()
            t_read += t1 - t0
            if fr is None:
                break
            acc.add_frame(fr.depth_m, fr.camera, np.asarray(fr.T_world_camera, float), p)
            t_proj += time.perf_counter() - t1
        res = acc.result()
        nr = len(rec_ids)
        for k, rid in enumerate(rec_ids):
            _append(cols, sid, "receptacle", rid, res, k, p.min_fraction, p.min_pixels)
        for j, oid in enumerate(obj_ids):
            _append(cols, sid, "object", oid, res, nr + j, p.object_min_fraction, p.object_min_pixels)
        if progress is not None:
            progress(1)
    if timings is not None:
        timings["visibility.read_depth"] = timings.get("visibility.read_depth", 0.0) + t_read
        timings["visibility.project"] = timings.get("visibility.project", 0.0) + t_proj
    schema = TABLES["visibility"].schema
    return pa.Table.from_pydict(cols, schema=schema).replace_schema_metadata(
        {**(schema.metadata or {}), b"psg_visibility_params": _json(p.to_dict())})


def _json(d: dict[str, Any]) -> bytes:
    import json

    return json.dumps(d, sort_keys=True).encode()


def _append(cols: dict[str, list[Any]], sid: str, kind: str, id_: str, res: SurfaceVisibility, k: int,
            min_fraction: float, min_pixels: float) -> None:
    frac, px = float(res.seen_fraction[k]), float(res.pixels[k])
    cols["scan_id"].append(sid)
    cols["kind"].append(kind)
    cols["id"].append(id_)
    cols["seen_fraction"].append(frac)
    cols["pixels"].append(px)
    cols["frames_seen"].append(int(res.frames_seen[k]))
    cols["visible"].append(bool(frac >= min_fraction and px >= min_pixels and px > 0))


def visibility_matrix(table: Any, scan_ids: list[str], ids: list[str], kind: str = "receptacle"
                      ) -> NDArray[np.bool_]:
    """(S, K) visible flags from a visibility table; pairs without a row are False."""
    out = np.zeros((len(scan_ids), len(ids)), bool)
    si = {s: i for i, s in enumerate(scan_ids)}
    ki = {k: i for i, k in enumerate(ids)}
    d = table.to_pydict()
    for s, kd, i, v in zip(d["scan_id"], d["kind"], d["id"], d["visible"]):
        if kd == kind and s in si and i in ki:
            out[si[s], ki[i]] = bool(v)
    return out
