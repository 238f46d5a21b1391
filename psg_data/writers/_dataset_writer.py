"""``DatasetWriter``: the one way producers (synth, convert) write a psg-dataset.

Writes go into ``ROOT.partial/`` beside the target; :meth:`DatasetWriter.close` writes the tables,
the checksum table and the manifest, then renames the directory into place. An existing dataset is
only replaced with ``overwrite=True``. An interrupted write leaves ``ROOT.partial/``; reopening with
``resume=True`` keeps the scans whose images are complete (see :meth:`DatasetWriter.completed_scans`).

Images go into one tar archive per scan by default (``image_layout="tar"``, written by
:class:`~psg_data.writers._tar_archive.TarArchiveWriter`) or one file per image (``"files"``).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass, fields, is_dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from psg_data.errors import FormatError
from psg_data.schemas._checksum import sha256_file
from psg_data.schemas._manifest import DatasetInfo
from psg_data.schemas._records import CameraIntrinsics, Door, ObjectInfo, Opening, Receptacle, Room
from psg_data.schemas._tables import (
    ARCHIVE_MEMBER_TEMPLATES,
    ARCHIVE_PATH_TEMPLATE,
    COLOR_PATH_TEMPLATE,
    DEPTH_PATH_TEMPLATE,
    IMAGE_LAYOUTS,
    MANIFEST_NAME,
    TABLES,
    table_path,
)
from psg_data.writers._safe_output import check_output, commit_tree, make_staging
from psg_data.writers._tar_archive import TarArchiveWriter

__all__ = ["DatasetWriter", "ScanWriter", "sha256_file", "to_arrow", "encode_color", "encode_depth", "PNG_LEVEL",
           "JPEG_QUALITY"]

log = logging.getLogger(__name__)

PNG_LEVEL = 1
"""zlib level for PNG images; chosen by measurement (see docs/FORMAT.md, BENCHMARKS.md)."""
JPEG_QUALITY = 95
_PARTIAL_SUFFIX = ".partial"
_SCANS_DIR = ".scans"
"""Inside ``ROOT.partial``: per completed scan, its frames (``ID.arrow``) and a JSON record
(``ID.json``, written last) with the scan row and file checksums: what a resumed write adopts."""
_WRITE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_BINARY", 0)


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


class _FrameColumns:
    """The ``frames`` rows of one scan, column by column (cheap to append, to tabulate and to store)."""

    def __init__(self) -> None:
        self.stamp_ns: list[int] = []
        self.T: list[NDArray[np.float64]] = []
        self.camera_id: list[str] = []
        self.color_path: list[str] = []
        self.depth_path: list[str] = []
        self.color_offset: list[int] = []
        self.color_size: list[int] = []
        self.depth_offset: list[int] = []
        self.depth_size: list[int] = []

    def append(self, stamp_ns: int, T: NDArray[np.float64], camera_id: str) -> int:
        self.stamp_ns.append(stamp_ns)
        self.T.append(T)
        self.camera_id.append(camera_id)
        return len(self.stamp_ns) - 1

    def table(self, scan_id: str, archive: str | None) -> pa.Table:
        """The rows as an Arrow table of the ``frames`` schema; ``archive``: the tar layout's path."""
        n = len(self.stamp_ns)
        T = np.stack(self.T).reshape(-1) if n else np.zeros(0)
        cols: dict[str, Any] = {
            "scan_id": pa.array([scan_id] * n, pa.string()),
            "frame_index": pa.array(np.arange(n, dtype=np.int32)),
            "stamp_ns": pa.array(np.asarray(self.stamp_ns, dtype=np.int64)),
            "camera_id": pa.array(self.camera_id, pa.string()),
            "T_world_camera": pa.FixedSizeListArray.from_arrays(pa.array(T, pa.float64()), 16),
        }
        if archive is not None:
            cols["color_path"] = cols["depth_path"] = pa.array([archive] * n, pa.string())
            for k in ("color_offset", "color_size", "depth_offset", "depth_size"):
                cols[k] = pa.array(np.asarray(getattr(self, k), dtype=np.int64))
        else:
            cols["color_path"] = pa.array(self.color_path, pa.string())
            cols["depth_path"] = pa.array(self.depth_path, pa.string())
            for k in ("color_offset", "color_size", "depth_offset", "depth_size"):
                cols[k] = pa.nulls(n, pa.int64())
        return to_arrow("frames", pa.table(cols))


