"""Converting an RTAB-Map database: one scan per session (``Node.map_id``), poses in one frame.

Poses, in order of preference (the choice is recorded per scan in the manifest):

1. ``optimized``: ``Admin.opt_poses``, the graph RTAB-Map optimised and saved on close;
2. ``pose_graph``: the pose graph (``Node.pose`` odometry and ``Link`` constraints) optimised here
   with Open3D's Levenberg-Marquardt, when the links connect every node with a pose;
3. ``odometry``: ``Node.pose`` as recorded, each session in its own odometry frame (a warning).

A node's camera-to-world pose is its base pose times the local transform of its calibration
(optical frame to base frame), so the axes come out as OpenCV's (x right, y down, z forward).
"""

from __future__ import annotations

from collections import Counter, defaultdict, deque
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.convert._config import ConvertConfig
from psg_data.convert._scan import ScanResult, ScanTask, _FrameWriter, _Payload, _ScanSink
from psg_data.errors import ConversionError
from psg_data.loaders.raw._rtabmap import (
    RtabCamera,
    RtabLink,
    RtabmapDatabase,
    RtabNode,
    decode_depth,
    parse_calibration,
)
from psg_data.schemas._records import CameraIntrinsics

__all__ = ["run_rtabmap", "resolve_poses", "optimize_pose_graph"]

_O3D_ORDER = [3, 4, 5, 0, 1, 2]
"""RTAB-Map information matrices are (x, y, z, roll, pitch, yaw); Open3D's are (rotation, translation)."""


def _spanning_poses(nodes: list[RtabNode], links: list[RtabLink]) -> dict[int, NDArray[np.float64]]:
    """Poses of the nodes reachable from the first one, composing link transforms breadth first
    (the initial guess of the optimisation: every session brought into the first one's frame).
    """
    adj: dict[int, list[tuple[int, NDArray[np.float64]]]] = defaultdict(list)
    for lk in links:
        adj[lk.from_id].append((lk.to_id, lk.transform))
        adj[lk.to_id].append((lk.from_id, np.asarray(np.linalg.inv(lk.transform), np.float64)))
    root = nodes[0]
    assert root.pose is not None
    poses = {root.id: root.pose}
    todo = deque([root.id])
    while todo:
        a = todo.popleft()
        for b, T in adj[a]:
            if b not in poses:
                poses[b] = poses[a] @ T
                todo.append(b)
    return poses


def optimize_pose_graph(nodes: list[RtabNode], links: list[RtabLink]) -> dict[int, NDArray[np.float64]] | None:
    """Base-to-world poses from the pose graph, in the frame of the first node's odometry; None
    when the links do not connect every node (the sessions cannot be put into one frame).

    Open3D's global optimisation (Levenberg-Marquardt), every link a certain edge, the first node
    fixed. RTAB-Map's link ``from -> to`` holds ``T_from^-1 T_to``: Open3D's edge from source
    ``to`` to target ``from`` with that transformation.
    """
    from psg_data.open3d_import import import_open3d

    posed = [n for n in nodes if n.pose is not None]
    init = _spanning_poses(posed, links)
    if any(n.id not in init for n in posed):  # init may hold nodes without a pose reached through links
        return None
    reg = import_open3d().pipelines.registration
    index = {n.id: k for k, n in enumerate(posed)}
    graph = reg.PoseGraph()
    for n in posed:
        graph.nodes.append(reg.PoseGraphNode(init[n.id]))
    for lk in links:
        if lk.from_id in index and lk.to_id in index:
            info = lk.information[np.ix_(_O3D_ORDER, _O3D_ORDER)]
            graph.edges.append(reg.PoseGraphEdge(index[lk.to_id], index[lk.from_id], lk.transform, info,
                                                 uncertain=False))
    option = reg.GlobalOptimizationOption(max_correspondence_distance=0.05, edge_prune_threshold=0.25,
                                          preference_loop_closure=1.0, reference_node=0)
    reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                            reg.GlobalOptimizationConvergenceCriteria(), option)
    return {n.id: np.asarray(graph.nodes[k].pose, dtype=np.float64) for n, k in zip(posed, range(len(posed)))}


