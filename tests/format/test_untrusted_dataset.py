"""A dataset is untrusted input (docs/SECURITY.md): a corpus of crafted datasets built from a small
synthetic one. Each attack gives a FormatError in the loader and a problem line in ``validate``, a
file outside the dataset is never opened, and a decompression bomb costs the loader (and the
validator) under 50 MB of resident memory.

Every crafted dataset is re-sealed with forged checksums (``files.parquet`` sizes and SHA-256, the
manifest's ``files_sha256`` rewritten to fit the crafted content), as an attacker would: the checks
must not rely on checksums, which detect accidents, not attacks.
"""

from __future__ import annotations

import builtins
import io
import json
import os
import pickle
import re
import shutil
import struct
import subprocess
import sys
import textwrap
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import psg_data
from psg_data.errors import FormatError
from psg_data.schemas._generator_model import load_process
from psg_data.schemas.validate import validate_dataset
from psg_data.writers import sha256_file
from tests.conftest import reseal_checksums, write_tiny_dataset

BOMB_SIDE = 20000


# -- building the corpus --------------------------------------------------------------------------
def _set_frames_cell(root: Path, column: str, row: int, value: object) -> None:
    p = root / "tables/frames.parquet"
    t = pq.read_table(p)
    values = t.column(column).to_pylist()
    values[row] = value
    i = t.column_names.index(column)
    pq.write_table(t.set_column(i, t.schema.field(column), pa.array(values, t.schema.field(column).type)), p)


