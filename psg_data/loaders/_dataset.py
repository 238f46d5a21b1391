"""Reading a psg-dataset: :func:`open_dataset` -> :class:`Dataset` -> :class:`Scan` -> :class:`Frame`.

Tables are read on first access and cached; images are decoded one frame at a time. An image is a
whole file (``files`` layout, every 1.x dataset) or a byte range of its scan's tar archive (``tar``
layout): reading frame *i* costs two ``pread`` calls either way, never a scan-wide read.

A dataset is untrusted input (docs/SECURITY.md): every path it names is opened only if it stays
inside the dataset (:mod:`psg_data.schemas._paths`), no image is read past the size its camera
allows, and an image's header must fit its camera before a pixel is decoded. Every table, the
generator model and every whole-file image are checked against their size and SHA-256 in
``tables/files.parquet`` when read (:mod:`psg_data.loaders._checksums`); a scan archive is not
hashed by the loader, so that one frame stays two reads (``validate`` checks archives).
"""

from __future__ import annotations

import bisect
import logging
import os
import stat
import threading
from collections.abc import Iterator, Sequence
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import FormatError
from psg_data.loaders._checks import check_frames, check_image_bytes, check_image_header, checked_table
from psg_data.loaders._checksums import FileChecksums
from psg_data.schemas._image_headers import max_encoded_bytes
from psg_data.schemas._manifest import DatasetInfo, read_manifest
from psg_data.schemas._paths import open_inside, real_root
from psg_data.schemas._records import Box, CameraIntrinsics, Door, Frame, ObjectInfo, Opening, Receptacle, Room
from psg_data.schemas._tables import TABLES, table_path

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd
    import pyarrow as pa

    from psg_data.loaders._frame_view import FrameView

__all__ = ["open_dataset", "Dataset", "Scan", "backproject"]

log = logging.getLogger(__name__)


def _box(row: dict[str, Any]) -> Box:
    return Box(np.asarray(row["center_m"], float), np.asarray(row["extent_m"], float),
               np.asarray(row["rotation"], float).reshape(3, 3))


