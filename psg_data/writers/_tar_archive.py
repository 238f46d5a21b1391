"""Appending a scan's images to one uncompressed POSIX (ustar) tar archive.

The archive is what ``tar``, Python's ``tarfile`` or any archive tool reads: one regular-file member
per image (``color/000000.png``, ``depth/000000.png``, ...), each a 512-byte header followed by the
image bytes padded to 512, then the end-of-archive zero blocks, padded with zeros to a multiple of
4 KiB. The byte offset of every member's data is returned to the caller, who stores it in the
``frames`` table: a reader then fetches one image with a single ``pread`` of a known range.

Members are copied into a batch buffer; each full batch goes to one writer thread, which hashes it
(SHA-256, for ``files.parquet``) and writes it with plain buffered writes, both without the GIL,
while the caller goes on reading and encoding. Three buffers per archive bound its memory.

Pages of the archive written more than :data:`DROP_BEHIND_BYTES` ago are dropped from the page
cache (``posix_fadvise(DONTNEED)``, where the system has it): a conversion writes gigabytes that
will not be read back soon, and on the development VM new page-cache pages cost so much that
writing without this ran at 0.4x the conversion's throughput with it (BENCHMARKS.md).
"""

from __future__ import annotations

import hashlib
import os
import queue
import threading
from typing import Any

__all__ = ["TarArchiveWriter", "ustar_header", "TAR_BLOCK", "ARCHIVE_ALIGN"]

TAR_BLOCK = 512
"""Tar block size: headers and member data are padded to it."""
ARCHIVE_ALIGN = 4096
"""Archives are padded with zero blocks to a multiple of this."""
BATCH_BYTES = 8 << 20
"""Bytes handed to the writer thread at a time."""
DROP_BEHIND_BYTES = 16 << 20
"""Pages of the archive further than this behind the end are dropped from the page cache."""
_ZEROS = bytes(ARCHIVE_ALIGN)


def _header_fields() -> tuple[bytes, bytes, int]:
    """(mode/uid/gid fields, fields after the checksum, byte sum of both with the blank checksum)."""
    h = bytearray(TAR_BLOCK)
    h[100:124] = b"0000644\0" b"0000000\0" b"0000000\0"  # mode, uid, gid
    h[156:157] = b"0"  # regular file
    h[257:265] = b"ustar\x0000"  # magic, version
    h[329:345] = b"0000000\0" b"0000000\0"  # devmajor, devminor
    return bytes(h[100:124]), bytes(h[156:]), sum(h) + 8 * ord(" ")  # the checksum counts itself as spaces


_MODE_IDS, _TAIL, _BLANK_SUM = _header_fields()


def ustar_header(name: str, size: int, mtime: int = 0) -> bytes:
    """The 512-byte ustar header of a regular file.

    Args:
        name: member name, at most 100 bytes in UTF-8.
        size: member size in bytes.
        mtime: modification time, seconds since the epoch (clamped to the field's range).

    Raises:
        ValueError: the name or the size does not fit the header.
    """
    raw = name.encode("utf-8")
    if len(raw) > 100:
        raise ValueError(f"tar member name {name!r} is longer than 100 bytes")
    if not 0 <= size < 8**11:
        raise ValueError(f"tar member {name!r}: size {size} does not fit an ustar header")
    size_mtime = b"%011o\0%011o\0" % (size, max(0, min(int(mtime), 8**11 - 1)))
    checksum = b"%06o\0 " % (_BLANK_SUM + sum(raw) + sum(size_mtime))
    return raw.ljust(100, b"\0") + _MODE_IDS + size_mtime + checksum + _TAIL


