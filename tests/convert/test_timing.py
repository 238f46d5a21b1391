"""Association by header stamps only: whatever the log time does, every frame whose partners exist converts.

Real recordings: a bag re-recorded months later (log time far after header stamps), a camera with
1-1.5 s latency (images logged long after their stamps while /tf is logged at once), /tf published
late, and single frames logged out of order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.convert import ConvertConfig, convert
from psg_data.loaders import open_dataset
from tests.contract import assert_one_error

from .conftest import pose, write_bag

S = 1_000_000_000
YEAR = 365 * 86400 * S
N = 24  # frames of 100 ms


def _poses_ok(out: Path, skip: tuple[int, ...] = ()) -> None:
    scan = open_dataset(out).scan("a")
    want = [i for i in range(N) if i not in skip]
    assert len(scan) == len(want)
    stamps = 1_700_000_000_000_000_000 + np.array(want) * 100_000_000
    assert np.array_equal(scan.stamps_ns, stamps)
    for k, i in enumerate(want):
        np.testing.assert_allclose(scan.poses[k], pose(i, 0), atol=1e-9)


@pytest.mark.parametrize("fmt", ["ros1", "ros2-mcap"])
@pytest.mark.parametrize(("what", "kw"), [
    ("log time 1 year after the stamps", {"log_lag_ns": YEAR}),
    ("log time 1 year before the stamps", {"log_lag_ns": -YEAR}),
    ("camera latency 1.24 s", {"image_latency_ns": 1_240_000_000}),
    ("camera latency 1.5 s", {"image_latency_ns": 1_500_000_000}),
    ("camera latency 3 s", {"image_latency_ns": 3 * S}),
    ("/tf logged 1.2 s late", {"tf_latency_ns": 1_200_000_000}),
])
def test_every_frame_converts_whatever_the_log_time(tmp_path: Path, fmt: str, what: str, kw: dict) -> None:
    bag = write_bag(tmp_path / ("a.bag" if fmt == "ros1" else "a"), fmt, n=N, **kw)
    rep = convert(bag, tmp_path / "out")
    assert rep.frames == N and rep.skipped == {}, (what, rep.skipped)
    _poses_ok(tmp_path / "out")


def test_an_out_of_order_frame_drops_itself_only(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag", n=N, late={5: 3 * S})  # frame 5 logged 3 s late, after frame ~35
    rep = convert(bag, tmp_path / "out")
    assert rep.frames == N - 1
    assert rep.skipped_by_kind == {"color": {"out_of_order": 1}, "depth": {"no_color": 1}, "frames": {}}
    assert rep.n_skipped == 1  # the orphan depth image is not counted as a frame
    _poses_ok(tmp_path / "out", skip=(5,))


def test_a_frame_late_within_buffer_is_sorted_in(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag", n=N, late={5: 500_000_000})
    rep = convert(bag, tmp_path / "out")
    assert rep.frames == N and rep.skipped == {}
    _poses_ok(tmp_path / "out")


def test_a_larger_buffer_takes_a_later_frame(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag", n=N, late={5: 3 * S})
    rep = convert(bag, tmp_path / "out", config=ConvertConfig(buffer_s=4.0))
    assert rep.frames == N and rep.skipped == {}


def test_summary_counts_colour_depth_and_frames_apart(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag", n=N, late={5: 3 * S}, nan_pose_at=9)
    r = CliRunner().invoke(main, ["convert", str(bag), str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    assert (f"converted 1 scans, {N - 2} frames" in r.stdout and "skipped 1 colour images (out_of_order 1); "
            "1 depth images (no_color 1); 1 frames (nonfinite_pose 1)" in r.stdout), r.stdout


def test_when_nothing_converts_the_error_names_the_settings(tmp_path: Path) -> None:
    far = write_bag(tmp_path / "far.bag", n=N, depth_stamp_offset_ns=500_000_000 + 50_000_000)
    line = assert_one_error(CliRunner().invoke(main, ["convert", str(far), str(tmp_path / "o"), "-q"]))
    assert "no depth image within sync_tolerance_s = 0.02 s" in line and "the nearest was 0.050 s away" in line
    assert "--sync-tolerance" in line
    off = write_bag(tmp_path / "off.bag", n=N, tf_stamp_offset_ns=100 * S)
    line = assert_one_error(CliRunner().invoke(main, ["convert", str(off), str(tmp_path / "o"), "-q"]))
    assert "no pose within max_pose_gap_s = 0.5 s / pose_tolerance_s = 0.02 s" in line, line
    assert "pose samples span [1700000100.000, 1700000102.300] s, frames [1700000000.000, 1700000002.300] s" in line
    assert "--poses" in line and "buffer_s" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["far.bag", "off.bag"]
