"""``validate_dataset``: check a psg-dataset directory against the format.

Each problem is one line ``file[:row]: field: what is wrong, what was expected``, where ``file`` is
relative to the dataset root and ``row`` is the 0-based row of the table.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pyarrow as pa

from psg_data.errors import FormatError, PsgDataError
from psg_data.schemas._camera_checks import intrinsics_problems
from psg_data.schemas._image_headers import header_problems, max_encoded_bytes, parse_image_header, read_image_header
from psg_data.schemas._manifest import FORMAT_VERSION, DatasetInfo, manifest_from_dict, parse_format_version
from psg_data.schemas._paths import path_problem, real_root
from psg_data.schemas._tables import (
    DOOR_STATES,
    LABEL_CODES,
    MANIFEST_NAME,
    TABLES,
    VISIBILITY_KINDS,
    schema_for,
    table_path,
)

__all__ = ["Problem", "validate_dataset"]

log = logging.getLogger(__name__)

_ROT_TOL = 1e-5
_MAX_PER_CHECK = 20  # problems reported per check before summarising
MAX_TABLE_BYTES = 1 << 30
"""Uncompressed bytes a table may declare (Parquet footer) before the validator refuses to load it."""
_OUTSIDE = "expected a relative path inside the dataset"


@dataclass(frozen=True)
class Problem:
    """One validation problem."""

    file: str
    field: str
    message: str
    row: int | None = None

    def __str__(self) -> str:
        """``file[:row]: field: message``."""
        where = self.file if self.row is None else f"{self.file}:{self.row}"
        return f"{where}: {self.field}: {self.message}"


class _Collector:
    def __init__(self) -> None:
        self.problems: list[Problem] = []
        self._counts: dict[tuple[str, str], int] = {}

    def add(self, file: str, field: str, message: str, row: int | None = None) -> None:
        key = (file, field)
        n = self._counts.get(key, 0) + 1
        self._counts[key] = n
        if n <= _MAX_PER_CHECK:
            self.problems.append(Problem(file, field, message, row))
        elif n == _MAX_PER_CHECK + 1:
            self.problems.append(Problem(file, field, "more problems of this kind not shown"))

    def has(self, file: str, field: str) -> bool:
        """Whether a problem of ``file`` and ``field`` was reported."""
        return (file, field) in self._counts


def _rows_where(mask: np.ndarray) -> list[int]:
    return [int(i) for i in np.flatnonzero(mask)]


def _check_rotations(c: _Collector, file: str, field: str, mats: np.ndarray, rows: np.ndarray | None = None) -> None:
    """mats: (N, 3, 3); ``rows`` maps them to table rows (default 0..N-1)."""
    if mats.size == 0:
        return
    rows = np.arange(len(mats)) if rows is None else rows
    finite = np.all(np.isfinite(mats), axis=(1, 2))
    for i in _rows_where(~finite):
        c.add(file, field, "contains NaN or infinite values, expected finite numbers", int(rows[i]))
    m = mats[finite]
    idx = rows[finite]
    err = np.abs(np.einsum("nji,njk->nik", m, m) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(m)
    for j in _rows_where((err > _ROT_TOL) | (det <= 0)):
        c.add(file, field, f"rotation is not orthonormal with det +1 (max |R^T R - I| = {err[j]:.3g}, "
                           f"det = {det[j]:.3g}), expected a proper rotation", int(idx[j]))


def validate_dataset(path: str | Path, *, checksums: bool = True, images: bool = True,
                     decode: bool = True) -> list[Problem]:
    """Validate the dataset at ``path``; returns every problem found (empty list = valid).

    Args:
        path: the dataset directory.
        checksums: verify the SHA-256 of every file (reads every byte; sizes are always checked).
        images: check that every image exists and that its header matches the camera
            (colour: 8-bit 3-channel; depth: 16-bit single-channel PNG; size = camera size).
        decode: also check every image whole (PNG chunk CRCs, JPEG markers through EOI) and decode
            it with OpenCV (``False``: headers only, ``psg-data validate --quick``).
    """
    root = Path(path)
    c = _Collector()
    if not root.is_dir():
        return [Problem(str(root), "path", "not a directory, expected a psg-dataset directory")]
    info = _read_manifest(c, root)
    if info is None:
        return c.problems
    if parse_format_version(info.format_version) > parse_format_version(FORMAT_VERSION):
        c.add(MANIFEST_NAME, "format_version", f"{info.format_version} is newer than this psg-data validates "
                                               f"({FORMAT_VERSION}); upgrade psg-data to validate it")
        return c.problems
    real = real_root(root)
    tables = _read_tables(c, root, real, info)
    _check_files(c, root, real, info, tables, checksums)
    cols: dict[str, dict[str, list[Any]]] = {n: t.to_pydict() for n, t in tables.items() if n != "files"}
    _check_keys(c, cols)
    cams = _check_cameras(c, cols)
    _check_boxes(c, tables)
    _check_door_states(c, cols)
    scan_bounds = _check_scans(c, cols)
    if "frames" in tables and tables["frames"].num_rows:
        _check_frames(c, tables["frames"], scan_bounds)
        if images:
            _check_images(c, root, real, cols["frames"], cams, info.color_encoding, decode)
    _check_label_tables(c, cols, scan_bounds)
    _check_process_file(c, root, real, info.extra, cols)
    for name, t in tables.items():
        if name in info.counts and info.counts[name] != t.num_rows and not c.has(MANIFEST_NAME, f"counts.{name}"):
            c.add(MANIFEST_NAME, f"counts.{name}", f"{info.counts[name]}, but {table_path(name)} has {t.num_rows} rows")
    return c.problems


def _read_manifest(c: _Collector, root: Path) -> DatasetInfo | None:
    """The manifest, or None (with the problem) when it is missing or malformed."""
    info = None
    mpath = root / MANIFEST_NAME
    if not mpath.is_file():
        c.add(MANIFEST_NAME, "file", "missing manifest, expected dataset.json at the dataset root")
    elif (outside := path_problem(real_root(root), MANIFEST_NAME)) is not None:
        c.add(MANIFEST_NAME, "path", f"{outside}, expected the manifest inside the dataset")
    else:
        try:
            info = manifest_from_dict(json.loads(mpath.read_text(encoding="utf-8")), MANIFEST_NAME,
                                      warn_newer_minor=False)
        except json.JSONDecodeError as exc:
            c.add(MANIFEST_NAME, "json", f"not valid JSON ({exc.msg} at line {exc.lineno})")
        except FormatError as exc:
            msg = str(exc)
            prefix = f"{MANIFEST_NAME}: "
            rest = msg[len(prefix):] if msg.startswith(prefix) else msg
            field, _, what = rest.partition(": ")
            c.add(MANIFEST_NAME, field or "manifest", what or rest)
    return info


def _read_tables(c: _Collector, root: Path, real: str, info: DatasetInfo) -> dict[str, pa.Table]:
    """Every table of the format that is present, inside the dataset, of the size ``files.parquet``
    and the manifest say (checked before it is loaded), readable and of its schema.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    major = info.major
    tables: dict[str, pa.Table] = {}
    listed: dict[str, int] = {}
    for name in sorted(TABLES, key=lambda n: n != "files"):  # files first: it bounds the others
        spec = TABLES[name]
        rel = table_path(name)
        p = root / rel
        schema = schema_for(name, major)
        if not p.is_file():
            if spec.required:
                c.add(rel, "file", f"missing table '{name}', expected a Parquet file with columns {schema.names}")
            continue
        if not _table_fits(c, p, rel, real, listed.get(rel), info.counts.get(name)):
            continue
        try:
            t = pq.read_table(p)
        except (OSError, pa.ArrowException) as exc:
            c.add(rel, "file", f"not a readable Parquet file ({str(exc).splitlines()[0][:120]}), "
                               "expected a complete Parquet file (truncated or corrupt?)")
            continue
        ok = True
        for f in schema:
            if f.name not in t.column_names:
                c.add(rel, f.name, f"missing column, expected type {f.type}")
                ok = False
                continue
            actual = t.schema.field(f.name).type
            if not actual.equals(f.type):
                c.add(rel, f.name, f"wrong type {actual}, expected {f.type}")
                ok = False
                continue
            if not f.nullable and t.column(f.name).null_count:
                nulls = np.flatnonzero(t.column(f.name).is_null().to_numpy(zero_copy_only=False))
                for i in nulls[:3]:
                    c.add(rel, f.name, "null value, expected a value (column is not nullable)", int(i))
                ok = False
        extra_cols = [n for n in t.column_names if n not in schema.names]
        for n in extra_cols:
            c.add(rel, n, f"unknown column, expected only {schema.names} (format {major}.x)")
        if ok:
            tables[name] = t
            if name == "files":
                listed = dict(zip(t.column("path").to_pylist(), t.column("size_bytes").to_pylist()))
    return tables


