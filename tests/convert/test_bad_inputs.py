"""Bad inputs: one ``error:`` line, exit code 1, no traceback, nothing left behind."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from .conftest import write_bag

from psg_data.cli.psg_data_cmd import main
from psg_data.loaders import open_dataset
from psg_data.synth._raw_export import export_raw


def run(*args: str) -> tuple[int, str, str]:
    res = CliRunner().invoke(main, ["convert", *args, "-q"])
    return res.exit_code, res.stdout, res.stderr


def assert_error(tmp_path: Path, args: list[str], match: str) -> None:
    out = tmp_path / "out"
    code, stdout, stderr = run(*args, str(out))
    assert code == 1, (code, stdout, stderr)
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    assert match in lines[0], lines[0]
    assert "Traceback" not in stderr
    assert not out.exists() and not (tmp_path / "out.partial").exists()


def test_ok_exit_code_and_summary(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag")
    code, stdout, _ = run(str(bag), str(tmp_path / "out"))
    assert code == 0 and "converted 1 scans, 4 frames" in stdout


def test_truncated_bag(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag")
    data = bag.read_bytes()
    bag.write_bytes(data[: len(data) // 2])
    assert_error(tmp_path, [str(bag)], "unreadable or truncated recording")


@pytest.mark.parametrize("fmt", ["ros2-mcap", "ros2-sqlite3"])
def test_truncated_ros2(tmp_path: Path, fmt: str) -> None:
    bag = write_bag(tmp_path / "a", fmt)
    f = next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2])
    assert_error(tmp_path, [str(bag)], "unreadable or truncated recording")


def test_zero_byte_file(tmp_path: Path) -> None:
    (tmp_path / "a.bag").write_bytes(b"")
    assert_error(tmp_path, [str(tmp_path / "a.bag")], "zero-byte file")
    d = tmp_path / "recs"
    d.mkdir()
    write_bag(d / "good.bag")
    (d / "empty.bag").write_bytes(b"")
    assert_error(tmp_path, [str(d)], "empty.bag: zero-byte file")


def test_recording_without_depth(tmp_path: Path) -> None:
    assert_error(tmp_path, [str(write_bag(tmp_path / "a.bag", depth=None))], "no depth topic")


def test_recording_without_camera_info(tmp_path: Path) -> None:
    assert_error(tmp_path, [str(write_bag(tmp_path / "a.bag", info=False))], "no sensor_msgs/CameraInfo topic")


def test_unknown_image_encoding(tmp_path: Path) -> None:
    assert_error(tmp_path, [str(write_bag(tmp_path / "a.bag", color="yuv422"))],
                 "/camera/color/image_raw: unknown colour image encoding 'yuv422'")


def test_unknown_depth_encoding(tmp_path: Path) -> None:
    assert_error(tmp_path, [str(write_bag(tmp_path / "a.bag", depth="mono8"))], "unknown depth image encoding")


def test_tf_tree_without_path(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a", "ros2-sqlite3", tf_static=False)  # ROS 2 bag without /tf_static
    assert_error(tmp_path, [str(bag)], "TF tree has no path from 'map' to 'camera_color_optical_frame'")


def make_static(parent: str, child: str, T: np.ndarray) -> dict[str, object]:
    """A ``static_transforms`` config entry from a 4x4 transform."""
    from psg_data.loaders.raw._transforms import matrix_to_quat_xyzw

    return {"parent": parent, "child": child, "translation": [float(v) for v in T[:3, 3]],
            "rotation_xyzw": [float(v) for v in matrix_to_quat_xyzw(T[:3, :3])]}


def test_missing_tf_static_supplied_in_config(tmp_path: Path) -> None:
    from psg_data.synth._raw_export import R_CAMERA_LINK_OPTICAL, STATIC_BASE_CAMERA_LINK
    from .conftest import pose

    bag = write_bag(tmp_path / "a", "ros2-sqlite3", tf_static=False)
    cl = np.eye(4)
    cl[:3, :3] = R_CAMERA_LINK_OPTICAL
    import json

    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps({"static_transforms": [make_static("base_link", "camera_link", STATIC_BASE_CAMERA_LINK),
                                                     make_static("camera_link", "camera_color_optical_frame", cl)]}))
    code, _, stderr = run(str(bag), str(tmp_path / "out"), "--config", str(cfg))
    assert code == 0, stderr
    np.testing.assert_allclose(open_dataset(tmp_path / "out").scan("a").poses[2], pose(2, 0), atol=1e-9)


def test_color_and_depth_of_different_sizes(tmp_path: Path) -> None:
    assert_error(tmp_path, [str(write_bag(tmp_path / "a.bag", depth_size=(16, 12)))],
                 "depth is 16x12 but colour is 32x24")


def test_duplicate_timestamps_are_skipped_and_reported(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag", duplicate=True)
    res = CliRunner().invoke(main, ["convert", str(bag), str(tmp_path / "out")])
    assert res.exit_code == 0
    assert "skipped 1 colour images (duplicate_stamp 1)" in res.stdout
    assert "1 colour images skipped: duplicate_stamp" in res.stderr
    ds = open_dataset(tmp_path / "out")
    assert len(ds.scan("a")) == 4 and ds.info.extra["convert"]["report"]["skipped"] == {"duplicate_stamp": 1}


def test_nonfinite_poses_are_skipped_and_reported(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag", nan_pose_at=2, extra_topics=True)  # + an rtabmap_ros/* topic
    code, stdout, _ = run(str(bag), str(tmp_path / "out"))
    assert code == 0 and "nonfinite_pose 1" in stdout
    stamps = open_dataset(tmp_path / "out").scan("a").stamps_ns
    assert len(stamps) == 3 and 1_700_000_000_200_000_000 not in stamps


def test_directory_mixing_formats(tmp_path: Path) -> None:
    d = tmp_path / "recs"
    d.mkdir()
    write_bag(d / "a.bag")
    write_bag(d / "b", "ros2-mcap")
    assert_error(tmp_path, [str(d)], "directory mixes recording formats (1 ROS 1 bags, 1 ROS 2 bags)")


def test_output_exists(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag")
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    code, _, stderr = run(str(bag), str(out))
    assert code == 1 and stderr.startswith("error: ") and "output exists" in stderr
    assert (out / "keep.txt").read_text() == "x"
    code, _, stderr = run(str(bag), str(out), "--overwrite")  # a folder psg-data did not write: refused
    assert code == 1 and "is not a psg-dataset (no readable dataset.json) and holds keep.txt" in stderr
    assert (out / "keep.txt").read_text() == "x" and sorted(p.name for p in tmp_path.iterdir()) == ["a.bag", "out"]
    (out / "keep.txt").unlink()  # an empty folder is replaced, and then the dataset written there
    for _ in range(2):
        code, _, stderr = run(str(bag), str(out), "--overwrite")
        assert code == 0 and (out / "dataset.json").is_file(), stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bag", "out"]  # no OUT.old, no OUT.partial


def test_bad_options(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag")
    assert_error(tmp_path, [str(bag), "--poses", "bogus"], "--poses (poses): expected tf:WORLD_FRAME->CAMERA_FRAME, odom:/TOPIC or tum:FILE, got 'bogus'")
    assert_error(tmp_path, [str(bag), "--color-topic", "/nope"], "/nope: no such topic")
    assert_error(tmp_path, [str(bag), "--keyframes", "every:0"], "--keyframes")
    code, _, _ = run(str(bag), str(tmp_path / "out"), "--jobs", "0")
    assert code == 2
    cfg = tmp_path / "c.yaml"
    cfg.write_text("colour_topic: /x\n")
    assert_error(tmp_path, [str(bag), "--config", str(cfg)], "unknown keys colour_topic")


def test_side_file_with_unknown_scan(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1")
    with open(raw / "schedule.csv", "a") as fh:
        fh.write("scan_999,mug,table1\n")
    assert_error(tmp_path, [str(raw)], "scan_id 'scan_999' is not a converted scan")


def test_side_table_given_twice(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1")
    shutil.copy(raw / "schedule.csv", raw / "schedule.yaml")
    assert_error(tmp_path, [str(raw)], "expected it once")


@pytest.mark.parametrize("exc_name", ["CorruptError", "IOError"])
def test_database_error_while_iterating_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    exc_name: str) -> None:
    """apsw (rosbags' sqlite3 driver) raises its own errors when a damaged page is reached mid-file."""
    from rosbags.rosbag2.storage_sqlite3 import apsw  # the driver rosbags reads ROS 2 sqlite3 bags with

    from psg_data.loaders.raw import _bag

    bag = write_bag(tmp_path / "a", "ros2-sqlite3", n=6)
    real = _bag._Ros2Reader.messages

    def messages(self, connections=()):  # type: ignore[no-untyped-def]
        for k, m in enumerate(real(self, connections)):
            if k == 5:
                raise getattr(apsw, exc_name)("database disk image is malformed")
            yield m

    monkeypatch.setattr(_bag._Ros2Reader, "messages", messages)
    assert_error(tmp_path, [str(bag)], f"unreadable or truncated recording ({exc_name}: database disk image is "
                                       f"malformed)")
