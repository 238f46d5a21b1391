"""Door observation: per scan and door, whether the doorway was seen and whether it was open.

A door is a semi-static "object" whose "receptacles" are its states (the paper's footnote): its
label edges are ``(door_id, 'open')`` and ``(door_id, 'closed')``, with the object codes' semantics
(1 / 0 when the door was seen, -1 when not, never -2).

Doorway samples: the doorway is the door's oriented box (``doors`` table). Its *doorway plane* is
the box mid-plane across its thinnest axis (the wall normal); the plane is covered by a grid of
samples (``spacing_m`` cells) kept ``inset_m`` inside the doorway edges (the frame and the wall
edges are not part of the opening). The *doorway slab* is the box between its two faces across
that axis (the wall and the leaf lie in it).

Test (vectorised per frame, same camera model and depth tolerance as receptacle visibility,
:mod:`psg_data.labeling._visibility`): a sample projects to pixel ``(u, v)`` (in front of the
camera, within range, incidence ``|cos| >= min_cos``, inside the image); the pixel's ray enters
the doorway slab at depth ``z_near`` and leaves it at ``z_far`` (camera z, metres); with the
measured depth ``d`` (0 = invalid, not seen) and ``tol = tolerance(z_plane)``:

* ``d < z_near - tol``: something stands in front of the doorway - **occluded**, not seen;
* ``z_near - tol <= d <= z_far + tol``: the ray stops in the doorway - **blocked** (the leaf);
* ``d > z_far + tol``: the ray passes through the doorway - **free**.

A sample is *seen* when blocked or free. Per scan and door: ``seen_fraction`` (union over frames),
``pixels`` (largest per-frame projected area of the seen samples, as for receptacles),
``frames_seen``; the door is *visible* when ``seen_fraction >= min_fraction`` and ``pixels >=
min_pixels``; ``open_fraction`` = free votes / (free + blocked votes) over all frames, and the
observed state is 'open' when ``open_fraction >= open_threshold``, else 'closed' (only for
visible doors; otherwise unknown). In the synthetic lab the closed leaf fills the doorway and the
open leaf is swung against the wall, so the state read from the depth agrees with the schedule.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import LabelingError
from psg_data.labeling._codes import LabelGrid, inject_noise
from psg_data.labeling._geometry import SurfaceSamples
from psg_data.labeling._visibility import SampleAccumulator, check_params, depth_tolerance_m, visibility_matrix
from psg_data.schemas._records import Box
from psg_data.schemas._tables import CODE_ABSENT, CODE_MISSING, CODE_PRESENT

__all__ = ["DOOR_EDGE_STATES", "DoorParams", "DoorwaySamples", "DoorObservations", "doorway_samples",
           "observe_doors", "door_ground_truth", "door_label_grid", "door_visibility_from_table", "is_door_row"]

log = logging.getLogger(__name__)

DOOR_EDGE_STATES = ("open", "closed")
"""The two "receptacles" of a door edge, in label-grid order."""


@dataclass(frozen=True)
class DoorParams:
    """Thresholds of the door observation (module docstring).

    Attributes:
        spacing_m: sample grid cell size on the doorway plane, metres.
        inset_m: samples are kept this far inside the doorway edges, metres.
        min_range_m, max_range_m: samples nearer / farther than this (camera z) are not seen, metres.
        tol_m, tol_k_per_m, tol_n_sigma: depth tolerance ``tol_m + n * k * z**2`` (metres).
        min_cos: minimum |cos| between the viewing ray and the doorway normal.
        border_px: samples projecting within this many pixels of the image edge are not seen.
        min_fraction: door visible if at least this fraction of its samples was seen ...
        min_pixels: ... and the seen part covered at least this many pixels in one frame.
        open_threshold: observed 'open' when the free fraction of the seen votes reaches this.
        frame_stride: use every ``frame_stride``-th frame.
    """

    spacing_m: float = 0.05
    inset_m: float = 0.06
    min_range_m: float = 0.3
    max_range_m: float = 6.0
    tol_m: float = 0.03
    tol_k_per_m: float = 0.004
    tol_n_sigma: float = 3.0
    min_cos: float = 0.1
    border_px: int = 0
    min_fraction: float = 0.2
    min_pixels: float = 20.0
    open_threshold: float = 0.4
    frame_stride: int = 1

    def __post_init__(self) -> None:
        check_params(self, "door", positive=("spacing_m", "max_range_m"),
                     unit=("min_fraction", "min_cos", "open_threshold"), non_negative=("inset_m",))

    def tolerance_m(self, z_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Depth tolerance at depth ``z_m``, metres."""
        return depth_tolerance_m(self, z_m)

    def to_dict(self) -> dict[str, Any]:
        """The settings as a dictionary (stored with the labels)."""
        return asdict(self)