def _table_fits(c: _Collector, p: Path, rel: str, real: str, listed_size: int | None, count: int | None) -> bool:
    """Checks of the table at ``p`` before it is loaded: its size against ``files.parquet`` and its
    row count (Parquet footer) against the manifest are reported; it may be loaded (True) if it is
    inside the dataset and declares at most :data:`MAX_TABLE_BYTES` uncompressed.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    outside = path_problem(real, rel)
    if outside is not None:
        c.add(rel, "path", f"{outside}, {_OUTSIDE}; not loaded")
        return False
    size = p.stat().st_size
    if listed_size is not None and size != listed_size:
        c.add(rel, "size_bytes", f"file has {size} bytes, tables/files.parquet says {listed_size} (changed or "
                                 "truncated after writing?)")
    try:
        meta = pq.read_metadata(p)
    except (OSError, pa.ArrowException):
        return True  # reading it reports what is wrong
    declared = sum(meta.row_group(i).total_byte_size for i in range(meta.num_row_groups))
    if declared > MAX_TABLE_BYTES:
        c.add(rel, "file", f"declares {declared} bytes uncompressed, more than the {MAX_TABLE_BYTES} a table may "
                           "have; not loaded")
        return False
    if count is not None and meta.num_rows != count:
        c.add(MANIFEST_NAME, f"counts.{p.stem}", f"{count}, but {rel} has {meta.num_rows} rows")
    return True


def _check_files(c: _Collector, root: Path, real: str, info: DatasetInfo, tables: dict[str, pa.Table],
                 checksums: bool) -> None:
    """``files.parquet`` against the manifest, and every file against ``files.parquet`` (sizes; with
    ``checksums`` also SHA-256); files on disk it does not list.
    """
    from psg_data.schemas._checksum import sha256_file

    files_rel = table_path("files")
    if (root / files_rel).is_file() and info.files_sha256:
        actual = sha256_file(root / files_rel)
        if actual != info.files_sha256:
            c.add(files_rel, "sha256", f"checksum {actual[:12]}... does not match dataset.json files_sha256 "
                                       f"{info.files_sha256[:12]}...; the file was changed after writing")
    elif (root / files_rel).is_file():
        c.add(MANIFEST_NAME, "files_sha256", "missing, expected the SHA-256 of tables/files.parquet")
    listed: set[str] = set()
    if "files" in tables:
        ft = tables["files"].to_pydict()
        for row, (rel, size, digest) in enumerate(zip(ft["path"], ft["size_bytes"], ft["sha256"])):
            listed.add(rel)
            outside = path_problem(real, rel)
            if outside is not None:
                if not c.has(rel, "path"):
                    c.add(files_rel, "path", f"{rel!r} {outside}, {_OUTSIDE}", row)
                continue
            p = root / rel
            if not p.is_file():
                c.add(rel, "file", "missing, listed in tables/files.parquet", None)
                continue
            st = p.stat().st_size
            if c.has(rel, "size_bytes"):
                continue
            if st != size:
                c.add(rel, "size_bytes", f"file has {st} bytes, tables/files.parquet says {size} (truncated?)")
            elif checksums and sha256_file(p) != digest:
                c.add(rel, "sha256", "checksum mismatch: content differs from tables/files.parquet")
        on_disk = {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file()}
        for rel in sorted(on_disk - listed - {MANIFEST_NAME, files_rel}):
            c.add(rel, "file", "not listed in tables/files.parquet (stray file; rewrite the dataset to register it)")


def _check_keys(c: _Collector, cols: dict[str, dict[str, list[Any]]]) -> None:
    """Unique keys and no dangling references, in every table."""
    for name, spec in TABLES.items():
        if name not in cols:
            continue
        rel = table_path(name)
        seen: dict[tuple, int] = {}
        keys = list(zip(*(cols[name][k] for k in spec.key)))
        for i, k in enumerate(keys):
            if k in seen:
                c.add(rel, "+".join(spec.key), f"duplicate key {k if len(k) > 1 else k[0]!r} "
                                               f"(also row {seen[k]}), expected unique values", i)
            else:
                seen[k] = i
        for col, ref_table, ref_col in spec.references:
            if ref_table not in cols:
                continue
            valid = set(cols[ref_table][ref_col])
            for i, v in enumerate(cols[name][col]):
                if v is not None and v not in valid:
                    c.add(rel, col, f"dangling id {v!r}: not in {table_path(ref_table)} column {ref_col}", i)


def _check_cameras(c: _Collector, cols: dict[str, dict[str, list[Any]]]) -> dict[str, dict[str, Any]]:
    """Intrinsics, depth scale and distortion model of every camera; returns each camera's image size."""
    cams: dict[str, dict] = {}
    if "cameras" in cols:
        rel = table_path("cameras")
        cam = cols["cameras"]
        for i, cid in enumerate(cam["camera_id"]):
            w, h = cam["width"][i], cam["height"][i]
            for fname, what in intrinsics_problems(w, h, cam["fx"][i], cam["fy"][i], cam["cx"][i], cam["cy"][i]):
                c.add(rel, fname, what, i)
            if not (np.isfinite(cam["depth_scale_m"][i]) and cam["depth_scale_m"][i] > 0):
                c.add(rel, "depth_scale_m", f"{cam['depth_scale_m'][i]}, expected a positive number (0.001 for mm)", i)
            if cam["distortion_model"][i] not in ("none", "plumb_bob", "rational_polynomial", "equidistant"):
                c.add(rel, "distortion_model", f"unknown model {cam['distortion_model'][i]!r}, expected none, "
                                               "plumb_bob, rational_polynomial or equidistant", i)
            cams[cid] = {"width": w, "height": h}
    return cams


