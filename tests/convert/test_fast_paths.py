"""The conversion's fast paths agree with the slow, general ones they replace.

- ``parse_compressed_image`` (reads header, format and data of a serialized CompressedImage) and
  ``parse_tf_message`` (every transform of a TFMessage) vs rosbags' serialiser/deserialiser, for
  ROS 1 and CDR, on arbitrary field values;
- the worker set-up of ``--jobs`` limits OpenCV to one thread.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.loaders.raw import RosRecording, parse_compressed_image, parse_tf_message
from psg_data.synth._raw_export import export_raw

from .conftest import make_dataset

_STORES: dict[bool, object] = {}


def _store(ros1: bool):  # type: ignore[no-untyped-def]
    from rosbags.typesys import Stores, get_typestore

    if ros1 not in _STORES:
        ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in ts.types:  # not in rosbags' ROS 1 store
            from rosbags.typesys import get_types_from_msg

            ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
        _STORES[ros1] = ts
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


_FRAME = st.text(alphabet=st.characters(blacklist_characters="\x00", blacklist_categories=("Cs",)), max_size=10)
_FLOAT = st.floats(allow_nan=False, width=64)
_TRANSFORM = st.tuples(st.integers(0, 2**31 - 1), st.integers(0, 999_999_999), _FRAME, _FRAME,
                       st.tuples(_FLOAT, _FLOAT, _FLOAT), st.tuples(_FLOAT, _FLOAT, _FLOAT, _FLOAT))


def _serialize_tf(ros1: bool, transforms: list) -> bytes:  # type: ignore[type-arg]
    ts = _store(ros1)
    T = ts.types  # type: ignore[attr-defined]
    H = T["std_msgs/msg/Header"]
    items = []
    for sec, nsec, parent, child, t, q in transforms:
        stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        h = H(seq=3, stamp=stamp, frame_id=parent) if ros1 else H(stamp=stamp, frame_id=parent)
        tf = T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](x=t[0], y=t[1], z=t[2]),
                                              rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))
        items.append(T["geometry_msgs/msg/TransformStamped"](header=h, child_frame_id=child, transform=tf))
    msg = T["tf2_msgs/msg/TFMessage"](transforms=items)
    typ = "tf2_msgs/msg/TFMessage"
    return bytes(ts.serialize_ros1(msg, typ) if ros1 else ts.serialize_cdr(msg, typ))  # type: ignore[attr-defined]


@settings(max_examples=150, deadline=None)
@given(ros1=st.booleans(), transforms=st.lists(_TRANSFORM, max_size=4))
def test_tf_parse_matches_rosbags(ros1: bool, transforms: list) -> None:  # type: ignore[type-arg]
    raw = _serialize_tf(ros1, transforms)
    got = parse_tf_message(raw, cdr=not ros1)
    assert got is not None
    typ = "tf2_msgs/msg/TFMessage"
    ref = _store(ros1).deserialize_ros1(raw, typ) if ros1 else _store(ros1).deserialize_cdr(raw, typ)  # type: ignore[attr-defined]
    assert len(got) == len(ref.transforms) == len(transforms)
    for g, r, (sec, nsec, parent, child, t, q) in zip(got, ref.transforms, transforms):
        assert g.stamp_ns == r.header.stamp.sec * 1_000_000_000 + r.header.stamp.nanosec == sec * 10**9 + nsec
        assert (g.parent, g.child) == (r.header.frame_id, r.child_frame_id) == (parent, child)
        assert g.translation == (r.transform.translation.x, r.transform.translation.y, r.transform.translation.z) == t
        assert g.rotation_xyzw == (r.transform.rotation.x, r.transform.rotation.y, r.transform.rotation.z,
                                   r.transform.rotation.w) == q
    if raw[4:]:
        assert parse_tf_message(raw + b"\x00" * 5, cdr=not ros1) is None  # trailing bytes
    if transforms:
        assert parse_tf_message(raw[:-9], cdr=not ros1) is None  # truncated


@settings(max_examples=60, deadline=None)
@given(ros1=st.booleans(), first=st.lists(_TRANSFORM, min_size=1, max_size=3), data=st.data())
def test_tf_shape_cache_never_serves_a_stale_shape(ros1: bool, first: list, data) -> None:  # type: ignore[no-untyped-def]
    """After one message, messages of the same length are read through the cached shape only when
    their frames match: new numbers and stamps come out right, other frames of equal length too."""
    cache: dict = {}  # type: ignore[type-arg]
    typ = "tf2_msgs/msg/TFMessage"
    store = _store(ros1)
    for transforms in [first, [(data.draw(st.integers(0, 2**31 - 1)), data.draw(st.integers(0, 999_999_999)), p, c,
                                data.draw(st.tuples(_FLOAT, _FLOAT, _FLOAT)),
                                data.draw(st.tuples(_FLOAT, _FLOAT, _FLOAT, _FLOAT))) for _, _, p, c, _, _ in first],
                       [(s, n, p[::-1], c.upper(), t, q) for s, n, p, c, t, q in first]]:
        raw = _serialize_tf(ros1, transforms)
        got = parse_tf_message(raw, cdr=not ros1, cache=cache)
        assert cache  # the shape is kept for the next message
        ref = store.deserialize_ros1(raw, typ) if ros1 else store.deserialize_cdr(raw, typ)  # type: ignore[attr-defined]
        assert got is not None and len(got) == len(ref.transforms)
        for g, r in zip(got, ref.transforms):
            assert (g.parent, g.child) == (r.header.frame_id, r.child_frame_id)
            assert g.stamp_ns == r.header.stamp.sec * 1_000_000_000 + r.header.stamp.nanosec
            assert g.translation == (r.transform.translation.x, r.transform.translation.y, r.transform.translation.z)
            assert g.rotation_xyzw == (r.transform.rotation.x, r.transform.rotation.y, r.transform.rotation.z,
                                       r.transform.rotation.w)


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
        for conn, _, raw in rec.raw_messages({"/tf", "/tf_static"}):
            assert parse_tf_message(raw, cdr=fmt != "ros1") is not None  # the fast path was taken
            msg = rec.deserialize(raw, conn.msgtype, conn.topic)
            fast_tf = rec.tf_transforms(raw, conn.topic)
            assert [(s.parent, s.child) for s in fast_tf] == [(t.header.frame_id, t.child_frame_id)
                                                               for t in msg.transforms]
            n += 1
    assert n == 6 + 3 + 1


def test_worker_init_limits_opencv_threads() -> None:
    import cv2

    from psg_data.convert._pipeline import _init_worker

    before = cv2.getNumThreads()
    try:
        _init_worker()
        assert cv2.getNumThreads() == 1
    finally:
        cv2.setNumThreads(before)


@pytest.mark.parametrize("compression", ["none", "lz4", "bz2"])
def test_ros1_zero_copy_loop_equals_rosbags(tmp_path: Path, compression: str) -> None:
    """RosRecording's ROS 1 message loop (memory map over rosbags' index) yields what rosbags'
    Reader.messages yields, in the same order, for uncompressed and compressed chunks, with
    interleaved topics, equal stamps across topics and many chunks."""
    from rosbags.rosbag1 import Reader, Writer

    bag = tmp_path / "a.bag"
    rng = np.random.default_rng(0)
    w = Writer(bag)
    if compression != "none":
        w.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    w.chunk_threshold = 20_000  # many chunks (attribute of the rosbags writer)
    expected = []
    with w:
        conns = [w.add_connection(t, "std_msgs/msg/String", typestore=_store(True)) for t in ("/a", "/b", "/c")]
        for i in range(300):
            c = conns[int(rng.integers(0, 3))]
            t = 1_000_000 + (i // 2) * 1000  # pairs of equal stamps
            data = rng.bytes(int(rng.integers(1, 3000)))
            w.write(c, t, data)
    with Reader(bag) as r:
        expected = [(c.topic, t, bytes(d)) for c, t, d in r.messages()]
        expected_b = [(c.topic, t, bytes(d)) for c, t, d in r.messages(connections=[x for x in r.connections
                                                                                    if x.topic != "/b"])]
    with RosRecording(bag) as rec:
        got = [(c.topic, t, bytes(d)) for c, t, d in rec.raw_messages()]
        got_b = [(c.topic, t, bytes(d)) for c, t, d in rec.raw_messages({"/a", "/c"})]
    assert got == expected and len(got) == 300
    assert got_b == expected_b


def _rss_file_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("RssFile:"):
            return int(line.split()[1])
    raise AssertionError("no RssFile line")


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="resident memory is read from Linux /proc")
def test_ros1_loop_releases_the_pages_it_read(tmp_path: Path) -> None:
    """Memory stays bounded by a chunk or two, not by the bag: pages of chunks already read are
    released from the memory map (a 48 MB bag leaves < 12 MB resident)."""
    from rosbags.rosbag1 import Writer

    bag = tmp_path / "big.bag"
    rng = np.random.default_rng(1)
    w = Writer(bag)
    with w:
        c = w.add_connection("/x", "std_msgs/msg/String", typestore=_store(True))
        for i in range(48):
            w.write(c, 1000 + i, rng.bytes(1 << 20))
    import hashlib

    with RosRecording(bag) as rec:
        before = _rss_file_kib()
        h, n = hashlib.sha256(), 0
        for _, _, raw in rec.raw_messages():  # reading every byte maps every page of the bag
            h.update(raw)
            n += len(raw)
        grown = _rss_file_kib() - before
    assert n >= 48 << 20
    assert grown < 12 * 1024, f"{grown} KiB of the bag still resident"


def test_ros1_fallback_to_rosbags_public_reader_gives_identical_output(tmp_path: Path, monkeypatch) -> None:
    """With rosbags' ROS 1 internals unavailable (as after an upstream rename), messages come from
    the public ``Reader.messages`` and the converted dataset is byte for byte the same."""
    from rosbags.rosbag1 import Reader

    import psg_data.loaders.raw._bag as bag_mod
    from psg_data.convert import convert

    from .conftest import dataset_bytes

    raw = export_raw(make_dataset(tmp_path / "canon", n_scans=2, n_frames=3), tmp_path / "raw", "ros1",
                     images="compressed")
    fast = Path(convert(raw, tmp_path / "fast").output)
    calls = []
    public = Reader.messages

    def spy(self, *a, **k):  # type: ignore[no-untyped-def]
        calls.append(1)
        return public(self, *a, **k)

    bag_mod._rosbags_ros1_internals.cache_clear()
    monkeypatch.setattr(bag_mod, "_rosbags_ros1_internals", lambda: None)
    monkeypatch.setattr(Reader, "messages", spy)
    slow = Path(convert(raw, tmp_path / "slow").output)
    assert calls, "the public reader was not used"
    a, b = dataset_bytes(fast), dataset_bytes(slow)
    assert sorted(a) == sorted(b) and any(k.endswith(".tar") for k in a)
    assert [k for k in a if a[k] != b[k]] == []


def test_ros1_internals_guard_catches_a_renamed_module(monkeypatch) -> None:
    """An upstream rename of ``rosbags.rosbag1.reader.decompressors`` gives None (the fallback), not ImportError."""
    import rosbags.rosbag1.reader as reader

    import psg_data.loaders.raw._bag as bag_mod

    bag_mod._rosbags_ros1_internals.cache_clear()
    try:
        assert bag_mod._rosbags_ros1_internals() is not None  # the rosbags this suite runs with
        bag_mod._rosbags_ros1_internals.cache_clear()
        monkeypatch.delattr(reader, "decompressors")
        assert bag_mod._rosbags_ros1_internals() is None
    finally:
        bag_mod._rosbags_ros1_internals.cache_clear()