def _replace_with_link(path: Path, target: Path) -> None:
    shutil.copyfile(path, target)
    path.unlink()
    path.symlink_to(target)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bomb(side: int = BOMB_SIDE) -> bytes:
    """A valid ~1.2 MB 8-bit RGB PNG of ``side`` x ``side`` zero pixels (1.2 GB when decoded)."""
    row = bytes(1 + 3 * side)
    rows = 100
    raw = row * rows
    co = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = co.compress(raw) + co.flush(zlib.Z_FULL_FLUSH)  # deflate blocks can be repeated as they are
    adler = 1
    for _ in range(side // rows):
        adler = zlib.adler32(raw, adler)
    stream = b"\x78\xda" + block * (side // rows) + co.flush(zlib.Z_FINISH) + struct.pack(">I", adler)
    ihdr = struct.pack(">IIBBBBB", side, side, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", stream)
            + _png_chunk(b"IEND", b""))


def jpeg_bomb(side: int = BOMB_SIDE) -> bytes:
    """A small JPEG whose frame header declares ``side`` x ``side`` pixels (libjpeg decodes it all)."""
    ok, enc = cv2.imencode(".jpg", np.full((16, 16, 3), 128, np.uint8))
    assert ok
    data = bytearray(enc.tobytes())
    i = data.index(b"\xff\xc0")  # baseline SOF0: marker, length, precision, height, width
    struct.pack_into(">HH", data, i + 5, side, side)
    return bytes(data)


def _first_image(root: Path, kind: str = "color") -> Path:
    return next(iter(sorted((root / "images/scan_000" / kind).iterdir())))


def _outside(root: Path) -> Path:
    out = root.parent / "outside"
    out.mkdir(exist_ok=True)
    return out


# Each case: crafts the dataset at root (a tiny synthetic one) and returns the sentinel outside it
# (or None), what the loader does that must raise, the FormatError pattern, the problem pattern.
Craft = Callable[[Path], "Path | None"]


def _absolute_path(root: Path) -> Path:
    sentinel = _outside(root) / "sentinel.png"
    shutil.copyfile(_first_image(root), sentinel)  # a valid image the loader would return as a frame
    _set_frames_cell(root, "color_path", 0, str(sentinel))
    return sentinel


def _dotdot_path(root: Path) -> Path:
    sentinel = _outside(root) / "sentinel.png"
    shutil.copyfile(_first_image(root), sentinel)
    _set_frames_cell(root, "color_path", 0, "../outside/sentinel.png")
    return sentinel


def _symlink_image(root: Path) -> Path:
    sentinel = _outside(root) / "sentinel.png"
    _replace_with_link(_first_image(root), sentinel)
    return sentinel


def _symlink_image_folder(root: Path) -> Path:
    folder = root / "images/scan_000/color"
    target = _outside(root) / "color"
    shutil.copytree(folder, target)
    shutil.rmtree(folder)
    folder.symlink_to(target, target_is_directory=True)
    return target / "000000.png"


def _symlink_archive(root: Path) -> Path:
    sentinel = _outside(root) / "sentinel.tar"
    _replace_with_link(root / "images/scan_000.tar", sentinel)
    return sentinel


def _symlink_table(root: Path) -> Path:
    sentinel = _outside(root) / "sentinel.parquet"
    _replace_with_link(root / "tables/doors.parquet", sentinel)
    return sentinel


def _symlink_manifest(root: Path) -> Path:
    sentinel = _outside(root) / "sentinel.json"
    _replace_with_link(root / "dataset.json", sentinel)
    return sentinel


def _range_past_end(root: Path) -> None:
    size = (root / "images/scan_000.tar").stat().st_size
    _set_frames_cell(root, "color_size", 0, size)


def _absurd_range(root: Path) -> None:
    _set_frames_cell(root, "color_size", 0, 10**12)  # a terabyte: never allocated


def _png_bomb(root: Path) -> None:
    _first_image(root).write_bytes(png_bomb())


def _jpeg_bomb(root: Path) -> None:
    _first_image(root).write_bytes(jpeg_bomb())


def _gray_colour(root: Path) -> None:
    p = _first_image(root)
    cv2.imwrite(str(p), np.full((24, 32), 7, np.uint8))  # right size, 1 channel: not the camera's RGB


def _depth_8bit(root: Path) -> None:
    p = _first_image(root, "depth")
    cv2.imwrite(str(p), np.full((24, 32), 7, np.uint8))


def _oversized_colour(root: Path) -> None:
    p = _first_image(root)
    cv2.imwrite(str(p), np.zeros((48, 64, 3), np.uint8))  # 64x48 where the camera says 32x24


def _padded_image(root: Path) -> None:
    p = _first_image(root)
    p.write_bytes(p.read_bytes() + bytes(3 << 20))  # a valid header, then 3 MB nobody should read


def _fifo_image(root: Path) -> None:
    p = _first_image(root)
    p.unlink()
    os.mkfifo(p)  # opening it for reading would block until a writer comes


def _fifo_archive(root: Path) -> None:
    p = root / "images/scan_000.tar"
    p.unlink()
    os.mkfifo(p)


def _frame0(ds: psg_data.Dataset) -> object:
    return ds.scan("scan_000").frame(0)


_IMG = r"images/scan_000/color/000000\.(png|jpg)"
CASES: dict[str, tuple[Craft, dict, Callable[[psg_data.Dataset], object], str, str]] = {
    "absolute path": (_absolute_path, {"image_layout": "files"}, _frame0,
                      r"tables/frames\.parquet:0: color_path: path '/.*' is absolute",
                      r"^tables/frames\.parquet:0: color_path: path '/.*' is absolute"),
    "dotdot path": (_dotdot_path, {"image_layout": "files"}, _frame0,
                    r"tables/frames\.parquet:0: color_path: path '\.\./outside/sentinel\.png' has a '\.\.' component",
                    r"^tables/frames\.parquet:0: color_path: path '\.\./outside/sentinel\.png' has a '\.\.' compon"),
    "symlinked image": (_symlink_image, {"image_layout": "files"}, _frame0,
                        r"tables/frames\.parquet:0: color_path: path 'images/scan_000/color/000000\.png' resolves "
                        r"outside the dataset",
                        r"^tables/frames\.parquet:0: color_path: path 'images/scan_000/color/000000\.png' resolves "
                        r"outside the dataset"),
    "symlinked image folder": (_symlink_image_folder, {"image_layout": "files"}, _frame0,
                               r"tables/frames\.parquet:0: color_path: path 'images/scan_000/color/000000\.png' "
                               r"resolves outside the dataset",
                               r"^tables/frames\.parquet:0: color_path: path 'images/scan_000/color/000000\.png' "
                               r"resolves outside the dataset"),
    "symlinked archive": (_symlink_archive, {}, _frame0,
                          r"tables/frames\.parquet:0: color_path: path 'images/scan_000\.tar' resolves outside",
                          r"^tables/files\.parquet:0: path: 'images/scan_000\.tar' resolves outside the dataset"),
    "symlinked table": (_symlink_table, {}, lambda ds: ds.doors,
                        r"table 'doors': path 'tables/doors\.parquet' resolves outside the dataset",
                        r"^tables/doors\.parquet: path: resolves outside the dataset .*; not loaded"),
    "symlinked manifest": (_symlink_manifest, {}, lambda ds: ds,
                           r"manifest: path 'dataset\.json' resolves outside the dataset",
                           r"^dataset\.json: path: resolves outside the dataset"),
    "archive range past the end": (_range_past_end, {}, _frame0,
                                   r"images/scan_000\.tar@\d+: missing or unreadable colour image \(\d+ bytes at "
                                   r"offset \d+ lie beyond the end",
                                   r"^tables/frames\.parquet:0: color_offset: byte range \[\d+, \d+\) is not inside"),
    "absurd byte range": (_absurd_range, {}, _frame0,
                          r"images/scan_000\.tar@\d+: missing or unreadable colour image \(1000000000000 bytes",
                          r"^tables/frames\.parquet:0: color_offset: byte range \[\d+, \d+\) is not inside"),
    "PNG bomb": (_png_bomb, {"image_layout": "files"}, _frame0,
                 _IMG + r": missing or unreadable colour image \(\d+ bytes, more than the \d+ an image of its camera",
                 "^" + _IMG + r": size: 20000x20000 = 400000000 pixels, over the limit"),
    "JPEG bomb": (_jpeg_bomb, {"image_layout": "files", "color_encoding": "jpeg"}, _frame0,
                  _IMG + r": colour image header does not fit camera 'd435', refused before decoding: size 20000x20000",
                  "^" + _IMG + r": size: 20000x20000, expected the camera's 32x24"),
    "grey colour image": (_gray_colour, {"image_layout": "files"}, _frame0,
                          _IMG + r": colour image header does not fit camera 'd435', refused before decoding: dtype "
                                 r"png uint8 with 1 channel",
                          "^" + _IMG + r": dtype: png uint8 with 1 channel\(s\), expected an 8-bit 3-channel png"),
    "8-bit depth image": (_depth_8bit, {"image_layout": "files"}, _frame0,
                          r"depth/000000\.png: depth image header does not fit camera 'd435', refused before decoding",
                          r"^images/scan_000/depth/000000\.png: dtype: png uint8 with 1 channel\(s\), expected a 16-bit"),
    "image file larger than its camera allows": (
        _padded_image, {"image_layout": "files"}, _frame0,
        _IMG + r": missing or unreadable colour image \(\d+ bytes, more than the 1053184 an image of its camera",
        "^" + _IMG + r": size_bytes: \d+ bytes, more than the 1053184 an image of its camera may take"),
    "FIFO in place of an image": (_fifo_image, {"image_layout": "files"}, _frame0,
                                  _IMG + r": missing or unreadable colour image \(not a regular file\)",
                                  r"^tables/frames\.parquet:0: color_path: image images/scan_000/color/000000\.png "
                                  r"does not exist"),
    "FIFO in place of an archive": (_fifo_archive, {}, _frame0,
                                    r"images/scan_000\.tar@\d+: missing or unreadable colour image \(not a regular",
                                    r"^tables/frames\.parquet:0: color_path: image images/scan_000\.tar does not exist"),
    "colour image larger than its camera": (
        _oversized_colour, {"image_layout": "files"}, _frame0,
        _IMG + r": colour image header does not fit camera 'd435', refused before decoding: size 64x48, expected "
               r"the camera's 32x24",
        "^" + _IMG + r": size: 64x48, expected the camera's 32x24"),
}


@pytest.fixture
def crafted(tmp_path: Path) -> Callable[[str], tuple[Path, Path | None]]:
    def build(name: str) -> tuple[Path, Path | None]:
        craft, kwargs = CASES[name][0], CASES[name][1]
        root = write_tiny_dataset(tmp_path / "ds", scans=2, frames=3, **kwargs)
        sentinel = craft(root)
        if name != "symlinked manifest":
            reseal_checksums(root)
        return root, sentinel

    return build


# -- watching every open ----------------------------------------------------------------------------
@pytest.fixture
def opened(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Real paths of every file opened (the call succeeded: an ``O_NOFOLLOW`` open refused on a link
    opened nothing) through Python, OpenCV's imread and pyarrow's Parquet readers."""
    seen: list[str] = []

    def watch(fn: Callable, pos: int = 0) -> Callable:
        def wrapper(*args: object, **kwargs: object) -> object:
            out = fn(*args, **kwargs)
            arg = args[pos] if len(args) > pos else None
            if isinstance(arg, (str, bytes, os.PathLike)):
                seen.append(os.path.realpath(os.fsdecode(arg)))
            return out
        return wrapper

    monkeypatch.setattr(builtins, "open", watch(builtins.open))
    monkeypatch.setattr(io, "open", watch(io.open))
    monkeypatch.setattr(os, "open", watch(os.open))
    monkeypatch.setattr(cv2, "imread", watch(cv2.imread))
    for name in ("read_table", "read_metadata", "read_schema", "ParquetFile"):
        monkeypatch.setattr(pq, name, watch(getattr(pq, name)))
    yield seen


# -- the corpus -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(CASES))
def test_loader_refuses_crafted_dataset(crafted, opened: list[str], name: str) -> None:
    root, sentinel = crafted(name)
    opened.clear()  # the crafting itself opened the sentinel
    *_, use, error, _ = CASES[name]
    with pytest.raises(FormatError, match=error):
        use(psg_data.open_dataset(root))
    if sentinel is not None:
        assert os.path.realpath(sentinel) not in opened


def test_the_watch_sees_the_loaders_opens(tmp_path: Path, opened: list[str]) -> None:
    root = write_tiny_dataset(tmp_path / "ds", scans=1, frames=1)
    opened.clear()
    psg_data.open_dataset(root).scan("scan_000").frame(0)
    for rel in ("dataset.json", "tables/frames.parquet", "images/scan_000.tar"):
        assert os.path.realpath(root / rel) in opened


@pytest.mark.parametrize("name", sorted(CASES))
def test_validate_reports_crafted_dataset(crafted, opened: list[str], name: str) -> None:
    import re

    root, sentinel = crafted(name)
    opened.clear()
    problem = CASES[name][4]
    lines = [str(p) for p in validate_dataset(root)]
    assert any(re.search(problem, ln) for ln in lines), lines
    assert not any(": sha256:" in ln for ln in lines), lines  # forged checksums fit: content checks caught it
    if sentinel is not None:
        assert os.path.realpath(sentinel) not in opened


def test_validate_cli_names_the_escaping_path_in_one_line(crafted) -> None:
    from click.testing import CliRunner

    from psg_data.cli.psg_data_cmd import main

    root, _ = crafted("dotdot path")
    res = CliRunner().invoke(main, ["validate", str(root)])
    assert res.exit_code == 1
    assert sum("has a '..' component" in ln for ln in res.stdout.splitlines()) == 1, res.stdout


def test_generator_model_symlinked_outside(tmp_path: Path, opened: list[str]) -> None:
    root = write_tiny_dataset(tmp_path / "ds", scans=1, frames=1)
    sentinel = _outside(root) / "process.json"
    sentinel.write_text("{}")
    (root / "generator").mkdir()
    (root / "generator/process.json").symlink_to(sentinel)
    m = json.loads((root / "dataset.json").read_text())
    m["extra"]["process_file"] = "generator/process.json"
    (root / "dataset.json").write_text(json.dumps(m))
    reseal_checksums(root)
    opened.clear()
    with pytest.raises(FormatError, match=r"generator model: path 'generator/process\.json' resolves outside"):
        load_process(psg_data.open_dataset(root))
    lines = [str(p) for p in validate_dataset(root)]
    assert any(ln.startswith("dataset.json: extra.process_file: path 'generator/process.json' resolves outside")
               for ln in lines), lines
    assert os.path.realpath(sentinel) not in opened


def test_files_table_listing_a_path_outside(tmp_path: Path, opened: list[str]) -> None:
    root = write_tiny_dataset(tmp_path / "ds", scans=1, frames=1)
    sentinel = _outside(root) / "secret"
    sentinel.write_text("secret")
    fp = root / "tables/files.parquet"
    rows = pq.read_table(fp).to_pylist()
    rows.append({"path": "../outside/secret", "size_bytes": 6, "sha256": "0" * 64})
    rows.append({"path": str(sentinel), "size_bytes": 6, "sha256": "0" * 64})
    pq.write_table(pa.Table.from_pylist(rows, schema=pq.read_schema(fp)), fp)
    reseal_checksums(root)
    opened.clear()
    lines = [str(p) for p in validate_dataset(root)]
    n = len(rows)
    assert f"tables/files.parquet:{n - 2}: path: '../outside/secret' has a '..' component, expected a relative path " \
           "inside the dataset" in lines
    assert any(ln.startswith(f"tables/files.parquet:{n - 1}: path: '{sentinel}' is absolute") for ln in lines), lines
    assert os.path.realpath(sentinel) not in opened


def test_table_size_and_rows_checked_before_loading(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = write_tiny_dataset(tmp_path / "ds", scans=2, frames=1)
    p = root / "tables/scans.parquet"
    p.write_bytes(p.read_bytes() + b"\0" * 4096)  # no longer the size files.parquet lists
    m = json.loads((root / "dataset.json").read_text())
    m["counts"]["frames"] = 10**9
    (root / "dataset.json").write_text(json.dumps(m))
    order: list[str] = []
    read_table, read_metadata = pq.read_table, pq.read_metadata
    monkeypatch.setattr(pq, "read_table", lambda p, *a, **k: order.append("load " + Path(p).name)
                        or read_table(p, *a, **k))
    monkeypatch.setattr(pq, "read_metadata", lambda p, *a, **k: order.append("footer " + Path(p).name)
                        or read_metadata(p, *a, **k))
    lines = [str(x) for x in validate_dataset(root)]
    assert "dataset.json: counts.frames: 1000000000, but tables/frames.parquet has 2 rows" in lines
    assert sum(ln.startswith("tables/scans.parquet: size_bytes: file has") for ln in lines) == 1, lines
    assert sum("counts.frames" in ln for ln in lines) == 1, lines
    assert order.index("footer frames.parquet") < order.index("load frames.parquet")
    assert order[0] == "footer files.parquet"  # files first: it bounds the others


def test_table_declaring_too_many_bytes_is_not_loaded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from psg_data.schemas import validate

    root = write_tiny_dataset(tmp_path / "ds", scans=2, frames=1)
    declared = pq.read_metadata(root / "tables/frames.parquet").row_group(0).total_byte_size
    monkeypatch.setattr(validate, "MAX_TABLE_BYTES", declared - 1)
    loaded: list[str] = []
    read_table = pq.read_table
    monkeypatch.setattr(pq, "read_table", lambda p, *a, **k: loaded.append(Path(p).name) or read_table(p, *a, **k))
    lines = [str(x) for x in validate_dataset(root)]
    assert f"tables/frames.parquet: file: declares {declared} bytes uncompressed, more than the {declared - 1} a " \
           "table may have; not loaded" in lines
    assert "frames.parquet" not in loaded and "scans.parquet" in loaded


@pytest.mark.parametrize("layout", ["tar", "files"])
def test_writers_never_write_a_path_that_leaves_the_dataset(tmp_path: Path, layout: str) -> None:
    from psg_data.schemas._paths import path_problem, real_root

    root = write_tiny_dataset(tmp_path / "ds", image_layout=layout)
    real = real_root(root)
    frames = pq.read_table(root / "tables/frames.parquet")
    files = pq.read_table(root / "tables/files.parquet")
    paths = set(frames.column("color_path").to_pylist() + frames.column("depth_path").to_pylist()
                + files.column("path").to_pylist())
    assert paths and all(path_problem(real, p) is None for p in paths)
    assert validate_dataset(root) == []


@pytest.mark.parametrize("rel, problem", [
    ("images/a.png", None), ("a/./b.png", None), ("/etc/passwd", "is absolute"), ("\\\\host\\share", "is absolute"),
    ("C:/x.png", "is absolute"), ("c:x.png", "is absolute"), ("../x", "has a '..' component"),
    ("images/../../x", "has a '..' component"), ("images\\..\\..\\x", "has a '..' component"),
    ("", "expected a non-empty string"), ("a\x00b", "contains a NUL character"),
])
def test_path_rule(tmp_path: Path, rel: str, problem: str | None) -> None:
    from psg_data.schemas._paths import path_problem, real_root

    got = path_problem(real_root(tmp_path), rel)
    assert (got is None) if problem is None else (got is not None and problem in got)


# -- bounded memory on bombs ------------------------------------------------------------------------
_RSS_SCRIPT = textwrap.dedent("""
    import resource, sys
    import psg_data
    from psg_data.errors import FormatError
    from psg_data.schemas.validate import validate_dataset
    scale = 1 if sys.platform == "darwin" else 1024  # ru_maxrss: bytes on macOS, KiB on Linux
    ds = psg_data.open_dataset(sys.argv[1])
    scan = ds.scan("scan_000")
    scan.frame(1)  # warm: tables, OpenCV, one good frame decoded
    validate_dataset(sys.argv[1], checksums=False, decode=False)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale
    try:
        scan.frame(0)
        refused = False
    except FormatError:
        refused = True
    loader = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale - before
    problems = validate_dataset(sys.argv[1])
    validate = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale - before - loader
    print(refused, loader, validate, len(problems))
""")


@pytest.mark.parametrize("name", ["PNG bomb", "JPEG bomb"])
def test_bombs_cost_under_50_mb(crafted, name: str) -> None:
    pytest.importorskip("resource", reason="ru_maxrss needs the POSIX resource module")
    root, _ = crafted(name)
    out = subprocess.run([sys.executable, "-c", _RSS_SCRIPT, str(root)], capture_output=True, text=True,
                         check=True, cwd=str(Path(__file__).resolve().parents[2]))
    refused, loader, validate, problems = out.stdout.split()
    assert refused == "True"
    assert int(loader) < 50 * 2**20, f"loader grew by {int(loader) / 2**20:.0f} MB"
    assert int(validate) < 50 * 2**20, f"validate grew by {int(validate) / 2**20:.0f} MB"
    assert int(problems) >= 1


def test_a_dataset_linked_as_a_whole_is_read(tmp_path: Path) -> None:
    """The root is resolved first: a dataset kept on another disk and linked to works as before."""
    root = write_tiny_dataset(tmp_path / "disk" / "lab", scans=1, frames=2, image_layout="files")
    link = tmp_path / "lab"
    link.symlink_to(root)
    fr = psg_data.open_dataset(link).scan("scan_000").frame(1)
    assert fr.color.shape == (24, 32, 3)
    assert validate_dataset(link) == []


def _forge_listed_checksum(root: Path, rel: str, *, reseal_manifest: bool) -> None:
    """Write a checksum that does not fit ``rel`` into files.parquet (content unchanged)."""
    fp = root / "tables/files.parquet"
    rows = pq.read_table(fp).to_pylist()
    assert any(r["path"] == rel for r in rows), rel
    for r in rows:
        if r["path"] == rel:
            r["sha256"] = "f" * 64
    pq.write_table(pa.Table.from_pylist(rows, schema=pq.read_schema(fp)), fp)
    if reseal_manifest:
        m = json.loads((root / "dataset.json").read_text())
        m["files_sha256"] = sha256_file(fp)
        (root / "dataset.json").write_text(json.dumps(m))


def test_forged_files_table_is_refused_by_loader_and_validate(tmp_path: Path) -> None:
    """files.parquet changed after writing (its SHA-256 no longer fits the manifest's)."""
    root = write_tiny_dataset(tmp_path / "ds", scans=1, frames=1)
    _forge_listed_checksum(root, "tables/scans.parquet", reseal_manifest=False)
    with pytest.raises(FormatError, match=r"tables/files\.parquet: sha256: .* does not match dataset\.json "
                                          r"files_sha256"):
        psg_data.open_dataset(root).table("scans")
    lines = [str(p) for p in validate_dataset(root)]
    assert any(ln.startswith("tables/files.parquet: sha256: checksum") for ln in lines), lines


# what the loader reads whole, the file whose checksum is forged, and the reading
FORGED = {
    "table": ("tar", "tables/scans.parquet", lambda ds: ds.table("scans")),
    "image file": ("files", "images/scan_000/color/000000.png", lambda ds: ds.scan("scan_000").frame(0)),
    "depth file": ("files", "images/scan_000/depth/000000.png", lambda ds: ds.scan("scan_000").frame(0)),
}


@pytest.mark.parametrize("name", sorted(FORGED))
def test_forged_checksum_is_refused_by_loader_and_validate(tmp_path: Path, name: str) -> None:
    """A file whose content does not fit its checksum in files.parquet (the files table itself
    consistent with the manifest): the loader refuses it when it reads the file, validate names it."""
    layout, rel, use = FORGED[name]
    root = write_tiny_dataset(tmp_path / "ds", scans=1, frames=1, image_layout=layout)
    use(psg_data.open_dataset(root))  # reads before forging
    _forge_listed_checksum(root, rel, reseal_manifest=True)
    with pytest.raises(FormatError, match=rf"{re.escape(rel)}: sha256: checksum [0-9a-f]{{12}}\.\.\. does not match "
                                          r"tables/files\.parquet f{12}"):
        use(psg_data.open_dataset(root))
    assert [str(p) for p in validate_dataset(root)] == [
        f"{rel}: sha256: checksum mismatch: content differs from tables/files.parquet"]


def test_changed_table_is_refused_by_loader(tmp_path: Path) -> None:
    """A table edited after writing, its checksum left as written (an accident, or a careless edit)."""
    root = write_tiny_dataset(tmp_path / "ds", scans=2, frames=1)
    p = root / "tables/scans.parquet"
    t = pq.read_table(p)
    pq.write_table(t.slice(0, 1), p)
    with pytest.raises(FormatError, match=r"tables/scans\.parquet: size_bytes: file has \d+ bytes, "
                                          r"tables/files\.parquet says \d+"):
        psg_data.open_dataset(root).scan_ids
    assert any(ln.startswith("tables/scans.parquet: size_bytes:") for ln in map(str, validate_dataset(root)))


def test_forged_generator_model_checksum_is_refused(tmp_path: Path) -> None:
    from psg_data.synth import LabConfig, build_lab

    root = build_lab(tmp_path / "lab", LabConfig(days=1, frames_per_scan=1, width=32, height=24))
    load_process(psg_data.open_dataset(root))
    _forge_listed_checksum(root, "generator/process.json", reseal_manifest=True)
    with pytest.raises(FormatError, match=r"generator/process\.json: sha256: checksum"):
        load_process(psg_data.open_dataset(root))
    load_process(root / "generator/process.json")  # a path is a plain file: no dataset, no checksum


def test_tar_archive_checksum_is_checked_by_validate_not_by_the_loader(tmp_path: Path) -> None:
    """Documented choice (docs/SECURITY.md): by default the loader reads one frame of an archive as two
    byte ranges and does not hash the whole archive (validate does); ``verify_archives=True`` does."""
    root = write_tiny_dataset(tmp_path / "ds", scans=1, frames=2)
    psg_data.open_dataset(root, verify_archives=True).scan("scan_000").frame(1)
    _forge_listed_checksum(root, "images/scan_000.tar", reseal_manifest=True)
    assert psg_data.open_dataset(root).scan("scan_000").frame(1).color.shape == (24, 32, 3)
    assert [str(p) for p in validate_dataset(root)] == [
        "images/scan_000.tar: sha256: checksum mismatch: content differs from tables/files.parquet"]
    ds = psg_data.open_dataset(root, verify_archives=True)
    with pytest.raises(FormatError, match=r"images/scan_000\.tar: sha256: checksum [0-9a-f]{12}\.\.\. does not "
                                          r"match tables/files\.parquet f{12}"):
        ds.scan("scan_000").frame(1)
    clone = pickle.loads(pickle.dumps(ds))  # a DataLoader worker's copy keeps the setting
    with pytest.raises(FormatError, match="sha256: checksum"):
        clone.scan("scan_000").frame(0)
