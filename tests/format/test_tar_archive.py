"""The scan archive writer against Python's tarfile (an independent reader) and hashlib."""

from __future__ import annotations

import errno
import hashlib
import os
import tarfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.writers._tar_archive import ARCHIVE_ALIGN, BufferPool, TarArchiveWriter, ustar_header


def _write(path: Path, members: list[tuple[str, bytes, int]], pool: BufferPool, direct: bool = True
           ) -> tuple[list[int], int, str]:
    w = TarArchiveWriter(path, pool, direct_io=direct)
    offsets = [w.add(name, data, mtime) for name, data, mtime in members]
    size, sha = w.close()
    return offsets, size, sha


def _check(path: Path, members: list[tuple[str, bytes, int]], offsets: list[int], size: int, sha: str) -> None:
    raw = path.read_bytes()
    assert len(raw) == size and size % ARCHIVE_ALIGN == 0
    assert hashlib.sha256(raw).hexdigest() == sha
    with tarfile.open(path) as tf:
        got = tf.getmembers()
        assert [m.name for m in got] == [m[0] for m in members]
        for m, (name, data, mtime), off in zip(got, members, offsets):
            assert m.isfile() and m.size == len(data) and m.mtime == mtime and m.offset_data == off
            assert tf.extractfile(m).read() == data
    for (_, data, _), off in zip(members, offsets):
        assert raw[off:off + len(data)] == data


@settings(max_examples=40, deadline=None)
@given(sizes=st.lists(st.integers(0, 20000), min_size=0, max_size=12),
       buffer_kib=st.sampled_from([4, 8, 12, 64]), seed=st.integers(0, 2**16))
def test_random_members_round_trip_through_tarfile(tmp_path_factory, sizes: list[int], buffer_kib: int,
                                                   seed: int) -> None:
    # buffers smaller than the members make every member span several buffers
    rng = np.random.default_rng(seed)
    members = [(f"{'color' if i % 2 == 0 else 'depth'}/{i // 2:06d}.png", rng.bytes(n), 1_700_000_000 + i)
               for i, n in enumerate(sizes)]
    path = tmp_path_factory.mktemp("tar") / "a.tar"
    pool = BufferPool(buffer_kib * 1024, max_buffers=2)
    offsets, size, sha = _write(path, members, pool)
    _check(path, members, offsets, size, sha)
    pool.close()


