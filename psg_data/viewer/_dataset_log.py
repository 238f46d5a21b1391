"""A dataset into a Rerun recording: frames, trajectory, point clouds, boxes by state, label streams.

Entities (world frame z up, metres) on two timelines: ``time`` (UTC timestamps) and ``scan`` (the
scan's index in the dataset, 0 for its first scan: one step per scan):

- ``world/rooms/ROOM``: floor outline (static).
- ``world/receptacles``, ``world/doors``: boxes logged at each scan's start, coloured by state
  (receptacle holding an object by the schedule: orange, empty: grey; door open: green, closed:
  red, unknown: grey), labelled with their ids.
- ``world/camera``: camera-to-world pose (``Transform3D``) and pinhole (intrinsics, OpenCV
  axes, drawn as a frustum) per frame; ``world/camera/rgb`` the stored colour image,
  ``world/camera/depth`` depth (``meter`` set, so it is shown in metres).
- ``world/trajectory``: the scan's camera positions as a line, at its start.
- ``world/points``: the scan's fused, coloured point cloud, at its end.
- ``labels/SOURCE/OBJECT/RECEPTACLE``: 1/0 observations of each object edge that is ever present
  (``gt``: from the schedule; every source of the ``labels`` table); ``labels/SOURCE/doors/DOOR``:
  1 open / 0 closed (``gt``: the ``door_states`` table). Drawn as steps: each value holds until the
  next observation (:func:`step_lines`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.viewer._recording import import_rerun

__all__ = ["TIMELINE", "SCAN_TIMELINE", "log_dataset", "edge_path", "timestamps", "step_lines"]

TIMELINE = "time"
"""The timeline every entity is logged on: UTC timestamps."""
SCAN_TIMELINE = "scan"
"""The sequence timeline of a dataset recording: the scan's index in the dataset (steps scan by scan)."""
_OCCUPIED, _EMPTY, _OPEN, _CLOSED = (255, 140, 0), (150, 150, 150), (40, 180, 60), (220, 40, 40)


def step_lines(rr: Any) -> Any:
    """How a 0/1 series is drawn: a step that holds each value until the next sample, then jumps
    (``SeriesLines`` ``interpolation_mode="StepAfter"``), not a straight line from one to the next.
    """
    return rr.SeriesLines(interpolation_mode="StepAfter")


def timestamps(t_s: Any) -> NDArray[np.datetime64]:
    """Seconds since the epoch (UTC) as ``datetime64[ns]`` for a Rerun time column."""
    return np.round(np.asarray(t_s, np.float64) * 1e9).astype("datetime64[ns]")


def edge_path(root: str, edge: Sequence[str]) -> str:
    import rerun as rr

    return "/".join([root, *(rr.escape_entity_path_part(str(p)) for p in edge)])