def _check_boxes(c: _Collector, tables: dict[str, pa.Table]) -> None:
    """Extents, centres and rotations of the receptacle, door and opening boxes."""
    for name in ("receptacles", "doors", "openings"):
        if name not in tables:
            continue
        rel = table_path(name)
        t = tables[name]
        if t.num_rows == 0:
            continue
        ext = np.asarray(t.column("extent_m").combine_chunks().flatten().to_numpy(), float).reshape(-1, 3)
        ctr = np.asarray(t.column("center_m").combine_chunks().flatten().to_numpy(), float).reshape(-1, 3)
        rot = np.asarray(t.column("rotation").combine_chunks().flatten().to_numpy(), float).reshape(-1, 3, 3)
        for i in _rows_where(~np.all(np.isfinite(ext), 1) | np.any(ext <= 0, 1)):
            c.add(rel, "extent_m", f"{ext[i].tolist()}, expected three positive finite side lengths", i)
        for i in _rows_where(~np.all(np.isfinite(ctr), 1)):
            c.add(rel, "center_m", f"{ctr[i].tolist()}, expected finite coordinates", i)
        _check_rotations(c, rel, "rotation", rot)


def _check_door_states(c: _Collector, cols: dict[str, dict[str, list[Any]]]) -> None:
    """Door states are one of :data:`DOOR_STATES`."""
    if "door_states" in cols:
        rel = table_path("door_states")
        for i, s in enumerate(cols["door_states"]["state"]):
            if s not in DOOR_STATES:
                c.add(rel, "state", f"{s!r}, expected one of {', '.join(DOOR_STATES)}", i)