class Dataset:
    """A psg-dataset directory opened for reading.

    Args:
        root: dataset directory.
        verify_archives: also hash each scan archive (tar layout) against ``tables/files.parquet``
            the first time one of its frames is read: one extra sequential read of the archive per
            process, and a damaged archive then yields no frame at all. Off by default: tables,
            the generator model and whole-file images are always checked (docs/SECURITY.md).

    Attributes:
        root: dataset directory.
        info: the manifest.
    """

    def __init__(self, root: str | Path, *, verify_archives: bool = False) -> None:
        self.root = Path(root)
        self.verify_archives = verify_archives
        if not self.root.is_dir():
            raise FormatError(f"{self.root}: not a directory; expected a psg-dataset directory")
        self.info: DatasetInfo = read_manifest(self.root)
        self._arrow: dict[str, pa.Table] = {}
        self._open_files()

    def _open_files(self) -> None:
        self._sums = FileChecksums(self.root, real_root(self.root), self.info.files_sha256)
        self._images = _ImageFiles(self.root, self._sums, self.verify_archives)

    def close(self) -> None:
        """Close the image archives kept open for reading (reopened on demand)."""
        self._images.close()

    def __enter__(self) -> Dataset:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Dataset({str(self.root)!r}, scans={len(self.scan_ids)}, frames={self.table('frames').num_rows})"

    # -- interop: pickling and the frame-indexed view ------------------------------------------
    def __getstate__(self) -> dict[str, Any]:
        """Pickled as its directory and manifest: no open file, no cached table travels; a copy in
        another process (a DataLoader worker, a Dask task) reopens tables and archives on first use.
        """
        return {"root": self.root, "info": self.info, "verify_archives": self.verify_archives}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.root, self.info = state["root"], state["info"]
        self.verify_archives = bool(state.get("verify_archives", False))
        self._arrow = {}
        self._open_files()

    def refresh(self) -> None:
        """Forget the tables and records read so far: the next use reads them again from disk
        (after another writer, e.g. :func:`psg_data.labeling.label_dataset`, changed the dataset),
        the manifest and the checksums of ``files.parquet`` included.
        """
        self._images.close()
        self.info = read_manifest(self.root)
        self._arrow = {}
        self._open_files()
        for name in [k for k, v in type(self).__dict__.items() if isinstance(v, cached_property)]:
            self.__dict__.pop(name, None)

    def frame_view(self, scan_ids: Sequence[str] | None = None, *, color: bool = True,
                   depth: bool = True) -> FrameView:
        """Every frame of ``scan_ids`` (default: all scans) by one flat index: ``len(view)``, and
        ``view[i]`` a :class:`~psg_data.loaders.FrameRecord` dict of numpy arrays (colour, depth in
        metres, ``T_world_camera``, intrinsics, stamp, scan id). Picklable, so it serves as the
        dataset of a ``torch.utils.data.DataLoader`` with worker processes.
        """
        from psg_data.loaders._frame_view import FrameView

        return FrameView(self, scan_ids, color=color, depth=depth)

    # -- tables -------------------------------------------------------------------------------
    def has_table(self, name: str) -> bool:
        """Whether the dataset has table ``name``."""
        return (self.root / table_path(name)).is_file()

    def table(self, name: str) -> pa.Table:
        """Table ``name`` as an Arrow table (cached), checked against its schema and its checksum.

        Raises:
            FormatError: missing, outside the dataset, unreadable, or its size or SHA-256 does not
                fit ``tables/files.parquet`` (``files.parquet`` itself: the manifest's ``files_sha256``).
        """
        if name not in self._arrow:
            import pyarrow as pa
            import pyarrow.parquet as pq

            rel = table_path(name)
            path = self.root / rel
            if not path.is_file():
                raise FormatError(f"{path}: missing table {name!r}")
            if name == "files":
                files = self._sums.files_table()
                if files is None:
                    raise FormatError(f"{path}: missing table {name!r}")
                self._arrow[name] = checked_table(name, files, str(path), self.info.major)
                return self._arrow[name]
            # the content is checked before the checksum, so that an error names what is wrong
            # (a missing column, a bad value) where it can, and the checksum only when all else fits
            data = self._sums.read_listed(rel, f"{self.root}: table {name!r}", check=False)
            try:
                table = pq.read_table(pa.BufferReader(data))
            except (OSError, pa.ArrowException) as exc:
                raise FormatError(f"{path}: unreadable Parquet ({exc})") from exc
            table = checked_table(name, table, str(path), self.info.major)
            self._sums.check_bytes(rel, data)
            self._arrow[name] = table
        return self._arrow[name]

    def read_file(self, rel: str) -> bytes:
        """The bytes of the dataset file ``rel`` (relative to the root, e.g. ``generator/process.json``),
        checked to lie inside the dataset and to fit its size and SHA-256 in ``tables/files.parquet``.

        Raises:
            FormatError: as :meth:`table`.
        """
        return self._sums.read_listed(rel, f"{self.root}: {rel}")

    def df(self, name: str) -> pd.DataFrame:
        """Table ``name`` as a pandas DataFrame."""
        return self.table(name).to_pandas()

    @property
    def table_names(self) -> list[str]:
        """Tables present: those of the format in their order, then any others by name."""
        return [n for n in TABLES if self.has_table(n)] + sorted(
            p.stem for p in (self.root / "tables").glob("*.parquet") if p.stem not in TABLES)

    # -- records ------------------------------------------------------------------------------
    @cached_property
    def cameras(self) -> dict[str, CameraIntrinsics]:
        out = {}
        t = self.table("cameras")
        for r in t.select([f.name for f in TABLES["cameras"].schema]).to_pylist():  # extra columns ignored
            r["distortion_coeffs"] = tuple(r["distortion_coeffs"] or ())
            out[r["camera_id"]] = CameraIntrinsics(**r)
        return out

    @cached_property
    def rooms(self) -> dict[str, Room]:
        return {r["room_id"]: Room(r["room_id"], r["name"],
                                   None if r["floor_polygon_m"] is None else np.asarray(r["floor_polygon_m"], float))
                for r in self.table("rooms").to_pylist()}

    @cached_property
    def receptacles(self) -> dict[str, Receptacle]:
        return {r["receptacle_id"]: Receptacle(r["receptacle_id"], r["name"], r["room_id"], _box(r), r["category"])
                for r in self.table("receptacles").to_pylist()}

    @cached_property
    def doors(self) -> dict[str, Door]:
        return {r["door_id"]: Door(r["door_id"], r["name"], r["room_a"], r["room_b"], _box(r))
                for r in self.table("doors").to_pylist()}

    @cached_property
    def openings(self) -> dict[str, Opening]:
        """Doorless passages between rooms (the optional ``openings`` table; empty without it)."""
        if not self.has_table("openings"):
            return {}
        return {r["opening_id"]: Opening(r["opening_id"], r["name"], r["room_a"], r["room_b"], _box(r))
                for r in self.table("openings").to_pylist()}

    @cached_property
    def objects(self) -> dict[str, ObjectInfo]:
        return {r["object_id"]: ObjectInfo(r["object_id"], r["name"], r["description"])
                for r in self.table("objects").to_pylist()}

    # -- scans --------------------------------------------------------------------------------
    @cached_property
    def _scan_rows(self) -> list[dict[str, Any]]:
        return sorted(self.table("scans").to_pylist(), key=lambda r: (r["start_stamp_ns"], r["scan_id"]))

    @cached_property
    def scan_ids(self) -> list[str]:
        """Scan ids ordered by start time."""
        return [r["scan_id"] for r in self._scan_rows]

    @property
    def scans(self) -> list[Scan]:
        """Every scan, ordered by start time."""
        return [self.scan(s) for s in self.scan_ids]

    @cached_property
    def _frames_by_scan(self) -> dict[str, dict[str, NDArray[Any]]]:
        t = self.table("frames")
        check_frames(t, set(self.scan_ids), set(self.table("cameras").column("camera_id").to_pylist()),
                     str(self.root / table_path("frames")))
        scan = np.asarray(t.column("scan_id").to_numpy(zero_copy_only=False))
        order = np.lexsort((t.column("frame_index").to_numpy(), scan))
        cols = {
            "row": order,
            "frame_index": t.column("frame_index").to_numpy()[order],
            "stamp_ns": t.column("stamp_ns").to_numpy()[order],
            "camera_id": np.asarray(t.column("camera_id").to_numpy(zero_copy_only=False))[order],
            "T": np.asarray(t.column("T_world_camera").combine_chunks().flatten().to_numpy(),
                            dtype=np.float64).reshape(-1, 4, 4)[order],
            "color_path": np.asarray(t.column("color_path").to_numpy(zero_copy_only=False))[order],
            "depth_path": np.asarray(t.column("depth_path").to_numpy(zero_copy_only=False))[order],
        }
        for col in ("color_offset", "color_size", "depth_offset", "depth_size"):  # 2.0; -1: whole file
            if col in t.column_names:
                cols[col] = np.asarray(t.column(col).fill_null(-1).to_numpy(), dtype=np.int64)[order]
            else:
                cols[col] = np.full(t.num_rows, -1, np.int64)
        scan = scan[order]
        out: dict[str, dict[str, NDArray[Any]]] = {}
        if scan.size == 0:
            return out
        bounds = np.flatnonzero(scan[1:] != scan[:-1]) + 1
        starts = np.concatenate([[0], bounds])
        ends = np.concatenate([bounds, [scan.size]])
        for a, b in zip(starts, ends):
            out[str(scan[a])] = {k: v[a:b] for k, v in cols.items()}
        return out

    @cached_property
    def _scan_row_by_id(self) -> dict[str, dict[str, Any]]:
        return {r["scan_id"]: r for r in self._scan_rows}

    def scan(self, scan_id: str) -> Scan:
        """The scan with id ``scan_id``.

        Raises:
            KeyError: no scan has that id.
        """
        row = self._scan_row_by_id.get(scan_id)
        if row is None:
            raise KeyError(f"{self.root}: no scan {scan_id!r}; scans are {', '.join(self.scan_ids[:5])}"
                           f"{', ...' if len(self.scan_ids) > 5 else ''}")
        return Scan(self, row, self._frames_by_scan.get(scan_id, {}))

    def scan_at(self, stamp_ns: int) -> Scan | None:
        """The scan whose [start, end] contains ``stamp_ns``, else the latest scan that started before it.

        Returns None if ``stamp_ns`` is before the first scan.
        """
        starts = [r["start_stamp_ns"] for r in self._scan_rows]
        i = bisect.bisect_right(starts, int(stamp_ns)) - 1
        return None if i < 0 else self.scan(self._scan_rows[i]["scan_id"])