def log_dataset(rec: Any, ds: Any, scan_ids: Sequence[str] | None = None, *, frame_stride: int = 1,
                point_stride: int = 4, max_depth_m: float = 5.0,
                progress: Callable[..., Any] | None = None) -> dict[str, int]:
    """Log ``scan_ids`` (default: all) of dataset ``ds`` to the recording ``rec`` (see the module docstring).

    Args:
        rec: a ``rerun.RecordingStream``.
        ds: an open :class:`~psg_data.loaders.Dataset`.
        scan_ids: scans to log, default all.
        frame_stride: log every ``frame_stride``-th frame.
        point_stride: pixel step of the fused point cloud.
        max_depth_m: depth beyond this is left out of the point cloud, metres.
        progress: called as ``progress(1)`` per scan logged.

    Returns:
        Counts of what was logged: ``scans``, ``frames``, ``points``, ``label_streams``.

    Raises:
        KeyError: an unknown scan id.
    """
    rr = import_rerun()
    from psg_data.loaders._dataset import backproject

    scans = [ds.scan(s) for s in (ds.scan_ids if scan_ids is None else scan_ids)]
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for room in ds.rooms.values() if ds.has_table("rooms") else ():
        if room.floor_polygon_m is not None and len(room.floor_polygon_m):
            ring = np.vstack([room.floor_polygon_m, room.floor_polygon_m[:1]])
            rec.log(f"world/rooms/{rr.escape_entity_path_part(room.room_id)}",
                    rr.LineStrips3D([np.column_stack([ring, np.zeros(len(ring))])], labels=[room.name]), static=True)
    gt = _ground_truth(ds)
    doors = _door_states(ds)
    counts = {"scans": len(scans), "frames": 0, "points": 0, "label_streams": 0}
    number = {sid: k for k, sid in enumerate(ds.scan_ids)}
    counts["label_streams"] = _log_label_streams(rec, rr, ds, gt, doors)  # first: small, and plotted at once
    for scan in scans:
        rec.set_time(SCAN_TIMELINE, sequence=number[scan.scan_id])  # with every time stamp of the scan below
        _log_boxes(rec, rr, ds, scan, gt, doors)
        pts: list[NDArray[np.float64]] = []
        cols: list[NDArray[np.float64]] = []
        for i in range(0, len(scan), max(1, frame_stride)):
            fr = _log_frame(rec, rr, scan, i)
            p, c = backproject(fr, stride=point_stride, max_depth_m=max_depth_m)
            pts.append(p)
            cols.append(c)
            counts["frames"] += 1
        if len(scan):
            rec.log("world/trajectory", rr.LineStrips3D([scan.poses[:, :3, 3]], labels=[scan.scan_id]))
        if pts:
            rec.set_time(TIMELINE, timestamp=np.datetime64(scan.end_stamp_ns, "ns"))
            xyz = np.concatenate(pts)
            rec.log("world/points", rr.Points3D(xyz, colors=(np.concatenate(cols) * 255).astype(np.uint8),
                                                radii=0.01))
            counts["points"] += len(xyz)
        if progress is not None:
            progress(1)
    return counts


def _log_frame(rec: Any, rr: Any, scan: Any, i: int) -> Any:
    """Pose, pinhole, colour and depth of frame ``i`` at its stamp; returns the decoded frame."""
    fr = scan.frame(i)
    cbytes, _ = scan.image_bytes(i, depth=False)
    cam = fr.camera
    rec.set_time(TIMELINE, timestamp=np.datetime64(fr.stamp_ns, "ns"))
    T = fr.T_world_camera
    rec.log("world/camera", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]),
            rr.Pinhole(image_from_camera=cam.K, resolution=[cam.width, cam.height],
                       camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.3))
    media = "image/jpeg" if cbytes[:2] == b"\xff\xd8" else "image/png"
    rec.log("world/camera/rgb", rr.EncodedImage(contents=cbytes, media_type=media))
    raw = np.rint(fr.depth_m / np.float32(cam.depth_scale_m)).astype(np.uint16)  # the stored 16-bit values
    rec.log("world/camera/depth", rr.DepthImage(raw, meter=1.0 / cam.depth_scale_m))
    return fr


def _log_boxes(rec: Any, rr: Any, ds: Any, scan: Any, gt: Any, doors: dict[str, dict[str, str]]) -> None:
    from scipy.spatial.transform import Rotation

    rec.set_time(TIMELINE, timestamp=np.datetime64(scan.start_stamp_ns, "ns"))
    for path, items, colour in (
        ("world/receptacles", ds.receptacles if ds.has_table("receptacles") else {}, _receptacle_colours(gt, scan)),
        ("world/doors", ds.doors if ds.has_table("doors") else {}, _door_colours(doors.get(scan.scan_id, {}))),
    ):
        if not items:
            continue
        ids = list(items)
        boxes = [items[k].box for k in ids]
        quats = Rotation.from_matrix(np.stack([b.rotation for b in boxes])).as_quat()  # x, y, z, w
        rec.log(path, rr.Boxes3D(centers=[b.center_m for b in boxes], half_sizes=[b.extent_m / 2 for b in boxes],
                                 quaternions=[rr.Quaternion(xyzw=q) for q in quats], labels=ids,
                                 colors=[colour(k) for k in ids]))