def _check_scans(c: _Collector, cols: dict[str, dict[str, list[Any]]]) -> dict[str, tuple[int, int]]:
    """Scan time spans and splits; returns each scan's (start, end) stamps."""
    scan_bounds: dict[str, tuple[int, int]] = {}
    if "scans" in cols:
        rel = table_path("scans")
        sc = cols["scans"]
        for i, sid in enumerate(sc["scan_id"]):
            a, b = sc["start_stamp_ns"][i], sc["end_stamp_ns"][i]
            if b < a:
                c.add(rel, "end_stamp_ns", f"{b} before start_stamp_ns {a}, expected end >= start", i)
            if sc["split"][i] not in (None, "train", "val", "test"):
                c.add(rel, "split", f"{sc['split'][i]!r}, expected train, val, test or null", i)
            scan_bounds[sid] = (a, b)
    return scan_bounds


def _check_frames(c: _Collector, t: pa.Table, scan_bounds: dict[str, tuple[int, int]]) -> None:
    """Poses, stamps and frame indices of the ``frames`` table."""
    rel = table_path("frames")
    scan = np.asarray(t.column("scan_id").to_numpy(zero_copy_only=False)).astype(str)
    fidx = t.column("frame_index").to_numpy()
    stamp = t.column("stamp_ns").to_numpy()
    T = np.asarray(t.column("T_world_camera").combine_chunks().flatten().to_numpy(), float).reshape(-1, 4, 4)
    bad_T = ~np.all(np.isfinite(T), axis=(1, 2))
    for i in _rows_where(bad_T):
        c.add(rel, "T_world_camera", "contains NaN or infinite values, expected a finite 4x4 pose", i)
    good = np.flatnonzero(~bad_T)
    _check_rotations(c, rel, "T_world_camera", T[good, :3, :3], rows=good)
    bottom = np.abs(T[good, 3, :] - np.array([0, 0, 0, 1.0])).max(axis=1) if good.size else np.zeros(0)
    for j in _rows_where(bottom > 1e-9):
        c.add(rel, "T_world_camera", "last row is not [0, 0, 0, 1], expected a homogeneous rigid transform",
              int(good[j]))
    order = np.lexsort((fidx, scan))
    s_o, f_o, t_o = scan[order], fidx[order], stamp[order]
    same = s_o[1:] == s_o[:-1]
    for j in _rows_where(same & (t_o[1:] <= t_o[:-1])):
        c.add(rel, "stamp_ns", f"must increase within scan {str(s_o[j + 1])!r}, got {t_o[j + 1]} after {t_o[j]}",
              int(order[j + 1]))
    starts = np.concatenate([[True], ~same])
    expect = np.zeros_like(f_o)
    run_start = 0
    for j in range(f_o.size):  # frame_index must be 0..N-1 per scan
        if starts[j]:
            run_start = j
        expect[j] = j - run_start
    for j in _rows_where(f_o != expect):
        c.add(rel, "frame_index", f"{f_o[j]} in scan {str(s_o[j])!r}, expected consecutive indices from 0 "
                                  f"(here {expect[j]})", int(order[j]))
    for j, sid in enumerate(scan):
        if sid in scan_bounds:
            a, b = scan_bounds[sid]
            if not a <= stamp[j] <= b:
                c.add(rel, "stamp_ns", f"{stamp[j]} outside its scan's [start_stamp_ns, end_stamp_ns] = "
                                       f"[{a}, {b}]", j)