class DoorwaySamples(SurfaceSamples):
    """Samples on the doorway planes of a list of doors (:class:`SurfaceSamples` plus slab thickness).

    Attributes:
        points: (N, 3) world points on the mid-planes, metres.
        normals: (N, 3) unit plane normals (world frame; sign arbitrary).
        half_thickness_m: (N,) half thickness of the sample's doorway slab, metres.
        area_m2: (N,) area each sample stands for, square metres.
        owner: (N,) door index.
        n_owners: number of doors.
    """

    def __init__(self, points: NDArray[np.float64], normals: NDArray[np.float64], half_thickness_m: NDArray[np.float64],
                 area_m2: NDArray[np.float64], owner: NDArray[np.int64], n_owners: int) -> None:
        super().__init__(points, normals, area_m2, owner, n_owners)
        self.half_thickness_m = half_thickness_m


def doorway_samples(boxes: list[Box], spacing_m: float = 0.05, inset_m: float = 0.06,
                    max_per_axis: int = 60) -> DoorwaySamples:
    """Grid samples on each doorway box's mid-plane across its thinnest axis (cell centres).

    Args:
        boxes: doorway boxes (world frame).
        spacing_m: target cell size, metres.
        inset_m: margin left free at the doorway edges, metres (halved if the opening is too small).
        max_per_axis: cap on samples per axis.
    """
    pts, nrm, half, area, own = [], [], [], [], []
    for k, b in enumerate(boxes):
        e = np.asarray(b.extent_m, float)
        R = np.asarray(b.rotation, float)
        a = int(np.argmin(e))
        u_ax, v_ax = [i for i in range(3) if i != a]
        lens = []
        for ax in (u_ax, v_ax):
            inset = inset_m if e[ax] > 4 * inset_m else e[ax] / 4
            lens.append(e[ax] - 2 * inset)
        nu = int(np.clip(np.ceil(lens[0] / spacing_m - 1e-9), 2, max_per_axis))
        nv = int(np.clip(np.ceil(lens[1] / spacing_m - 1e-9), 2, max_per_axis))
        gu = (np.arange(nu) + 0.5) / nu - 0.5
        gv = (np.arange(nv) + 0.5) / nv - 0.5
        U, V = np.meshgrid(gu * lens[0], gv * lens[1], indexing="ij")
        local = np.zeros((nu * nv, 3))
        local[:, u_ax] = U.ravel()
        local[:, v_ax] = V.ravel()
        pts.append(local @ R.T + np.asarray(b.center_m, float))
        nrm.append(np.repeat(R[:, a][None, :], nu * nv, axis=0))
        half.append(np.full(nu * nv, e[a] / 2))
        area.append(np.full(nu * nv, lens[0] * lens[1] / (nu * nv)))
        own.append(np.full(nu * nv, k, np.int64))
    if not boxes:
        z = np.zeros((0, 3))
        return DoorwaySamples(z, z.copy(), np.zeros(0), np.zeros(0), np.zeros(0, np.int64), 0)
    return DoorwaySamples(np.concatenate(pts), np.concatenate(nrm), np.concatenate(half), np.concatenate(area),
                          np.concatenate(own), len(boxes))