def resolve_poses(db: RtabmapDatabase, nodes: list[RtabNode]) -> tuple[dict[int, NDArray[np.float64]], str, str]:
    """(base-to-world pose by node id, source, warning or "") -- see the module docstring."""
    opt = db.optimized_poses()
    if opt:
        missing = sum(1 for n in nodes if n.id not in opt)
        warn = (f"{db.where}: {missing} of {len(nodes)} nodes are not in Admin.opt_poses (not in the optimised "
                f"graph); they are skipped as no_pose") if missing else ""
        return opt, "optimized", warn
    links = db.links()
    sessions = len({n.map_id for n in nodes})
    if links and any(n.pose is not None for n in nodes):
        graph = optimize_pose_graph(nodes, links)
        if graph is not None:
            return graph, "pose_graph", ""
    odom = {n.id: n.pose for n in nodes if n.pose is not None}
    why = ("no links" if not links else "the links do not connect every node")
    warn = (f"{db.where}: no optimized poses (Admin.opt_poses empty) and {why}: poses are Node.pose odometry"
            + (f", each of the {sessions} sessions in its own frame" if sessions > 1 else "")
            + "; open and close the map in RTAB-Map to save its optimised graph")
    return odom, "odometry", warn


class _Cameras:
    """Parsed ``Data.calibration`` blobs (cached by content), checked to be one mono camera."""

    def __init__(self, version: tuple[int, ...]) -> None:
        self.version = version
        self.cache: dict[bytes, RtabCamera] = {}

    def get(self, blob: bytes | None, where: str) -> RtabCamera:
        if not blob:
            raise ConversionError(f"{where}: empty; expected the camera calibration of a node with images")
        cam = self.cache.get(blob)
        if cam is None:
            cams = parse_calibration(blob, self.version, where)
            if len(cams) != 1:
                raise ConversionError(f"{where}: {len(cams)} cameras (a multi-camera rig, images stored side by "
                                      f"side); expected one camera (multi-camera databases are not supported)")
            cam = self.cache[blob] = cams[0]
        return cam


def _intrinsics(cam: RtabCamera, camera_id: str, where: str) -> CameraIntrinsics:
    from psg_data.loaders.raw._folders import check_intrinsics

    fx, fy, cx, cy = check_intrinsics((cam.fx, cam.fy, cam.cx, cam.cy), cam.width, cam.height, where)
    d = cam.distortion
    coeffs: tuple[float, ...]
    if not any(d):
        model, coeffs = "none", ()
    elif len(d) in (4, 5, 8):
        model, coeffs = "plumb_bob", tuple(d)
    elif len(d) == 6:  # RTAB-Map's equidistant layout: k1, k2, p1, p2, k3, k4
        model, coeffs = "equidistant", (d[0], d[1], d[4], d[5])
    else:
        raise ConversionError(f"{where}: {len(d)} distortion coefficients; expected 4, 5, 6 or 8")
    return CameraIntrinsics(camera_id, cam.width, cam.height, fx, fy, cx, cy, model, coeffs, 0.001, None)


def _same_camera(a: CameraIntrinsics, b: CameraIntrinsics) -> bool:
    return (a.width, a.height, a.fx, a.fy, a.cx, a.cy, a.distortion_model, a.distortion_coeffs) == \
        (b.width, b.height, b.fx, b.fy, b.cx, b.cy, b.distortion_model, b.distortion_coeffs)


_HINTS = {
    "no_depth": "no node with a colour image has a depth image in Data.depth (a map saved without depth?)",
    "no_pose": "no node with images has a pose: not in Admin.opt_poses and no Node.pose to fall back on; open "
               "and close the map in RTAB-Map to save its optimised graph",
    "nonfinite_pose": "every node's pose (Admin.opt_poses or Node.pose, times the camera's local transform in "
                      "Data.calibration) has NaN or infinite values",
}
"""Why no frame was converted, in the database's terms (the recording hints name options of bags)."""