class Scan:
    """One scan (mapping session): metadata and lazy access to its frames."""

    def __init__(self, dataset: Dataset, row: dict[str, Any], frames: dict[str, NDArray[Any]]) -> None:
        self.dataset = dataset
        self.scan_id: str = row["scan_id"]
        self.start_stamp_ns: int = int(row["start_stamp_ns"])
        self.end_stamp_ns: int = int(row["end_stamp_ns"])
        self.source: str | None = row.get("source")
        self.split: str | None = row.get("split")
        self._f = frames

    def __repr__(self) -> str:
        return f"Scan({self.scan_id!r}, frames={len(self)})"

    def __len__(self) -> int:
        return 0 if not self._f else int(self._f["frame_index"].size)

    @property
    def stamps_ns(self) -> NDArray[np.int64]:
        """(N,) frame stamps, int64 UTC nanoseconds."""
        return self._f["stamp_ns"] if self._f else np.zeros(0, np.int64)

    @property
    def poses(self) -> NDArray[np.float64]:
        """(N, 4, 4) camera-to-world poses."""
        return self._f["T"] if self._f else np.zeros((0, 4, 4))

    @property
    def camera_ids(self) -> NDArray[np.str_]:
        """(N,) id of the camera of each frame."""
        return np.asarray(self._f["camera_id"], dtype=str) if self._f else np.zeros(0, dtype=str)

    def _read(self, kind: str, i: int) -> bytes:
        f = self._f
        path, off = str(f[f"{kind}_path"][i]), int(f[f"{kind}_offset"][i])
        cam = self.dataset.cameras[str(f["camera_id"][i])]
        images = self.dataset._images
        field = f"{table_path('frames')}:{int(f['row'][i])}: {kind}_path"
        try:
            return images.read(path, off, int(f[f"{kind}_size"][i]), max_encoded_bytes(cam.width, cam.height, kind),
                               field)
        except _UnsafePath:
            raise
        except FormatError as exc:
            what = "colour" if kind == "color" else "depth"
            raise FormatError(f"{self._where(kind, i)}: missing or unreadable {what} image ({exc})") from exc

    def _where(self, kind: str, i: int) -> Path:
        """Where an image is stored: its file, or ``ARCHIVE@OFFSET``."""
        path = str(self._f[f"{kind}_path"][i])
        off = int(self._f[f"{kind}_offset"][i])
        return self.dataset.root / (path if off < 0 else f"{path}@{off}")

    def image_bytes(self, i: int, *, color: bool = True, depth: bool = True) -> tuple[bytes, bytes]:
        """The stored (encoded) images of frame ``i``: colour PNG/JPEG and 16-bit depth PNG bytes
        (``b""`` for an image not asked for).

        Raises:
            FormatError: an image file is missing or its byte range lies outside its archive.
        """
        cbytes, dbytes = self._image_bytes(i, color, depth)
        self._check_sums(i, cbytes, dbytes)
        return cbytes, dbytes

    def _image_bytes(self, i: int, color: bool, depth: bool) -> tuple[bytes, bytes]:
        if not 0 <= i < len(self):
            raise IndexError(f"scan {self.scan_id}: frame index {i} out of range 0..{len(self) - 1}")
        return (self._read("color", i) if color else b""), (self._read("depth", i) if depth else b"")

    def _check_sums(self, i: int, cbytes: bytes, dbytes: bytes) -> None:
        """Whole-file images against their checksums (an image in an archive is not hashed alone)."""
        for kind, data in (("color", cbytes), ("depth", dbytes)):
            if data and int(self._f[f"{kind}_offset"][i]) < 0:
                self.dataset._sums.check_bytes(str(self._f[f"{kind}_path"][i]), data)

    def frame(self, i: int, *, color: bool = True, depth: bool = True) -> Frame:
        """Frame ``i`` (random access: reads only that frame's two images).

        Raises:
            FormatError: an image is missing, does not fit its camera, is damaged, or (a whole-file
                image) does not fit its checksum; structure is checked first, the checksum last.
        """
        cbytes, dbytes = self._image_bytes(i, color, depth)
        import cv2

        cam = self.dataset.cameras[str(self._f["camera_id"][i])]
        rgb = np.zeros((0, 0, 3), np.uint8)
        dm = np.zeros((0, 0), np.float32)
        if color:
            check_image_header(cbytes, cam, "color", self._where("color", i))
            check_image_bytes(cbytes, self._where("color", i), "colour")
            decoded = _decode_rgb(cv2, cbytes)
            if decoded is None:
                raise FormatError(f"{self._where('color', i)}: missing or unreadable colour image (cannot decode)")
            rgb = decoded
        if depth:
            check_image_header(dbytes, cam, "depth", self._where("depth", i))
            check_image_bytes(dbytes, self._where("depth", i), "depth")
            raw = cv2.imdecode(np.frombuffer(dbytes, np.uint8), cv2.IMREAD_UNCHANGED) if dbytes else None
            where = self._where("depth", i)
            if raw is None:
                raise FormatError(f"{where}: missing or unreadable depth image")
            if raw.dtype != np.uint16 or raw.ndim != 2:
                raise FormatError(f"{where}: depth must be single-channel uint16, got {raw.dtype} with shape "
                                  f"{raw.shape}")
            dm = np.multiply(raw, np.float32(cam.depth_scale_m), dtype=np.float32)
        self._check_sums(i, cbytes, dbytes)
        return Frame(self.scan_id, int(self._f["frame_index"][i]), int(self._f["stamp_ns"][i]), rgb, dm, cam,
                     self._f["T"][i].copy())

    def frames(self, *, color: bool = True, depth: bool = True, stride: int = 1, prefetch: int = 2) -> Iterator[Frame]:
        """Yield frames lazily in order (every ``stride``-th).

        Args:
            color: decode the colour images.
            depth: decode the depth images.
            stride: every ``stride``-th frame.
            prefetch: frames decoded ahead in background threads (OpenCV releases the GIL while
                decoding); 0 decodes each frame only when it is requested.
        """
        indices = range(0, len(self), max(1, stride))
        if prefetch <= 0 or len(indices) < 2:
            for i in indices:
                yield self.frame(i, color=color, depth=depth)
            return
        from collections import deque
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=prefetch) as pool:
            pending: deque = deque()
            it = iter(indices)
            for i in it:
                pending.append(pool.submit(self.frame, i, color=color, depth=depth))
                if len(pending) > prefetch:
                    break
            while pending:
                fut = pending.popleft()
                nxt = next(it, None)
                if nxt is not None:
                    pending.append(pool.submit(self.frame, nxt, color=color, depth=depth))
                yield fut.result()

    def point_cloud(self, *, stride: int = 4, frame_stride: int = 1, max_depth_m: float = 5.0,
                    voxel_size_m: float | None = None) -> Any:
        """Fused coloured point cloud of the scan in the world frame (an ``open3d.geometry.PointCloud``).

        Args:
            stride: pixel subsampling step in both image axes.
            frame_stride: use every ``frame_stride``-th frame.
            max_depth_m: ignore depth beyond this range, metres.
            voxel_size_m: optional voxel down-sampling of the fused cloud, metres.
        """
        from psg_data.open3d_import import import_open3d

        o3d = import_open3d()
        pts, cols = [], []
        for fr in self.frames(stride=frame_stride):
            p, c = backproject(fr, stride=stride, max_depth_m=max_depth_m)
            pts.append(p)
            cols.append(c)
        pcd = o3d.geometry.PointCloud()
        if pts:
            pcd.points = o3d.utility.Vector3dVector(np.concatenate(pts))
            pcd.colors = o3d.utility.Vector3dVector(np.concatenate(cols))
        if voxel_size_m:
            pcd = pcd.voxel_down_sample(voxel_size_m)
        return pcd


