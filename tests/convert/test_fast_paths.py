"""The conversion's fast paths agree with the slow, general ones they replace.

- ``parse_compressed_image`` (reads header, format and data of a serialized CompressedImage) vs
  rosbags' serialiser/deserialiser, for ROS 1 and CDR, on arbitrary field values;
- ``DatasetWriter.completed_scans(trusted=...)`` skips re-hashing only the trusted scans;
- the worker set-up of ``--jobs`` limits OpenCV to one thread.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.loaders.raw import RosRecording, parse_compressed_image
from psg_data.synth._raw_export import export_raw
from psg_data.writers import DatasetWriter

from .conftest import CAMERA, images, make_dataset, pose

_STORES: dict[bool, object] = {}


def _store(ros1: bool):  # type: ignore[no-untyped-def]
    from rosbags.typesys import Stores, get_typestore

    if ros1 not in _STORES:
        _STORES[ros1] = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    return _STORES[ros1]


def _serialize(ros1: bool, sec: int, nsec: int, frame_id: str, fmt: str, data: bytes) -> bytes:
    ts = _store(ros1)
    T = ts.types  # type: ignore[attr-defined]
    t = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    H = T["std_msgs/msg/Header"]
    h = H(seq=7, stamp=t, frame_id=frame_id) if ros1 else H(stamp=t, frame_id=frame_id)
    msg = T["sensor_msgs/msg/CompressedImage"](header=h, format=fmt, data=np.frombuffer(data, np.uint8))
    typ = "sensor_msgs/msg/CompressedImage"
    return bytes(ts.serialize_ros1(msg, typ) if ros1 else ts.serialize_cdr(msg, typ))  # type: ignore[attr-defined]


@settings(max_examples=150, deadline=None)
@given(ros1=st.booleans(), sec=st.integers(0, 2**31 - 1), nsec=st.integers(0, 999_999_999),
       frame_id=st.text(max_size=12), fmt=st.text(max_size=40), data=st.binary(max_size=40))
def test_parse_matches_rosbags(ros1: bool, sec: int, nsec: int, frame_id: str, fmt: str, data: bytes) -> None:
    raw = _serialize(ros1, sec, nsec, frame_id, fmt, data)
    got = parse_compressed_image(raw, cdr=not ros1)
    assert got is not None
    ref = _store(ros1).deserialize_ros1(raw, "sensor_msgs/msg/CompressedImage") if ros1 else \
        _store(ros1).deserialize_cdr(raw, "sensor_msgs/msg/CompressedImage")  # type: ignore[attr-defined]
    assert got.stamp_ns == ref.header.stamp.sec * 1_000_000_000 + ref.header.stamp.nanosec == sec * 10**9 + nsec
    assert got.frame_id == ref.header.frame_id == frame_id
    assert got.format == ref.format == fmt
    assert bytes(got.data) == bytes(ref.data) == data


@settings(max_examples=60, deadline=None)
@given(ros1=st.booleans(), data=st.binary(min_size=1, max_size=30), cut=st.integers(1, 40))
def test_truncated_or_foreign_bytes_give_none(ros1: bool, data: bytes, cut: int) -> None:
    raw = _serialize(ros1, 5, 6, "cam", "jpeg", data)
    assert parse_compressed_image(raw[:max(0, len(raw) - cut)], cdr=not ros1) is None  # truncated
    assert parse_compressed_image(raw + b"\x00" * 4, cdr=not ros1) is None  # trailing bytes
    if not ros1:
        assert parse_compressed_image(b"\x00\x00" + raw[2:], cdr=True) is None  # big-endian CDR: fall back


@pytest.mark.parametrize("fmt", ["ros1", "ros2-sqlite3", "ros2-mcap"])
def test_recording_fast_path_equals_deserialize(tmp_path: Path, fmt: str) -> None:
    canon = make_dataset(tmp_path / "canon", n_scans=1, n_frames=3)
    out = export_raw(canon, tmp_path / "raw", fmt, images="compressed")
    src = next(p for p in sorted(out.iterdir()) if p.suffix == ".bag" or p.is_dir())
    n = 0
    with RosRecording(src) as rec:
        for conn, _, raw in rec.raw_messages():
            if conn.msgtype != "sensor_msgs/msg/CompressedImage":
                continue
            fast = rec.compressed_image(raw, conn.topic)
            assert parse_compressed_image(raw, cdr=fmt != "ros1") is not None  # the fast path was taken
            msg = rec.deserialize(raw, conn.msgtype, conn.topic)
            assert fast.stamp_ns == msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            assert (fast.frame_id, fast.format) == (msg.header.frame_id, msg.format)
            assert bytes(fast.data) == bytes(msg.data)
            n += 1
    assert n == 6


def _interrupted_write(root: Path) -> Path:
    w = DatasetWriter(root, threads=1)
    w.add_camera(CAMERA)
    for s in range(2):
        with w.scan(f"scan_{s}") as sw:
            for i in range(2):
                c, d = images(i, s)
                sw.add_frame(1_000 + i, pose(i, s), c, d, CAMERA.camera_id)
    w.abort(keep_partial=True)
    return root.with_name(root.name + ".partial")


def test_completed_scans_trusted_skips_only_the_trusted_checksums(tmp_path: Path) -> None:
    tmp = _interrupted_write(tmp_path / "ds")
    for s in range(2):  # corrupt one image of each scan (same size, other bytes)
        p = tmp / "images" / f"scan_{s}.tar"
        data = bytearray(p.read_bytes())
        data[600] ^= 0xFF
        p.write_bytes(bytes(data))
    w = DatasetWriter(tmp_path / "ds", resume=True, threads=1)
    assert w.completed_scans() == {}
    got = w.completed_scans(trusted={"scan_1"})
    assert set(got) == {"scan_1"}
    marker = json.loads((tmp / ".scans" / "scan_1.json").read_text())
    assert got["scan_1"]["files"] == marker["files"] and list(marker["files"]) == ["images/scan_1.tar"]
    w.abort()


def test_worker_init_limits_opencv_threads() -> None:
    import cv2

    from psg_data.convert._pipeline import _init_worker

    before = cv2.getNumThreads()
    try:
        _init_worker()
        assert cv2.getNumThreads() == 1
    finally:
        cv2.setNumThreads(before)
