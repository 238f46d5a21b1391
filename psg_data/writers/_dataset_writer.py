"""``DatasetWriter``: the one way producers (synth, convert) write a psg-dataset.

Writes go into ``ROOT.partial/`` beside the target; :meth:`DatasetWriter.close` writes the tables,
the checksum table and the manifest, then renames the directory into place. An existing dataset is
only replaced with ``overwrite=True``. An interrupted write leaves ``ROOT.partial/``; reopening with
``resume=True`` keeps the scans whose images are complete (see :meth:`DatasetWriter.completed_scans`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
from collections.abc import Collection, Iterable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from psg_data.errors import DatasetExistsError, FormatError
from psg_data.schemas._manifest import DatasetInfo
from psg_data.schemas._records import CameraIntrinsics, Door, ObjectInfo, Receptacle, Room
from psg_data.schemas._tables import (
    COLOR_PATH_TEMPLATE,
    DEPTH_PATH_TEMPLATE,
    MANIFEST_NAME,
    TABLES,
    table_path,
)

__all__ = ["DatasetWriter", "ScanWriter", "sha256_file", "PNG_LEVEL", "JPEG_QUALITY"]

log = logging.getLogger(__name__)

PNG_LEVEL = 1
"""zlib level for PNG images; chosen by measurement (see docs/FORMAT.md, BENCHMARKS.md)."""
JPEG_QUALITY = 95
_PARTIAL_SUFFIX = ".partial"
_SCAN_DONE = ".scan_complete.json"
_WRITE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_BINARY", 0)


def sha256_file(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def _package_version() -> str:
    from psg_data import __version__

    return __version__


def _row(record: Any) -> dict[str, Any]:
    if is_dataclass(record) and not isinstance(record, type):
        return {f.name: getattr(record, f.name) for f in fields(record)}
    return dict(record)


def _box_cols(box: Any) -> dict[str, list[float]]:
    return {
        "center_m": [float(v) for v in np.asarray(box.center_m, float).reshape(3)],
        "extent_m": [float(v) for v in np.asarray(box.extent_m, float).reshape(3)],
        "rotation": [float(v) for v in np.asarray(box.rotation, float).reshape(9)],
    }


def to_arrow(name: str, rows: Any) -> pa.Table:
    """Cast rows (list of dicts, DataFrame or Arrow table) to the schema of table ``name``."""
    schema = TABLES[name].schema
    if isinstance(rows, pa.Table):
        table = rows
    elif hasattr(rows, "to_dict") and hasattr(rows, "columns"):  # pandas DataFrame
        table = pa.Table.from_pandas(rows, preserve_index=False)
    else:
        rows = list(rows)
        table = pa.Table.from_pylist(rows, schema=schema) if rows else schema.empty_table()
    missing = [f.name for f in schema if f.name not in table.column_names]
    if missing:
        raise FormatError(f"table '{name}': missing columns {missing}, expected {schema.names}")
    try:
        return table.select(schema.names).cast(schema)
    except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError) as exc:
        raise FormatError(f"table '{name}': cannot cast to the format schema: {exc}") from exc


class ScanWriter:
    """Adds the frames of one scan; obtained from :meth:`DatasetWriter.scan`."""

    def __init__(self, writer: DatasetWriter, scan_id: str, source: str | None, split: str | None) -> None:
        self._w = writer
        self.scan_id = scan_id
        self.source = source
        self.split = split
        self._frames: list[dict[str, Any]] = []
        self._pending: list[Future[None]] = []

    def __enter__(self) -> ScanWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            for fut in self._pending:
                fut.cancel()

    @property
    def n_frames(self) -> int:
        return len(self._frames)

    def _paths(self, index: int) -> tuple[str, str]:
        ext = "jpg" if self._w.color_encoding == "jpeg" else "png"
        return (COLOR_PATH_TEMPLATE.format(scan_id=self.scan_id, frame_index=index, ext=ext),
                DEPTH_PATH_TEMPLATE.format(scan_id=self.scan_id, frame_index=index))

    def _record(self, stamp_ns: int, T_world_camera: NDArray[np.float64], camera_id: str) -> tuple[int, str, str]:
        T = np.asarray(T_world_camera, dtype=np.float64)
        if T.shape != (4, 4):
            raise FormatError(f"scan {self.scan_id}: T_world_camera must be 4x4, got shape {T.shape}")
        if camera_id not in self._w._cameras:
            raise FormatError(f"scan {self.scan_id}: unknown camera_id {camera_id!r}; add it with add_camera first")
        index = len(self._frames)
        color_path, depth_path = self._paths(index)
        self._frames.append({
            "scan_id": self.scan_id, "frame_index": index, "stamp_ns": int(stamp_ns), "camera_id": camera_id,
            "T_world_camera": T.reshape(16).tolist(), "color_path": color_path, "depth_path": depth_path,
        })
        return index, color_path, depth_path

    def add_frame(
        self,
        stamp_ns: int,
        T_world_camera: NDArray[np.float64],
        color_rgb: NDArray[np.uint8],
        depth_mm: NDArray[np.uint16],
        camera_id: str,
    ) -> int:
        """Encode and store one frame; returns its index.

        Args:
            stamp_ns: capture time, int64 UTC nanoseconds.
            T_world_camera: (4, 4) camera-to-world pose, OpenCV camera axes, metres.
            color_rgb: (H, W, 3) uint8 RGB.
            depth_mm: (H, W) uint16 millimetres, 0 = invalid.
            camera_id: a camera added with :meth:`DatasetWriter.add_camera`.
        """
        cam = self._w._cameras.get(camera_id)
        color_rgb = np.asarray(color_rgb)
        depth_mm = np.asarray(depth_mm)
        if cam is not None:
            expect = (cam.height, cam.width)
            if color_rgb.shape != (*expect, 3) or color_rgb.dtype != np.uint8:
                raise FormatError(f"scan {self.scan_id}: color must be {expect[0]}x{expect[1]}x3 uint8 RGB, "
                                  f"got {color_rgb.shape} {color_rgb.dtype}")
            if depth_mm.shape != expect or depth_mm.dtype != np.uint16:
                raise FormatError(f"scan {self.scan_id}: depth must be {expect[0]}x{expect[1]} uint16 mm, "
                                  f"got {depth_mm.shape} {depth_mm.dtype}")
        index, color_path, depth_path = self._record(stamp_ns, T_world_camera, camera_id)
        self._submit(self._w._encode_color, color_path, color_rgb)
        self._submit(self._w._encode_depth, depth_path, depth_mm)
        return index

    def add_encoded_frame(
        self,
        stamp_ns: int,
        T_world_camera: NDArray[np.float64],
        color_bytes: bytes,
        depth_png_bytes: bytes,
        camera_id: str,
    ) -> int:
        """Store already-encoded images as they are (no re-encoding).

        ``color_bytes`` must be in the dataset's colour encoding (PNG or JPEG) and
        ``depth_png_bytes`` a 16-bit single-channel PNG in millimetres; the caller checks that.
        """
        index, color_path, depth_path = self._record(stamp_ns, T_world_camera, camera_id)
        # one task for both files: small payloads make the per-task overhead count
        self._submit(self._w._write_pair, color_path, bytes(color_bytes), depth_path, bytes(depth_png_bytes))
        return index

    def _submit(self, fn: Any, *args: Any) -> None:
        self._pending.append(self._w._pool.submit(fn, *args))
        if len(self._pending) > 4 * self._w._threads:
            self._pending.pop(0).result()

    def close(self) -> None:
        """Wait for pending writes, then register the scan with the dataset writer."""
        for fut in self._pending:
            fut.result()
        self._pending.clear()
        self._w._finish_scan(self)


class DatasetWriter:
    """Write a psg-dataset directory atomically.

    Example::

        with DatasetWriter("lab", name="lab", timezone="America/Toronto") as w:
            w.add_camera(cam)
            w.set_rooms(rooms); w.set_receptacles(recs); w.set_objects(objs)
            with w.scan("scan_000", source="rec.bag") as s:
                s.add_frame(stamp_ns, T_world_camera, color_rgb, depth_mm, cam.camera_id)

    Args:
        root: target dataset directory (must not exist unless ``overwrite``).
        name: dataset name.
        timezone: IANA timezone of the site.
        color_encoding: ``png`` (lossless) or ``jpeg``.
        overwrite: replace an existing dataset at ``root`` (only once the new one is complete).
        resume: reuse the scans of an interrupted write found in ``ROOT.partial``.
        threads: image-encoding threads (OpenCV releases the GIL).
        extra: provenance stored in the manifest's ``extra``.
    """

    def __init__(
        self,
        root: str | Path,
        *,
        name: str | None = None,
        timezone: str = "UTC",
        color_encoding: str = "png",
        overwrite: bool = False,
        resume: bool = False,
        threads: int = 2,
        extra: Mapping[str, Any] | None = None,
    ) -> None:
        self.root = Path(root)
        if color_encoding not in ("png", "jpeg"):
            raise FormatError(f"color_encoding: expected 'png' or 'jpeg', got {color_encoding!r}")
        if self.root.exists() and not overwrite:
            raise DatasetExistsError(f"{self.root}: output exists; pass --overwrite (overwrite=True) to replace it")
        self.name = name or self.root.name
        self.timezone = timezone
        self.color_encoding = color_encoding
        self.extra: dict[str, Any] = dict(extra or {})
        self.tmp = self.root.with_name(self.root.name + _PARTIAL_SUFFIX)
        if self.tmp.exists() and not resume:
            shutil.rmtree(self.tmp)
        self.tmp.mkdir(parents=True, exist_ok=True)
        self._tmp_str = str(self.tmp)
        self._threads = max(1, threads)
        self._pool = ThreadPoolExecutor(max_workers=self._threads)
        self._cameras: dict[str, CameraIntrinsics] = {}
        self._tables: dict[str, pa.Table] = {}
        self._scans: dict[str, dict[str, Any]] = {}
        self._frames: dict[str, list[dict[str, Any]]] = {}
        self._files: dict[str, tuple[int, str]] = {}
        """relative path -> (size, sha256) of every file written or adopted (hashed from memory)."""
        self._written: dict[str, tuple[int, str]] = {}
        self._closed = False

    # -- context manager -------------------------------------------------------------------
    def __enter__(self) -> DatasetWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort(keep_partial=True)

    # -- static tables ----------------------------------------------------------------------
    def add_camera(self, camera: CameraIntrinsics) -> None:
        self._cameras[camera.camera_id] = camera

    def set_rooms(self, rooms: Iterable[Room]) -> None:
        self._tables["rooms"] = to_arrow("rooms", [
            {"room_id": r.room_id, "name": r.name,
             "floor_polygon_m": None if r.floor_polygon_m is None else np.asarray(r.floor_polygon_m, float).tolist()}
            for r in rooms])

    def set_receptacles(self, receptacles: Iterable[Receptacle]) -> None:
        self._tables["receptacles"] = to_arrow("receptacles", [
            {"receptacle_id": r.receptacle_id, "name": r.name, "category": r.category, "room_id": r.room_id,
             **_box_cols(r.box)} for r in receptacles])

    def set_doors(self, doors: Iterable[Door]) -> None:
        self._tables["doors"] = to_arrow("doors", [
            {"door_id": d.door_id, "name": d.name, "room_a": d.room_a, "room_b": d.room_b, **_box_cols(d.box)}
            for d in doors])

    def set_objects(self, objects: Iterable[ObjectInfo]) -> None:
        self._tables["objects"] = to_arrow("objects", [_row(o) for o in objects])

    def set_table(self, name: str, rows: Any) -> None:
        """Set any table of the format (``door_states``, ``schedule``, ...) from rows."""
        if name not in TABLES or name in ("frames", "scans", "cameras", "files"):
            raise FormatError(f"set_table: {name!r} is not a settable table")
        self._tables[name] = to_arrow(name, rows)

    # -- scans ------------------------------------------------------------------------------
    def scan(self, scan_id: str, *, source: str | None = None, split: str | None = None) -> ScanWriter:
        """Start a scan. Frames are added to the returned :class:`ScanWriter`."""
        if scan_id in self._scans:
            raise FormatError(f"scan {scan_id!r} was already written")
        if not scan_id or "/" in scan_id or scan_id.startswith("."):
            raise FormatError(f"scan_id: {scan_id!r} must be a non-empty name without '/' and not start with '.'")
        shutil.rmtree(self.tmp / "images" / scan_id, ignore_errors=True)
        return ScanWriter(self, scan_id, source, split)

    def completed_scans(self, trusted: Collection[str] = ()) -> dict[str, dict[str, Any]]:
        """Scans of an interrupted write that are complete and whose images match their checksums.

        Each value is the scan's stored record (``scan``, ``frames``, ``files``); pass it to
        :meth:`adopt_scan` to keep the scan without rewriting it.

        Args:
            trusted: scan ids whose images were just written by this process or its workers (their
                checksums were computed from memory while writing): their files are not re-read.
        """
        trust = set(trusted)
        done: dict[str, dict[str, Any]] = {}
        for marker in sorted((self.tmp / "images").glob(f"*/{_SCAN_DONE}")):
            try:
                rec = json.loads(marker.read_text())
            except (OSError, json.JSONDecodeError):
                continue
            if rec["scan"]["scan_id"] in trust:
                ok = True
            else:
                ok = all((self.tmp / p).is_file() and sha256_file(self.tmp / p) == s
                         for p, (_, s) in rec["files"].items())
            if ok:
                done[rec["scan"]["scan_id"]] = rec
        return done

    def adopt_scan(self, record: Mapping[str, Any]) -> None:
        """Keep a scan from :meth:`completed_scans` of an interrupted write."""
        scan_id = record["scan"]["scan_id"]
        self._scans[scan_id] = dict(record["scan"])
        self._frames[scan_id] = list(record["frames"])
        self._files.update({p: tuple(v) for p, v in record["files"].items()})

    def _finish_scan(self, sw: ScanWriter) -> None:
        if not sw._frames:
            raise FormatError(f"scan {sw.scan_id}: no frames were added")
        stamps = [f["stamp_ns"] for f in sw._frames]
        scan = {"scan_id": sw.scan_id, "start_stamp_ns": min(stamps), "end_stamp_ns": max(stamps),
                "source": sw.source, "split": sw.split}
        files: dict[str, tuple[int, str]] = {}
        for f in sw._frames:
            for rel in (f["color_path"], f["depth_path"]):
                files[rel] = self._written.pop(rel)
        self._scans[sw.scan_id] = scan
        self._frames[sw.scan_id] = sw._frames
        self._files.update(files)
        marker = self.tmp / "images" / sw.scan_id / _SCAN_DONE
        marker.write_text(json.dumps({"scan": scan, "frames": sw._frames,
                                      "files": {k: list(v) for k, v in files.items()}}))

    # -- image encoding (run in the thread pool) ---------------------------------------------
    def _write_bytes(self, rel: str, data: bytes) -> None:
        # os-level calls: fewer GIL round trips per file than open()/write()/close() on a file object
        path = os.path.join(self._tmp_str, rel)
        try:
            fd = os.open(path, _WRITE_FLAGS, 0o666)
        except FileNotFoundError:
            os.makedirs(os.path.dirname(path), exist_ok=True)
            fd = os.open(path, _WRITE_FLAGS, 0o666)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
        finally:
            os.close(fd)
        self._written[rel] = (len(data), hashlib.sha256(data).hexdigest())

    def _write_pair(self, rel_a: str, data_a: bytes, rel_b: str, data_b: bytes) -> None:
        self._write_bytes(rel_a, data_a)
        self._write_bytes(rel_b, data_b)

    def _encode_color(self, rel: str, rgb: NDArray[np.uint8]) -> None:
        import cv2

        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        if self.color_encoding == "jpeg":
            ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        else:
            ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])
        if not ok:  # pragma: no cover
            raise FormatError(f"{rel}: OpenCV could not encode the colour image")
        self._write_bytes(rel, buf.tobytes())

    def _encode_depth(self, rel: str, depth_mm: NDArray[np.uint16]) -> None:
        import cv2

        ok, buf = cv2.imencode(".png", depth_mm, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])
        if not ok:  # pragma: no cover
            raise FormatError(f"{rel}: OpenCV could not encode the depth image")
        self._write_bytes(rel, buf.tobytes())

    # -- finish -------------------------------------------------------------------------------
    def abort(self, keep_partial: bool = False) -> None:
        """Stop writing; remove ``ROOT.partial`` unless ``keep_partial`` (to resume later)."""
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._closed = True
        if not keep_partial:
            shutil.rmtree(self.tmp, ignore_errors=True)

    def _write_table(self, name: str, table: pa.Table) -> None:
        path = self.tmp / table_path(name)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, path, compression="zstd")
        self._files[table_path(name)] = (path.stat().st_size, sha256_file(path))

    def close(self) -> Path:
        """Write tables, checksums and manifest; rename into place. Returns the dataset path."""
        if self._closed:
            return self.root
        self._pool.shutdown(wait=True)
        scans = sorted(self._scans.values(), key=lambda s: (s["start_stamp_ns"], s["scan_id"]))
        frames = [f for s in scans for f in self._frames[s["scan_id"]]]
        tables: dict[str, pa.Table] = dict(self._tables)
        tables["cameras"] = to_arrow("cameras", [
            {**asdict(c), "distortion_coeffs": list(c.distortion_coeffs)} for c in self._cameras.values()])
        tables["scans"] = to_arrow("scans", scans)
        tables["frames"] = to_arrow("frames", frames)
        for name, spec in TABLES.items():
            if name == "files":
                continue
            if name not in tables and spec.required:
                tables[name] = spec.schema.empty_table()
        for name, table in tables.items():
            self._write_table(name, table)
        for marker in (self.tmp / "images").glob(f"*/{_SCAN_DONE}"):
            marker.unlink()
        files = sorted(self._files.items())
        files_table = to_arrow("files", [{"path": p, "size_bytes": n, "sha256": s} for p, (n, s) in files])
        fpath = self.tmp / table_path("files")
        pq.write_table(files_table, fpath, compression="zstd")
        counts = {name: t.num_rows for name, t in sorted(tables.items())}
        counts["images"] = 2 * len(frames)
        info = DatasetInfo(name=self.name, timezone=self.timezone, color_encoding=self.color_encoding,
                           files_sha256=sha256_file(fpath), counts=counts,
                           created_by=f"psg-data {_package_version()}", extra=self.extra)
        (self.tmp / MANIFEST_NAME).write_text(info.to_json(), encoding="utf-8")
        self._closed = True
        if self.root.exists():
            trash = self.root.with_name(self.root.name + ".old")
            shutil.rmtree(trash, ignore_errors=True)
            os.replace(self.root, trash)
            os.replace(self.tmp, self.root)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            self.root.parent.mkdir(parents=True, exist_ok=True)
            os.replace(self.tmp, self.root)
        log.info("wrote %s (%d scans, %d frames)", self.root, len(scans), len(frames))
        return self.root


