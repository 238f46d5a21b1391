"""Export a canonical psg-dataset as raw robot recordings (one ROS 1 / ROS 2 bag per scan).

The recordings look like what ``realsense2_camera`` + RTAB-Map record (see docs/RAW_FORMATS.md):

=================================================================  ================================
topic                                                              type
=================================================================  ================================
/camera/color/image_raw                                            sensor_msgs/Image (rgb8)
/camera/color/image_raw/compressed                                 sensor_msgs/CompressedImage (jpeg)
/camera/aligned_depth_to_color/image_raw                           sensor_msgs/Image (16UC1, mm)
/camera/aligned_depth_to_color/image_raw/compressedDepth           sensor_msgs/CompressedImage
/camera/color/camera_info                                          sensor_msgs/CameraInfo
/tf                                                                tf2_msgs/TFMessage (map->odom, odom->base_link)
/tf_static                                                         tf2_msgs/TFMessage (base_link->camera_link->optical)
/rtabmap/odom                                                      nav_msgs/Odometry (odom->base_link)
=================================================================  ================================

``header.stamp`` is the frame stamp; the bag log time is 5-30 ms later (as when recording live).
Side files (``site.json``, ``door_states.csv``, ``schedule.csv``, ``scans.csv``) go beside the
recordings; :func:`psg_data.convert.convert` turns the directory back into the dataset.
"""

from __future__ import annotations

import csv
import heapq
import json
import logging
import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import FormatError
from psg_data.loaders._checks import check_image_header
from psg_data.loaders.raw._images import make_compressed_depth
from psg_data.loaders.raw._transforms import invert, make_transform, matrix_to_quat_xyzw
from psg_data.schemas._records import CameraIntrinsics
from psg_data.writers._safe_output import check_output, commit_tree, make_staging

__all__ = ["export_raw", "RAW_EXPORT_FORMATS", "TOPICS", "STATIC_BASE_CAMERA_LINK", "R_CAMERA_LINK_OPTICAL"]

log = logging.getLogger(__name__)

RAW_EXPORT_FORMATS = ("ros1", "ros2-sqlite3", "ros2-mcap")

TOPICS = {
    "color": "/camera/color/image_raw",
    "color_compressed": "/camera/color/image_raw/compressed",
    "depth": "/camera/aligned_depth_to_color/image_raw",
    "depth_compressed": "/camera/aligned_depth_to_color/image_raw/compressedDepth",
    "camera_info": "/camera/color/camera_info",
    "tf": "/tf",
    "tf_static": "/tf_static",
    "odom": "/rtabmap/odom",
}
"""Topic names written by :func:`export_raw`."""

