"""Appending a scan's images to one uncompressed POSIX (ustar) tar archive.

The archive is what ``tar``, Python's ``tarfile`` or any archive tool reads: one regular-file member
per image (``color/000000.png``, ``depth/000000.png``, ...), each a 512-byte header followed by the
image bytes padded to 512, then the end-of-archive zero blocks, padded with zeros to a multiple of
4 KiB. The byte offset of every member's data is returned to the caller, who stores it in the
``frames`` table: a reader then fetches one image with a single ``pread`` of a known range.

Members are gathered into batches of about 8 MiB (headers, the caller's bytes, padding); one writer
thread joins each batch into one buffer, hashes it (SHA-256, for ``files.parquet``) and writes it
with one ``write``, both without the GIL, while the caller goes on reading and encoding (hashing
and writing piece by piece instead took the GIL back some 350 times per batch: converting took 1.14
times as long, BENCHMARKS.md). Read-only data (``bytes``, views of a memory-mapped recording) is not
copied until then; writable buffers are copied at once, since their owner may reuse them.

Pages of the archive more than :data:`DROP_BEHIND_BYTES` behind its end are dropped from the page
cache (``posix_fadvise(DONTNEED)`` where the system has it): a conversion writes gigabytes that are
not read back soon, and on the development VM filling fresh page-cache pages cost so much that
converting ran at about half the speed without this (BENCHMARKS.md).
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
"""Pages of the archive further than this behind its end are dropped from the page cache."""
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


def _write_all(fd: int, data: memoryview) -> None:
    """Write all of ``data`` (one ``write`` for a regular file; more if it writes less)."""
    while data:
        data = data[os.write(fd, data):]


class TarArchiveWriter:
    """Write one tar archive of images (see the module docstring).

    Args:
        path: archive path (created or truncated).
        batch_bytes: bytes gathered before a batch goes to the writer thread (two batches at most
            wait for it, which bounds the memory an archive holds).
    """

    def __init__(self, path: str | os.PathLike[str], *, batch_bytes: int = BATCH_BYTES) -> None:
        self.path = os.fspath(path)
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_BINARY", 0),
                                       0o666)
        self._sha = hashlib.sha256()
        self._size = 0
        """Bytes of the archive so far (handed over and gathered)."""
        self._batch: list[memoryview] = []
        self._batch_bytes = 0
        self._limit = batch_bytes
        self._slots = threading.Semaphore(2)
        self._todo: queue.SimpleQueue[list[memoryview] | None] = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._finished = False
        self._thread = threading.Thread(target=self._write_batches, name="psg-tar-write", daemon=True)
        self._thread.start()

    def add(self, name: str, data: Any, mtime: int = 0) -> int:
        """Append a member ``name`` holding ``data`` (any bytes-like object); returns its data offset.

        Read-only ``data`` must not change until :meth:`result` returns (bytes and memory maps
        opened read-only do not); writable buffers are copied.
        """
        view = memoryview(data).cast("B")
        if not view.readonly:
            view = memoryview(view.tobytes())
        self._put(memoryview(ustar_header(name, view.nbytes, mtime)))
        offset = self._size
        self._put(view)
        self._put(memoryview(_ZEROS)[:-view.nbytes % TAR_BLOCK])
        return offset

    def finish(self) -> None:
        """Append the end of the archive; returns while the writer thread completes it (see :meth:`result`)."""
        if self._finished:
            raise ValueError(f"{self.path}: archive already finished")
        self._put(memoryview(_ZEROS)[:2 * TAR_BLOCK])
        self._put(memoryview(_ZEROS)[:-self._size % ARCHIVE_ALIGN])
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

    def _put(self, piece: memoryview) -> None:
        if not piece:
            return
        self._batch.append(piece)
        self._batch_bytes += len(piece)
        self._size += len(piece)
        if self._batch_bytes >= self._limit:
            self._hand_over()

    def _hand_over(self) -> None:
        self._check()
        if self._batch:
            self._slots.acquire()  # waits while two batches wait for the writer thread
            self._todo.put(self._batch)
            self._batch, self._batch_bytes = [], 0

    def _write_batches(self) -> None:
        end = 0
        while (batch := self._todo.get()) is not None:
            if self._error is None:
                try:
                    end = self._write(batch, end)
                except BaseException as exc:  # reported to the caller by its next call
                    self._error = exc
            self._slots.release()

    def _write(self, batch: list[memoryview], offset: int) -> int:
        """Hash and write one batch that starts at byte ``offset`` of the archive; returns its end."""
        assert self._fd is not None
        data = memoryview(b"".join(batch))  # one buffer: one GIL hand-off to hash it, one to write it
        self._sha.update(data)
        _write_all(self._fd, data)
        end = offset + len(data)
        if end > DROP_BEHIND_BYTES and hasattr(os, "posix_fadvise"):
            os.posix_fadvise(self._fd, 0, end - DROP_BEHIND_BYTES, os.POSIX_FADV_DONTNEED)
        return end

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
