"""Factories for tiny canonical datasets and raw recordings built in tmp_path."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from psg_data.schemas._records import Box, CameraIntrinsics, Door, ObjectInfo, Receptacle, Room
from psg_data.writers import DatasetWriter

W, H = 32, 24
CAMERA = CameraIntrinsics("cam0", W, H, 30.0, 31.0, 15.5, 11.5, frame_id="camera_color_optical_frame")


def rot(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def pose(i: int, scan: int) -> np.ndarray:
    """A camera-to-world pose in OpenCV axes (camera looking roughly along world +x)."""
    base = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T = np.eye(4)
    T[:3, :3] = rot([0, 0, 1], 0.3 * scan + 0.1 * i) @ base @ rot([1, 0, 0], 0.05 * i)
    T[:3, 3] = [0.5 + 0.1 * i, -0.2 * scan + 0.03 * i, 1.2 + 0.01 * i]
    return T


def images(i: int, scan: int, w: int = W, h: int = H) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1000 * scan + i)
    yy, xx = np.mgrid[0:h, 0:w]
    color = np.stack([(xx * 7 + i * 5) % 256, (yy * 9 + scan * 40) % 256, (xx + yy) * 3 % 256], -1).astype(np.uint8)
    color = np.clip(color.astype(int) + rng.integers(-3, 4, color.shape), 0, 255).astype(np.uint8)
    depth = (800 + 40 * xx + 13 * yy + 7 * i + rng.integers(0, 50, (h, w))).astype(np.uint16)
    depth[0, :3] = 0
    depth[5, 5] = 60000
    return color, depth


def camera_for(w: int, h: int) -> CameraIntrinsics:
    """:data:`CAMERA` scaled to ``w`` x ``h`` pixels."""
    if (w, h) == (W, H):
        return CAMERA
    return CameraIntrinsics("cam0", w, h, 30.0 * w / W, 31.0 * w / W, w / 2 - 0.5, h / 2 - 0.5,
                            frame_id="camera_color_optical_frame")


def make_dataset(root: Path, *, n_scans: int = 2, n_frames: int = 4, color_encoding: str = "png",
                 period_ns: int = 100_000_000, w: int = W, h: int = H) -> Path:
    cam = camera_for(w, h)
    rooms = [Room("kitchen", "Kitchen", np.array([[0, 0], [4, 0], [4, 3], [0, 3.0]])), Room("office", "Office")]
    recs = [Receptacle("table1", "Table", "kitchen", Box(np.array([1.0, 2.0, 0.4]), np.array([1.2, 0.8, 0.8]),
                                                         rot([0, 0, 1], 0.3)), "table"),
            Receptacle("shelf1", "Shelf", "office", Box(np.array([3.0, -1.0, 0.9]), np.array([0.4, 1.0, 1.8])))]
    doors = [Door("door1", "Kitchen door", "kitchen", "office", Box(np.array([4.0, 1.0, 1.0]),
                                                                       np.array([0.1, 0.9, 2.0])))]
    objs = [ObjectInfo("mug", "redmug", "a red mug"), ObjectInfo("book", "book", None)]
    with DatasetWriter(root, name="tiny", timezone="America/Toronto", color_encoding=color_encoding,
                       threads=1) as wr:
        wr.add_camera(cam)
        wr.set_rooms(rooms)
        wr.set_receptacles(recs)
        wr.set_doors(doors)
        wr.set_objects(objs)
        ds_rows, sched = [], []
        for s in range(n_scans):
            sid = f"scan_{s:03d}"
            t0 = 1_700_000_000_000_000_000 + s * 86_400_000_000_000
            with wr.scan(sid, source="factory", split="train" if s % 2 == 0 else "test") as sw:
                for i in range(n_frames):
                    c, d = images(i, s, w, h)
                    sw.add_frame(t0 + i * period_ns + 1234, pose(i, s), c, d, "cam0")
            ds_rows.append({"scan_id": sid, "door_id": "door1", "state": "open" if s % 2 else "closed"})
            sched.append({"scan_id": sid, "object_id": "mug", "receptacle_id": "table1" if s % 2 else "shelf1"})
            sched.append({"scan_id": sid, "object_id": "book", "receptacle_id": None if s % 2 else "table1"})
        wr.set_table("door_states", ds_rows)
        wr.set_table("schedule", sched)
    return root


@pytest.fixture
def tiny_dataset(tmp_path: Path) -> Path:
    return make_dataset(tmp_path / "canon")


COLOR_TOPIC = "/camera/color/image_raw"
DEPTH_TOPIC = "/camera/aligned_depth_to_color/image_raw"


def write_bag(path: Path, fmt: str = "ros1", *, n: int = 4, w: int = W, h: int = H, color: str | None = "rgb8",
              depth: str | None = "16UC1", info: bool = True, tf: bool = True, tf_static: bool = True,
              depth_size: tuple[int, int] | None = None, duplicate: bool = False, nan_pose_at: int | None = None,
              t0: int = 1_700_000_000_000_000_000, period_ns: int = 100_000_000,
              extra_topics: bool = False, log_lag_ns: int = 0, image_latency_ns: int = 0, tf_latency_ns: int = 0,
              late: dict[int, int] | None = None, tf_period: int = 1, depth_stamp_offset_ns: int = 0,
              tf_stamp_offset_ns: int = 0,
              payload: Callable[[str, int, bytes], bytes] | None = None) -> Path:
    """A hand-made recording with chosen defects (poses: pose(i, 0) in the map frame).

    ``header.stamp`` of frame i is ``t0 + i * period_ns``; its log time is that plus a few ms, plus
    ``log_lag_ns`` (every message: a re-recorded bag), ``image_latency_ns`` (colour, depth and
    CameraInfo: a camera's latency) or ``tf_latency_ns`` (/tf), plus ``late[i]`` for the colour and
    depth images of frame i (logged after later frames: out of order in header time). /tf is
    published every ``tf_period`` frames; depth and /tf header stamps may be offset from the colour
    stamps by ``depth_stamp_offset_ns`` / ``tf_stamp_offset_ns``. ``color``: an Image encoding, or ``jpeg`` / ``png`` for a
    CompressedImage; ``payload(topic, i, data)`` may replace the encoded bytes of a CompressedImage.
    """
    from psg_data.synth._raw_export import (
        STATIC_BASE_CAMERA_LINK,
        R_CAMERA_LINK_OPTICAL,
        _BagWriter,
        _Msgs,
    )
    from psg_data.loaders.raw._images import make_compressed_depth
    from psg_data.loaders.raw._transforms import invert
    import cv2

    msgs = _Msgs(fmt == "ros1")
    if extra_topics:
        from rosbags.typesys import get_types_from_msg

        msgs.ts.register(get_types_from_msg("std_msgs/Header header\nint32 ref_id\nfloat32 loop_closure",
                                            "rtabmap_ros/msg/Info"))
    bw = _BagWriter(path, fmt, msgs)
    fid = "camera_color_optical_frame"
    compressed_color = color in ("jpeg", "png")
    color_topic = COLOR_TOPIC + ("/compressed" if compressed_color else "")
    depth_topic = DEPTH_TOPIC + ("/compressedDepth" if depth == "compressedDepth" else "")
    if color:
        bw.connection(color_topic, "sensor_msgs/msg/CompressedImage" if compressed_color else "sensor_msgs/msg/Image")
    if depth:
        bw.connection(depth_topic, "sensor_msgs/msg/CompressedImage" if depth == "compressedDepth" else
                      "sensor_msgs/msg/Image")
    if info:
        bw.connection("/camera/color/camera_info", "sensor_msgs/msg/CameraInfo")
    if tf:
        bw.connection("/tf", "tf2_msgs/msg/TFMessage")
    if tf_static:
        bw.connection("/tf_static", "tf2_msgs/msg/TFMessage", latching=True)
    if extra_topics:
        bw.connection("/rtabmap/info", "rtabmap_ros/msg/Info")
    cl_opt = np.eye(4)
    cl_opt[:3, :3] = R_CAMERA_LINK_OPTICAL
    T_base_opt = STATIC_BASE_CAMERA_LINK @ cl_opt
    events: list[tuple[int, int, str, Any]] = []

    def push(topic: str, log_ns: int, msg: Any) -> None:
        events.append((log_ns + log_lag_ns, len(events), topic, msg))

    if tf_static:
        push("/tf_static", t0 - 10_000_000, msgs.tf_message(t0, [("base_link", "camera_link", STATIC_BASE_CAMERA_LINK),
                                                                ("camera_link", fid, cl_opt)]))
    late = late or {}
    for i in range(n):
        t = t0 + i * period_ns
        lat = image_latency_ns + late.get(i, 0)
        c, d = images(i, 0, w, h)
        if color:
            if compressed_color:
                ext = ".jpg" if color == "jpeg" else ".png"
                data = cv2.imencode(ext, cv2.cvtColor(c, cv2.COLOR_RGB2BGR))[1].tobytes()
                if payload is not None:
                    data = payload(color_topic, i, data)
                m = msgs.compressed(t, fid, f"rgb8; {color} compressed bgr8", data)
            else:
                m = msgs.image(t, fid, c, "rgb8")
                if color != "rgb8":
                    m = msgs.T["sensor_msgs/msg/Image"](header=m.header, height=m.height, width=m.width,
                                                        encoding=color, is_bigendian=0, step=m.step, data=m.data)
            push(color_topic, t + 7_000_000 + lat, m)
            if duplicate and i == 1:
                push(color_topic, t + 9_000_000 + lat, msgs.image(t, fid, c, "rgb8"))
        td = t + depth_stamp_offset_ns
        if depth:
            dw, dh = depth_size or (w, h)
            dd = cv2.resize(d, (dw, dh), interpolation=cv2.INTER_NEAREST)
            if depth == "compressedDepth":
                png = cv2.imencode(".png", dd)[1].tobytes()
                if payload is not None:
                    png = payload(depth_topic, i, png)
                push(depth_topic, t + 8_000_000 + lat,
                     msgs.compressed(td, fid, "16UC1; compressedDepth png", make_compressed_depth(png)))
            elif depth == "32FC1":
                push(depth_topic, t + 8_000_000 + lat, msgs.image(td, fid, dd.astype(np.float32) / 1000.0, "32FC1"))
            else:
                push(depth_topic, t + 8_000_000 + lat, msgs.image(td, fid, dd, depth))
        if info:
            push("/camera/color/camera_info", t + 6_000_000 + image_latency_ns, msgs.camera_info(t, fid, camera_for(w, h)))
        if tf and (i % tf_period == 0 or i == n - 1):
            T = pose(i, 0)
            if nan_pose_at == i:
                T = T.copy()
                T[0, 3] = np.nan
            T_ob = T @ invert(T_base_opt)
            push("/tf", t + 12_000_000 + tf_latency_ns,
                 msgs.tf_message(t + tf_stamp_offset_ns, [("map", "odom", np.eye(4)), ("odom", "base_link", T_ob)]))
        if extra_topics:
            push("/rtabmap/info", t + 15_000_000, msgs.T["rtabmap_ros/msg/Info"](
                header=msgs.header(t, "map"), ref_id=i, loop_closure=0.0))
    for log_ns, _, topic, msg in sorted(events, key=lambda e: (e[0], e[1])):  # recorded in log-time order
        bw.push(topic, log_ns, msg)
    bw.flush()
    bw.close()
    return path


def dataset_bytes(root: Path) -> dict[str, bytes]:
    """Every file of a dataset (manifest, Parquet tables, image archives) by relative path: two
    conversions of the same input compare byte for byte (the manifest holds no wall-clock time)."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}