def _receptacle_colours(gt: Any, scan: Any) -> Any:
    occupied: set[str] = set()
    if gt is not None and scan.scan_id in gt.scan_ids:
        s = gt.scan_ids.index(scan.scan_id)
        occupied = {gt.receptacle_ids[r] for r in np.flatnonzero((gt.codes[s] == 1).any(axis=0))}
    return lambda rid: _OCCUPIED if rid in occupied else _EMPTY


def _door_colours(states: dict[str, str]) -> Any:
    return lambda did: {"open": _OPEN, "closed": _CLOSED}.get(states.get(did, ""), _EMPTY)


def _ground_truth(ds: Any) -> Any:
    """The schedule's ground-truth label grid, or None for a dataset without a schedule (no table, or no
    rows: every converted recording), objects or receptacles.
    """
    if not all(ds.has_table(t) for t in ("schedule", "objects", "receptacles")) or not ds.table("schedule").num_rows:
        return None
    from psg_data.labeling import ground_truth

    return ground_truth(ds)


def _door_states(ds: Any) -> dict[str, dict[str, str]]:
    """``{scan_id: {door_id: state}}`` from the ``door_states`` table (empty without one)."""
    out: dict[str, dict[str, str]] = {}
    if ds.has_table("door_states"):
        for r in ds.table("door_states").to_pylist():
            out.setdefault(r["scan_id"], {})[r["door_id"]] = r["state"]
    return out


def _scan_numbers(ds: Any) -> Callable[[Any], NDArray[np.int64]]:
    """Times (ns) -> the index of the scan that started last at or before each (0 before the first)."""
    starts = np.array([ds.scan(s).start_stamp_ns for s in ds.scan_ids], dtype=np.int64)  # scan_ids: by start
    return lambda t_ns: np.clip(np.searchsorted(starts, np.asarray(t_ns, np.int64), side="right") - 1, 0, None)


def _log_label_streams(rec: Any, rr: Any, ds: Any, gt: Any, doors: dict[str, dict[str, str]]) -> int:
    from psg_data.labeling import grid_streams, load_label_streams

    scan_of = _scan_numbers(ds)

    streams: list[tuple[str, Any]] = [("gt", s) for s in (grid_streams(gt) if gt is not None else [])]
    if ds.has_table("labels"):
        for source in sorted(set(ds.table("labels").column("source").to_pylist())):
            streams += [(source, s) for s in load_label_streams(ds, source, doors=True)]
    door_ids = set(ds.doors) if ds.has_table("doors") else set()
    n = 0
    for source, s in streams:
        is_door = s.edge[0] in door_ids
        if (is_door and s.edge[1] != "open") or (not is_door and not (s.y == 1).any()):
            continue  # one stream per door (1 open); object edges that are ever present
        path = edge_path(f"labels/{rr.escape_entity_path_part(source)}",
                         ("doors", s.edge[0]) if is_door else s.edge)
        t = timestamps(s.t_s)
        rec.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, timestamp=t),
                                        rr.TimeColumn(SCAN_TIMELINE, sequence=scan_of(t.astype(np.int64)))],
                         columns=rr.Scalars.columns(scalars=s.y.astype(np.float64)))
        rec.log(path, step_lines(rr), static=True)
        n += 1
    starts = {sc: ds.scan(sc).start_stamp_ns for sc in doors if sc in set(ds.scan_ids)}
    for did in sorted({d for st in doors.values() for d in st}):
        rows = sorted((starts[sc], st[did] == "open") for sc, st in doors.items() if did in st and sc in starts)
        t = np.array([r[0] for r in rows], dtype="datetime64[ns]")
        rec.send_columns(edge_path("labels/gt", ("doors", did)),
                         indexes=[rr.TimeColumn(TIMELINE, timestamp=t),
                                  rr.TimeColumn(SCAN_TIMELINE, sequence=scan_of(t.astype(np.int64)))],
                         columns=rr.Scalars.columns(scalars=np.array([float(r[1]) for r in rows])))
        rec.log(edge_path("labels/gt", ("doors", did)), step_lines(rr), static=True)
        n += 1
    return n