@dataclass
class DoorObservations:
    """What each scan saw of every door.

    Attributes:
        scan_ids: (S,) scans, chronological.
        door_ids: (D,) doors (table order).
        stamps_ns: (S,) scan start stamps, int64 UTC nanoseconds.
        seen_fraction: (S, D) fraction of the doorway samples seen in at least one frame.
        pixels: (S, D) largest per-frame projected area of the seen samples, pixels.
        frames_seen: (S, D) frames with at least one seen sample.
        visible: (S, D) the door counts as seen.
        open_fraction: (S, D) free votes / seen votes (NaN without votes).
        params: the parameters used.
    """

    scan_ids: list[str]
    door_ids: list[str]
    stamps_ns: NDArray[np.int64]
    seen_fraction: NDArray[np.float64]
    pixels: NDArray[np.float64]
    frames_seen: NDArray[np.int64]
    visible: NDArray[np.bool_]
    open_fraction: NDArray[np.float64]
    params: DoorParams = field(default_factory=DoorParams)

    @property
    def observed_open(self) -> NDArray[np.int8]:
        """(S, D) observed state: 1 open, 0 closed, -1 not seen."""
        out = np.full(self.visible.shape, CODE_MISSING, np.int8)
        with np.errstate(invalid="ignore"):
            is_open = self.open_fraction >= self.params.open_threshold
        out[self.visible & is_open] = 1
        out[self.visible & ~is_open] = 0
        return out

    def visibility_table(self) -> Any:
        """Rows of kind 'door' with the ``visibility`` label-table schema (scan order, door order)."""
        import pyarrow as pa

        from psg_data.schemas._tables import TABLES

        S, D = self.visible.shape
        si, di = (a.ravel() for a in np.meshgrid(np.arange(S), np.arange(D), indexing="ij"))
        cols = {
            "scan_id": [self.scan_ids[i] for i in si], "kind": ["door"] * (S * D),
            "id": [self.door_ids[j] for j in di],
            "seen_fraction": self.seen_fraction[si, di].astype(float).tolist(),
            "pixels": self.pixels[si, di].astype(float).tolist(),
            "frames_seen": self.frames_seen[si, di].astype(np.int32).tolist(),
            "visible": self.visible[si, di].astype(bool).tolist(),
        }
        return pa.Table.from_pydict(cols, schema=TABLES["visibility"].schema)