def _decode_rgb(cv2: Any, data: bytes) -> NDArray[np.uint8] | None:
    """Decode encoded image bytes straight to RGB (OpenCV >= 4.11 has IMREAD_COLOR_RGB)."""
    if not data:
        return None
    buf = np.frombuffer(data, np.uint8)
    flag = getattr(cv2, "IMREAD_COLOR_RGB", None)
    if flag is not None:
        rgb = cv2.imdecode(buf, flag)
    else:
        bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        rgb = None if bgr is None else cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    return None if rgb is None else np.asarray(rgb, dtype=np.uint8)


class _UnsafePath(FormatError):
    """A path of the dataset leaves it (raised as it is, not as an unreadable image)."""


class _ImageFiles:
    """Reads images: whole files, or byte ranges of archives kept open (``pread``, thread-safe).

    Every path is checked to stay inside the dataset before it is opened (an archive once, when
    its descriptor is opened), and no read exceeds the ``limit`` its caller allows.
    """

    _MAX_OPEN = 64

    def __init__(self, root: Path, sums: FileChecksums, verify_archives: bool = False) -> None:
        self.root, self._sums, self._verify_archives = root, sums, verify_archives
        self._fds: dict[str, tuple[int, int]] = {}  # rel -> (descriptor, file size)
        self._dirs: set[str] = set()  # directories found inside the dataset
        self._lock = threading.Lock()

    def __getstate__(self) -> dict[str, Any]:
        return {"root": self.root, "sums": self._sums.root, "real": self._sums.real,
                "files_sha256": self._sums.files_sha256,
                "verify_archives": self._verify_archives}  # descriptors and the lock stay in this process

    def __setstate__(self, state: dict[str, Any]) -> None:
        sums = FileChecksums(state["sums"], state["real"], state["files_sha256"])
        self.__init__(state["root"], sums, state["verify_archives"])  # type: ignore[misc]

    @cached_property
    def real_root(self) -> str:
        """The dataset root, symbolic links resolved (what every path must stay inside)."""
        return real_root(self.root)

    def _open(self, rel: str, where: str) -> tuple[int, int]:
        """A read descriptor of the regular file ``rel`` inside the dataset, and its size (a FIFO or
        device is refused without blocking: ``O_NONBLOCK`` where the system has it).
        """
        flags = os.O_RDONLY | getattr(os, "O_BINARY", 0) | getattr(os, "O_NONBLOCK", 0)
        try:
            fd = open_inside(self.real_root, rel, where, flags, self._dirs)
        except FormatError as exc:
            raise _UnsafePath(str(exc)) from None
        except OSError as exc:
            raise FormatError(exc.strerror or type(exc).__name__) from exc
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            os.close(fd)
            raise FormatError("not a regular file")
        return fd, st.st_size

    def read(self, rel: str, offset: int, size: int, limit: int, where: str) -> bytes:
        """Bytes of the image stored at ``rel`` (``offset`` < 0: the whole file), at most ``limit``.

        Args:
            rel: the path the ``frames`` table names, relative to the dataset root.
            offset: byte offset of the image in the archive ``rel``; < 0 for the whole file.
            size: bytes of the image in the archive (ignored for a whole file).
            limit: most bytes the image may have (:func:`~psg_data.schemas._image_headers.max_encoded_bytes`).
            where: the table cell naming ``rel``, for the error (``tables/frames.parquet:ROW: color_path``).

        Raises:
            FormatError: says why not (:class:`_UnsafePath` when ``rel`` leaves the dataset).
        """
        if offset < 0:
            fd, fsize = self._open(rel, where)
            with open(fd, "rb") as fh:
                if fsize > limit:
                    raise FormatError(f"{fsize} bytes, more than the {limit} an image of its camera may take")
                return fh.read(fsize + 1)
        fd, fsize = self._fd(rel, where)
        if offset + size > fsize:
            raise FormatError(f"{size} bytes at offset {offset} lie beyond the end of {rel} ({fsize} bytes; "
                              "truncated?)")
        if not 0 < size <= limit:
            raise FormatError(f"{size} bytes, expected 1 to {limit} (the most an image of its camera may take)")
        data = os.pread(fd, size, offset) if hasattr(os, "pread") else self._seek_read(fd, size, offset)
        if len(data) != size:
            raise FormatError(f"{size} bytes at offset {offset} lie beyond the end of {rel} (truncated?)")
        return data

    def _seek_read(self, fd: int, size: int, offset: int) -> bytes:
        with self._lock:
            os.lseek(fd, offset, os.SEEK_SET)
            return os.read(fd, size)

    def _fd(self, rel: str, where: str) -> tuple[int, int]:
        with self._lock:
            entry = self._fds.get(rel)
            if entry is None:
                if len(self._fds) >= self._MAX_OPEN:
                    os.close(self._fds.pop(next(iter(self._fds)))[0])
                entry = self._open(rel, where)
                if self._verify_archives:
                    try:
                        self._sums.check_fd(rel, *entry)
                    except FormatError:
                        os.close(entry[0])
                        raise
                self._fds[rel] = entry
            return entry

    def close(self) -> None:
        with self._lock:
            for fd, _ in self._fds.values():
                os.close(fd)
            self._fds.clear()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # pragma: no cover - interpreter shutdown
            pass


