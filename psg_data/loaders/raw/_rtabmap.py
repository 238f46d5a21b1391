"""RTAB-Map databases (``rtabmap.db``): nodes, links, optimized poses and sensor data, read-only.

Layouts as RTAB-Map writes them (introlab/rtabmap; docs/RAW_FORMATS.md cites the files and
versions): ``Node.pose``, ``Link.transform`` are 3x4 row-major float32 (12 x 4 bytes, ``Transform``);
``Link.information_matrix`` 6x6 float64 (x, y, z, roll, pitch, yaw order); ``Admin.opt_ids`` /
``opt_poses`` are ``compressData2`` blobs (zlib stream + int32 rows, cols, OpenCV type);
``Data.calibration`` is, from 0.18.0, one ``CameraModel::serialize`` record per camera (11 int32
header, K, D, R, P float64, local transform float32) and before that 18 float32 per camera
(fx, fy, cx, cy, width, height, local transform); ``Data.image`` is JPEG/PNG bytes; ``Data.depth``
a 16-bit PNG (millimetres), an 8-bit 4-channel PNG holding float32 metres, or ``DEPTHRVL`` + uint32
cols, rows + RVL words. The database is opened with a read-only ``immutable`` URI and never written:
SQLite takes no lock and creates no ``-wal`` / ``-shm`` file beside it (a read-only folder works); a
database with a non-empty ``-wal`` or ``-journal`` beside it (still open in RTAB-Map, or left by a
crash) is refused, since ``immutable`` would read it without those transactions. Every blob is
checked against its declared size before it is inflated or decoded (docs/SECURITY.md).
"""

from __future__ import annotations

import sqlite3
import struct
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

import numpy as np
from numpy.typing import NDArray

from psg_data._settings import STAMP_MAX_NS
from psg_data.errors import ConversionError
from psg_data.schemas._image_headers import inflate_bounded, parse_image_header, pixels_problem

__all__ = ["RtabmapDatabase", "RtabNode", "RtabLink", "RtabCamera", "rtabmap_format", "parse_transform",
           "uncompress_data", "parse_calibration", "decode_rvl", "decode_depth", "rvl_max_bytes", "MIN_VERSION",
           "RVL_SIGNATURE", "GRAPH_LINK_TYPES"]

MIN_VERSION = (0, 17, 0)
"""Oldest database schema read (``Admin.opt_ids`` / ``opt_poses`` exist from 0.17.0)."""
RVL_SIGNATURE = b"DEPTHRVL"
GRAPH_LINK_TYPES = (0, 1, 2, 3, 4, 6)
"""Link types that constrain two nodes' poses: neighbor, global / local-space / local-time / user
closure, merged neighbor (pose priors, 7, and landmarks, 8, are not node-to-node constraints)."""
_SQLITE_MAGIC = b"SQLite format 3\x00"
_CV_DTYPES = {0: np.uint8, 1: np.int8, 2: np.uint16, 3: np.int16, 4: np.int32, 5: np.float32, 6: np.float64}
_OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
"""``CameraModel::opticalRotation()``: the default local transform (optical frame -> base frame)."""


def rtabmap_format(path: str | Path) -> str | None:
    """``rtabmap`` for a ``.db`` file (an RTAB-Map database), else None."""
    p = Path(path)
    return "rtabmap" if p.is_file() and p.suffix.lower() == ".db" else None


@dataclass
class RtabNode:
    """One ``Node`` row: ``pose`` is base-to-world (RTAB-Map's robot frame: x forward, z up), 4x4."""

    id: int
    map_id: int
    stamp_ns: int
    pose: NDArray[np.float64] | None
    label: str | None


@dataclass
class RtabLink:
    """One ``Link`` row: the pose of ``to_id`` in the frame of ``from_id`` (``T_from^-1 T_to``)."""

    from_id: int
    to_id: int
    type: int
    transform: NDArray[np.float64]
    information: NDArray[np.float64]