@dataclass(frozen=True)
class _ScanContext:
    """What a :class:`ScanWriter` gets from its dataset writer."""

    root: Path
    """The staging directory the images go to."""
    color_encoding: str
    image_layout: str
    cameras: Mapping[str, CameraIntrinsics]
    encoder: ThreadPoolExecutor | None
    """Image-encoding threads (None: encode in the caller's thread)."""
    threads: int
    on_close: Callable[[ScanWriter], None]
    """Called once the scan is closed (its archive may still be being written)."""
    on_abort: Callable[[ScanWriter], None]


class ScanWriter:
    """Adds the frames of one scan; obtained from :meth:`DatasetWriter.scan`.

    Images are stored in frame order: appended to the scan's tar archive (``tar`` layout) or
    written one file each (``files`` layout). With encoding threads, :meth:`add_frame` returns
    before its images are encoded; they are stored in order as the encodings finish.
    """

    def __init__(self, context: _ScanContext, scan_id: str, source: str | None, split: str | None) -> None:
        self._ctx = context
        self.scan_id = scan_id
        self.source = source
        self.split = split
        self._cols = _FrameColumns()
        self._queue: deque[tuple[int, Any, Any]] = deque()
        self._files: dict[str, tuple[int, str]] = {}
        self._ext = "jpg" if context.color_encoding == "jpeg" else "png"
        self._archive: TarArchiveWriter | None = None
        self._archive_rel = ARCHIVE_PATH_TEMPLATE.format(scan_id=scan_id)
        cname, dname = ARCHIVE_MEMBER_TEMPLATES  # as %-templates: formatted twice per frame
        self._color_member = cname.replace("{frame_index:06d}", "%06d").replace("{ext}", self._ext)
        self._depth_member = dname.replace("{frame_index:06d}", "%06d")
        if context.image_layout == "tar":
            path = context.root / self._archive_rel
            path.parent.mkdir(parents=True, exist_ok=True)
            self._archive = TarArchiveWriter(path)
        self._done = False

    def __enter__(self) -> ScanWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    @property
    def n_frames(self) -> int:
        """Frames added so far."""
        return len(self._cols.stamp_ns)

    def _record(self, stamp_ns: int, T_world_camera: NDArray[np.float64], camera_id: str) -> int:
        T = T_world_camera
        if type(T) is not np.ndarray or T.dtype != np.float64:
            T = np.asarray(T, dtype=np.float64)
        if T.shape != (4, 4):
            raise FormatError(f"scan {self.scan_id}: T_world_camera must be 4x4, got shape {T.shape}")
        if camera_id not in self._ctx.cameras:
            raise FormatError(f"scan {self.scan_id}: unknown camera_id {camera_id!r}; add it with add_camera first")
        return self._cols.append(int(stamp_ns), T, camera_id)

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
        cam = self._ctx.cameras.get(camera_id)
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
        i = self._record(stamp_ns, T_world_camera, camera_id)
        pool = self._ctx.encoder
        if pool is None:
            self._store(i, encode_color(color_rgb, self._ctx.color_encoding), encode_depth(depth_mm))
        else:
            self._push(i, pool.submit(encode_color, color_rgb, self._ctx.color_encoding),
                       pool.submit(encode_depth, depth_mm))
        return i

    def add_encoded_frame(
        self,
        stamp_ns: int,
        T_world_camera: NDArray[np.float64],
        color_bytes: Any,
        depth_png_bytes: Any,
        camera_id: str,
    ) -> int:
        """Store already-encoded images as they are (no re-encoding); returns the frame index.

        ``color_bytes`` must be in the dataset's colour encoding (PNG or JPEG) and
        ``depth_png_bytes`` a 16-bit single-channel PNG in millimetres; the caller checks that.
        Both may be any bytes-like object (a ``memoryview`` of a message buffer is copied once,
        straight into the archive's write buffer).
        """
        i = self._record(stamp_ns, T_world_camera, camera_id)
        if not self._queue:
            self._store(i, color_bytes, depth_png_bytes)
        else:  # behind frames still being encoded: keep a copy, the caller may reuse its buffers
            self._push(i, _owned(color_bytes), _owned(depth_png_bytes))
        return i

    def _push(self, i: int, color: Any, depth: Any) -> None:
        self._queue.append((i, color, depth))
        while self._queue:
            _, c, d = self._queue[0]
            if len(self._queue) <= 2 * self._ctx.threads and (
                    (isinstance(c, Future) and not c.done()) or (isinstance(d, Future) and not d.done())):
                break
            self._store(*self._queue.popleft())

    def _store(self, i: int, color: Any, depth: Any) -> None:
        if self._ctx.encoder is not None:
            if isinstance(color, Future):
                color = color.result()
            if isinstance(depth, Future):
                depth = depth.result()
        cols = self._cols
        if self._archive is not None:
            mtime = cols.stamp_ns[i] // 1_000_000_000
            cols.color_offset.append(self._archive.add(self._color_member % i, color, mtime))
            cols.color_size.append(_nbytes(color))
            cols.depth_offset.append(self._archive.add(self._depth_member % i, depth, mtime))
            cols.depth_size.append(_nbytes(depth))
        else:
            crel = COLOR_PATH_TEMPLATE.format(scan_id=self.scan_id, frame_index=i, ext=self._ext)
            drel = DEPTH_PATH_TEMPLATE.format(scan_id=self.scan_id, frame_index=i)
            self._files[crel] = _write_image_file(self._ctx.root, crel, color)
            self._files[drel] = _write_image_file(self._ctx.root, drel, depth)
            cols.color_path.append(crel)
            cols.depth_path.append(drel)

    def frames_table(self) -> pa.Table:
        """The scan's rows of ``frames`` (every frame stored)."""
        return self._cols.table(self.scan_id, self._archive_rel if self._ctx.image_layout == "tar" else None)

    def abort(self) -> None:
        """Drop the scan: cancel pending encodings and stop its archive (the file stays partial)."""
        for _, c, d in self._queue:
            for x in (c, d):
                if isinstance(x, Future):
                    x.cancel()
        self._queue.clear()
        if self._archive is not None:
            self._archive.abort()
        self._done = True
        self._ctx.on_abort(self)

    def close(self) -> None:
        """Store pending frames and finish the scan.

        In the tar layout the archive's last buffers are still being hashed and written when this
        returns; the scan is registered (and its resume record written) once they are done, at the
        latest when the dataset writer needs it (next scan, :meth:`DatasetWriter.scan_record`,
        close). Reading the next recording meanwhile keeps both cores busy.
        """
        if self._done:
            return
        try:
            while self._queue:
                self._store(*self._queue.popleft())
            if not self.n_frames:
                raise FormatError(f"scan {self.scan_id}: no frames were added")
            if self._archive is not None:
                self._archive.finish()
        except BaseException:
            self.abort()
            raise
        self._done = True
        self._ctx.on_close(self)

    @property
    def archive_done(self) -> bool:
        """Whether a closed scan's archive is completely written (always, in the files layout)."""
        return self._archive is None or self._archive.done

    def record(self) -> dict[str, Any]:
        """The closed scan as :meth:`DatasetWriter.scan_record` describes it, once its archive is
        written (waits for it).

        Raises:
            OSError: writing the archive failed.
        """
        if self._archive is not None:
            self._files[self._archive_rel] = self._archive.result()
            self._archive = None
        stamps = self._cols.stamp_ns
        scan = {"scan_id": self.scan_id, "start_stamp_ns": min(stamps), "end_stamp_ns": max(stamps),
                "source": self.source, "split": self.split}
        return {"scan": scan, "frames": self.frames_table(), "files": dict(self._files)}

    def stop_archive(self) -> None:
        """Stop writing a closed scan's archive (the dataset writer is aborting)."""
        if self._archive is not None:
            self._archive.abort()


