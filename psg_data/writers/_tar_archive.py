"""Appending a scan's images to one uncompressed POSIX (ustar) tar archive.

The archive is what ``tar``, Python's ``tarfile`` or any archive tool reads: one regular-file member
per image (``color/000000.png``, ``depth/000000.png``, ...), each a 512-byte header followed by the
image bytes padded to 512, then the end-of-archive zero blocks, padded with zeros to a multiple of
4 KiB. The byte offset of every member's data is returned to the caller, who stores it in the
``frames`` table: a reader then fetches one image with a single ``pread`` of a known range.

Writing is a pipeline: the caller puts member headers and in-memory bytes into page-aligned 16 MiB
buffers; members given as a :class:`FileRange` of an open file only reserve their place. Full
buffers go to a hashing thread, which first reads the buffer's file ranges into it (in file order,
nearby ranges in one ``os.preadv``), then passes the buffer to a writing thread and computes the
archive's SHA-256 (for ``files.parquet``) while it is written; both release the GIL. When the
hashing thread is behind, the caller reads the ranges itself before handing the buffer over, so
the copying goes to whichever core has time. Where the file system supports it the archive is
written with ``O_DIRECT``: the bytes go from the buffers to the device without first being copied
into newly allocated page-cache pages (on the development VM that copy made buffered writing
2-10x slower and erratic; BENCHMARKS.md). Buffers are private anonymous memory (transparent huge
pages where enabled) reused from a :class:`BufferPool`, so a conversion touches a bounded,
constant amount of memory whatever the recording size.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import mmap
import os
import queue
import threading
from collections.abc import Iterator
from typing import Any, NamedTuple

__all__ = ["BufferPool", "FileRange", "TarArchiveWriter", "reuse_buffers", "ustar_header", "TAR_BLOCK",
           "ARCHIVE_ALIGN"]

TAR_BLOCK = 512
"""Tar block size: headers and member data are padded to it."""
ARCHIVE_ALIGN = 4096
"""Archives are padded with zero blocks to a multiple of this (the O_DIRECT transfer unit)."""
BUFFER_BYTES = 16 << 20
"""Size of one write buffer (a multiple of ARCHIVE_ALIGN)."""
_SPARE_MAX = 4
_spare: list[mmap.mmap] = []
"""Buffers of closed pools kept for the next pool, inside :func:`reuse_buffers` (at most 4)."""
_spare_lock = threading.Lock()
_reuse_depth = 0


@contextlib.contextmanager
def reuse_buffers() -> Iterator[None]:
    """Within this block, closed buffer pools keep their buffers for the next pool of the process.

    A conversion opens one dataset writer per recording; without reuse each would fault in fresh
    buffer pages (64 MiB at about 1 GB/s on the development VM). On leaving the outermost block
    the kept buffers are unmapped.
    """
    global _reuse_depth
    with _spare_lock:
        _reuse_depth += 1
    try:
        yield
    finally:
        with _spare_lock:
            _reuse_depth -= 1
            if _reuse_depth == 0:
                for b in _spare:
                    b.close()
                _spare.clear()


_ZEROS = bytes(ARCHIVE_ALIGN)


class FileRange(NamedTuple):
    """``size`` bytes at ``offset`` of the open file ``fd``, as a member's content.

    :meth:`TarArchiveWriter.add` does not read them itself: the archive's hashing thread reads them
    straight into the write buffer just before hashing it (``os.preadv``, one call for a run of
    nearby ranges, the GIL released), so the copy runs beside the caller's work. The converter
    passes images stored uncompressed in a recording this way. ``fd`` must stay open until the
    archive has read the range: give an ``owner`` that keeps it open while referenced (the
    converter gives the ROS 1 reader's ``SharedFd``), or keep the file open until
    :meth:`TarArchiveWriter.result` returns.
    """

    fd: int
    offset: int
    size: int
    owner: Any = None

    def read(self) -> bytes:
        """The bytes (for a consumer that needs them in memory)."""
        data = os.pread(self.fd, self.size, self.offset)
        if len(data) != self.size:
            raise OSError(f"file ends before byte {self.offset + self.size} (truncated?)")
        return data


def _iov_max() -> int:
    """Buffers one ``preadv`` call may take (POSIX guarantees at least 16)."""
    try:
        n = os.sysconf("SC_IOV_MAX")
    except (AttributeError, ValueError, OSError):
        return 16
    return min(1024, n) if n >= 16 else 16


_IOV_MAX = _iov_max()
_GAP_MAX = 1 << 20
"""Ranges of one file at most this far apart are read in one ``preadv`` (the gap goes to scratch)."""


def _file_order(c: tuple[int, FileRange]) -> tuple[int, int]:
    return c[1].fd, c[1].offset


def _read_ranges(mv: memoryview, copies: list[tuple[int, FileRange]], scratch: memoryview) -> None:
    """Read each (buffer offset, FileRange) into ``mv``: nearby ranges of a file in one ``preadv``."""
    copies = sorted(copies, key=_file_order)  # in file order (the buffer order may differ: colour/depth)
    i, n = 0, len(copies)
    while i < n:
        boff, r = copies[i]
        fd, start = r.fd, r.offset
        end = start + r.size
        iov = [mv[boff:boff + r.size]]
        try:
            i += 1
            while i < n and len(iov) < _IOV_MAX - 1:
                b2, r2 = copies[i]
                gap = r2.offset - end
                if r2.fd != fd or gap < 0 or gap > _GAP_MAX:
                    break
                if gap:
                    iov.append(scratch[:gap])
                iov.append(mv[b2:b2 + r2.size])
                end = r2.offset + r2.size
                i += 1
            got = os.preadv(fd, iov, start)
        finally:
            iov.clear()  # views of the buffer: none may outlive this call (the buffer is unmapped later)
        if got != end - start:
            raise OSError(f"file ends before byte {end} (truncated?)")


def _header_template() -> tuple[bytearray, int]:
    h = bytearray(TAR_BLOCK)
    h[100:108] = b"0000644\0"  # mode
    h[108:116] = b"0000000\0"  # uid
    h[116:124] = b"0000000\0"  # gid
    h[156:157] = b"0"  # regular file
    h[257:263] = b"ustar\0"
    h[263:265] = b"00"
    h[329:337] = b"0000000\0"  # devmajor
    h[337:345] = b"0000000\0"  # devminor
    return h, sum(h) + 8 * ord(" ")  # the checksum counts its own field as eight spaces


_TEMPLATE, _TEMPLATE_SUM = _header_template()


_HEAD_MODE = bytes(_TEMPLATE[100:124])  # mode, uid, gid
_HEAD_TAIL = bytes(_TEMPLATE[156:512])  # type, link name, magic, version, owner, devices, prefix
_NAME_PAD = [bytes(100 - k) for k in range(101)]


def ustar_header(name: str, size: int, mtime: int = 0) -> bytes:
    """512-byte ustar header of a regular file ``name`` (ASCII, at most 100 bytes) of ``size`` bytes."""
    raw = name.encode("utf-8")
    if len(raw) > 100:
        raise ValueError(f"tar member name {name!r} is longer than 100 bytes")
    if not 0 <= size < 8 ** 11:
        raise ValueError(f"tar member {name!r}: size {size} does not fit an ustar header")
    st = b"%011o\0%011o\0" % (size, max(0, min(int(mtime), 8 ** 11 - 1)))  # size and mtime fields
    return (raw + _NAME_PAD[len(raw)] + _HEAD_MODE + st
            + b"%06o\0 " % (_TEMPLATE_SUM + sum(raw) + sum(st)) + _HEAD_TAIL)


def _anonymous_map(size: int) -> mmap.mmap:
    """``size`` bytes of private anonymous memory, page-aligned.

    Private, not ``mmap.mmap(-1, n)``'s default shared mapping: shared anonymous memory is shmem,
    which gets transparent huge pages only where ``shmem_enabled`` allows (usually not), while
    private memory gets them under the usual ``madvise`` setting. On the development VM that made
    copies into the buffers a third faster and a fresh 16 MiB buffer 8 page faults instead of 4096.
    """
    flags = getattr(mmap, "MAP_PRIVATE", None), getattr(mmap, "MAP_ANONYMOUS", None)
    if flags[0] is None or flags[1] is None:
        return mmap.mmap(-1, size)
    return mmap.mmap(-1, size, flags=flags[0] | flags[1])


class BufferPool:
    """Page-aligned write buffers (anonymous mmaps), reused by every archive of one dataset writer.

    Reuse matters: a fresh buffer's pages must be faulted in on first use, which costs as much as
    writing them. :meth:`take` blocks while ``max_buffers`` are in use. Inside
    :func:`reuse_buffers`, a closed pool hands its buffers to the next pool of the process.
    """

    def __init__(self, buffer_bytes: int = BUFFER_BYTES, max_buffers: int = 4) -> None:
        if buffer_bytes % ARCHIVE_ALIGN:
            raise ValueError(f"buffer_bytes must be a multiple of {ARCHIVE_ALIGN}")
        self.buffer_bytes = buffer_bytes
        self.max_buffers = max(2, max_buffers)
        self._free: list[mmap.mmap] = []
        self._made = 0
        self._cond = threading.Condition()

    def take(self) -> mmap.mmap:
        with self._cond:
            while not self._free and self._made >= self.max_buffers:
                self._cond.wait()
            if self._free:
                return self._free.pop()
            self._made += 1
        if self.buffer_bytes == BUFFER_BYTES:
            with _spare_lock:
                if _spare:
                    return _spare.pop()
        buf = _anonymous_map(self.buffer_bytes)
        if hasattr(mmap, "MADV_HUGEPAGE"):  # transparent huge pages where enabled: cheaper copies into it
            try:
                buf.madvise(mmap.MADV_HUGEPAGE)
            except OSError:
                pass
        return buf

    def give(self, buf: mmap.mmap) -> None:
        with self._cond:
            self._free.append(buf)
            self._cond.notify()

    def close(self) -> None:
        """Unmap the free buffers (buffers still in use are unmapped when they are given back)."""
        with self._cond:
            for b in self._free:
                with _spare_lock:
                    if _reuse_depth and self.buffer_bytes == BUFFER_BYTES and len(_spare) < _SPARE_MAX:
                        _spare.append(b)
                        continue
                b.close()
            self._made -= len(self._free)
            self._free.clear()


class _Stage(threading.Thread):
    """One pipeline stage: applies ``fn`` to each buffer in order, then releases it; on the stop
    signal (None) stops, passing the signal on to ``then`` (a queue of the next stage)."""

    def __init__(self, fn: Any, release: Any, name: str, then: Any = None) -> None:
        super().__init__(name=name, daemon=True)
        self.fn, self.release, self.then = fn, release, then
        self.q: queue.SimpleQueue[tuple[mmap.mmap, int, list[tuple[int, FileRange]]] | None] = \
            queue.SimpleQueue()
        self.error: BaseException | None = None
        self.start()

    def run(self) -> None:
        while (item := self.q.get()) is not None:
            if self.error is None:
                try:
                    self.fn(*item)
                except BaseException as exc:  # reported by the caller's next call
                    # without its traceback: its frames hold views of the buffer, which must be unmappable
                    self.error = exc.with_traceback(None)
            self.release(item)
        if self.then is not None:
            self.then.put(None)


class TarArchiveWriter:
    """Write one tar archive of images (see the module docstring).

    Args:
        path: archive path (created or truncated).
        pool: buffers to use (shared by the archives of one dataset writer).
        direct_io: write with ``O_DIRECT`` where the file system accepts it (falls back to
            buffered writes, with the same bytes, where it does not).
    """

    def __init__(self, path: str | os.PathLike[str], pool: BufferPool, *, direct_io: bool = True) -> None:
        self.path = os.fspath(path)
        self._pool = pool
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_BINARY", 0)
        direct = getattr(os, "O_DIRECT", 0) if direct_io else 0
        self.direct = False
        self._fd: int | None
        if direct:
            try:
                self._fd = os.open(self.path, flags | direct, 0o666)
                self.direct = True
            except OSError:
                self._fd = os.open(self.path, flags, 0o666)
        else:
            self._fd = os.open(self.path, flags, 0o666)
        self._sha = hashlib.sha256()
        self._scratch: memoryview | None = None
        self._refs: dict[int, int] = {}
        self._lock = threading.Lock()
        self._writer = _Stage(self._write, self._release, "psg-tar-write")
        self._hasher = _Stage(self._hash, self._release, "psg-tar-sha256", then=self._writer.q)
        self._buf = pool.take()
        self._mv = memoryview(self._buf)
        self._copies: list[tuple[int, FileRange]] = []
        """FileRange members of the current buffer, read by the hashing thread: (buffer offset, range)."""
        self._n = 0
        self._size = 0
        """Bytes of the archive so far (dispatched + buffered)."""
        self._closed = False
        """finish() or abort() was called: the stages got their stop signal."""

    # -- stages (worker threads) ------------------------------------------------------------
    def _hash(self, buf: mmap.mmap, n: int, copies: list[tuple[int, FileRange]]) -> None:
        """Read the buffer's file ranges into it, pass it on to the writer, and hash it meanwhile."""
        try:
            if copies:
                with memoryview(buf) as mv:
                    self._read(mv, copies)
                copies.clear()  # the ranges' owners: their files may close now
        finally:  # the writer gets every buffer (also after an error: the caller discards the archive)
            with self._lock:
                self._refs[id(buf)] = 2  # released by this stage and by the writer
            self._writer.q.put((buf, n, copies))
        with memoryview(buf) as mv:
            self._sha.update(mv[:n])

    def _read(self, mv: memoryview, copies: list[tuple[int, FileRange]]) -> None:
        """Read a buffer's file ranges into it (either thread; the scratch takes gaps, never read)."""
        if self._scratch is None:
            self._scratch = memoryview(bytearray(_GAP_MAX))
        _read_ranges(mv, copies, self._scratch)

    def _write(self, buf: mmap.mmap, n: int, copies: list[tuple[int, FileRange]]) -> None:
        with memoryview(buf) as whole:
            mv = whole[:n]
            while mv:
                try:
                    k = os.write(self._fd, mv)
                except OSError as exc:
                    if not (self.direct and exc.errno == errno.EINVAL):
                        raise
                    self._drop_direct()  # the file system refused this transfer: continue buffered
                    continue
                mv = mv[k:]

    def _drop_direct(self) -> None:
        import fcntl

        fl = fcntl.fcntl(self._fd, fcntl.F_GETFL)
        fcntl.fcntl(self._fd, fcntl.F_SETFL, fl & ~os.O_DIRECT)
        self.direct = False

    def _release(self, item: tuple[mmap.mmap, int, list[tuple[int, FileRange]]]) -> None:
        """Give the buffer back once both stages are done with it."""
        buf = item[0]
        with self._lock:
            left = self._refs.get(id(buf), 0) - 1
            if left > 0:
                self._refs[id(buf)] = left
                return
            self._refs.pop(id(buf), None)
        self._pool.give(buf)

    # -- caller side -------------------------------------------------------------------------
    def _check(self) -> None:
        for stage in (self._writer, self._hasher):
            if stage.error is not None:
                raise OSError(f"{self.path}: writing the image archive failed: {stage.error}") from stage.error

    def _dispatch(self) -> None:
        self._check()
        if self._copies and self._hasher.q.qsize():  # the hashing thread is behind: read them here
            self._read(self._mv, self._copies)
            self._copies = []
        self._hasher.q.put((self._buf, self._n, self._copies))
        self._buf = self._pool.take()
        self._mv = memoryview(self._buf)
        self._copies = []
        self._n = 0

    def _put(self, data: Any) -> None:
        src = data if isinstance(data, memoryview) else memoryview(data)
        if src.format != "B" or src.ndim != 1:
            src = src.cast("B")
        cap = self._pool.buffer_bytes
        while src:
            k = min(len(src), cap - self._n)
            self._mv[self._n:self._n + k] = src[:k]
            self._n += k
            self._size += k
            src = src[k:]
            if self._n == cap:
                self._dispatch()

    def _put_range(self, r: FileRange) -> None:
        """Queue a file range for reading into the buffers (spanning as many as it needs)."""
        cap = self._pool.buffer_bytes
        offset, left = r.offset, r.size
        while left:
            k = min(left, cap - self._n)
            self._copies.append((self._n, FileRange(r.fd, offset, k, r.owner)))
            self._n += k
            self._size += k
            offset += k
            left -= k
            if self._n == cap:
                self._dispatch()

    def add(self, name: str, data: Any, mtime: int = 0) -> int:
        """Append one member ``name`` holding ``data`` (bytes-like or a :class:`FileRange`); returns
        the offset of its data in the archive."""
        if isinstance(data, FileRange):
            size = data.size
            src = None
        else:
            src = data if type(data) is memoryview and data.format == "B" else memoryview(data).cast("B")
            size = len(src)
        hdr = ustar_header(name, size, mtime)
        pad = -size % TAR_BLOCK
        n = self._n
        end = n + TAR_BLOCK + size + pad
        if end <= self._pool.buffer_bytes:  # the usual case: the member fits the current buffer
            mv = self._mv
            mv[n:n + TAR_BLOCK] = hdr
            if src is not None:
                mv[n + TAR_BLOCK:end - pad] = src
            elif size:
                self._copies.append((n + TAR_BLOCK, data))
            if pad:
                mv[end - pad:end] = _ZEROS[:pad]
            offset = self._size + TAR_BLOCK
            self._size += end - n
            self._n = end
            if end == self._pool.buffer_bytes:
                self._dispatch()
            return offset
        self._put(hdr)
        offset = self._size
        if src is None:
            self._put_range(data)
        else:
            self._put(src)
        if pad:
            self._put(_ZEROS[:pad])
        return offset

    def finish(self) -> None:
        """Append the end of the archive and hand the last buffer over; returns without waiting
        (the stages finish in the background; :meth:`result` waits for them)."""
        if self._closed:
            raise ValueError(f"{self.path}: archive already finished")
        try:
            self._put(_ZEROS[:2 * TAR_BLOCK])
            pad = -self._size % ARCHIVE_ALIGN
            if pad:
                self._put(_ZEROS[:pad])
            if self._n:
                self._dispatch()
        except BaseException:
            self._stop()
            raise
        self._closed = True
        self._hasher.q.put(None)  # passed on to the writer

    @property
    def done(self) -> bool:
        """Whether a finished archive is completely hashed and written."""
        return self._closed and not self._hasher.is_alive() and not self._writer.is_alive()

    def result(self) -> tuple[int, str]:
        """Wait for a finished archive; returns (size in bytes, hex SHA-256)."""
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

    def _stop(self) -> None:
        if self._fd is None:
            return
        if not self._closed:
            self._closed = True
            self._hasher.q.put(None)
        for stage in (self._hasher, self._writer):
            stage.join()
        self._copies = []
        self._mv.release()
        self._pool.give(self._buf)
        os.close(self._fd)
        self._fd = None