class _DoorAccumulator(SampleAccumulator):
    """Door samples: the visibility bookkeeping of :class:`SampleAccumulator` plus free / blocked votes."""

    def __init__(self, s: DoorwaySamples) -> None:
        super().__init__(s)
        self.s: DoorwaySamples = s
        self.free_votes = np.zeros(s.n_owners)
        self.blocked_votes = np.zeros(s.n_owners)

    def add_frame(self, depth_m: NDArray[np.float32], cam: Any, T: NDArray[np.float64],  # type: ignore[override]
                  p: DoorParams) -> None:
        s = self.s
        if len(s) == 0:
            return
        pc, z, nc, ndotp, dist = self.to_camera(T)  # ndotp: signed distance of the camera to the plane, negated
        # camera outside the slab (farther from the mid-plane than its half thickness), sample in front
        cand = ((z > p.min_range_m) & (z < p.max_range_m) & (np.abs(ndotp) > s.half_thickness_m)
                & (np.abs(ndotp) >= p.min_cos * dist))
        idx, ui, vi, nd = self.in_image(pc, nc, cand, depth_m.shape, cam, p.border_px)
        if idx.size == 0:
            return
        h = s.half_thickness_m[idx]
        with np.errstate(divide="ignore", invalid="ignore"):
            z_plane = ndotp[idx] / nd
            za = (ndotp[idx] - h) / nd
            zb = (ndotp[idx] + h) / nd
        z_near, z_far = np.minimum(za, zb), np.maximum(za, zb)
        d = depth_m[vi, ui].astype(np.float64)
        ok = (d > 0) & np.isfinite(z_plane) & (z_near > 0)
        tol = p.tolerance_m(np.where(np.isfinite(z_plane), z_plane, 0.0))
        seen = ok & (d >= z_near - tol)
        free = seen & (d > z_far + tol)
        blocked = seen & ~free
        self.mark_seen(idx[seen], ndotp, z, cam)
        self.free_votes += np.bincount(s.owner[idx[free]], minlength=s.n_owners)
        self.blocked_votes += np.bincount(s.owner[idx[blocked]], minlength=s.n_owners)

    def door_result(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
        votes = self.free_votes + self.blocked_votes
        with np.errstate(invalid="ignore", divide="ignore"):
            of = np.where(votes > 0, self.free_votes / np.maximum(votes, 1), np.nan)
        return self.seen_fraction(), self.pixels.copy(), self.frames.copy(), of


def observe_doors(ds: Any, params: DoorParams | None = None, *, progress: Callable[..., Any] | None = None,
                  frames: Callable[[str], Any] | None = None) -> DoorObservations:
    """Door visibility and observed state per scan from the depth images (module docstring).

    Args:
        ds: an opened :class:`~psg_data.loaders.Dataset` with a ``doors`` table.
        params: thresholds (default :class:`DoorParams`).
        progress: called as ``progress(1)`` after each scan.
        frames: optional ``scan_id -> iterable of Frame`` (default: the scan's depth frames).

    Raises:
        LabelingError: the dataset has no doors.
    """
    p = params or DoorParams()
    door_ids = list(ds.doors)
    if not door_ids:
        raise LabelingError(f"{ds.root}/tables/doors.parquet: no doors to observe")
    samples = doorway_samples([ds.doors[d].box for d in door_ids], p.spacing_m, p.inset_m)
    scan_ids = list(ds.scan_ids)
    S, D = len(scan_ids), len(door_ids)
    frac, px, fs, of = np.zeros((S, D)), np.zeros((S, D)), np.zeros((S, D), np.int64), np.full((S, D), np.nan)
    stamps = np.zeros(S, np.int64)
    for i, sid in enumerate(scan_ids):
        scan = ds.scan(sid)
        stamps[i] = scan.start_stamp_ns
        acc = _DoorAccumulator(samples)
        it = frames(sid) if frames is not None else scan.frames(color=False, stride=p.frame_stride)
        for fr in it:
            acc.add_frame(fr.depth_m, fr.camera, np.asarray(fr.T_world_camera, float), p)
        frac[i], px[i], fs[i], of[i] = acc.door_result()
        if progress is not None:
            progress(1)
    visible = (frac >= p.min_fraction) & (px >= p.min_pixels) & (px > 0) & np.isfinite(of)
    return DoorObservations(scan_ids, door_ids, stamps, frac, px, fs, visible, of, p)


def door_visibility_from_table(table: Any, scan_ids: list[str], door_ids: list[str]) -> NDArray[np.bool_] | None:
    """(S, D) visible flags of the doors from a ``visibility`` table; None if it has no door rows."""
    if "door" not in set(table.column("kind").to_pylist()):
        return None
    return visibility_matrix(table, scan_ids, door_ids, kind="door")


# -- label grids ----------------------------------------------------------------------------------
def _grid_from_open(scan_ids: list[str], door_ids: list[str], stamps: NDArray[np.int64], is_open: NDArray[np.int8],
                    source: str, meta: dict[str, Any] | None = None) -> LabelGrid:
    """Door label grid (S, D, 2) from (S, D) codes of the open state (1 open, 0 closed, -1 unknown)."""
    codes = np.full((len(scan_ids), len(door_ids), 2), CODE_MISSING, np.int8)
    o = np.asarray(is_open, np.int8)
    codes[..., 0] = np.where(o == 1, CODE_PRESENT, np.where(o == 0, CODE_ABSENT, CODE_MISSING))
    codes[..., 1] = np.where(o == 1, CODE_ABSENT, np.where(o == 0, CODE_PRESENT, CODE_MISSING))
    return LabelGrid(list(scan_ids), list(door_ids), list(DOOR_EDGE_STATES), np.asarray(stamps, np.int64), codes,
                     source, dict(meta or {}))


def door_ground_truth(ds: Any) -> LabelGrid:
    """Ground-truth door label grid from the ``door_states`` table (state 'unknown' or no row: -1).

    Raises:
        LabelingError: no doors or no door_states table.
    """
    door_ids = list(ds.doors)
    if not door_ids:
        raise LabelingError(f"{ds.root}/tables/doors.parquet: no doors")
    if not ds.has_table("door_states"):
        raise LabelingError(f"{ds.root}/tables/door_states.parquet: missing; door ground truth needs it")
    scan_ids = list(ds.scan_ids)
    stamps = np.array([ds.scan(s).start_stamp_ns for s in scan_ids], np.int64)
    si = {s: i for i, s in enumerate(scan_ids)}
    di = {d: i for i, d in enumerate(door_ids)}
    is_open = np.full((len(scan_ids), len(door_ids)), CODE_MISSING, np.int8)
    t = ds.table("door_states").to_pydict()
    for s, d, st in zip(t["scan_id"], t["door_id"], t["state"]):
        if s in si and d in di and st in DOOR_EDGE_STATES:
            is_open[si[s], di[d]] = 1 if st == "open" else 0
    return _grid_from_open(scan_ids, door_ids, stamps, is_open, "gt")


def door_label_grid(ds: Any, kind: str, *, source: str | None = None, visible: NDArray[np.bool_] | None = None,
                    observations: DoorObservations | None = None, p_m: float = 0.0, p_f: float = 0.0,
                    seed: int = 0) -> LabelGrid:
    """Door label grid of one source kind.

    Args:
        ds: the dataset.
        kind: ``gt`` (door_states), ``privileged`` (gt where the door was visible), ``noisy``
            (privileged with the open-state code flipped 1 -> 0 with ``p_m`` and 0 -> 1 with
            ``p_f``; the closed edge is its complement) or ``observed`` (state read from the depth).
        source: value of the ``source`` column (default: ``kind``).
        visible: (S, D) door visibility (privileged / noisy; default from ``observations``).
        observations: door observations (``observed``; or to get ``visible``).
        p_m: P(observed closed | open) of the ``noisy`` kind.
        p_f: P(observed open | closed) of the ``noisy`` kind.
        seed: seed of that noise.

    Raises:
        LabelingError: unknown kind or missing inputs.
    """
    name = source or kind
    if kind == "observed":
        if observations is None:
            raise LabelingError("door labels 'observed': door observations are needed")
        return _grid_from_open(observations.scan_ids, observations.door_ids, observations.stamps_ns,
                               observations.observed_open, name, {"door_params": observations.params.to_dict()})
    gt = door_ground_truth(ds)
    if kind == "gt":
        return gt.with_codes(gt.codes, name)
    if kind not in ("privileged", "noisy"):
        raise LabelingError(f"door labels: unknown source kind {kind!r}, expected gt, privileged, noisy or observed")
    if visible is None:
        if observations is None:
            raise LabelingError(f"door labels {kind!r}: door visibility is needed")
        visible = observations.visible
    vis = np.asarray(visible, bool)
    if vis.shape != (len(gt.scan_ids), len(gt.object_ids)):
        raise LabelingError(f"door visibility: shape {vis.shape}, expected {(len(gt.scan_ids), len(gt.object_ids))}")
    privileged = _grid_from_open(gt.scan_ids, gt.object_ids, gt.stamps_ns,
                                 np.where(vis, _open_state(gt.codes[..., 0]), -1), name)
    if kind == "privileged":
        return privileged
    # noise on the 'open' edge only (as object codes are flipped); the 'closed' edge stays its complement
    open_edge = LabelGrid(privileged.scan_ids, privileged.object_ids, ["open"], privileged.stamps_ns,
                          privileged.codes[..., :1], "privileged")
    noisy = inject_noise(open_edge, p_m, p_f, seed, source=name)
    return _grid_from_open(gt.scan_ids, gt.object_ids, gt.stamps_ns, _open_state(noisy.codes[..., 0]), name,
                           noisy.meta)


def _open_state(open_codes: NDArray[np.int8]) -> NDArray[np.int8]:
    """Codes of the 'open' edge as a door state: 1 open, 0 closed, -1 unknown."""
    return np.where(open_codes == CODE_PRESENT, 1, np.where(open_codes == CODE_ABSENT, 0, -1)).astype(np.int8)


def is_door_row(object_ids: list[str], receptacle_ids: list[str], door_ids: set[str]) -> NDArray[np.bool_]:
    """(N,) label rows that are door-state edges (object_id a door, receptacle_id 'open' / 'closed')."""
    return np.array([o in door_ids and r in DOOR_EDGE_STATES for o, r in zip(object_ids, receptacle_ids)], bool)