def _write_image_file(root: Path, rel: str, data: Any) -> tuple[int, str]:
    """Write one image file (``files`` layout) under ``root``; returns (size, sha256) hashed from memory."""
    path = os.path.join(root, rel)
    try:
        fd = os.open(path, _WRITE_FLAGS, 0o666)
    except FileNotFoundError:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd = os.open(path, _WRITE_FLAGS, 0o666)
    view = memoryview(data).cast("B")
    size = view.nbytes
    try:
        while view:
            view = view[os.write(fd, view):]
    finally:
        os.close(fd)
    return size, hashlib.sha256(data).hexdigest()


def _nbytes(data: Any) -> int:
    return memoryview(data).nbytes


def _owned(data: Any) -> Any:
    """``data`` as bytes of its own (the caller may reuse its buffer before it is stored)."""
    return bytes(data)


def encode_color(rgb: NDArray[np.uint8], encoding: str) -> bytes:
    """(H, W, 3) uint8 RGB -> PNG (level :data:`PNG_LEVEL`) or JPEG (quality :data:`JPEG_QUALITY`) bytes."""
    import cv2

    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    if encoding == "jpeg":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    else:
        ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])
    if not ok:  # pragma: no cover
        raise FormatError("OpenCV could not encode the colour image")
    return buf.tobytes()


