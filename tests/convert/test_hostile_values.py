"""Values a user can type or a recording can hold, refused in one line before any work (issue 28).

D2/D3: TUM stamps that are not finite or beyond int64 nanoseconds (in every list file and a
``--poses tum:FILE``), ScanNet stamps beyond the range; D4/D5: option and config values that
crashed or silently produced unusable data. Each: exit 1, one ``error:`` line naming the file or
key, the value and what is allowed, and nothing written.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main as psg_data
from tests.contract import assert_one_error
from tests.convert.conftest import CAMERA, images, pose
from tests.convert.test_folders import make_tum

BAD_STAMPS = ["nan", "inf", "-Infinity", "1e999999", "91628069033.66", "-5"]


@pytest.fixture
def tum(tmp_path: Path) -> Path:
    d = tmp_path / "fr1"
    make_tum(d, n=3)
    (d / "intrinsics.txt").write_text(f"{CAMERA.fx} {CAMERA.fy} {CAMERA.cx} {CAMERA.cy}\n")
    return d


def _scannet(d: Path, n: int = 3) -> Path:
    for sub in ("color", "depth", "pose", "intrinsic"):
        (d / sub).mkdir(parents=True)
    K = np.eye(4)
    K[0, 0], K[1, 1], K[0, 2], K[1, 2] = CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy
    np.savetxt(d / "intrinsic" / "intrinsic_depth.txt", K)
    for i in range(n):
        c, dm = images(i, 0)
        cv2.imwrite(str(d / "color" / f"{i}.jpg"), cv2.cvtColor(c, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(d / "depth" / f"{i}.png"), dm)
        np.savetxt(d / "pose" / f"{i}.txt", pose(i, 0))
    return d


def _run(args: list[str]) -> object:
    return CliRunner().invoke(psg_data, ["convert", *args, "--quiet"])


def _nothing_left(out: Path) -> None:
    assert sorted(p.name for p in out.parent.iterdir() if p.name.startswith((out.name, f".{out.name}"))) == []


def _replace_stamp(path: Path, row: int, stamp: str) -> int:
    """Replace the stamp of the ``row``-th data line of a TUM list file; returns its line number."""
    lines = path.read_text().splitlines()
    data = [k for k, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    k = data[row]
    lines[k] = " ".join([stamp, *lines[k].split()[1:]])
    path.write_text("\n".join(lines) + "\n")
    return k + 1


@pytest.mark.parametrize("name", ["rgb.txt", "depth.txt", "groundtruth.txt", "poses"])
@pytest.mark.parametrize("stamp", BAD_STAMPS)
def test_tum_stamps_not_finite_or_out_of_range(tum: Path, tmp_path: Path, name: str, stamp: str) -> None:
    extra: list[str] = []
    if name == "poses":
        f = tmp_path / "traj.txt"
        f.write_text((tum / "groundtruth.txt").read_text())
        extra = ["--poses", f"tum:{f}"]
    else:
        f = tum / name
    line = _replace_stamp(f, 1, stamp)
    out = tmp_path / "out"
    r = _run([str(tum), str(out), *extra])
    msg = assert_one_error(r, f"{f}:{line}: expected a timestamp in seconds")
    assert repr(stamp) in msg
    _nothing_left(out)


def test_scannet_start_stamp_beyond_int64(tmp_path: Path) -> None:
    d = _scannet(tmp_path / "scene0000_00")
    cfg = tmp_path / "c.yaml"
    cfg.write_text("start_stamp_ns: 99999999999999999999\n")
    r = _run([str(d), str(tmp_path / "out"), "--config", str(cfg)])
    assert_one_error(r, "start_stamp_ns: expected an integer in [0, 4611686018427387904], got 99999999999999999999")
    _nothing_left(tmp_path / "out")


def test_scannet_last_stamp_beyond_range_names_the_folder(tmp_path: Path) -> None:
    d = _scannet(tmp_path / "scene0000_00")
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"start_stamp_ns: {2**62 - 10}\n")
    r = _run([str(d), str(tmp_path / "out"), "--config", str(cfg)])
    assert_one_error(r, f"{d}: frame 2 would be stamped")
    _nothing_left(tmp_path / "out")


OPTIONS = [  # (command-line options, text the one error line holds)
    (["--sync-tolerance", "inf"], "--sync-tolerance (sync_tolerance_s): expected a finite number in [0, 31536000], "
                                  "got inf"),
    (["--sync-tolerance", "1e308"], "--sync-tolerance (sync_tolerance_s): expected a finite number"),
    (["--sync-tolerance", "nan"], "--sync-tolerance (sync_tolerance_s): expected a finite number"),
    (["--split", "gap:inf"], "--split (split): expected gap:SECONDS or slot:SECONDS"),
    (["--split", "slot:inf"], "--split (split): expected gap:SECONDS or slot:SECONDS"),
    (["--split", "slot:1e-300"], "--split (split): expected gap:SECONDS or slot:SECONDS"),
    (["--depth-scale", "inf"], "--depth-scale (depth_scale_m): expected a finite number in [1e-06, 1]"),
    (["--depth-scale", "1e-300"], "--depth-scale (depth_scale_m): expected a finite number in [1e-06, 1]"),
    (["--keyframes", "motion:nan,nan"], "--keyframes (keyframes): expected every:N"),
    (["--keyframes", "every:99999999999999999999"], "--keyframes (keyframes): expected every:N"),
]


@pytest.mark.parametrize(("opts", "match"), OPTIONS, ids=[" ".join(o) for o, _ in OPTIONS])
def test_bad_option_values(tum: Path, tmp_path: Path, opts: list[str], match: str) -> None:
    out = tmp_path / "out"
    line = assert_one_error(_run([str(tum), str(out), *opts]), match)
    assert line.startswith("error: command line: ")
    _nothing_left(out)


CONFIGS = [  # (config file text, text the one error line holds)
    ("buffer_s: .inf\n", "buffer_s: expected a finite number in [0, 31536000], got inf"),
    ("sync_tolerance_s: .inf\n", "sync_tolerance_s: expected a finite number in [0, 31536000], got inf"),
    ("start_stamp_ns: .nan\n", "start_stamp_ns: expected an integer in [0, 4611686018427387904], got nan"),
    ("start_stamp_ns: abc\n", "start_stamp_ns: expected an integer in [0, 4611686018427387904], got 'abc'"),
    ("fps: 1e-300\n", "fps: expected a finite number in [0.001, 1000000], got 1e-300"),
    ("fps: .inf\n", "fps: expected a finite number in [0.001, 1000000], got inf"),
    ("fps: 0\n", "fps: expected a finite number in [0.001, 1000000], got 0"),
    ("static_transforms: [{parent: a, child: b, translation: [1, 2], rotation_xyzw: [0, 0, 0, 1]}]\n",
     "static_transforms: expected a list of {parent: FRAME"),
    ("static_transforms: 5\n", "static_transforms: expected a list of {parent: FRAME"),
    ("static_transforms: [5]\n", "item 0 is not such a mapping"),
    ("camera_frame: [a, b]\n", "camera_frame: expected a text or none, got ['a', 'b']"),
    ("timezone: Mars/Olympus\n", "timezone: expected an IANA time zone name"),
    ("keyframes: 'motion:nan,nan'\n", "keyframes: expected every:N"),
    ("intrinsics: [1, 2, .nan, 4]\n", "intrinsics: expected a list of 4 finite numbers"),
    ("strict: 1\n", "strict: expected true or false, got 1"),
    ("depth_scale_m: .inf\n", "depth_scale_m: expected a finite number in [1e-06, 1] or none, got inf"),
    (f"start_stamp_ns: {10**400}\n", "start_stamp_ns: expected an integer in [0, 4611686018427387904], got 1000"),
]


@pytest.mark.parametrize(("text", "match"), CONFIGS, ids=[t.strip()[:40] for t, _ in CONFIGS])
def test_bad_config_values(tum: Path, tmp_path: Path, text: str, match: str) -> None:
    cfg = tmp_path / "c.yaml"
    cfg.write_text(text)
    out = tmp_path / "out"
    line = assert_one_error(_run([str(tum), str(out), "--config", str(cfg)]), match)
    assert line.startswith(f"error: {cfg}: ") and len(line) < 400
    _nothing_left(out)


def test_site_file_timezone_is_checked(tum: Path, tmp_path: Path) -> None:
    (tum / "site.json").write_text('{"name": "lab", "timezone": "Mars/Olympus"}')
    out = tmp_path / "out"
    r = _run([str(tum), str(out), "--side-dir", str(tum)])
    assert_one_error(r, f"{tum / 'site.json'}: timezone: expected an IANA time zone name")
    _nothing_left(out)


def test_the_same_check_for_flag_and_key(tum: Path, tmp_path: Path) -> None:
    cfg = tmp_path / "c.yaml"
    cfg.write_text("sync_tolerance_s: .inf\n")
    by_key = assert_one_error(_run([str(tum), str(tmp_path / "o1"), "--config", str(cfg)]))
    by_flag = assert_one_error(_run([str(tum), str(tmp_path / "o2"), "--sync-tolerance", "inf"]))
    assert by_key.split("sync_tolerance_s", 1)[1] == by_flag.split("sync_tolerance_s)", 1)[1]


# -- the minor messages ---------------------------------------------------------------------------


def test_groundtruth_with_only_a_comment_is_not_called_missing(tum: Path, tmp_path: Path) -> None:
    (tum / "groundtruth.txt").write_text("# timestamp tx ty tz qx qy qz qw\n")
    r = _run([str(tum), str(tmp_path / "out")])
    assert_one_error(r, f"{tum / 'groundtruth.txt'}: lists no poses; expected 'timestamp tx ty tz qx qy qz qw'")


def test_tum_folder_without_depth_list(tum: Path, tmp_path: Path) -> None:
    (tum / "depth.txt").unlink()
    assert_one_error(_run([str(tum), str(tmp_path / "out")]), f"{tum / 'depth.txt'}: missing; expected a TUM RGB-D")
    assert_one_error(_run([str(tum.parent), str(tmp_path.parent / f"{tmp_path.name}-out")]),
                     f"{tum / 'depth.txt'}: missing")


def test_size_mismatch_names_the_file(tum: Path, tmp_path: Path) -> None:
    first = sorted((tum / "depth").iterdir())[1]
    cv2.imwrite(str(first), np.zeros((10, 12), np.uint16))
    r = _run([str(tum), str(tmp_path / "out")])
    assert_one_error(r, f"{first}: 12x10 pixels, expected the camera's 32x24 (depth image); not decoded")


def test_out_of_order_warning_names_buffer_s(tmp_path: Path) -> None:
    from tests.convert.conftest import write_bag

    bag = write_bag(tmp_path / "a.bag", n=40, late={5: 3_000_000_000})  # logged after frame ~35
    r = CliRunner().invoke(psg_data, ["convert", str(bag), str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    assert "out_of_order" in r.stderr and "raise buffer_s with --config" in r.stderr, r.stderr


def test_every_config_key_is_declared() -> None:
    """A key added to ConvertConfig without a declaration would go unchecked: this keeps them together."""
    from dataclasses import fields

    from psg_data.convert import CONVERT_SETTINGS, ConvertConfig

    assert {f.name for f in fields(ConvertConfig)} == set(CONVERT_SETTINGS)