def _check_images(c: _Collector, root: Path, real: str, d: dict[str, list], cams: dict[str, dict],
                  color_encoding: str, decode: bool = True) -> None:
    """Every image is inside the dataset and exists (whole file or byte range of a tar member), its
    header fits its camera and (``decode``, only then) it is complete and decodes.
    """
    rel = table_path("frames")
    n = len(d["scan_id"])
    sizes: dict[str, int | None] = {}
    outside: dict[str, str | None] = {}
    fds: dict[str, object] = {}

    def file_size(rp: str) -> int | None:
        if rp not in sizes:
            p = root / rp
            sizes[rp] = p.stat().st_size if p.is_file() else None
        return sizes[rp]

    try:
        for j in range(n):
            cam = cams.get(d["camera_id"][j])
            for kind in ("color", "depth"):
                rp = d[f"{kind}_path"][j]
                off = d.get(f"{kind}_offset", [None] * n)[j]
                size = d.get(f"{kind}_size", [None] * n)[j]
                if rp not in outside:
                    outside[rp] = path_problem(real, rp)
                if outside[rp] is not None:
                    c.add(rel, f"{kind}_path", f"path {rp!r} {outside[rp]}, {_OUTSIDE}", j)
                    continue
                fsize = file_size(rp)
                if fsize is None:
                    c.add(rel, f"{kind}_path", f"image {rp} does not exist", j)
                    continue
                where = rp
                if (off is None) != (size is None):
                    c.add(rel, f"{kind}_offset", f"{kind}_offset and {kind}_size must both be set (a byte range of "
                                                 f"{rp}) or both null (the whole file)", j)
                    continue
                if off is not None:
                    where = f"{rp}@{off}"
                    if off < 512 or size <= 0 or off + size > fsize or off % 512:
                        c.add(rel, f"{kind}_offset", f"byte range [{off}, {off + size}) is not inside {rp} "
                                                     f"({fsize} bytes) at a tar block boundary, expected the data "
                                                     f"of one archive member", j)
                        continue
                    fh = fds.get(rp)
                    if fh is None:
                        fh = fds[rp] = open(root / rp, "rb")
                    fh.seek(off - 512)  # type: ignore[attr-defined]
                    block = fh.read(512 + min(size, 65536))  # type: ignore[attr-defined]
                    member = _tar_member(block[:512])
                    if member is None or member[1] != size:
                        c.add(where, "tar", f"no tar member header of {size} bytes before the image "
                                            f"(found {member!r}), expected the ustar header of its member")
                        continue
                    try:
                        hdr = parse_image_header(block[512:])
                    except ValueError:
                        try:
                            hdr = read_image_header(root / rp, off, size)
                        except (OSError, ValueError) as exc:
                            c.add(where, "image", f"unreadable image header ({exc}), expected PNG or JPEG")
                            continue
                else:
                    try:
                        hdr = read_image_header(root / rp)
                    except (OSError, ValueError) as exc:
                        c.add(where, "image", f"unreadable image header ({exc}), expected PNG or JPEG")
                        continue
                w, h = (cam["width"], cam["height"]) if cam is not None else (hdr.width, hdr.height)
                problems = header_problems(hdr, kind, w, h, "jpeg" if color_encoding == "jpeg" else "png")
                nbytes, limit = (fsize if off is None else size), max_encoded_bytes(w, h, kind)
                if nbytes > limit:
                    problems.append(("size_bytes", f"{nbytes} bytes, more than the {limit} an image of its camera "
                                                   "may take"))
                for field, what in problems:
                    c.add(where, field, what)
                if decode and not problems:  # never decode an image whose header does not fit: a bomb
                    _verify(c, root / rp, off, size, hdr, where)
    finally:
        for fh in fds.values():
            fh.close()  # type: ignore[attr-defined]


