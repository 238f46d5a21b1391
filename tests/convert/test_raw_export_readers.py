"""Exported raw recordings open with the upstream readers (rosbags, mcap) and hold the documented
topics, message types and counts (docs/RAW_FORMATS.md), independently of psg-data's own loaders."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

from psg_data.loaders import open_dataset
from psg_data.synth._raw_export import export_raw

DOCUMENTED = {  # topic -> ROS 2 type name, as listed in docs/RAW_FORMATS.md
    "/camera/color/image_raw": "sensor_msgs/msg/Image",
    "/camera/color/image_raw/compressed": "sensor_msgs/msg/CompressedImage",
    "/camera/aligned_depth_to_color/image_raw": "sensor_msgs/msg/Image",
    "/camera/aligned_depth_to_color/image_raw/compressedDepth": "sensor_msgs/msg/CompressedImage",
    "/camera/color/camera_info": "sensor_msgs/msg/CameraInfo",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/rtabmap/odom": "nav_msgs/msg/Odometry",
}


def test_the_documented_topics_are_those_of_the_doc() -> None:
    doc = (Path(__file__).resolve().parents[2] / "docs" / "RAW_FORMATS.md").read_text()
    for topic, msgtype in DOCUMENTED.items():
        short = msgtype.replace("/msg/", "/")
        assert f"| `{topic}` | {short} " in doc, f"RAW_FORMATS.md does not list {topic} as {short}"


@pytest.mark.parametrize("fmt", ["ros1", "ros2-sqlite3", "ros2-mcap"])
def test_rosbags_reads_documented_topics_types_and_counts(tmp_path: Path, tiny_dataset: Path, fmt: str) -> None:
    from rosbags.highlevel import AnyReader

    out = export_raw(tiny_dataset, tmp_path / "raw", fmt)
    ds = open_dataset(tiny_dataset)
    recordings = sorted(out.glob("*.bag")) if fmt == "ros1" else sorted(p for p in out.iterdir() if p.is_dir())
    assert [r.stem if fmt == "ros1" else r.name for r in recordings] == sorted(ds.scan_ids)
    for rec in recordings:
        sid = rec.stem if fmt == "ros1" else rec.name
        n_frames = len(ds.scan(sid))
        with AnyReader([rec]) as reader:
            types = {c.topic: c.msgtype for c in reader.connections}
            counts: Counter[str] = Counter()
            first_stamp = {}
            for conn, _, raw in reader.messages():
                counts[conn.topic] += 1
                if conn.topic == "/camera/color/image_raw" and conn.topic not in first_stamp:
                    msg = reader.deserialize(raw, conn.msgtype)
                    first_stamp[conn.topic] = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        assert types == DOCUMENTED, sid
        expected = {t: (1 if t == "/tf_static" else n_frames) for t in DOCUMENTED}
        assert dict(counts) == expected, sid
        assert first_stamp["/camera/color/image_raw"] == int(ds.scan(sid).stamps_ns[0])  # header stamp = frame stamp


def test_mcap_reader_reads_the_ros2_mcap_export(tmp_path: Path, tiny_dataset: Path) -> None:
    from mcap.reader import make_reader

    out = export_raw(tiny_dataset, tmp_path / "raw", "ros2-mcap")
    ds = open_dataset(tiny_dataset)
    for sid in ds.scan_ids:
        files = list((out / sid).glob("*.mcap"))
        assert len(files) == 1
        with open(files[0], "rb") as fh:
            reader = make_reader(fh)
            summary = reader.get_summary()
            assert summary is not None and summary.statistics is not None  # indexed, with statistics
            schemas = {ch.topic: summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
            assert all(ch.message_encoding == "cdr" for ch in summary.channels.values())
            counts = Counter(ch.topic for _, ch, _ in reader.iter_messages())
        assert schemas == DOCUMENTED
        n = len(ds.scan(sid))
        assert dict(counts) == {t: (1 if t == "/tf_static" else n) for t in DOCUMENTED}
        by_channel = {summary.channels[cid].topic: c for cid, c in summary.statistics.channel_message_counts.items()}
        assert by_channel == dict(counts)
