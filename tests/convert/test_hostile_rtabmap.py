"""RTAB-Map databases crafted as an attacker would (issue 46, families A-C): decompression and decode
bombs refused before they inflate (peak memory measured in a child process), hostile node values
refused at convert with one ``error:`` line, and the input folder never written to (WAL databases,
read-only folders)."""

from __future__ import annotations

import json
import os
import sqlite3
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import psg_data
from psg_data.cli.psg_data_cmd import main
from psg_data.schemas._image_headers import MAX_IMAGE_PIXELS

from .rtabmap_writer import camera_blob
from .test_rtabmap import LOCAL, _assert_error, _edit, lab, lab_database  # noqa: F401  (the lab fixture)

_ROOT = Path(psg_data.__file__).resolve().parents[1]

_PROBE = r"""
import resource, sys
import numpy, cv2, sqlite3, zlib, pyarrow, pyarrow.parquet, pandas
import psg_data.convert, psg_data.convert._rtabmap, psg_data.writers, psg_data.schemas.validate
from psg_data.cli.psg_data_cmd import main
status = open('/proc/self/status').read()
vm = int(status.split('VmSize:')[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + (1 << 30), resource.RLIM_INFINITY))  # protects the machine
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
code = 0
try:
    main(sys.argv[2:])
except SystemExit as exc:
    code = exc.code
finally:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    open(sys.argv[1], 'w').write(f'{(peak - base) / 1024:.1f} {code}')
sys.exit(code)
"""


def _convert_measured(tmp_path: Path, db: Path) -> tuple[float, subprocess.CompletedProcess[str]]:
    """``psg-data convert DB OUT`` in a child process: (peak resident memory above the baseline
    after imports in MB, the finished process); address space capped 1 GiB above that baseline."""
    report = tmp_path / "peak.txt"
    env = {**os.environ, "PYTHONPATH": str(_ROOT), "MALLOC_ARENA_MAX": "2"}
    proc = subprocess.run([sys.executable, "-c", _PROBE, str(report), "convert", str(db), str(tmp_path / "out"),
                           "-q"], env=env, capture_output=True, text=True, timeout=600)
    peak = float(report.read_text().split()[0]) if report.exists() else float("inf")
    return peak, proc