def backproject(frame: Frame, *, stride: int = 1, max_depth_m: float = np.inf
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World points (N, 3) and RGB colours in [0, 1] (N, 3) of a frame's valid depth pixels."""
    cam = frame.camera
    d = frame.depth_m[::stride, ::stride]
    v, u = np.mgrid[0:frame.depth_m.shape[0]:stride, 0:frame.depth_m.shape[1]:stride]
    ok = (d > 0) & (d <= max_depth_m)
    z = d[ok].astype(np.float64)
    x = (u[ok] - cam.cx) / cam.fx * z
    y = (v[ok] - cam.cy) / cam.fy * z
    pc = np.stack([x, y, z], axis=1)
    T = frame.T_world_camera
    pw = pc @ T[:3, :3].T + T[:3, 3]
    col = frame.color[::stride, ::stride][ok].astype(np.float64) / 255.0 if frame.color.size else np.zeros_like(pw)
    return pw, col


def open_dataset(path: str | Path, *, verify_archives: bool = False) -> Dataset:
    """Open the psg-dataset at ``path`` (reads only the manifest; tables load on first use).

    Args:
        path: the dataset directory.
        verify_archives: also hash each scan archive when first read (see :class:`Dataset`).

    Raises:
        FormatError: not a dataset, bad manifest, or a newer format major version.
    """
    return Dataset(path, verify_archives=verify_archives)