class TarArchiveWriter:
    """Write one tar archive of images (see the module docstring).

    Args:
        path: archive path (created or truncated).
        batch_bytes: size of each of the three batch buffers.
    """

    def __init__(self, path: str | os.PathLike[str], *, batch_bytes: int = BATCH_BYTES) -> None:
        self.path = os.fspath(path)
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_BINARY", 0),
                                       0o666)
        self._sha = hashlib.sha256()
        self._size = 0
        """Bytes of the archive so far (handed over and buffered)."""
        self._written = 0
        """Bytes written by the writer thread."""
        self._free: queue.SimpleQueue[bytearray] = queue.SimpleQueue()
        for _ in range(3):
            self._free.put(bytearray(batch_bytes))
        self._todo: queue.SimpleQueue[tuple[bytearray, int] | None] = queue.SimpleQueue()
        self._buf, self._n = self._free.get(), 0
        self._error: BaseException | None = None
        self._finished = False
        self._thread = threading.Thread(target=self._write_batches, name="psg-tar-write", daemon=True)
        self._thread.start()

    def add(self, name: str, data: Any, mtime: int = 0) -> int:
        """Append a member ``name`` holding ``data`` (any bytes-like object); returns its data offset."""
        view = memoryview(data).cast("B")
        self._put(ustar_header(name, view.nbytes, mtime))
        offset = self._size
        self._put(view)
        self._put(_ZEROS[:-view.nbytes % TAR_BLOCK])
        return offset

    def finish(self) -> None:
        """Append the end of the archive; returns while the writer thread completes it (see :meth:`result`)."""
        if self._finished:
            raise ValueError(f"{self.path}: archive already finished")
        self._put(_ZEROS[:2 * TAR_BLOCK])
        self._put(_ZEROS[:-self._size % ARCHIVE_ALIGN])
        self._hand_over()
        self._finished = True
        self._todo.put(None)

    @property
    def done(self) -> bool:
        """Whether a finished archive is completely written."""
        return self._finished and not self._thread.is_alive()

    def result(self) -> tuple[int, str]:
        """Wait for a finished archive; returns (size in bytes, hex SHA-256).

        Raises:
            OSError: writing failed (disk full, ...).
        """
        self._stop()
        self._check()
        return self._size, self._sha.hexdigest()

    def close(self) -> tuple[int, str]:
        """Finish the archive and wait for it; returns (size in bytes, hex SHA-256)."""
        self.finish()
        return self.result()

    def abort(self) -> None:
        """Stop without finishing the archive (the caller removes the file)."""
        self._stop()

    def _put(self, data: bytes | memoryview) -> None:
        view = memoryview(data)
        while view:
            k = min(len(view), len(self._buf) - self._n)
            self._buf[self._n:self._n + k] = view[:k]
            self._n += k
            self._size += k
            view = view[k:]
            if self._n == len(self._buf):
                self._hand_over()

    def _hand_over(self) -> None:
        self._check()
        if self._n:
            self._todo.put((self._buf, self._n))
            self._buf, self._n = self._free.get(), 0

    def _write_batches(self) -> None:
        while (item := self._todo.get()) is not None:
            buf, n = item
            if self._error is None:
                try:
                    self._write(memoryview(buf)[:n])
                except BaseException as exc:  # reported to the caller by its next call
                    self._error = exc
            self._free.put(buf)

    def _write(self, batch: memoryview) -> None:
        self._sha.update(batch)
        self._written += len(batch)
        while batch:
            batch = batch[os.write(self._fd, batch):]  # type: ignore[arg-type]
        if self._written > DROP_BEHIND_BYTES and hasattr(os, "posix_fadvise"):
            os.posix_fadvise(self._fd, 0, self._written - DROP_BEHIND_BYTES, os.POSIX_FADV_DONTNEED)  # type: ignore[arg-type]

    def _check(self) -> None:
        if self._error is not None:
            raise OSError(f"{self.path}: writing the image archive failed: {self._error}") from self._error

    def _stop(self) -> None:
        if self._fd is None:
            return
        if not self._finished:
            self._finished = True
            self._todo.put(None)
        self._thread.join()
        os.close(self._fd)
        self._fd = None