def _assert_refused_bounded(tmp_path: Path, src: Path, match: str) -> None:
    """One error line, peak memory < 200 MB above the baseline, the input's folder unchanged, no output."""
    folder = src if src.is_dir() else src.parent
    before = sorted(p.name for p in folder.iterdir())
    peak, proc = _convert_measured(tmp_path, src)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    print(f"peak resident memory above baseline: {peak} MB")
    assert peak < 200, f"peak memory {peak} MB above baseline; {proc.stderr[-300:]}"
    assert proc.returncode == 1 and len(lines) == 1 and lines[0].startswith("error: "), proc.stderr[-3000:]
    assert match in lines[0], lines[0]
    assert sorted(p.name for p in folder.iterdir()) == before
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.partial").exists()


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bomb(width: int, height: int, bits: int, color_type: int) -> bytes:
    """A valid PNG of ``width`` x ``height`` zero pixels, built row by row (its raw size never in memory)."""
    channels = {0: 1, 2: 3, 6: 4}[color_type]
    row = bytes(1 + width * channels * bits // 8)
    c = zlib.compressobj(9)
    idat = b"".join(c.compress(row) for _ in range(height)) + c.flush()
    ihdr = struct.pack(">IIBBBBB", width, height, bits, color_type, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")


def zlib_bomb(n_bytes: int) -> bytes:
    """``n_bytes`` zeros as one zlib stream (about n_bytes / 1000 bytes)."""
    c = zlib.compressobj(9)
    piece = bytes(1 << 20)
    return b"".join(c.compress(piece) for _ in range(n_bytes >> 20)) + c.flush()


@pytest.fixture()
def small_db(tmp_path: Path, lab: Path) -> Path:  # noqa: F811
    d = tmp_path / "in"
    d.mkdir()
    return lab_database(lab, d / "map.db", "0.23.0", sessions=1)[0]


def _node_count(db: Path) -> int:
    con = sqlite3.connect(db)
    (n,) = con.execute("SELECT COUNT(*) FROM Node").fetchone()
    con.close()
    return int(n)


# ---- A: bounded decoding ----


def test_opt_poses_zlib_bomb_is_refused_before_inflating(tmp_path: Path, small_db: Path) -> None:
    """512 MB of zeros in Admin.opt_poses (a 0.5 MB stream) behind a trailer declaring 3 nodes' poses."""
    bomb = zlib_bomb(512 << 20) + struct.pack("<3i", 1, 12 * _node_count(small_db), 5)
    _edit(small_db, "UPDATE Admin SET opt_poses = ?", args=(bomb,))
    assert small_db.stat().st_size < 2 << 20
    _assert_refused_bounded(tmp_path, small_db, "Admin.opt_poses: zlib stream inflates to more than")


def test_opt_poses_trailer_declaring_gigabytes_is_refused(tmp_path: Path, small_db: Path) -> None:
    """A trailer that declares a 3 GB matrix (the zlib bomb honest about its size)."""
    bomb = zlib_bomb(64 << 20) + struct.pack("<3i", 1, 750_000_000, 5)
    _edit(small_db, "UPDATE Admin SET opt_poses = ?", args=(bomb,))
    _assert_refused_bounded(tmp_path, small_db, "Admin.opt_poses: matrix trailer declares")


def test_float_depth_png_bomb_is_refused_before_decoding(tmp_path: Path, small_db: Path) -> None:
    """A 12000 x 12000 8-bit RGBA PNG (RTAB-Map's float depth) of 0.6 MB: 576 MB decoded, 2 GB as floats."""
    _edit(small_db, "UPDATE Data SET depth = ? WHERE id = 2", args=(png_bomb(12000, 12000, 8, 6),))
    _assert_refused_bounded(tmp_path, small_db, "node 2: Data.depth: 12000x12000")


def test_rvl_blob_longer_than_its_pixels_is_refused_before_decoding(tmp_path: Path, small_db: Path) -> None:
    """An RVL header for the camera's 64 x 48 pixels followed by 8 MB of words."""
    blob = b"DEPTHRVL" + struct.pack("<2I", 64, 48) + bytes(8 << 20)
    _edit(small_db, "UPDATE Data SET depth = ? WHERE id = 2", args=(blob,))
    _assert_refused_bounded(tmp_path, small_db, "node 2: Data.depth: RVL data of 8388608 bytes")


def test_rvl_header_larger_than_the_camera_is_refused(tmp_path: Path, small_db: Path) -> None:
    blob = b"DEPTHRVL" + struct.pack("<2I", 16000, 16000) + bytes(64)
    _edit(small_db, "UPDATE Data SET depth = ? WHERE id = 2", args=(blob,))
    _assert_error(tmp_path, small_db, "node 2: Data.depth: RVL image of 16000x16000: 16000x16000 = ")


def test_colour_png_bomb_is_refused_before_decoding(tmp_path: Path, small_db: Path) -> None:
    """A 12000 x 12000 8-bit grey PNG in Data.image (not passed through: decoded, 144 MB, then made RGB)."""
    _edit(small_db, "UPDATE Data SET image = ? WHERE id = 2", args=(png_bomb(12000, 12000, 8, 0),))
    _assert_refused_bounded(tmp_path, small_db, "node 2: Data.image: 12000x12000")


def test_camera_over_the_pixel_cap_is_refused_at_convert(tmp_path: Path, lab: Path) -> None:  # noqa: F811
    """A calibration declaring 8200 x 8200 pixels (over 2^26) with images of that size (0.3 MB each)."""
    assert 8200 * 8200 > MAX_IMAGE_PIXELS
    d = tmp_path / "in"
    d.mkdir()
    db = lab_database(lab, d / "map.db", "0.18.0", sessions=1)[0]
    color, depth = png_bomb(8200, 8200, 8, 2), png_bomb(8200, 8200, 16, 0)
    calib = camera_blob("0.18.0", 4000.0, 4000.0, 4099.5, 4099.5, 8200, 8200, LOCAL)
    _edit(db, "UPDATE Data SET image = ?, depth = ?, calibration = ?", args=(color, depth, calib))
    _assert_refused_bounded(tmp_path, db, "Data.calibration: width/height: image size 8200x8200")


def test_folder_camera_over_the_pixel_cap_is_refused_at_convert(tmp_path: Path) -> None:
    """The same rule for a frame folder: its camera's size is its images' (8200 x 8200, 0.3 MB each)."""
    from .conftest import CAMERA
    from .test_folders import make_tum

    d = tmp_path / "fr1"
    make_tum(d, n=2)
    (d / "intrinsics.txt").write_text(f"{CAMERA.fx} {CAMERA.fy} {CAMERA.cx} {CAMERA.cy}\n")
    color, depth = png_bomb(8200, 8200, 8, 2), png_bomb(8200, 8200, 16, 0)
    for f in (d / "rgb").iterdir():
        f.write_bytes(color)
    for f in (d / "depth").iterdir():
        f.write_bytes(depth)
    _assert_refused_bounded(tmp_path, d, "width/height: image size 8200x8200")


# ---- B: hostile values: one error line, nothing left ----


@pytest.mark.parametrize("stamp", [1e300, 1.0e10, -5.0], ids=["1e300", "year-2286", "negative"])
def test_node_stamp_out_of_range(tmp_path: Path, small_db: Path, stamp: float) -> None:
    _edit(small_db, "UPDATE Node SET stamp = ? WHERE id = 2", args=(stamp,))
    _assert_error(tmp_path, small_db, "node 2: Node.stamp")


def test_duplicate_node_stamps(tmp_path: Path, small_db: Path) -> None:
    _edit(small_db, "UPDATE Node SET stamp = (SELECT stamp FROM Node WHERE id = 1) WHERE id = 3")
    _assert_error(tmp_path, small_db, "node 3: Node.stamp")


def test_all_zero_node_stamps(tmp_path: Path, small_db: Path) -> None:
    _edit(small_db, "UPDATE Node SET stamp = 0")
    _assert_error(tmp_path, small_db, "node 2: Node.stamp")


def test_nan_distortion(tmp_path: Path, small_db: Path) -> None:
    calib = camera_blob("0.23.0", 50.0, 50.0, 31.5, 23.5, 64, 48, LOCAL, (0.1, float("nan"), 0.0, 0.0, 0.0))
    _edit(small_db, "UPDATE Data SET calibration = ?", args=(calib,))
    _assert_error(tmp_path, small_db, "Data.calibration: distortion")


def test_null_pose_linked_in_the_pose_graph(tmp_path: Path, small_db: Path) -> None:
    """No optimised graph; node 2 has no pose but links to node 1; node 3 is linked to nothing."""
    _edit(small_db, "UPDATE Admin SET opt_ids = NULL, opt_poses = NULL", "UPDATE Node SET pose = NULL WHERE id = 2",
          "DELETE FROM Link WHERE from_id = 3 OR to_id = 3")
    res = CliRunner().invoke(main, ["convert", str(small_db), str(tmp_path / "out")])
    assert res.exit_code == 0 and "Traceback" not in res.output, res.output
    assert "the links do not connect every node" in res.stderr
    manifest = json.loads((tmp_path / "out" / "dataset.json").read_text())
    assert manifest["counts"]["frames"] == 2


@pytest.mark.parametrize("sql, match, bag_only", [
    ("UPDATE Data SET depth = NULL", "Data.depth", ("--sync-tolerance", "--depth-topic")),
    ("UPDATE Admin SET opt_ids = ?, opt_poses = ?", "Admin.opt_poses", ("--poses", "buffer_s")),
], ids=["no-depth", "no-pose"])
def test_hints_name_no_bag_only_option(tmp_path: Path, small_db: Path, sql: str, match: str,
                                       bag_only: tuple[str, ...]) -> None:
    from .rtabmap_writer import compress_data

    args = (compress_data(np.array([[99]], np.int32)), compress_data(np.eye(4, dtype=np.float32)[:3].reshape(1, 12)))
    _edit(small_db, sql, args=args if "?" in sql else ())
    res = CliRunner().invoke(main, ["convert", str(small_db), str(tmp_path / "out"), "-q"])
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.exit_code == 1 and len(lines) == 1 and match in lines[0], res.stderr
    assert not any(opt in lines[0] for opt in bag_only), lines[0]


def test_long_database_name_leaves_nothing(tmp_path: Path, small_db: Path) -> None:
    """A 250-character stem: the scan id, whose files (``.scans/ID.arrow``) would exceed NAME_MAX."""
    db = small_db.rename(small_db.with_name("s" * 250 + ".db"))
    _assert_error(tmp_path, db, "scan id of 250 bytes")


# ---- C: the input is opened strictly read-only ----


def _to_wal(db: Path) -> None:
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA journal_mode=WAL").fetchone()[0] == "wal"
    con.close()


def test_wal_database_gets_no_side_files(tmp_path: Path, small_db: Path) -> None:
    _to_wal(small_db)
    before = sorted(p.name for p in small_db.parent.iterdir())
    assert before == ["map.db"]
    res = CliRunner().invoke(main, ["convert", str(small_db), str(tmp_path / "out"), "-q"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in small_db.parent.iterdir()) == before


def test_wal_database_in_a_read_only_folder(tmp_path: Path, small_db: Path) -> None:
    _to_wal(small_db)
    small_db.chmod(0o444)
    small_db.parent.chmod(0o555)  # as root the folder stays writable: the listing below still checks it
    try:
        res = CliRunner().invoke(main, ["convert", str(small_db), str(tmp_path / "out"), "-q"])
        listing = sorted(p.name for p in small_db.parent.iterdir())
    finally:
        small_db.parent.chmod(0o755)
    assert res.exit_code == 0 and "damaged" not in res.output, res.output
    assert listing == ["map.db"]


def test_wal_with_unwritten_transactions_is_refused(tmp_path: Path, small_db: Path) -> None:
    """RTAB-Map still has the map open: its last transactions are only in map.db-wal, which an
    immutable reader would not see."""
    _to_wal(small_db)
    con = sqlite3.connect(small_db)
    con.execute("PRAGMA wal_autocheckpoint=0")
    con.execute("UPDATE Node SET label = 'late' WHERE id = 1")
    con.commit()
    try:
        before = sorted(p.name for p in small_db.parent.iterdir())
        assert "map.db-wal" in before
        _assert_error(tmp_path, small_db, "map.db-wal holds transactions not yet written")
        assert sorted(p.name for p in small_db.parent.iterdir()) == before
    finally:
        con.close()


def test_rvl_decoded_block_by_block_equals_the_image() -> None:
    """Bounded RVL decoding (blocks of words, values cut across block ends) against the test
    writer's encoder on an image of more than 2 blocks, with runs of zeros and large deltas."""
    from psg_data.loaders.raw._rtabmap import _RVL_BLOCK_WORDS, decode_depth

    from .rtabmap_writer import rvl_blob

    rng = np.random.default_rng(3)
    depth = rng.integers(0, 65536, (480, 640)).astype(np.uint16)
    depth[rng.random(depth.shape) < 0.3] = 0
    depth[50:80] = 0
    blob = rvl_blob(depth)
    assert (len(blob) - 16) // 4 > 2 * _RVL_BLOCK_WORDS
    out = decode_depth(blob, "x", (640, 480))
    assert out is not None and np.array_equal(out, depth)