@dataclass
class RtabCamera:
    """One camera of ``Data.calibration``: pixels; ``local`` maps the optical frame to the base frame."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    local: NDArray[np.float64]
    distortion: tuple[float, ...] = ()


_ROT_TOL_F32 = 4e-6
"""Largest |R^T R - I| accepted in a stored rotation: float32 rounding gives ~2e-7; validate allows 1e-5
for the camera poses, which are products of two such rotations."""


def parse_transform(blob: bytes | None, where: str) -> NDArray[np.float64] | None:
    """A ``Transform`` blob (12 float32, 3x4 row-major) as a 4x4 float64 matrix; None for NULL."""
    if blob is None:
        return None
    if len(blob) != 48:
        raise ConversionError(f"{where}: {len(blob)} bytes; expected 48 (a 3x4 float32 transform)")
    T = np.eye(4)
    T[:3, :] = np.frombuffer(blob, "<f4").reshape(3, 4)
    check_rotation(T, where)
    return T


def check_rotation(T: NDArray[np.float64], where: str) -> None:
    """Refuse a finite transform whose rotation is not proper to float32 precision (NaN / inf: the caller's message)."""
    R = T[:3, :3]
    if np.all(np.isfinite(R)):
        err = float(np.abs(R.T @ R - np.eye(3)).max())
        if err > _ROT_TOL_F32 or np.linalg.det(R) <= 0:
            raise ConversionError(f"{where}: rotation is not orthonormal with det +1 (max |R^T R - I| = {err:.3g}); "
                                  f"expected a proper rotation to float32 precision ({_ROT_TOL_F32:g})")


def uncompress_data(blob: bytes, where: str, max_bytes: int) -> NDArray[np.generic]:
    """A ``compressData2`` blob: zlib stream, then int32 rows, cols and OpenCV type; as a (rows, cols*cn) array.

    The trailer's size is checked against ``max_bytes`` before anything is inflated, and the stream
    is inflated to at most that size (:func:`~psg_data.schemas._image_headers.inflate_bounded`).
    """
    if len(blob) < 12:
        raise ConversionError(f"{where}: {len(blob)} bytes; expected a zlib stream and a 12-byte matrix trailer")
    rows, cols, cv_type = struct.unpack("<3i", blob[-12:])
    depth, channels = cv_type & 7, (cv_type >> 3) + 1
    if depth not in _CV_DTYPES or rows < 0 or cols < 0:
        raise ConversionError(f"{where}: matrix trailer rows {rows}, cols {cols}, type {cv_type}; expected a "
                              f"non-negative size and an OpenCV depth 0-6")
    dtype = np.dtype(_CV_DTYPES[depth]).newbyteorder("<")
    want = rows * cols * channels * dtype.itemsize
    if want > max_bytes:
        raise ConversionError(f"{where}: matrix trailer declares {rows}x{cols}x{channels} {dtype.name} ({want} "
                              f"bytes); expected at most {max_bytes} bytes for this database (not inflated)")
    try:
        raw = inflate_bounded([memoryview(blob)[:-12]], want)
    except ValueError as exc:
        msg = f"zlib data cut short or corrupt ({exc})" if "early" in str(exc) or "damaged" in str(exc) else str(exc)
        raise ConversionError(f"{where}: {msg}; the trailer says {rows}x{cols}x{channels} {dtype.name}") from None
    return np.frombuffer(raw, dtype).reshape(rows, cols * channels)


def _camera(fx: float, fy: float, cx: float, cy: float, w: int, h: int, local: NDArray[np.float64],
            dist: tuple[float, ...], where: str) -> RtabCamera:
    vals = np.array([fx, fy, cx, cy, w, h], float)
    if not np.all(np.isfinite(vals)) or not np.all(np.isfinite(local)) or w < 0 or h < 0:
        raise ConversionError(f"{where}: non-finite or negative values (fx {fx}, fy {fy}, cx {cx}, cy {cy}, "
                              f"{w}x{h}); expected a camera calibration")
    check_rotation(local, f"{where}: local transform")
    if not all(np.isfinite(dist)):
        raise ConversionError(f"{where}: distortion coefficients {list(dist)}: NaN or infinite; expected finite "
                              f"values")
    if cx == 0.0 and w > 0:  # CameraModel: a zero principal point means the image centre
        cx = w / 2.0 - 0.5
    if cy == 0.0 and h > 0:
        cy = h / 2.0 - 0.5
    return RtabCamera(float(fx), float(fy), float(cx), float(cy), int(w), int(h), local, dist)


def _serialized_cameras(blob: bytes, where: str) -> list[RtabCamera]:
    """``CameraModel::serialize`` records one after the other (RTAB-Map >= 0.18.0)."""
    cams, off = [], 0
    while off < len(blob):
        if len(blob) - off < 44:
            raise ConversionError(f"{where}: {len(blob) - off} bytes left; expected an 11-int32 camera header "
                                  f"(calibration of the wrong size)")
        hdr = struct.unpack_from("<11i", blob, off)
        kind, w, h, nk, nd, nr, np_, nl = hdr[3], hdr[4], hdr[5], hdr[6], hdr[7], hdr[8], hdr[9], hdr[10]
        if kind != 0:
            raise ConversionError(f"{where}: camera type {kind} (1 is a stereo pair); expected a mono RGB-D camera "
                                  f"(type 0)")
        if nk not in (0, 9) or nr not in (0, 9) or np_ not in (0, 12) or nl not in (0, 12) or not 0 <= nd <= 14:
            raise ConversionError(f"{where}: header sizes K {nk}, D {nd}, R {nr}, P {np_}, local {nl}; expected "
                                  f"K 9, R 9 or 0, P 12 or 0, local 12 or 0")
        need = 44 + 8 * (nk + nd + nr + np_) + 4 * nl
        if len(blob) - off < need:
            raise ConversionError(f"{where}: {len(blob) - off} bytes; the camera header announces {need} "
                                  f"(calibration of the wrong size)")
        p = off + 44
        K = np.frombuffer(blob, "<f8", nk, p).reshape(3, 3) if nk else None
        p += 8 * nk
        D = tuple(float(v) for v in np.frombuffer(blob, "<f8", nd, p))
        p += 8 * (nd + nr)
        P = np.frombuffer(blob, "<f8", np_, p).reshape(3, 4) if np_ else None
        p += 8 * np_
        local = _OPTICAL.copy()
        if nl:
            local[:3, :] = np.frombuffer(blob, "<f4", 12, p).reshape(3, 4)
        M = K if K is not None else P
        if M is None:
            raise ConversionError(f"{where}: neither K nor P; expected the camera matrix")
        cams.append(_camera(M[0, 0], M[1, 1], M[0, 2], M[1, 2], w, h, local, D, where))
        off += need
    return cams


def parse_calibration(blob: bytes, version: tuple[int, ...], where: str) -> list[RtabCamera]:
    """The cameras of a ``Data.calibration`` blob of a database of ``version``.

    Raises:
        ConversionError: a blob of the wrong size, a stereo calibration, or non-finite values.
    """
    if version >= (0, 18, 0):
        return _serialized_cameras(blob, where)
    per = (6 + 12) * 4
    if len(blob) in ((5 + 12) * 4, (7 + 12) * 4):
        raise ConversionError(f"{where}: a stereo calibration ({len(blob)} bytes); expected a mono RGB-D camera")
    if len(blob) == 0 or len(blob) % per:
        raise ConversionError(f"{where}: {len(blob)} bytes; expected a multiple of {per} (fx, fy, cx, cy, width, "
                              f"height, 3x4 local transform as float32 per camera: calibration of the wrong size)")
    cams = []
    for f in np.frombuffer(blob, "<f4").reshape(-1, 18).astype(np.float64):
        local = np.eye(4)
        local[:3, :] = f[6:].reshape(3, 4)
        w, h = (int(v) if np.isfinite(v) else -1 for v in f[4:6])
        cams.append(_camera(f[0], f[1], f[2], f[3], w, h, local, (), where))
    return cams


_RVL_BLOCK_WORDS = 1 << 16
"""RVL words expanded to nibbles at a time (a few MB of temporaries)."""


def _rvl_values(data: bytes | memoryview, limit: int, n_pixels: int, where: str) -> NDArray[np.int64]:
    """The first ``limit`` VLE values of RVL ``data`` (fewer if it holds fewer), a block of words at a time."""
    words = np.frombuffer(data, "<u4", len(data) // 4)
    shifts = np.arange(28, -1, -4, dtype=np.uint32)
    out: list[NDArray[np.int64]] = []
    have, carry = 0, np.empty(0, np.uint8)
    for k in range(0, len(words), _RVL_BLOCK_WORDS):
        nib = np.concatenate([carry, ((words[k:k + _RVL_BLOCK_WORDS, None] >> shifts) & 0xF).astype(np.uint8).ravel()])
        ends = np.flatnonzero(nib < 8)
        starts = np.r_[0, ends[:-1] + 1] if ends.size else ends
        carry = nib[ends[-1] + 1:] if ends.size else nib
        if carry.size > 10 or (ends.size and int((ends - starts).max()) > 10):
            raise ConversionError(f"{where}: RVL value longer than 32 bits; expected RVL-coded depth")
        if not ends.size:
            continue
        pos = np.arange(ends[-1] + 1) - np.repeat(starts, ends - starts + 1)
        out.append(np.add.reduceat((nib[: ends[-1] + 1] & 7).astype(np.int64) << (3 * pos), starts))
        have += out[-1].size
        if have >= limit:
            break
    if not out:
        raise ConversionError(f"{where}: RVL data cut short (no complete value); expected {n_pixels} pixels")
    return np.concatenate(out)[:limit]


def decode_rvl(data: bytes | memoryview, n_pixels: int, where: str) -> NDArray[np.uint16]:
    """RVL-coded 16-bit pixels (runs of zeros / non-zeros, zig-zag deltas in 3-bit-nibble VLE words).

    Vectorised: the nibbles of the 32-bit words (most significant first), a block of words at a
    time, give the VLE values; only the runs are walked in Python, and the non-zero pixels are the
    running sum of the deltas (uint16 arithmetic, as the codec's). Memory is bounded by the block and
    by the ``3 * n_pixels + 2`` values an image can need (each run pair covers a pixel), whatever
    the length of ``data``.
    """
    vals = _rvl_values(data, 3 * n_pixels + 2, n_pixels, where)
    runs, i, px, nv = [], 0, 0, vals.size
    while px < n_pixels:
        if i + 2 > nv:
            raise ConversionError(f"{where}: RVL data cut short at pixel {px}; expected {n_pixels} pixels")
        zeros, nonzeros = int(vals[i]), int(vals[i + 1])
        px += zeros
        if px + nonzeros > n_pixels or i + 2 + nonzeros > nv:
            raise ConversionError(f"{where}: RVL run of {nonzeros} values at pixel {px} overflows the image or the "
                                  f"data; expected {n_pixels} pixels")
        if nonzeros:
            runs.append((px, i + 2, nonzeros))
        i += 2 + nonzeros
        px += nonzeros
    out = np.zeros(n_pixels, np.uint16)
    if runs:
        r = np.array(runs, np.int64)
        counts = r[:, 2]
        offs = np.repeat(np.cumsum(counts) - counts, counts)
        k = np.arange(counts.sum()) - offs
        z = vals[np.repeat(r[:, 1], counts) + k]
        delta = (z >> 1) ^ -(z & 1)
        out[np.repeat(r[:, 0], counts) + k] = (np.cumsum(delta) & 0xFFFF).astype(np.uint16)
    return out


def rvl_max_bytes(n_pixels: int) -> int:
    """Most bytes RVL codes ``n_pixels`` pixels in: at most one (zeros, non-zeros) pair of run lengths
    (9 nibbles each below 2^27) and one delta (6 nibbles for 16 bits, zig-zagged) per pixel.
    """
    return 12 * n_pixels + 16


def decode_depth(blob: bytes, where: str, size: tuple[int, int]) -> NDArray[np.uint16] | None:
    """A ``Data.depth`` blob that is not a 16-bit PNG, as uint16 millimetres (0 = invalid).

    Returns None for a 16-bit PNG (stored as is by the caller). RVL (``DEPTHRVL``) is decoded;
    an 8-bit 4-channel PNG is RTAB-Map's lossless float32 metres (``compressImage`` of a 32FC1
    image), rounded to millimetres. Nothing is decoded before the declared size (RVL header, PNG
    IHDR) is checked against the camera's ``size`` (width, height) and the pixel cap, and the length
    of RVL data against what that many pixels can take.

    Raises:
        ConversionError: an unknown or damaged depth encoding, or a size that does not fit.
    """
    import cv2

    if blob[:8] == RVL_SIGNATURE:
        if len(blob) < 16:
            raise ConversionError(f"{where}: RVL header cut short ({len(blob)} bytes); expected 16")
        cols, rows = struct.unpack_from("<2I", blob, 8)
        problem = "a positive size is expected" if cols * rows == 0 else pixels_problem(cols, rows, size)
        if problem:
            raise ConversionError(f"{where}: RVL image of {cols}x{rows}: {problem}; not decoded")
        if len(blob) - 16 > rvl_max_bytes(cols * rows):
            raise ConversionError(f"{where}: RVL data of {len(blob) - 16} bytes for {cols}x{rows} pixels; expected "
                                  f"at most {rvl_max_bytes(cols * rows)}; not decoded")
        return decode_rvl(memoryview(blob)[16:], cols * rows, where).reshape(rows, cols)
    try:
        info = parse_image_header(blob)
    except ValueError:
        raise ConversionError(f"{where}: neither a PNG nor RVL depth image (starts with {bytes(blob[:8]).hex()}); "
                              f"expected 16-bit PNG, RVL or 32-bit float depth") from None
    problem = pixels_problem(info.width, info.height, size)
    if problem:
        raise ConversionError(f"{where}: {problem}; not decoded")
    if info.kind == "png" and info.bit_depth == 16 and info.channels == 1:
        return None
    if info.kind == "png" and info.bit_depth == 8 and info.channels == 4:
        img = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None or img.ndim != 3 or img.shape[2] != 4:
            raise ConversionError(f"{where}: float depth PNG does not decode; expected an 8-bit 4-channel PNG")
        m = np.ascontiguousarray(img).view("<f4")[..., 0]
        mm = np.where(np.isfinite(m) & (m > 0), np.rint(m * 1000.0), 0)
        return np.clip(mm, 0, 65535).astype(np.uint16)
    raise ConversionError(f"{where}: depth is a {info.bit_depth}-bit {info.channels}-channel {info.kind.upper()}; "
                          f"expected 16-bit PNG, RVL or 32-bit float depth")


def _blob(value: object, where: str) -> bytes | None:
    """A BLOB column's value (NULL -> None); anything else is refused."""
    if value is None or isinstance(value, bytes):
        return value
    raise ConversionError(f"{where}: a {type(value).__name__} value; expected a BLOB")


def _version(text: str, where: str) -> tuple[int, ...]:
    try:
        return tuple(int(p) for p in str(text).strip().split("."))
    except ValueError:
        raise ConversionError(f"{where}: Admin.version {text!r}; expected an RTAB-Map version like 0.21.4") from None


class RtabmapDatabase:
    """A read-only connection to an RTAB-Map database (``with`` closes it).

    Raises:
        ConversionError: not a readable SQLite database, locked by a writer, a required table or
            column missing, or a version before :data:`MIN_VERSION`.
    """

    _REQUIRED = {"Admin": ("version",), "Node": ("id", "map_id", "stamp", "pose", "label"),
                 "Data": ("id", "image", "depth", "calibration"),
                 "Link": ("from_id", "to_id", "type", "transform", "information_matrix")}

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.where = str(self.path)
        self.size_bytes = self.path.stat().st_size
        with open(self.path, "rb") as fh:
            magic = fh.read(16)
        if magic != _SQLITE_MAGIC:
            raise ConversionError(f"{self.where}: not an SQLite database (header {magic[:16]!r}); expected an "
                                  f"RTAB-Map database (rtabmap.db)")
        self._refuse_live_journal()
        # immutable: SQLite takes no lock and creates no -wal / -shm / -journal file beside the input
        uri = f"file:{quote(str(self.path.resolve()))}?mode=ro&immutable=1"
        try:
            self.con = sqlite3.connect(uri, uri=True, timeout=1.0, check_same_thread=False)
        except sqlite3.Error as exc:
            raise ConversionError(f"{self.where}: cannot open read-only ({exc}); expected a readable RTAB-Map "
                                  f"database") from None
        try:
            self._check_schema()
        except BaseException:
            self.con.close()
            raise

    def _refuse_live_journal(self) -> None:
        """Refuse a database whose last transactions are in a journal beside it: opened ``immutable``,
        SQLite would not read a write-ahead log (``-wal``) nor roll back a hot ``-journal``.
        """
        for suffix, why in (("-wal", "holds transactions not yet written into the database"),
                            ("-journal", "means a transaction is being written (or was interrupted)")):
            side = self.path.with_name(self.path.name + suffix)
            try:
                size = side.stat().st_size
            except OSError:
                continue
            if size > 0:
                raise ConversionError(f"{self.where}: database is locked by another writer: {side.name} {why}; close "
                                      f"RTAB-Map (or the process writing it) and rerun (after a crash, opening the "
                                      f"database once with sqlite3 applies {side.name})")

    def _rows(self, sql: str, what: str, args: tuple[object, ...] = ()) -> list[tuple[object, ...]]:
        """Every row of a query; an SQLite error (locked, malformed, ...) as a ConversionError, and so
        is text that is not UTF-8 (in a damaged file, even SQLite's own error message may be such text).
        """
        try:
            return self.con.execute(sql, args).fetchall()
        except (sqlite3.Error, UnicodeDecodeError) as exc:
            raise self._error(exc, what) from None

    def _error(self, exc: sqlite3.Error | UnicodeDecodeError, what: str) -> ConversionError:
        msg = str(exc)
        if "locked" in msg or "busy" in msg:
            return ConversionError(f"{self.where}: {what}: database is locked by another writer; close RTAB-Map "
                                   f"(or the process writing it) and rerun")
        return ConversionError(f"{self.where}: {what}: {msg} (a truncated or damaged file?); expected a complete "
                               f"RTAB-Map database")

    def _check_schema(self) -> None:
        tables = {r[0] for r in self._rows("SELECT name FROM sqlite_master WHERE type='table'", "sqlite_master")}
        for table, cols in self._REQUIRED.items():
            if table not in tables:
                raise ConversionError(f"{self.where}: table {table} missing; expected an RTAB-Map database with "
                                      f"tables {', '.join(self._REQUIRED)}")
            have = {r[1] for r in self._rows(f"PRAGMA table_info({table})", table)}
            missing = [c for c in cols if c not in have]
            if missing:
                raise ConversionError(f"{self.where}: {table}.{missing[0]}: column missing; expected the RTAB-Map "
                                      f"schema of 0.17.0 or later")
        rows = self._rows("SELECT version FROM Admin", "Admin.version")
        row = rows[0] if rows else None
        if row is None:
            raise ConversionError(f"{self.where}: Admin.version: no row; expected the database version")
        self.version_text = str(row[0])
        self.version = _version(self.version_text, self.where)
        if self.version < MIN_VERSION:
            raise ConversionError(f"{self.where}: Admin.version {self.version_text}: expected an RTAB-Map database "
                                  f"of version 0.17.0 or later")
        self.has_opt = {"opt_ids", "opt_poses"} <= {r[1] for r in self._rows("PRAGMA table_info(Admin)", "Admin")}

    def __enter__(self) -> RtabmapDatabase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.con.close()

    def nodes(self) -> list[RtabNode]:
        """Every node, by id (stamps: ``Node.stamp`` seconds to integer nanoseconds)."""
        out = []
        for nid, map_id, stamp, pose, label in self._rows(
                "SELECT id, map_id, stamp, pose, label FROM Node ORDER BY id", "Node"):
            where = f"{self.where}: node {nid}"
            if not isinstance(nid, int) or not isinstance(map_id, int):
                raise ConversionError(f"{where}: Node.id / Node.map_id {nid!r}, {map_id!r}; expected integers")
            pose = _blob(pose, f"{where}: Node.pose")
            T = parse_transform(pose, f"{where}: Node.pose")
            if T is not None and not np.all(np.isfinite(T)):
                raise ConversionError(f"{where}: Node.pose: NaN or infinite values; expected a finite 3x4 transform")
            if not isinstance(stamp, (int, float)) or not 0 <= float(stamp) * 1e9 <= STAMP_MAX_NS:
                raise ConversionError(f"{where}: Node.stamp {stamp!r}; expected a time in seconds from 0 to "
                                      f"{STAMP_MAX_NS / 1e9:.0f} (int64 nanoseconds)")
            out.append(RtabNode(int(nid), int(map_id), int(round(float(stamp) * 1e9)), T,
                                None if label is None else str(label)))
        return out

    def links(self) -> list[RtabLink]:
        """Every node-to-node constraint (:data:`GRAPH_LINK_TYPES`), each pair once with ``from_id < to_id``.

        RTAB-Map stores a link in both directions (the reverse with the inverse transform).
        """
        seen: dict[tuple[int, int, int], RtabLink] = {}
        for a, b, typ, tf, info in self._rows(
                "SELECT from_id, to_id, type, transform, information_matrix FROM Link ORDER BY from_id, to_id", "Link"):
            if not isinstance(typ, int) or typ not in GRAPH_LINK_TYPES or a == b:
                continue
            where = f"{self.where}: link {a}->{b}"
            if not isinstance(a, int) or not isinstance(b, int):
                raise ConversionError(f"{where}: Link.from_id / to_id: expected node ids (integers)")
            tf, info = _blob(tf, f"{where}: Link.transform"), _blob(info, f"{where}: Link.information_matrix")
            T = parse_transform(tf, f"{where}: Link.transform")
            if T is None or not np.all(np.isfinite(T)):
                raise ConversionError(f"{where}: Link.transform: missing or non-finite; expected a 3x4 transform")
            if info is None or len(info) != 288:
                raise ConversionError(f"{where}: Link.information_matrix: {0 if info is None else len(info)} bytes; "
                                      f"expected 288 (6x6 float64)")
            I = np.frombuffer(info, "<f8").reshape(6, 6).copy()
            if a > b:
                a, b, T = b, a, np.asarray(np.linalg.inv(T), np.float64)
            seen.setdefault((a, b, int(typ)), RtabLink(int(a), int(b), int(typ), T, I))
        return list(seen.values())

    def optimized_poses(self) -> dict[int, NDArray[np.float64]]:
        """``Admin.opt_ids`` / ``opt_poses`` (the graph RTAB-Map optimised and saved on close); {} if absent."""
        if not self.has_opt:
            return {}
        rows = self._rows("SELECT opt_ids, opt_poses FROM Admin", "Admin.opt_poses")
        row = rows[0] if rows else None
        if row is None or not row[0] or not row[1]:
            return {}
        w_ids, w_poses = f"{self.where}: Admin.opt_ids", f"{self.where}: Admin.opt_poses"
        # one pose per node or landmark (a landmark is a Link row): the matrices are no larger than that
        count = self._rows("SELECT (SELECT COUNT(*) FROM Node) + (SELECT COUNT(*) FROM Link)", "Node, Link")
        n = int(count[0][0]) if count else 0  # type: ignore[call-overload]
        ids = uncompress_data(_blob(row[0], w_ids) or b"", w_ids, 4 * n).ravel()
        poses = uncompress_data(_blob(row[1], w_poses) or b"", w_poses, 48 * n)
        if ids.dtype != np.int32 or poses.dtype != np.float32 or poses.size != 12 * ids.size:
            raise ConversionError(f"{self.where}: Admin.opt_poses: {poses.size} {poses.dtype} values for {ids.size} "
                                  f"{ids.dtype} ids; expected 12 float32 per int32 id")
        P = poses.reshape(-1, 3, 4).astype(np.float64)
        if not np.all(np.isfinite(P)):
            bad = int(ids[np.flatnonzero(~np.isfinite(P).all(axis=(1, 2)))[0]])
            raise ConversionError(f"{self.where}: node {bad}: Admin.opt_poses: NaN or infinite values; expected "
                                  f"finite transforms")
        out = {}
        for nid, M in zip(ids.tolist(), P):
            T = np.eye(4)
            T[:3, :] = M
            check_rotation(T, f"{self.where}: node {nid}: Admin.opt_poses")
            out[int(nid)] = T
        return out

    def node_data(self, node_id: int) -> tuple[bytes | None, bytes | None, bytes | None]:
        """``(image, depth, calibration)`` of one node (Nones without a ``Data`` row)."""
        rows = self._rows("SELECT image, depth, calibration FROM Data WHERE id = ?", f"node {node_id}: Data",
                          (node_id,))
        if not rows:
            return None, None, None
        row = rows[0]
        w = f"{self.where}: node {node_id}: Data."
        return _blob(row[0], w + "image"), _blob(row[1], w + "depth"), _blob(row[2], w + "calibration")

    def first_image(self) -> bytes | None:
        """The first non-empty ``Data.image`` (to choose the dataset's colour encoding)."""
        rows = self._rows("SELECT image FROM Data WHERE image IS NOT NULL AND length(image) > 0 ORDER BY id LIMIT 1",
                          "Data.image")
        return _blob(rows[0][0], f"{self.where}: Data.image") if rows else None