def _verify(c: _Collector, path: Path, off: int | None, size: int | None, hdr: Any, where: str) -> None:
    """The whole image: structure checked and decoded (see :func:`~psg_data.schemas._image_check.verify_image`)."""
    from psg_data.schemas._image_check import DamagedImage, verify_image

    try:
        with open(path, "rb") as fh:
            if off is not None:
                fh.seek(off)
            data = fh.read() if size is None else fh.read(size)
    except OSError as exc:
        c.add(where, "image", f"unreadable ({exc.strerror or exc})")
        return
    try:
        verify_image(data, hdr)
    except DamagedImage as exc:
        c.add(where, "image", f"corrupt {hdr.kind.upper()}: {exc}; expected a complete image that decodes")


def _tar_member(block: bytes) -> tuple[str, int] | None:
    """(name, size) of a regular-file tar header block with a valid checksum (``tarfile``), else None."""
    import tarfile

    try:
        info = tarfile.TarInfo.frombuf(block, "utf-8", "surrogateescape")
    except tarfile.HeaderError:
        return None
    return (info.name, info.size) if info.isreg() else None


def _check_label_tables(c: _Collector, cols: dict[str, dict[str, list[Any]]],
                        scan_bounds: dict[str, tuple[int, int]]) -> None:
    """Value checks of the optional ``labels`` and ``visibility`` tables."""
    objects = set(cols.get("objects", {}).get("object_id", []))
    receptacles = set(cols.get("receptacles", {}).get("receptacle_id", []))
    doors = set(cols.get("doors", {}).get("door_id", []))
    door_edge_states = {"open", "closed"}
    if "labels" in cols:
        rel = table_path("labels")
        d = cols["labels"]
        for i, (sid, oid, rid, st, code) in enumerate(zip(d["scan_id"], d["object_id"], d["receptacle_id"],
                                                          d["stamp_ns"], d["code"])):
            if code not in LABEL_CODES:
                c.add(rel, "code", f"{code}, expected one of 1, 0, -1, -2", i)
            if sid in scan_bounds and not scan_bounds[sid][0] <= st <= scan_bounds[sid][1]:
                c.add(rel, "stamp_ns", f"{st} outside scan {sid!r} [{scan_bounds[sid][0]}, {scan_bounds[sid][1]}], "
                                       "expected a time within its scan", i)
            if oid in doors:
                if rid not in door_edge_states:
                    c.add(rel, "receptacle_id", f"{rid!r} for door {oid!r}, expected 'open' or 'closed'", i)
            elif oid not in objects:
                c.add(rel, "object_id", f"dangling id {oid!r}: not in tables/objects.parquet nor "
                                        f"tables/doors.parquet", i)
            elif rid not in receptacles:
                c.add(rel, "receptacle_id", f"dangling id {rid!r}: not in tables/receptacles.parquet column "
                                            "receptacle_id", i)
    if "visibility" in cols:
        rel = table_path("visibility")
        d = cols["visibility"]
        ids = {"receptacle": receptacles, "object": objects, "door": doors}
        for i, (kind, id_, frac, px, fs, vis) in enumerate(zip(d["kind"], d["id"], d["seen_fraction"], d["pixels"],
                                                               d["frames_seen"], d["visible"])):
            if kind not in VISIBILITY_KINDS:
                c.add(rel, "kind", f"{kind!r}, expected one of {', '.join(VISIBILITY_KINDS)}", i)
            elif id_ not in ids[kind]:
                c.add(rel, "id", f"dangling {kind} id {id_!r}: not in {table_path(kind + 's')}", i)
            if not (np.isfinite(frac) and 0.0 <= frac <= 1.0):
                c.add(rel, "seen_fraction", f"{frac}, expected a number in [0, 1]", i)
            if not (np.isfinite(px) and px >= 0):
                c.add(rel, "pixels", f"{px}, expected a finite number >= 0", i)
            if fs < 0:
                c.add(rel, "frames_seen", f"{fs}, expected >= 0", i)
            if vis and (frac <= 0 or fs <= 0):
                c.add(rel, "visible", "true although nothing was seen (seen_fraction or frames_seen is 0), "
                                      "expected false", i)