def run_rtabmap(task: ScanTask, cfg: ConvertConfig, progress: Callable[..., Any] | None, writer: Any
                ) -> list[ScanResult]:
    """Convert one RTAB-Map database into one scan per session (``{name}_{map_id:03d}`` when it
    holds several sessions, else ``{name}``), split further by ``split``.
    """
    with RtabmapDatabase(task.source) as db:
        nodes = db.nodes()
        if not nodes:
            raise ConversionError(f"{db.where}: Node: no nodes (an empty map); expected at least one node with "
                                  f"images")
        poses, source, warning = resolve_poses(db, nodes)
        sessions: dict[int, list[RtabNode]] = defaultdict(list)
        for n in nodes:
            sessions[n.map_id].append(n)
        fw = _FrameWriter(task.color_encoding, cfg.depth_scale_m or 0.001, db.where, cfg.image_check)
        sink = _ScanSink(task, cfg, writer, fw, ("Data.image", "Data.depth"), progress)
        sink.diagnosis["hints"] = _HINTS
        cams = _Cameras(db.version)
        cid = cfg.camera_id or task.camera_ids.get("") or "camera"
        labels: dict[str, dict[str, str]] = defaultdict(dict)
        sink.result_fields = lambda sid: {"pose_source": source, "node_labels": dict(labels.get(sid, {}))}
        if warning:
            sink.warnings.append(warning)  # reported with the first scan
        ran = False
        try:
            for map_id in sorted(sessions):
                members = sorted(sessions[map_id], key=lambda n: (n.stamp_ns, n.id))
                sid = task.scan_id if len(sessions) == 1 else f"{task.scan_id}_{map_id:03d}"
                if cfg.split is None and sid in task.skip_scans:
                    continue  # complete from an interrupted run (kept by the pipeline)
                sink._close_scan()  # with the session's own camera
                sink.task, sink.k, sink.last_stamp, sink.camera = replace(task, scan_id=sid), 0, None, None
                _convert_session(db, members, poses, sink, cams, cid, labels)
                ran = True
            sink.diagnosis.update(frame_span=sink.stamp_span)
            results = sink.finish(Counter()) if ran else []  # [] : every session was complete already
        except BaseException:
            sink.abort_scan()
            raise
    return results


def _convert_session(db: RtabmapDatabase, members: list[RtabNode], poses: dict[int, NDArray[np.float64]],
                     sink: _ScanSink, cams: _Cameras, cid: str, labels: dict[str, dict[str, str]]) -> None:
    """Write the frames of one session's nodes (in stamp order), counting nodes without images.

    Raises:
        ConversionError: two nodes with images share a stamp (a dataset's frames have distinct stamps).
    """
    prev: RtabNode | None = None
    for n in members:
        where = f"{db.where}: node {n.id}"
        image, depth, calib = db.node_data(n.id)
        if not image:
            sink.skipped["no_image"] += 1
            continue
        if not depth:
            sink.skipped["no_depth"] += 1
            continue
        cam = cams.get(calib, f"{where}: Data.calibration")
        intr = _intrinsics(cam, cid, f"{where}: Data.calibration")
        if sink.camera is None:
            sink.camera = intr
        elif not _same_camera(sink.camera, intr):
            raise ConversionError(f"{where}: Data.calibration: intrinsics differ from the session's first node "
                                  f"({intr.fx}, {intr.fy}, {intr.cx}, {intr.cy} vs {sink.camera.fx}, {sink.camera.fy}, "
                                  f"{sink.camera.cx}, {sink.camera.cy}); expected one camera per session")
        if prev is not None and n.stamp_ns == prev.stamp_ns:
            raise ConversionError(f"{where}: Node.stamp {n.stamp_ns / 1e9!r} s, the stamp of node {prev.id} too; "
                                  f"expected distinct stamps for the nodes with images of a session")
        prev = n
        base = poses.get(n.id)
        T = None if base is None else base @ cam.local
        arr = decode_depth(depth, f"{where}: Data.depth", (cam.width, cam.height))
        dp = _Payload("bytes", depth, "png", f"{where}: Data.depth") if arr is None else \
            _Payload("array", arr, "", f"{where}: Data.depth")
        cp = _Payload("bytes", image, "", f"{where}: Data.image")
        sink.frame(n.stamp_ns, T, cp, dp, len(image) + len(depth) + len(calib or b""))
        if n.label and sink.scan_id is not None:
            labels[sink.scan_id][str(n.stamp_ns)] = n.label
