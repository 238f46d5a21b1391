"""The validator: a good dataset is OK; each corruption gives one clear line and exit 1."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.schemas.validate import validate_dataset
from psg_data.writers import sha256_file


def _run(*args: str) -> tuple[int, str, str]:
    res = CliRunner().invoke(main, list(args))
    return res.exit_code, res.stdout, res.stderr


def _rewrite_table(root: Path, name: str, fn: Callable[[pa.Table], pa.Table], *, fix_checksums: bool = True) -> None:
    """Modify a table and (by default) re-register its checksum so only the intended problem remains."""
    p = root / f"tables/{name}.parquet"
    pq.write_table(fn(pq.read_table(p)), p)
    if fix_checksums:
        _refresh_checksum(root, f"tables/{name}.parquet")


def _refresh_checksum(root: Path, rel: str) -> None:
    fp = root / "tables/files.parquet"
    files = pq.read_table(fp).to_pylist()
    p = root / rel
    for f in files:
        if f["path"] == rel:
            f["size_bytes"] = p.stat().st_size
            f["sha256"] = sha256_file(p)
    pq.write_table(pa.Table.from_pylist(files, schema=pq.read_schema(fp)), fp)
    m = json.loads((root / "dataset.json").read_text())
    m["files_sha256"] = sha256_file(fp)
    (root / "dataset.json").write_text(json.dumps(m))


def _set_cell(table: pa.Table, column: str, row: int, value: object) -> pa.Table:
    values = table.column(column).to_pylist()
    values[row] = value
    idx = table.column_names.index(column)
    return table.set_column(idx, table.schema.field(column), pa.array(values, type=table.schema.field(column).type))


def test_good_dataset_ok(make_dataset) -> None:
    root = make_dataset()
    code, out, _ = _run("validate", str(root))
    assert code == 0 and out.strip() == "OK"


def _corrupt_missing_table(root: Path) -> None:
    (root / "tables/doors.parquet").unlink()


def _corrupt_wrong_type(root: Path) -> None:
    _rewrite_table(root, "frames", lambda t: t.set_column(
        t.column_names.index("stamp_ns"), "stamp_ns", t.column("stamp_ns").cast(pa.string())))


def _corrupt_dangling(root: Path) -> None:
    _rewrite_table(root, "schedule", lambda t: _set_cell(t, "receptacle_id", 0, "sofa"))


def _corrupt_truncated(root: Path) -> None:
    p = root / "tables/receptacles.parquet"
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])


def _corrupt_checksum(root: Path) -> None:
    p = root / "images/scan_001/color/000002.png"
    img = cv2.imread(str(p))
    img[0, 0] = 255 - img[0, 0]
    cv2.imwrite(str(p), img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    # same size is unlikely; force equal size so only the checksum can catch it
    data = bytearray((root / "images/scan_001/color/000002.png").read_bytes())
    _ = data


def _corrupt_stamps(root: Path) -> None:
    _rewrite_table(root, "frames", lambda t: _set_cell(t, "stamp_ns", 2, t.column("stamp_ns")[0].as_py()))


def _corrupt_nan_pose(root: Path) -> None:
    def fn(t: pa.Table) -> pa.Table:
        T = t.column("T_world_camera").to_pylist()
        T[5][3] = float("nan")
        return t.set_column(t.column_names.index("T_world_camera"), t.schema.field("T_world_camera"),
                            pa.array(T, type=t.schema.field("T_world_camera").type))
    _rewrite_table(root, "frames", fn)


def _corrupt_rotation(root: Path) -> None:
    def fn(t: pa.Table) -> pa.Table:
        R = t.column("rotation").to_pylist()
        R[1] = [1.0, 0.2, 0, 0, 1, 0, 0, 0, 1]
        return t.set_column(t.column_names.index("rotation"), t.schema.field("rotation"),
                            pa.array(R, type=t.schema.field("rotation").type))
    _rewrite_table(root, "receptacles", fn)


def _corrupt_extent(root: Path) -> None:
    def fn(t: pa.Table) -> pa.Table:
        E = t.column("extent_m").to_pylist()
        E[2] = [1.0, -0.5, 0.7]
        return t.set_column(t.column_names.index("extent_m"), t.schema.field("extent_m"),
                            pa.array(E, type=t.schema.field("extent_m").type))
    _rewrite_table(root, "receptacles", fn)


def _corrupt_depth_dtype(root: Path) -> None:
    rel = "images/scan_000/depth/000001.png"
    cv2.imwrite(str(root / rel), np.zeros((24, 32), np.uint8))
    _refresh_checksum(root, rel)


def _corrupt_depth_size(root: Path) -> None:
    rel = "images/scan_000/depth/000003.png"
    cv2.imwrite(str(root / rel), np.zeros((12, 16), np.uint16))
    _refresh_checksum(root, rel)


def _corrupt_missing_image(root: Path) -> None:
    (root / "images/scan_002/depth/000000.png").unlink()


def _corrupt_newer_manifest(root: Path) -> None:
    m = json.loads((root / "dataset.json").read_text())
    m["format_version"] = "3.0"
    (root / "dataset.json").write_text(json.dumps(m))


CORRUPTIONS = {
    "missing table": (_corrupt_missing_table, r"^tables/doors\.parquet: file: missing table 'doors'"),
    "wrong column type": (_corrupt_wrong_type, r"^tables/frames\.parquet: stamp_ns: wrong type string, expected int64"),
    "dangling id": (_corrupt_dangling, r"^tables/schedule\.parquet:0: receptacle_id: dangling id 'sofa'"),
    "truncated parquet": (_corrupt_truncated, r"^tables/receptacles\.parquet: file: not a readable Parquet file"),
    "checksum mismatch": (_corrupt_checksum, r"^images/scan_001/color/000002\.png: (sha256: checksum mismatch|size_bytes)"),
    "non-increasing stamps": (_corrupt_stamps, r"^tables/frames\.parquet:2: stamp_ns: must increase within scan 'scan_000'"),
    "NaN pose": (_corrupt_nan_pose, r"^tables/frames\.parquet:5: T_world_camera: contains NaN"),
    "non-orthonormal rotation": (_corrupt_rotation, r"^tables/receptacles\.parquet:1: rotation: rotation is not orthonormal"),
    "negative extent": (_corrupt_extent, r"^tables/receptacles\.parquet:2: extent_m: \[1\.0, -0\.5, 0\.7\], expected three positive"),
    "depth dtype": (_corrupt_depth_dtype, r"^images/scan_000/depth/000001\.png: dtype: png uint8 .* expected a 16-bit single-channel PNG"),
    "depth size": (_corrupt_depth_size, r"^images/scan_000/depth/000003\.png: size: 16x12, expected the camera's 32x24"),
    "missing image": (_corrupt_missing_image, r"^images/scan_002/depth/000000\.png: file: missing"),
    "newer manifest": (_corrupt_newer_manifest, r"^dataset\.json: format_version: 3\.0 is newer than this psg-data reads"),
}


@pytest.mark.parametrize("name", sorted(CORRUPTIONS))
def test_each_corruption_one_clear_line(make_dataset, name: str) -> None:
    import re

    root = make_dataset(image_layout="files")
    corrupt, pattern = CORRUPTIONS[name]
    corrupt(root)
    code, out, err = _run("validate", str(root))
    assert code == 1, out
    lines = out.strip().splitlines()
    assert lines, "no problem printed"
    assert any(re.search(pattern, ln) for ln in lines), lines
    assert "Traceback" not in out + err
    # the corruption is reported exactly once (no cascade of lines for one cause),
    # except a missing image, which is also missing from the checksum list's point of view
    matching = [ln for ln in lines if re.search(pattern, ln)]
    assert len(matching) == 1, lines
    assert len(lines) <= 2, lines


def test_problem_lines_have_the_documented_shape(make_dataset) -> None:
    root = make_dataset()
    _corrupt_extent(root)
    _corrupt_dangling(root)
    problems = validate_dataset(root)
    assert len(problems) == 2
    for p in problems:
        file_part, field, rest = str(p).split(": ", 2)
        assert file_part.startswith("tables/") and field and "expected" in rest or "dangling" in rest


def test_stray_file_and_counts(make_dataset) -> None:
    root = make_dataset(image_layout="files")
    (root / "images/scan_000/notes.txt").write_text("hello")
    problems = [str(p) for p in validate_dataset(root)]
    assert problems == ["images/scan_000/notes.txt: file: not listed in tables/files.parquet "
                        "(stray file; rewrite the dataset to register it)"]


def test_files_table_tampering_detected(make_dataset) -> None:
    root = make_dataset()
    fp = root / "tables/files.parquet"
    t = pq.read_table(fp)
    pq.write_table(t.slice(0, t.num_rows - 1), fp)  # drop one entry to hide a file
    problems = [str(p) for p in validate_dataset(root)]
    assert any(p.startswith("tables/files.parquet: sha256: checksum") for p in problems)


def test_quick_mode_skips_content_checksums(make_dataset) -> None:
    root = make_dataset(image_layout="files")
    p = root / "images/scan_001/depth/000000.png"
    data = bytearray(p.read_bytes())
    data[-20] ^= 0xFF  # same size, different content (inside IDAT/IEND crc)
    p.write_bytes(bytes(data))
    damaged = ("images/scan_001/depth/000000.png: image: corrupt PNG: chunk 'IDAT' at byte 33: CRC mismatch "
               "(damaged data); expected a complete image that decodes")
    assert [str(x) for x in validate_dataset(root, checksums=False)] == [damaged]  # the image check sees it
    assert validate_dataset(root, checksums=False, decode=False) == []
    assert [str(x) for x in validate_dataset(root)] == [
        "images/scan_001/depth/000000.png: sha256: checksum mismatch: content differs from tables/files.parquet",
        damaged]
    code, out, _ = _run("validate", "--no-checksums", "--quick", str(root))
    assert code == 0 and out.strip() == "OK"
    code, out, _ = _run("validate", "--no-checksums", str(root))
    assert code == 1 and out.strip() == damaged


def test_info_summary(make_dataset) -> None:
    root = make_dataset()
    code, out, err = _run("info", str(root))
    assert code == 0, err
    assert "scans        3  (splits: test 1, train 2)" in out
    assert "frames       12  (4-4 per scan)" in out
    assert "receptacles  3  (Kitchen: 2, Office: 1)" in out
    assert "doors        1  (states: closed 1, open 2)" in out
    assert "America/Toronto" in out
    code, out, _ = _run("info", "--json", str(root))
    assert code == 0 and json.loads(out)["objects"] == 2


def test_cli_errors_are_one_line(tmp_path: Path) -> None:
    code, out, err = _run("info", str(tmp_path / "missing"))
    assert code == 1
    assert err.strip().count("\n") == 0 and err.startswith("error: ") and "not a directory" in err
    code, out, err = _run("validate", str(tmp_path))
    assert code == 1 and out.strip() == "dataset.json: file: missing manifest, expected dataset.json at the dataset root"


# -- the tar layout -----------------------------------------------------------------------------

def _frames(root: Path) -> pa.Table:
    return pq.read_table(root / "tables/frames.parquet")


def test_tar_archive_content_change_is_a_checksum_mismatch(make_dataset) -> None:
    root = make_dataset()
    p = root / "images/scan_001.tar"
    data = bytearray(p.read_bytes())
    off = _frames(root).column("color_offset")[5].as_py()
    data[off + 100] ^= 0xFF
    p.write_bytes(bytes(data))
    assert [str(x) for x in validate_dataset(root)] == [
        "images/scan_001.tar: sha256: checksum mismatch: content differs from tables/files.parquet",
        f"images/scan_001.tar@{off}: image: corrupt PNG: chunk 'IDAT' at byte 33: CRC mismatch (damaged data); "
        "expected a complete image that decodes"]


def test_truncated_tar_archive(make_dataset) -> None:
    root = make_dataset()
    p = root / "images/scan_002.tar"
    t = _frames(root)
    cut = t.filter(pa.compute.equal(t.column("scan_id"), "scan_002")).column("depth_offset")[1].as_py()
    p.write_bytes(p.read_bytes()[:cut])
    code, out, err = _run("validate", str(root))
    assert code == 1 and "Traceback" not in out + err
    lines = out.strip().splitlines()
    assert lines[0].startswith("images/scan_002.tar: size_bytes: file has")
    assert any(ln.startswith("tables/frames.parquet:9: depth_offset: byte range") for ln in lines), lines


def test_tar_offset_not_at_a_member(make_dataset) -> None:
    root = make_dataset()
    _rewrite_table(root, "frames", lambda t: _set_cell(t, "color_offset", 2, t.column("color_offset")[2].as_py() + 512))
    problems = [str(p) for p in validate_dataset(root)]
    assert len(problems) == 1 and problems[0].startswith("images/scan_000.tar@")
    assert "tar: no tar member header" in problems[0]


def test_tar_member_header_damaged(make_dataset) -> None:
    root = make_dataset()
    p = root / "images/scan_000.tar"
    off = _frames(root).column("depth_offset")[1].as_py()
    data = bytearray(p.read_bytes())
    data[off - 512 + 3] ^= 0x01  # one bit of the member name: the header checksum no longer holds
    p.write_bytes(bytes(data))
    _refresh_checksum(root, "images/scan_000.tar")
    problems = [str(p) for p in validate_dataset(root)]
    assert problems == [f"images/scan_000.tar@{off}: tar: no tar member header of "
                        f"{_frames(root).column('depth_size')[1].as_py()} bytes before the image (found None), "
                        "expected the ustar header of its member"]


def test_tar_depth_range_pointing_at_colour(make_dataset) -> None:
    root = make_dataset()

    def fn(t: pa.Table) -> pa.Table:
        t = _set_cell(t, "depth_offset", 1, t.column("color_offset")[1].as_py())
        return _set_cell(t, "depth_size", 1, t.column("color_size")[1].as_py())
    _rewrite_table(root, "frames", fn)
    off = _frames(root).column("depth_offset")[1].as_py()
    assert [str(p) for p in validate_dataset(root)] == [
        f"images/scan_000.tar@{off}: dtype: png uint8 with 3 channel(s), expected a 16-bit single-channel PNG "
        "(uint16 millimetres)"]


def test_tar_offset_without_size(make_dataset) -> None:
    root = make_dataset()
    _rewrite_table(root, "frames", lambda t: _set_cell(t, "color_size", 4, None))
    assert [str(p) for p in validate_dataset(root)] == [
        "tables/frames.parquet:4: color_offset: color_offset and color_size must both be set (a byte range of "
        "images/scan_001.tar) or both null (the whole file)"]


# -- format 1.x datasets ------------------------------------------------------------------------

def _as_format_1(root: Path, *, drop_columns: bool = True) -> None:
    if drop_columns:
        _rewrite_table(root, "frames", lambda t: t.drop_columns(["color_offset", "color_size", "depth_offset",
                                                                 "depth_size"]))
    m = json.loads((root / "dataset.json").read_text())
    m["format_version"] = "1.0"
    (root / "dataset.json").write_text(json.dumps(m))


def test_format_1_dataset_is_read_and_valid(make_dataset) -> None:
    import psg_data

    root = make_dataset(image_layout="files", scans=2, frames=2)
    before = psg_data.open_dataset(root).scan("scan_001").frame(1)
    _as_format_1(root)
    assert validate_dataset(root) == []
    ds = psg_data.open_dataset(root)
    assert ds.info.format_version == "1.0" and "color_offset" not in ds.df("frames").columns
    fr = ds.scan("scan_001").frame(1)
    np.testing.assert_array_equal(fr.color, before.color)
    np.testing.assert_array_equal(fr.depth_m, before.depth_m)


def test_format_1_dataset_with_format_2_columns_is_flagged(make_dataset) -> None:
    root = make_dataset(image_layout="files", scans=1, frames=1)
    _as_format_1(root, drop_columns=False)
    problems = [str(p) for p in validate_dataset(root)]
    assert [p.split(": ")[1] for p in problems] == ["color_offset", "color_size", "depth_offset", "depth_size"]
    assert all(p.startswith("tables/frames.parquet: ") and "(format 1.x)" in p for p in problems)