def _check_process_file(c: _Collector, root: Path, real: str, extra: dict[str, Any],
                        cols: dict[str, dict[str, list]]) -> None:
    """A synthetic dataset's generator model (manifest ``extra.process_file``): present, readable,
    well formed (shapes, stochastic rows, ranges) and naming objects, doors and receptacles of the
    dataset (docs/FORMAT.md, "Generator model").
    """
    rel = extra.get("process_file") if isinstance(extra, dict) else None
    if not rel:
        return
    outside = path_problem(real, rel)
    if outside is not None:
        c.add(MANIFEST_NAME, "extra.process_file", f"path {rel!r} {outside}, {_OUTSIDE}")
        return
    path = root / str(rel)
    if not path.is_file():
        c.add(MANIFEST_NAME, "extra.process_file", f"{rel!r} does not exist, expected the generator model file")
        return
    from psg_data.schemas._generator_model import PROCESS_FORMAT, StepProcess

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        c.add(str(rel), "json", f"not valid JSON ({exc}), expected a {PROCESS_FORMAT} document")
        return
    try:
        proc = StepProcess.from_dict(data, str(rel), check=False)
    except PsgDataError as exc:
        msg = str(exc)
        c.add(str(rel), "process", msg[len(str(rel)) + 2:] if msg.startswith(f"{rel}: ") else msg)
        return
    for problem in proc.problems():
        field, _, what = problem.rpartition(": ")
        c.add(str(rel), field.replace(": ", ".") or "process", what)
    objects = set(cols.get("objects", {}).get("object_id", []))
    doors = set(cols.get("doors", {}).get("door_id", []))
    recs = set(cols.get("receptacles", {}).get("receptacle_id", []))
    for eid, ent in proc.entities.items():
        if ent.kind == "object":
            if eid not in objects:
                c.add(str(rel), f"entities.{eid}", "object not in tables/objects.parquet")
            bad = [s for s in ent.states if s is not None and s not in recs]
            if bad:
                c.add(str(rel), f"entities.{eid}.states", f"receptacles {bad} not in tables/receptacles.parquet")
        elif ent.kind == "door":
            if eid not in doors:
                c.add(str(rel), f"entities.{eid}", "door not in tables/doors.parquet")
            if set(ent.states) - {"open", "closed"}:
                c.add(str(rel), f"entities.{eid}.states", f"{list(ent.states)}, expected states open/closed")
        else:
            c.add(str(rel), f"entities.{eid}.kind", f"{ent.kind!r}, expected object or door")