STATIC_BASE_CAMERA_LINK = make_transform([0.12, 0.0, 0.35], [0.0, 0.0, 0.0, 1.0])
"""T_base_link_camera_link written to /tf_static."""
R_CAMERA_LINK_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Rotation camera_link (x forward, z up) <- optical frame (z forward, y down)."""

DEFAULT_OPTICAL_FRAME = "camera_color_optical_frame"
JPEG_QUALITY = 95
PNG_LEVEL = 1


def _map_odom(dt_s: float) -> NDArray[np.float64]:
    """A slowly drifting map->odom correction (what RTAB-Map publishes), as a function of time."""
    yaw = 0.02 * math.sin(0.3 * dt_s)
    return make_transform([0.05 * math.sin(0.2 * dt_s), 0.03 * (math.cos(0.1 * dt_s) - 1.0), 0.0],
                          [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])


class _Msgs:
    """Builds ROS 1 or ROS 2 messages with a rosbags typestore."""

    def __init__(self, ros1: bool) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in self.ts.types:  # not in rosbags' ROS 1 store
            from rosbags.typesys import get_types_from_msg

            self.ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                "tf2_msgs/msg/TFMessage"))
        self.T = self.ts.types
        self._seq = 0

    def serialize(self, msg: Any) -> bytes:
        if self.ros1:
            return bytes(self.ts.serialize_ros1(msg, msg.__msgtype__))
        return bytes(self.ts.serialize_cdr(msg, msg.__msgtype__))

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        t = self.T["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000),
                                                  nanosec=int(stamp_ns % 1_000_000_000))
        H = self.T["std_msgs/msg/Header"]
        if self.ros1:
            self._seq += 1
            return H(seq=self._seq, stamp=t, frame_id=frame_id)
        return H(stamp=t, frame_id=frame_id)

    def image(self, stamp_ns: int, frame_id: str, arr: NDArray[Any], encoding: str) -> Any:
        h, w = arr.shape[:2]
        data = np.ascontiguousarray(arr).view(np.uint8).reshape(-1)
        return self.T["sensor_msgs/msg/Image"](
            header=self.header(stamp_ns, frame_id), height=h, width=w, encoding=encoding, is_bigendian=0,
            step=data.size // h, data=data)

    def compressed(self, stamp_ns: int, frame_id: str, fmt: str, payload: bytes) -> Any:
        return self.T["sensor_msgs/msg/CompressedImage"](
            header=self.header(stamp_ns, frame_id), format=fmt, data=np.frombuffer(payload, np.uint8))

    def camera_info(self, stamp_ns: int, frame_id: str, cam: Any) -> Any:
        K = np.array([cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1], float)
        P = np.array([cam.fx, 0, cam.cx, 0, 0, cam.fy, cam.cy, 0, 0, 0, 1, 0], float)
        R = np.eye(3).reshape(9)
        if cam.distortion_model == "none":
            model, D = "plumb_bob", np.zeros(5)
        else:
            model, D = cam.distortion_model, np.asarray(cam.distortion_coeffs, float)
        roi = self.T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        kw = {"D": D, "K": K, "R": R, "P": P} if self.ros1 else {"d": D, "k": K, "r": R, "p": P}
        return self.T["sensor_msgs/msg/CameraInfo"](
            header=self.header(stamp_ns, frame_id), height=cam.height, width=cam.width, distortion_model=model,
            binning_x=0, binning_y=0, roi=roi, **kw)

    def _tf(self, stamp_ns: int, parent: str, child: str, T: NDArray[np.float64]) -> Any:
        q = matrix_to_quat_xyzw(T[:3, :3])
        tr = self.T["geometry_msgs/msg/Transform"](
            translation=self.T["geometry_msgs/msg/Vector3"](x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
            rotation=self.T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))
        return self.T["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp_ns, parent), child_frame_id=child, transform=tr)

    def tf_message(self, stamp_ns: int, edges: list[tuple[str, str, NDArray[np.float64]]]) -> Any:
        return self.T["tf2_msgs/msg/TFMessage"](transforms=[self._tf(stamp_ns, p, c, T) for p, c, T in edges])

    def odometry(self, stamp_ns: int, T_odom_base: NDArray[np.float64]) -> Any:
        q = matrix_to_quat_xyzw(T_odom_base[:3, :3])
        G = self.T
        pose = G["geometry_msgs/msg/Pose"](
            position=G["geometry_msgs/msg/Point"](x=float(T_odom_base[0, 3]), y=float(T_odom_base[1, 3]),
                                                 z=float(T_odom_base[2, 3])),
            orientation=G["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))
        cov = np.zeros(36)
        zero = G["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return G["nav_msgs/msg/Odometry"](
            header=self.header(stamp_ns, "odom"), child_frame_id="base_link",
            pose=G["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            twist=G["geometry_msgs/msg/TwistWithCovariance"](
                twist=G["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov))


class _BagWriter:
    """One recording: rosbags writer + connections, messages written in log-time order."""

    def __init__(self, path: Path, fmt: str, msgs: _Msgs) -> None:
        self.msgs = msgs
        self.fmt = fmt
        if fmt == "ros1":
            from rosbags.rosbag1 import Writer as W1

            self.w: Any = W1(path)
        else:
            from rosbags.rosbag2 import StoragePlugin
            from rosbags.rosbag2 import Writer as W2

            plugin = StoragePlugin.MCAP if fmt == "ros2-mcap" else StoragePlugin.SQLITE3
            self.w = W2(path, version=8, storage_plugin=plugin)
        self.w.open()
        self.conns: dict[str, Any] = {}
        self.heap: list[tuple[int, int, str, bytes]] = []
        self.seq = 0
        self.last_log: dict[str, int] = {}

    def connection(self, topic: str, msgtype: str, latching: bool = False) -> None:
        if self.fmt == "ros1":
            self.conns[topic] = self.w.add_connection(topic, msgtype, typestore=self.msgs.ts,
                                                      latching=1 if latching else None)
        else:
            self.conns[topic] = self.w.add_connection(topic, msgtype, typestore=self.msgs.ts)

    def push(self, topic: str, log_ns: int, msg: Any) -> int:
        log_ns = max(int(log_ns), self.last_log.get(topic, -1) + 1)
        self.last_log[topic] = log_ns
        data = self.msgs.serialize(msg)
        heapq.heappush(self.heap, (log_ns, self.seq, topic, data))
        self.seq += 1
        return len(data)

    def flush(self, before_ns: int | None = None) -> None:
        while self.heap and (before_ns is None or self.heap[0][0] < before_ns):
            log_ns, _, topic, data = heapq.heappop(self.heap)
            self.w.write(self.conns[topic], log_ns, data)

    def close(self) -> None:
        self.flush()
        self.w.close()


def _operating_hours(extra: dict[str, Any]) -> dict[str, str]:
    """``{"operating_hours": "09:00-17:00"}`` of a synthetic lab (its first scan hour to the end of its last
    step, as it is scored), so that the dataset converted from its recordings is scored on the same hours;
    ``{}`` for other datasets.
    """
    if extra.get("generator") != "psg_data.synth":
        return {}
    hours = sorted(float(h) for h in (extra.get("scan_hours") or [9, 11, 13, 15]))
    step = float(np.median(np.diff(hours))) if len(hours) > 1 else 2.0
    hhmm = lambda h: f"{int(h):02d}:{int(round(60 * (h - int(h)))):02d}"  # noqa: E731
    return {"operating_hours": f"{hhmm(hours[0])}-{hhmm(min(24.0, hours[-1] + step))}"}


def _write_side_files(ds: Any, out: Path, recordings: dict[str, str], optical: dict[str, str]) -> None:
    def rows(name: str) -> list[dict[str, Any]]:
        return ds.table(name).to_pylist() if ds.has_table(name) else []

    site = {
        "name": ds.info.name,
        "timezone": ds.info.timezone,
        **_operating_hours(dict(ds.info.extra)),
        "cameras": [{"camera_id": cid, "frame_id": fid} for cid, fid in sorted(optical.items())],
        "rooms": rows("rooms"),
        "receptacles": rows("receptacles"),
        "doors": rows("doors"),
        **({"openings": rows("openings")} if ds.has_table("openings") else {}),
        "objects": rows("objects"),
    }
    (out / "site.json").write_text(json.dumps(site, indent=1) + "\n", encoding="utf-8")
    for name, cols in (("door_states", ("scan_id", "door_id", "state")),
                       ("schedule", ("scan_id", "object_id", "receptacle_id"))):
        with open(out / f"{name}.csv", "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            for r in rows(name):
                w.writerow(["" if r[c] is None else r[c] for c in cols])
    with open(out / "scans.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(("scan_id", "recording", "split"))
        for r in rows("scans"):
            w.writerow((r["scan_id"], recordings[r["scan_id"]], r["split"] or ""))


def export_raw(
    dataset_path: str | Path,
    out: str | Path,
    fmt: str,
    *,
    overwrite: bool = False,
    progress: Callable[..., Any] | None = None,
    images: str = "both",
    seed: int = 0,
) -> Path:
    """Write every scan of a canonical dataset as a raw recording in directory ``out``.

    Args:
        dataset_path: a psg-dataset directory.
        out: output directory (one recording per scan + side files); written atomically.
        fmt: ``ros1`` (``SCAN.bag``), ``ros2-sqlite3`` or ``ros2-mcap`` (``SCAN/`` bag directories).
        overwrite: replace ``out`` if it is a folder of recordings psg-data wrote (or empty); anything
            else is refused (:mod:`psg_data.writers._safe_output`).
        progress: called as ``progress(n_frames, nbytes)`` after each frame.
        images: ``both`` (raw and compressed topics), ``raw`` or ``compressed``.
        seed: seed of the log-time delays (5-30 ms after ``header.stamp``).

    Returns:
        The output directory.

    Raises:
        DatasetExistsError: ``out`` exists and ``overwrite`` is False.
        UnsafeOutputError: ``out`` or ``OUT.partial`` holds something psg-data did not write, or is
            (or lies inside) the input dataset.
        FormatError: bad ``fmt`` / ``images``, or a scan mixing cameras.
    """
    from psg_data.loaders import open_dataset

    if fmt not in RAW_EXPORT_FORMATS:
        raise FormatError(f"fmt: expected one of {', '.join(RAW_EXPORT_FORMATS)}, got {fmt!r}")
    if images not in ("both", "raw", "compressed"):
        raise FormatError(f"images: expected 'both', 'raw' or 'compressed', got {images!r}")
    out = Path(out)
    check_output(out, overwrite=overwrite, kind="recordings", inputs=[dataset_path])
    ds = open_dataset(dataset_path)
    tmp = make_staging(out.with_name(out.name + ".partial"))
    topics = _Topics(images in ("both", "raw"), images in ("both", "compressed"))
    rng = np.random.default_rng(seed)
    optical = {cid: (cam.frame_id or DEFAULT_OPTICAL_FRAME) for cid, cam in ds.cameras.items()}
    recordings: dict[str, str] = {}
    try:
        for scan in ds.scans:
            cams = set(scan.camera_ids.tolist())
            if len(cams) > 1:
                raise FormatError(f"scan {scan.scan_id}: frames from cameras {sorted(cams)}; raw export writes one "
                                  f"camera per recording")
            if not cams:
                continue
            cam = ds.cameras[cams.pop()]
            recordings[scan.scan_id] = name = f"{scan.scan_id}.bag" if fmt == "ros1" else scan.scan_id
            _export_scan(ds, scan, cam, optical[cam.camera_id], _BagWriter(tmp / name, fmt, _Msgs(fmt == "ros1")),
                         topics, rng, progress)
        _write_side_files(ds, tmp, recordings, optical)
        commit_tree(tmp, out, kind="recordings")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    log.info("exported %d recordings (%s) to %s", len(recordings), fmt, out)
    return out


@dataclass(frozen=True)
class _Topics:
    """Which image topics an export writes."""

    raw: bool
    compressed: bool


def _export_scan(ds: Any, scan: Any, cam: CameraIntrinsics, frame_id: str, bw: _BagWriter, topics: _Topics,
                 rng: np.random.Generator, progress: Callable[..., Any] | None) -> None:
    """Write one scan as one recording (closes ``bw``)."""
    msgs = bw.msgs
    cl_opt = np.eye(4)
    cl_opt[:3, :3] = R_CAMERA_LINK_OPTICAL
    T_base_opt = STATIC_BASE_CAMERA_LINK @ cl_opt
    try:
        if topics.raw:
            bw.connection(TOPICS["color"], "sensor_msgs/msg/Image")
            bw.connection(TOPICS["depth"], "sensor_msgs/msg/Image")
        if topics.compressed:
            bw.connection(TOPICS["color_compressed"], "sensor_msgs/msg/CompressedImage")
            bw.connection(TOPICS["depth_compressed"], "sensor_msgs/msg/CompressedImage")
        bw.connection(TOPICS["camera_info"], "sensor_msgs/msg/CameraInfo")
        bw.connection(TOPICS["tf"], "tf2_msgs/msg/TFMessage")
        bw.connection(TOPICS["tf_static"], "tf2_msgs/msg/TFMessage", latching=True)
        bw.connection(TOPICS["odom"], "nav_msgs/msg/Odometry")
        t0 = int(scan.stamps_ns[0])
        bw.push(TOPICS["tf_static"], t0 - 50_000_000, msgs.tf_message(t0, [
            ("base_link", "camera_link", STATIC_BASE_CAMERA_LINK), ("camera_link", frame_id, cl_opt)]))
        jpeg_in = ds.info.color_encoding == "jpeg"
        for i in range(len(scan)):
            t = int(scan.stamps_ns[i])
            color_bytes, depth_png, rgb, depth_mm = _frame_images(ds, scan, cam, i, topics.raw)
            delays = rng.integers(5_000_000, 30_000_001, size=6)
            nbytes = 0
            if topics.raw:
                assert rgb is not None and depth_mm is not None  # decoded for the raw topics
                nbytes += bw.push(TOPICS["color"], t + delays[0], msgs.image(t, frame_id, rgb, "rgb8"))
                nbytes += bw.push(TOPICS["depth"], t + delays[1], msgs.image(t, frame_id, depth_mm, "16UC1"))
            if topics.compressed:
                if jpeg_in:
                    jpg = color_bytes
                else:
                    assert rgb is not None  # decoded to re-encode as JPEG
                    jpg = _encode_jpeg(rgb)
                nbytes += bw.push(TOPICS["color_compressed"], t + delays[2],
                                  msgs.compressed(t, frame_id, "rgb8; jpeg compressed bgr8", jpg))
                nbytes += bw.push(TOPICS["depth_compressed"], t + delays[3],
                                  msgs.compressed(t, frame_id, "16UC1; compressedDepth png",
                                                  make_compressed_depth(depth_png)))
            nbytes += bw.push(TOPICS["camera_info"], t + delays[4], msgs.camera_info(t, frame_id, cam))
            T_mo = _map_odom((t - t0) / 1e9)
            T_ob = invert(T_mo) @ scan.poses[i] @ invert(T_base_opt)
            nbytes += bw.push(TOPICS["tf"], t + delays[5], msgs.tf_message(
                t, [("map", "odom", T_mo), ("odom", "base_link", T_ob)]))
            nbytes += bw.push(TOPICS["odom"], t + delays[5] // 2, msgs.odometry(t, T_ob))
            bw.flush(before_ns=t)
            if progress is not None:
                progress(1, nbytes)
    finally:
        bw.close()


def _encode_jpeg(rgb: NDArray[np.uint8]) -> bytes:
    """JPEG bytes (quality :data:`JPEG_QUALITY`) of an RGB image."""
    import cv2

    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    return bytes(cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])[1])


def _frame_images(ds: Any, scan: Any, cam: CameraIntrinsics, i: int, want_raw: bool
                  ) -> tuple[bytes, bytes, NDArray[np.uint8] | None, NDArray[np.uint16] | None]:
    """(colour bytes, depth PNG in millimetres, RGB array, depth array) of frame ``i``; the arrays are
    decoded only when needed (raw topics, PNG colour to turn into JPEG, depth not in millimetres).
    """
    import cv2

    color_bytes, depth_png = scan.image_bytes(i)
    rgb = depth_mm = None
    if want_raw or ds.info.color_encoding != "jpeg":
        check_image_header(color_bytes, cam, "color", f"{ds.root}: scan {scan.scan_id} frame {i}")
        bgr = cv2.imdecode(np.frombuffer(color_bytes, np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FormatError(f"{ds.root}: scan {scan.scan_id} frame {i}: unreadable colour image")
        rgb = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
    rescale = abs(cam.depth_scale_m - 0.001) > 1e-12
    if want_raw or rescale:
        check_image_header(depth_png, cam, "depth", f"{ds.root}: scan {scan.scan_id} frame {i}")
        raw = cv2.imdecode(np.frombuffer(depth_png, np.uint8), cv2.IMREAD_UNCHANGED)
        if raw is None:
            raise FormatError(f"{ds.root}: scan {scan.scan_id} frame {i}: unreadable depth image")
        if rescale:
            mm = np.rint(raw.astype(np.float64) * cam.depth_scale_m * 1000.0)
            raw = np.where((mm > 0) & (mm <= 65535), mm, 0).astype(np.uint16)
            depth_png = cv2.imencode(".png", raw, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])[1].tobytes()
        depth_mm = np.asarray(raw, dtype=np.uint16)
    return color_bytes, depth_png, rgb, depth_mm
