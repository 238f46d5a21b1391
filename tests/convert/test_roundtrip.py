"""canonical -> raw (ROS 1, ROS 2 sqlite3, ROS 2 MCAP) -> convert gives the same dataset."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from .conftest import make_dataset

from psg_data.convert import ConvertConfig, convert
from psg_data.loaders import open_dataset
from psg_data.loaders.raw import RosRecording
from psg_data.synth._raw_export import export_raw

TABLES = ("cameras", "scans", "rooms", "receptacles", "doors", "door_states", "objects", "schedule")


def assert_same_dataset(a_root: Path, b_root: Path, *, color_exact: bool = True, jpeg_tol: float = 3.0) -> None:
    a, b = open_dataset(a_root), open_dataset(b_root)
    for t in TABLES:
        x = a.df(t).drop(columns=["source"], errors="ignore")
        y = b.df(t).drop(columns=["source"], errors="ignore")
        assert x.to_dict("records") == y.to_dict("records") if t not in ("rooms", "receptacles", "doors", "cameras") \
            else x.astype(str).equals(y.astype(str)), t
    assert a.scan_ids == b.scan_ids
    for sid in a.scan_ids:
        sa, sb = a.scan(sid), b.scan(sid)
        assert np.array_equal(sa.stamps_ns, sb.stamps_ns)
        dT = sa.poses - sb.poses
        assert np.abs(dT[:, :3, 3]).max() < 1e-6
        assert np.abs(dT[:, :3, :3]).max() < 1e-6
        for i in range(len(sa)):
            fa, fb = sa.frame(i), sb.frame(i)
            assert np.array_equal(fa.depth_m, fb.depth_m)
            if color_exact:
                assert np.array_equal(fa.color, fb.color)
            else:
                diff = np.abs(fa.color.astype(int) - fb.color.astype(int))
                assert diff.mean() <= jpeg_tol, diff.mean()


@pytest.mark.parametrize("fmt", ["ros1", "ros2-sqlite3", "ros2-mcap"])
def test_roundtrip_every_format(tmp_path: Path, tiny_dataset: Path, fmt: str) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", fmt)
    rep = convert(raw, tmp_path / "out")
    assert rep.frames == 8 and rep.n_skipped == 0 and rep.scans == ["scan_000", "scan_001"]
    assert rep.passthrough.get("depth") == 8  # compressedDepth PNG stored as is
    assert_same_dataset(tiny_dataset, tmp_path / "out")
    extra = open_dataset(tmp_path / "out").info.extra["convert"]
    assert extra["config"] == ConvertConfig().to_dict()
    assert open_dataset(tmp_path / "out").df("scans")["source"].tolist() == \
        [("scan_000.bag" if fmt == "ros1" else "scan_000"), ("scan_001.bag" if fmt == "ros1" else "scan_001")]


def test_header_stamps_not_log_times(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros2-mcap", images="raw")
    with RosRecording(raw / "scan_000") as rec:
        delays = [t - (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec)
                  for _, _, t, m in rec.messages({"/camera/color/image_raw"})]
    assert all(5_000_000 <= d <= 30_000_000 for d in delays)
    convert(raw, tmp_path / "out")
    assert np.array_equal(open_dataset(tmp_path / "out").scan("scan_000").stamps_ns,
                          open_dataset(tiny_dataset).scan("scan_000").stamps_ns)


def test_raw_only_topics_lossless(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1", images="raw")
    rep = convert(raw, tmp_path / "out")
    assert rep.passthrough == {}
    assert_same_dataset(tiny_dataset, tmp_path / "out")


def test_compressed_only_gives_jpeg_within_tolerance(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros2-sqlite3", images="compressed")
    rep = convert(raw, tmp_path / "out")
    assert open_dataset(tmp_path / "out").info.color_encoding == "jpeg"
    assert rep.passthrough == {"color": 8, "depth": 8}
    assert_same_dataset(tiny_dataset, tmp_path / "out", color_exact=False)


def test_jpeg_dataset_roundtrip_is_byte_identical(tmp_path: Path) -> None:
    src = make_dataset(tmp_path / "canon", color_encoding="jpeg")
    raw = export_raw(src, tmp_path / "raw", "ros1")
    convert(raw, tmp_path / "out", config=ConvertConfig(color_encoding="jpeg"))
    a, b = open_dataset(src), open_dataset(tmp_path / "out")
    assert b.info.color_encoding == "jpeg"
    n = 0
    for sa, sb in zip(a.scans, b.scans):
        for i in range(len(sa)):
            assert sa.image_bytes(i) == sb.image_bytes(i)  # JPEG colour and depth PNG, byte for byte
            n += 1
    assert n == len(a.df("frames")) > 0
    assert_same_dataset(src, tmp_path / "out")


@pytest.mark.parametrize("poses", ["odom:/rtabmap/odom", "tf:map->camera_color_optical_frame", "tf:odom->base_link"])
def test_pose_sources_agree(tmp_path: Path, tiny_dataset: Path, poses: str) -> None:
    from psg_data.synth._raw_export import _map_odom

    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1", images="compressed")
    convert(raw, tmp_path / "out", config=ConvertConfig(poses=poses))
    a, b = open_dataset(tiny_dataset), open_dataset(tmp_path / "out")
    for sid in a.scan_ids:
        Ta, Tb = a.scan(sid).poses, b.scan(sid).poses
        if poses.startswith("tf:map"):
            np.testing.assert_allclose(Tb, Ta, atol=1e-9)
        else:  # odometry poses live in the odom frame: map = map->odom (drifting correction) * odom
            st = a.scan(sid).stamps_ns
            exp = np.stack([np.linalg.inv(_map_odom((t - st[0]) / 1e9)) @ T for t, T in zip(st, Ta)])
            np.testing.assert_allclose(Tb, exp, atol=1e-9)
            assert not np.allclose(Ta[1:], Tb[1:], atol=1e-6)


def test_interpolated_poses_between_samples(tmp_path: Path, tiny_dataset: Path) -> None:
    """Frames between two TF samples get the slerp/lerp pose (checked against scipy)."""
    from scipy.spatial.transform import Rotation, Slerp

    from .conftest import pose, write_bag

    bag = write_bag(tmp_path / "a.bag", n=3)
    # move every colour/depth stamp by +30 ms: poses are then interpolated between TF samples
    cfg = ConvertConfig(sync_tolerance_s=0.02)
    rep = convert(bag, tmp_path / "out", config=cfg)
    assert rep.frames == 3
    Ts = open_dataset(tmp_path / "out").scan("a").poses
    np.testing.assert_allclose(Ts[1], pose(1, 0), atol=1e-9)
    sl = Slerp([0.0, 1.0], Rotation.from_matrix([pose(0, 0)[:3, :3], pose(1, 0)[:3, :3]]))
    from psg_data.loaders.raw import PoseSeries
    from psg_data.loaders.raw._transforms import matrix_to_quat_xyzw

    s = PoseSeries()
    for k in range(2):
        s.add(k * 100, pose(k, 0)[:3, 3], matrix_to_quat_xyzw(pose(k, 0)[:3, :3]))
    T = s.at(30, max_gap_ns=100, tolerance_ns=0)
    np.testing.assert_allclose(T[:3, :3], sl(0.3).as_matrix(), atol=1e-9)
    np.testing.assert_allclose(T[:3, 3], 0.7 * pose(0, 0)[:3, 3] + 0.3 * pose(1, 0)[:3, 3], atol=1e-12)
    assert s.at(30, max_gap_ns=50, tolerance_ns=0) is None  # gap too large, nearest too far


def test_config_file_and_overrides(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1")
    cfg_file = tmp_path / "c.yaml"
    cfg_file.write_text("color_topic: /camera/color/image_raw/compressed\nkeyframes: every:2\nname: fromcfg\n")
    from psg_data.convert import load_config

    cfg = load_config(cfg_file)
    rep = convert(raw, tmp_path / "out", config=cfg)
    ds = open_dataset(tmp_path / "out")
    assert ds.info.name == "fromcfg" and ds.info.color_encoding == "jpeg"  # auto: JPEG input
    assert rep.frames == 4 and rep.keyframe_dropped == 4
    stored = ConvertConfig.from_dict(ds.info.extra["convert"]["config"])
    rep2 = convert(raw, tmp_path / "out2", config=stored)  # repeatable from the manifest
    assert rep2.frames == rep.frames
    assert np.array_equal(ds.scan("scan_000").stamps_ns, open_dataset(tmp_path / "out2").scan("scan_000").stamps_ns)
    assert np.array_equal(ds.scan("scan_000").stamps_ns, open_dataset(tiny_dataset).scan("scan_000").stamps_ns[::2])


def test_keyframes_by_motion(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1", images="compressed")
    convert(raw, tmp_path / "out", config=ConvertConfig(keyframes="motion:0.2,1000"))
    a = open_dataset(tiny_dataset).scan("scan_000").poses
    kept = open_dataset(tmp_path / "out").scan("scan_000").poses
    # brute force: greedy selection on translation only
    exp, last = [0], a[0]
    for i in range(1, len(a)):
        if np.linalg.norm((np.linalg.inv(last) @ a[i])[:3, 3]) >= 0.2:
            exp.append(i)
            last = a[i]
    np.testing.assert_allclose(kept, a[exp], atol=1e-9)


def test_split_long_recording_by_gap_and_slot(tmp_path: Path) -> None:
    from .conftest import write_bag

    bag = tmp_path / "long.bag"
    write_bag(bag, n=6, period_ns=100_000_000)
    # a recording with a 2 s gap after frame 2: rebuild with two writes is awkward; use slot splitting instead
    rep = convert(bag, tmp_path / "out", config=ConvertConfig(split="slot:0.3"))
    ds = open_dataset(tmp_path / "out")
    stamps = np.concatenate([ds.scan(s).stamps_ns for s in ds.scan_ids])
    assert rep.frames == 6 and len(stamps) == 6
    slots = stamps // 300_000_000
    assert len(ds.scan_ids) == len(np.unique(slots))
    for s in ds.scan_ids:
        assert len(np.unique(ds.scan(s).stamps_ns // 300_000_000)) == 1
    rep = convert(bag, tmp_path / "out2", config=ConvertConfig(split="gap:0.05"))
    assert len(open_dataset(tmp_path / "out2").scan_ids) == 6  # every gap (0.1 s) exceeds 0.05 s
    rep = convert(bag, tmp_path / "out3", config=ConvertConfig(split="gap:0.5"))
    assert open_dataset(tmp_path / "out3").scan_ids == ["long_000"]


def test_resume_after_interruption(tmp_path: Path, tiny_dataset: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import psg_data.convert._pipeline as pl

    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1")
    real = pl.run_task
    calls: list[str] = []

    def flaky(task, progress=None, writer=None):  # type: ignore[no-untyped-def]
        calls.append(task.scan_id)
        if task.scan_id == "scan_001":
            raise KeyboardInterrupt
        return real(task, progress, writer)

    monkeypatch.setattr(pl, "run_task", flaky)
    with pytest.raises(KeyboardInterrupt):
        convert(raw, tmp_path / "out")
    assert not (tmp_path / "out").exists() and (tmp_path / "out.partial").is_dir()
    monkeypatch.setattr(pl, "run_task", real)
    calls.clear()
    monkeypatch.setattr(pl, "run_task", lambda t, p=None, w=None: (calls.append(t.scan_id), real(t, p, w))[1])
    rep = convert(raw, tmp_path / "out")
    assert calls == ["scan_001"] and rep.resumed == ["scan_000"]
    assert not (tmp_path / "out.partial").exists()
    assert_same_dataset(tiny_dataset, tmp_path / "out")
    assert not list((tmp_path / "out").rglob(".psg_convert"))


def test_resume_redoes_a_corrupted_scan(tmp_path: Path, tiny_dataset: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import psg_data.convert._pipeline as pl

    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1")
    real = pl.run_task

    def flaky(task, progress=None, writer=None):  # type: ignore[no-untyped-def]
        if task.scan_id == "scan_001":
            raise KeyboardInterrupt
        return real(task, progress, writer)

    monkeypatch.setattr(pl, "run_task", flaky)
    with pytest.raises(KeyboardInterrupt):
        convert(raw, tmp_path / "out")
    archive = tmp_path / "out.partial" / "images" / "scan_000.tar"
    data = bytearray(archive.read_bytes())
    data[1000] ^= 0xFF  # same size, other bytes: only the checksum can tell
    archive.write_bytes(bytes(data))
    monkeypatch.setattr(pl, "run_task", real)
    rep = convert(raw, tmp_path / "out")
    assert rep.resumed == []
    assert_same_dataset(tiny_dataset, tmp_path / "out")


@pytest.mark.slow
def test_jobs_two_gives_same_dataset(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros2-sqlite3")
    rep = convert(raw, tmp_path / "out", jobs=2)
    assert rep.frames == 8
    assert_same_dataset(tiny_dataset, tmp_path / "out")


def test_export_overwrite_and_side_files(tmp_path: Path, tiny_dataset: Path) -> None:
    from psg_data.errors import DatasetExistsError

    out = export_raw(tiny_dataset, tmp_path / "raw", "ros1")
    with pytest.raises(DatasetExistsError, match="exists"):
        export_raw(tiny_dataset, out, "ros1")
    export_raw(tiny_dataset, out, "ros1", overwrite=True)
    site = json.loads((out / "site.json").read_text())
    assert site["cameras"] == [{"camera_id": "cam0", "frame_id": "camera_color_optical_frame"}]
    assert {r["receptacle_id"] for r in site["receptacles"]} == {"table1", "shelf1"}
    assert (out / "schedule.csv").read_text().splitlines()[0] == "scan_id,object_id,receptacle_id"


def test_write_failure_is_one_line_and_resumable(tmp_path: Path, tiny_dataset: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """An OS error while writing (here: the disk fills up during the second scan's archive) ends
    the CLI with one ``error:`` line and exit code 1, keeps the finished scans, and a rerun resumes."""
    import errno

    from click.testing import CliRunner

    import psg_data.writers._tar_archive as ta
    from psg_data.cli.psg_data_cmd import main

    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1")
    real_write = ta.TarArchiveWriter._write

    def full_disk(self, *args):  # type: ignore[no-untyped-def]
        if self.path.endswith("scan_001.tar"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(self, *args)

    monkeypatch.setattr(ta.TarArchiveWriter, "_write", full_disk)
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["convert", str(raw), str(out), "-q", "-j", "1"])
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.exit_code == 1 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("error: ") and "scan_001.tar" in lines[0] and "No space left" in lines[0]
    assert "rerun the same command to resume" in lines[0]
    assert not out.exists() and (tmp_path / "out.partial").is_dir()
    monkeypatch.setattr(ta.TarArchiveWriter, "_write", real_write)
    rep = convert(raw, out)
    assert rep.resumed == ["scan_000"]
    assert_same_dataset(tiny_dataset, out)