def test_direct_and_buffered_writes_give_the_same_bytes(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    members = [(f"color/{i:06d}.jpg", rng.bytes(int(n)), i) for i, n in enumerate(rng.integers(1, 70000, 30))]
    pool = BufferPool(64 * 1024)
    a = _write(tmp_path / "d.tar", members, pool, direct=True)
    b = _write(tmp_path / "b.tar", members, pool, direct=False)
    assert a == b
    assert (tmp_path / "d.tar").read_bytes() == (tmp_path / "b.tar").read_bytes()
    _check(tmp_path / "d.tar", members, *a)


def test_header_matches_tarfile(tmp_path: Path) -> None:
    hdr = ustar_header("depth/000042.png", 123456, 1_700_000_123)
    info = tarfile.TarInfo.frombuf(hdr, "utf-8", "surrogateescape")
    assert (info.name, info.size, info.mtime, info.mode, info.type) == (
        "depth/000042.png", 123456, 1_700_000_123, 0o644, tarfile.REGTYPE)
    with pytest.raises(ValueError, match="longer than 100 bytes"):
        ustar_header("x" * 101, 1)


def test_refused_direct_transfer_falls_back_to_buffered(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real_write = os.write
    calls = {"n": 0}

    def write(fd: int, data: object) -> int:
        calls["n"] += 1
        if calls["n"] == 1:  # the first transfer is refused as a file system without O_DIRECT would
            raise OSError(errno.EINVAL, "Invalid argument")
        return real_write(fd, data)

    members = [(f"color/{i:06d}.png", bytes([i]) * 9000, 0) for i in range(20)]
    pool = BufferPool(16 * 1024)
    w = TarArchiveWriter(tmp_path / "a.tar", pool, direct_io=True)
    if not w.direct:
        pytest.fail("this file system refused O_DIRECT at open; the fallback under test needs it at write")
    monkeypatch.setattr(os, "write", write)
    offsets = [w.add(n, d, m) for n, d, m in members]
    size, sha = w.close()
    monkeypatch.undo()
    assert not w.direct and calls["n"] > 1
    _check(tmp_path / "a.tar", members, offsets, size, sha)


def test_write_failure_is_reported_with_the_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def write(fd: int, data: object) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")

    pool = BufferPool(8 * 1024, max_buffers=2)
    w = TarArchiveWriter(tmp_path / "a.tar", pool)
    monkeypatch.setattr(os, "write", write)
    with pytest.raises(OSError, match=r"a\.tar: writing the image archive failed: .*No space left"):
        for i in range(50):  # the error surfaces at a later add() or at close()
            w.add(f"color/{i:06d}.png", bytes(5000))
        w.close()
    w.abort()
    monkeypatch.undo()
    # the pool got every buffer back: two fresh takes do not block
    a, b = pool.take(), pool.take()
    pool.give(a)
    pool.give(b)
    pool.close()


@settings(max_examples=25, deadline=None)
@given(sizes=st.lists(st.integers(0, 30000), min_size=1, max_size=10), seed=st.integers(0, 2**16))
def test_file_range_members_equal_bytes_members(tmp_path_factory, sizes: list[int], seed: int) -> None:
    """Members given as FileRange (read into the buffer with preadv) give the same archive as the
    same bytes given in memory, across buffer boundaries."""
    from psg_data.writers._tar_archive import FileRange

    d = tmp_path_factory.mktemp("fr")
    rng = np.random.default_rng(seed)
    blob = rng.bytes(sum(sizes) + 100)
    (d / "src.bin").write_bytes(blob)
    fd = os.open(d / "src.bin", os.O_RDONLY)
    try:
        pool = BufferPool(8 * 1024, max_buffers=2)
        members, ranges, o = [], [], 50
        for i, n in enumerate(sizes):
            members.append((f"color/{i:06d}.jpg", blob[o:o + n], i))
            ranges.append((f"color/{i:06d}.jpg", FileRange(fd, o, n), i))
            o += n
        a = _write(d / "a.tar", members, pool)
        b = _write(d / "b.tar", ranges, pool)
        assert a == b and (d / "a.tar").read_bytes() == (d / "b.tar").read_bytes()
        _check(d / "b.tar", members, *b)
        w = TarArchiveWriter(d / "c.tar", pool)
        w.add("x", FileRange(fd, len(blob) - 10, 20))  # read later, by the hashing thread
        with pytest.raises(OSError, match=r"c\.tar: writing the image archive failed: file ends before byte"):
            w.close()
        pool.close()
    finally:
        os.close(fd)


def test_file_ranges_read_by_either_thread_in_any_file_order(tmp_path: Path, monkeypatch) -> None:
    """FileRange members are read by the hashing thread or, when it is behind, by the caller at
    dispatch; ranges out of file order (depth stored before colour) and gaps between them give the
    same archive as the bytes in memory."""
    import threading
    import time

    import psg_data.writers._tar_archive as ta

    rng = np.random.default_rng(3)
    blob = rng.bytes(400_000)
    (tmp_path / "src.bin").write_bytes(blob)
    spans = []
    o = 10
    for n in rng.integers(1, 9000, 60):
        spans.append((o, int(n)))
        o += int(n) + int(rng.integers(0, 300))
    order = [k ^ 1 for k in range(len(spans))]  # pairs swapped: every other range goes backwards in the file
    members = [(f"color/{i:06d}.jpg", blob[spans[k][0]:spans[k][0] + spans[k][1]], i) for i, k in enumerate(order)]

    readers: list[int] = []
    real_read, real_hash = ta._read_ranges, ta.TarArchiveWriter._hash

    def read_ranges(mv, copies, scratch):
        readers.append(threading.get_ident())
        return real_read(mv, copies, scratch)

    def slow_hash(self, buf, n, copies):
        time.sleep(0.01)  # the hashing thread falls behind: later buffers are read by the caller
        return real_hash(self, buf, n, copies)

    monkeypatch.setattr(ta, "_read_ranges", read_ranges)
    monkeypatch.setattr(ta.TarArchiveWriter, "_hash", slow_hash)
    pool = BufferPool(16 * 1024, max_buffers=6)
    a = _write(tmp_path / "a.tar", members, pool)
    from psg_data.loaders.raw._bag import SharedFd

    sf = SharedFd(tmp_path / "src.bin")
    ranges = [(name, ta.FileRange(sf.fd, spans[k][0], spans[k][1], sf), i)
              for (name, _, i), k in zip(members, order)]
    del sf
    b = _write(tmp_path / "b.tar", ranges, pool)
    assert a == b and (tmp_path / "a.tar").read_bytes() == (tmp_path / "b.tar").read_bytes()
    _check(tmp_path / "b.tar", members, *b)
    me = threading.get_ident()
    assert me in readers and any(t != me for t in readers)
    pool.close()


def test_shared_fd_stays_open_while_a_range_of_it_waits(tmp_path: Path) -> None:
    """The caller may drop its file (close the recording) right after adding: the archive's
    FileRange keeps it open until read, and the file is closed once the last range is read."""
    import gc

    from psg_data.loaders.raw._bag import SharedFd
    from psg_data.writers._tar_archive import FileRange

    (tmp_path / "src.bin").write_bytes(b"0123456789" * 100)
    ino = (tmp_path / "src.bin").stat().st_ino
    pool = BufferPool(8 * 1024)
    w = TarArchiveWriter(tmp_path / "a.tar", pool)
    sf = SharedFd(tmp_path / "src.bin")
    fd = sf.fd
    w.add("color/000000.jpg", FileRange(fd, 5, 100, sf))
    del sf
    gc.collect()
    assert os.fstat(fd).st_ino == ino  # still open: the pending range holds it
    size, sha = w.close()
    with tarfile.open(tmp_path / "a.tar") as tf:
        assert tf.extractfile("color/000000.jpg").read() == (b"0123456789" * 11)[5:105]
    try:
        reopened = os.fstat(fd).st_ino == ino
    except OSError:
        reopened = False
    assert not reopened  # closed with the last range
    pool.close()