def encode_depth(depth_mm: NDArray[np.uint16]) -> bytes:
    """(H, W) uint16 millimetres -> 16-bit PNG bytes (level :data:`PNG_LEVEL`)."""
    import cv2

    ok, buf = cv2.imencode(".png", depth_mm, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])
    if not ok:  # pragma: no cover
        raise FormatError("OpenCV could not encode the depth image")
    return buf.tobytes()


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
            Only a psg-dataset whose every file psg-data wrote, or an empty folder, is replaced
            (see :mod:`psg_data.writers._safe_output`); anything else is refused.
        resume: reuse the scans of an interrupted write found in ``ROOT.partial``.
        threads: image-encoding threads (OpenCV releases the GIL); 0 encodes in the calling thread.
        image_layout: ``tar`` (one archive per scan, the default) or ``files`` (one file per image);
            see docs/FORMAT.md.
        extra: provenance stored in the manifest's ``extra``.
        inputs: paths the dataset is made from: ``root`` may not be, contain or lie inside one.

    Raises:
        DatasetExistsError: ``root`` exists and ``overwrite`` is False.
        UnsafeOutputError: ``root`` is not something this writer may replace, or ``ROOT.partial``
            exists without psg-data's marker.
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
        image_layout: str = "tar",
        extra: Mapping[str, Any] | None = None,
        inputs: Iterable[str | Path | None] = (),
    ) -> None:
        self.root = Path(root)
        if color_encoding not in ("png", "jpeg"):
            raise FormatError(f"color_encoding: expected 'png' or 'jpeg', got {color_encoding!r}")
        if image_layout not in IMAGE_LAYOUTS:
            raise FormatError(f"image_layout: expected one of {', '.join(IMAGE_LAYOUTS)}, got {image_layout!r}")
        check_output(self.root, overwrite=overwrite, kind="dataset", inputs=inputs)
        self.name = name or self.root.name
        self.timezone = timezone
        self.color_encoding = color_encoding
        self.image_layout = image_layout
        self.extra: dict[str, Any] = dict(extra or {})
        self.tmp = self.root.with_name(self.root.name + _PARTIAL_SUFFIX)
        make_staging(self.tmp, resume=resume)
        self._threads = max(0, int(threads))
        self._pool = ThreadPoolExecutor(max_workers=self._threads) if self._threads else None
        self._open: set[ScanWriter] = set()
        self._pending: list[ScanWriter] = []
        """Closed scans whose archives are still being written (see ScanWriter.close)."""
        self._cameras: dict[str, CameraIntrinsics] = {}
        self._tables: dict[str, pa.Table] = {}
        self._scans: dict[str, dict[str, Any]] = {}
        self._frames: dict[str, pa.Table] = {}
        self._table_files: dict[str, tuple[int, str]] = {}
        """relative path -> (size, sha256) of each table written."""
        self._scan_files: dict[str, dict[str, tuple[int, str]]] = {}
        """scan id -> its image files: relative path -> (size, sha256), hashed from memory."""
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
        """Add (or replace) a camera; frames name it by ``camera.camera_id``."""
        self._cameras[camera.camera_id] = camera

    @property
    def cameras(self) -> Mapping[str, CameraIntrinsics]:
        """The cameras added so far, by id (read-only)."""
        return MappingProxyType(self._cameras)

    def set_rooms(self, rooms: Iterable[Room]) -> None:
        """Set the ``rooms`` table."""
        self._tables["rooms"] = to_arrow("rooms", [
            {"room_id": r.room_id, "name": r.name,
             "floor_polygon_m": None if r.floor_polygon_m is None else np.asarray(r.floor_polygon_m, float).tolist()}
            for r in rooms])

    def set_receptacles(self, receptacles: Iterable[Receptacle]) -> None:
        """Set the ``receptacles`` table."""
        self._tables["receptacles"] = to_arrow("receptacles", [
            {"receptacle_id": r.receptacle_id, "name": r.name, "category": r.category, "room_id": r.room_id,
             **_box_cols(r.box)} for r in receptacles])

    def set_doors(self, doors: Iterable[Door]) -> None:
        """Set the ``doors`` table."""
        self._tables["doors"] = to_arrow("doors", [
            {"door_id": d.door_id, "name": d.name, "room_a": d.room_a, "room_b": d.room_b, **_box_cols(d.box)}
            for d in doors])

    def set_openings(self, openings: Iterable[Opening]) -> None:
        """Set the optional ``openings`` table (doorless passages between rooms)."""
        self._tables["openings"] = to_arrow("openings", [
            {"opening_id": o.opening_id, "name": o.name, "room_a": o.room_a, "room_b": o.room_b, **_box_cols(o.box)}
            for o in openings])

    def set_objects(self, objects: Iterable[ObjectInfo]) -> None:
        """Set the ``objects`` table."""
        self._tables["objects"] = to_arrow("objects", [_row(o) for o in objects])

    def set_table(self, name: str, rows: Any) -> None:
        """Set any table of the format (``door_states``, ``schedule``, ...) from rows."""
        if name not in TABLES or name in ("frames", "scans", "cameras", "files"):
            raise FormatError(f"set_table: {name!r} is not a settable table")
        self._tables[name] = to_arrow(name, rows)

    def add_file(self, rel: str, data: bytes) -> None:
        """Store a side file of the dataset (e.g. ``generator/process.json``, the generator's model).

        It is listed with its size and SHA-256 in ``tables/files.parquet`` like every other file.

        Raises:
            FormatError: ``rel`` is absolute, leaves the dataset, or lies in ``tables/`` / ``images/``.
        """
        parts = Path(rel).parts
        if (not parts or Path(rel).is_absolute() or ".." in parts or parts[0] in ("tables", "images")
                or rel == MANIFEST_NAME):
            raise FormatError(f"add_file: {rel!r}, expected a relative path outside tables/ and images/")
        path = self.tmp / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(bytes(data))
        self._table_files[Path(rel).as_posix()] = (len(data), hashlib.sha256(data).hexdigest())

    # -- scans ------------------------------------------------------------------------------
    def scan(self, scan_id: str, *, source: str | None = None, split: str | None = None) -> ScanWriter:
        """Start a scan. Frames are added to the returned :class:`ScanWriter`."""
        if scan_id in self._scans:
            raise FormatError(f"scan {scan_id!r} was already written")
        if not scan_id or "/" in scan_id or scan_id.startswith("."):
            raise FormatError(f"scan_id: {scan_id!r} must be a non-empty name without '/' and not start with '.'")
        if any(sw.scan_id == scan_id for sw in (*self._open, *self._pending)):
            raise FormatError(f"scan {scan_id!r} is already being written")
        self._settle(block=False)
        shutil.rmtree(self.tmp / "images" / scan_id, ignore_errors=True)
        (self.tmp / ARCHIVE_PATH_TEMPLATE.format(scan_id=scan_id)).unlink(missing_ok=True)
        ctx = _ScanContext(self.tmp, self.color_encoding, self.image_layout, self._cameras, self._pool,
                           self._threads, self._scan_closed, self._open.discard)
        sw = ScanWriter(ctx, scan_id, source, split)
        self._open.add(sw)
        return sw

    def _scan_closed(self, sw: ScanWriter) -> None:
        self._open.discard(sw)
        self._pending.append(sw)
        self._settle(block=False)

    def _settle(self, block: bool) -> None:
        """Register the closed scans whose archives are complete (all of them if ``block``)."""
        while self._pending:
            sw = self._pending[0]
            if not block and not sw.archive_done:
                return
            self._pending.pop(0)
            self._register(sw.record())

    def completed_scans(self) -> dict[str, dict[str, Any]]:
        """Scans of an interrupted write that are complete and whose images match their checksums.

        Each value is the scan's stored record (see :meth:`scan_record`); pass it to
        :meth:`adopt_scan` to keep the scan without rewriting it.
        """
        import pyarrow.feather as feather

        done: dict[str, dict[str, Any]] = {}
        for marker in sorted((self.tmp / _SCANS_DIR).glob("*.json")):
            try:
                rec = json.loads(marker.read_text())
                scan_id = rec["scan"]["scan_id"]
                files = rec["files"]
                frames = feather.read_table(marker.with_suffix(".arrow"))
                if frames.num_rows != rec["n_frames"]:
                    continue
            except (OSError, json.JSONDecodeError, KeyError, TypeError, pa.ArrowException):
                continue
            if all((self.tmp / p).is_file() and (self.tmp / p).stat().st_size == n and sha256_file(self.tmp / p) == s
                   for p, (n, s) in files.items()):
                done[scan_id] = {"scan": rec["scan"], "frames": frames, "files": files}
        return done

    def scan_record(self, scan_id: str) -> dict[str, Any]:
        """A scan this writer finished: ``{"scan": row, "frames": Arrow table, "files": {path: [size,
        sha256]}}`` (what :meth:`adopt_scan` takes, e.g. in the process merging its workers' scans).
        """
        if scan_id not in self._scans:
            self._settle(block=True)
        files = self._scan_files[scan_id]
        return {"scan": self._scans[scan_id], "frames": self._frames[scan_id],
                "files": {k: list(v) for k, v in files.items()}}

    def adopt_scan(self, record: Mapping[str, Any]) -> None:
        """Keep a scan from :meth:`completed_scans` of an interrupted write (or of a worker)."""
        scan_id = record["scan"]["scan_id"]
        files = {p: (int(v[0]), str(v[1])) for p, v in record["files"].items()}
        self._scans[scan_id] = dict(record["scan"])
        self._frames[scan_id] = to_arrow("frames", record["frames"])
        self._scan_files[scan_id] = files

    def _register(self, record: dict[str, Any]) -> None:
        """Keep a scan this writer finished, and store its record for resuming: its frames, then
        the JSON that commits them.
        """
        scan, frames, files = record["scan"], record["frames"], record["files"]
        self._scans[scan["scan_id"]] = scan
        self._frames[scan["scan_id"]] = frames
        self._scan_files[scan["scan_id"]] = files
        markers = self.tmp / _SCANS_DIR
        markers.mkdir(exist_ok=True)
        import pyarrow.feather as feather

        feather.write_feather(frames, markers / f"{scan['scan_id']}.arrow", compression="uncompressed")
        tmp = markers / f".{scan['scan_id']}.json.tmp"
        tmp.write_text(json.dumps({"scan": scan, "n_frames": frames.num_rows,
                                   "files": {k: list(v) for k, v in files.items()}}))
        os.replace(tmp, markers / f"{scan['scan_id']}.json")

    # -- finish -------------------------------------------------------------------------------
    def abort(self, keep_partial: bool = False) -> None:
        """Stop writing; remove ``ROOT.partial`` unless ``keep_partial`` (to resume later).

        Scans already closed are completed first (with ``keep_partial`` a resumed write keeps them).
        """
        for sw in list(self._open):
            sw.abort()
        try:
            self._settle(block=True)
        except Exception as exc:  # best effort: that scan is not registered and is redone on resume
            log.warning("%s: a closed scan could not be completed (%s)", self.tmp, exc)
            for sw in self._pending:
                sw.stop_archive()
            self._pending.clear()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        self._closed = True
        if not keep_partial:
            shutil.rmtree(self.tmp, ignore_errors=True)

    def _write_table(self, name: str, table: pa.Table) -> None:
        path = self.tmp / table_path(name)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, path, compression="zstd")
        self._table_files[table_path(name)] = (path.stat().st_size, sha256_file(path))

    def _remove_stale_images(self, keep: Mapping[str, Any]) -> None:
        """Delete image files left by an interrupted run that no scan of this dataset uses."""
        images = self.tmp / "images"
        if not images.is_dir():
            return
        for p in sorted(images.rglob("*"), reverse=True):
            rel = p.relative_to(self.tmp).as_posix()
            if p.is_file() and rel not in keep:
                p.unlink()
            elif p.is_dir() and not any(p.iterdir()):
                p.rmdir()

    def close(self) -> Path:
        """Write tables, checksums and manifest; rename into place. Returns the dataset path."""
        if self._closed:
            return self.root
        if self._open:
            open_ids = ", ".join(sorted(sw.scan_id for sw in self._open))
            raise FormatError(f"{self.root}: scans still open ({open_ids}); close them before the dataset")
        self._settle(block=True)
        if self._pool is not None:
            self._pool.shutdown(wait=True)
        scans = sorted(self._scans.values(), key=lambda s: (s["start_stamp_ns"], s["scan_id"]))
        frames = pa.concat_tables([self._frames[s["scan_id"]] for s in scans]) if scans else \
            TABLES["frames"].schema.empty_table()
        tables: dict[str, pa.Table] = dict(self._tables)
        tables["cameras"] = to_arrow("cameras", [
            {**asdict(c), "distortion_coeffs": list(c.distortion_coeffs)} for c in self._cameras.values()])
        tables["scans"] = to_arrow("scans", scans)
        tables["frames"] = frames.combine_chunks()
        for name, spec in TABLES.items():
            if name == "files":
                continue
            if name not in tables and spec.required:
                tables[name] = spec.schema.empty_table()
        for name, table in tables.items():
            self._write_table(name, table)
        shutil.rmtree(self.tmp / _SCANS_DIR, ignore_errors=True)
        all_files = dict(self._table_files)
        for scan_files in self._scan_files.values():
            all_files.update(scan_files)
        self._remove_stale_images(all_files)
        files = sorted(all_files.items())
        files_table = to_arrow("files", [{"path": p, "size_bytes": n, "sha256": s} for p, (n, s) in files])
        fpath = self.tmp / table_path("files")
        pq.write_table(files_table, fpath, compression="zstd")
        counts = {name: t.num_rows for name, t in sorted(tables.items())}
        counts["images"] = 2 * frames.num_rows
        info = DatasetInfo(name=self.name, timezone=self.timezone, color_encoding=self.color_encoding,
                           files_sha256=sha256_file(fpath), counts=counts,
                           created_by=f"psg-data {_package_version()}", extra=self.extra)
        (self.tmp / MANIFEST_NAME).write_text(info.to_json(), encoding="utf-8")
        self._closed = True
        commit_tree(self.tmp, self.root, kind="dataset")
        log.info("wrote %s (%d scans, %d frames)", self.root, len(scans), frames.num_rows)
        return self.root
