"""The scan archive writer against Python's tarfile (an independent writer and reader) and hashlib."""

from __future__ import annotations

import errno
import hashlib
import io
import os
import tarfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.writers._tar_archive import ARCHIVE_ALIGN, TarArchiveWriter, ustar_header


def _write(path: Path, members: list[tuple[str, bytes, int]], batch_bytes: int = 1 << 20
           ) -> tuple[list[int], int, str]:
    w = TarArchiveWriter(path, batch_bytes=batch_bytes)
    offsets = [w.add(name, data, mtime) for name, data, mtime in members]
    size, sha = w.close()
    return offsets, size, sha


def _tarfile_bytes(members: list[tuple[str, bytes, int]]) -> bytes:
    """The same members written by Python's tarfile (ustar, mode 0644, owner 0), padded to ARCHIVE_ALIGN.

    tarfile leaves the device number fields of a regular file empty where ours hold octal zeros
    (both valid ustar): they are filled in and the checksum recomputed the way tarfile does.
    """
    out = io.BytesIO()
    with tarfile.open(fileobj=out, mode="w", format=tarfile.USTAR_FORMAT) as tf:
        for name, data, mtime in members:
            info = tarfile.TarInfo(name)
            info.size, info.mtime, info.mode, info.uname, info.gname = len(data), mtime, 0o644, "", ""
            tf.addfile(info, io.BytesIO(data))
    # tarfile pads the end to its 10 KiB record: keep the members and the two end blocks
    body = bytearray(out.getvalue()[:sum(512 + -(-len(d) // 512) * 512 for _, d, _ in members) + 1024])
    pos = 0
    for _, data, _ in members:
        head = body[pos:pos + 512]
        head[329:345] = b"0000000\0" * 2
        head[148:156] = b" " * 8
        head[148:155] = b"%06o\0" % tarfile.calc_chksums(bytes(head))[0]
        body[pos:pos + 512] = head
        pos += 512 + -(-len(data) // 512) * 512
    return bytes(body) + bytes(-len(body) % ARCHIVE_ALIGN)


def _check(path: Path, members: list[tuple[str, bytes, int]], offsets: list[int], size: int, sha: str) -> None:
    raw = path.read_bytes()
    assert len(raw) == size and size % ARCHIVE_ALIGN == 0
    assert hashlib.sha256(raw).hexdigest() == sha
    assert raw == _tarfile_bytes(members)
    with tarfile.open(path) as tf:
        got = tf.getmembers()
        assert [m.name for m in got] == [m[0] for m in members]
        for m, (_, data, mtime), off in zip(got, members, offsets):
            assert m.isfile() and m.size == len(data) and m.mtime == mtime and m.offset_data == off
            assert tf.extractfile(m).read() == data


@settings(max_examples=40, deadline=None)
@given(sizes=st.lists(st.integers(0, 20000), min_size=0, max_size=12),
       batch_kib=st.sampled_from([4, 8, 12, 64]), seed=st.integers(0, 2**16))
def test_random_members_equal_tarfile_bytes(tmp_path_factory, sizes: list[int], batch_kib: int, seed: int) -> None:
    # batches smaller than the members make every member span several of them
    rng = np.random.default_rng(seed)
    members = [(f"{'color' if i % 2 == 0 else 'depth'}/{i // 2:06d}.png", rng.bytes(n), 1_700_000_000 + i)
               for i, n in enumerate(sizes)]
    path = tmp_path_factory.mktemp("tar") / "a.tar"
    _check(path, members, *_write(path, members, batch_kib * 1024))


def test_bytes_identical_to_the_previous_writer(tmp_path: Path) -> None:
    """The digest and member offsets of a fixed set of members as written by the O_DIRECT pipeline
    this writer replaced (psg-data main at 5c95686, measured once): the archive format is unchanged."""
    rng = np.random.default_rng(20)
    sizes = [0, 1, 511, 512, 513, 70000, 3_000_000, 4095, 4096, 20_000_001]
    members = [(f"{'color' if i % 2 == 0 else 'depth'}/{i // 2:06d}.{'jpg' if i % 2 == 0 else 'png'}", rng.bytes(n),
                1_700_000_000 + 37 * i) for i, n in enumerate(sizes)]
    offsets, size, sha = _write(tmp_path / "a.tar", members, TarArchiveWriter.__init__.__kwdefaults__["batch_bytes"])
    assert (size, sha) == (23089152, "425042d55a1e4eeb2fc7c1c9661ba868a091e7ae45d8724d51936d2d1d4cf177")
    assert offsets == [512, 1024, 2048, 3072, 4096, 5632, 76288, 3077120, 3081728, 3086336]
    _check(tmp_path / "a.tar", members, offsets, size, sha)


def test_views_and_arrays_are_stored_as_their_bytes(tmp_path: Path) -> None:
    data = np.arange(3000, dtype=np.uint16)  # cv2.imencode hands over arrays; messages come as memoryviews
    members = [("depth/000000.png", data.tobytes(), 0), ("color/000000.jpg", b"abc" * 700, 0)]
    w = TarArchiveWriter(tmp_path / "a.tar", batch_bytes=4096)
    offsets = [w.add("depth/000000.png", data), w.add("color/000000.jpg", memoryview(b"x" + b"abc" * 700)[1:])]
    _check(tmp_path / "a.tar", members, offsets, *w.close())


def test_header_matches_tarfile() -> None:
    hdr = ustar_header("depth/000042.png", 123456, 1_700_000_123)
    info = tarfile.TarInfo.frombuf(hdr, "utf-8", "surrogateescape")
    assert (info.name, info.size, info.mtime, info.mode, info.type) == (
        "depth/000042.png", 123456, 1_700_000_123, 0o644, tarfile.REGTYPE)
    with pytest.raises(ValueError, match="longer than 100 bytes"):
        ustar_header("x" * 101, 1)
    with pytest.raises(ValueError, match="does not fit an ustar header"):
        ustar_header("x", 8**11)


def test_write_failure_is_reported_with_the_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def write(fd: int, data: object) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")

    w = TarArchiveWriter(tmp_path / "a.tar", batch_bytes=8 * 1024)
    monkeypatch.setattr(os, "write", write)
    with pytest.raises(OSError, match=r"a\.tar: writing the image archive failed: .*No space left"):
        for i in range(50):  # the error surfaces at a later add() or at close()
            w.add(f"color/{i:06d}.png", bytes(5000))
        w.close()
    w.abort()
    assert w.done


def test_partial_writes_are_completed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """write may write less than asked (a signal, a pipe): the rest follows, in order."""
    real = os.write

    def short_write(fd: int, data: memoryview) -> int:
        return real(fd, memoryview(data)[:max(1, len(data) // 3)])

    rng = np.random.default_rng(5)
    members = [(f"color/{i:06d}.jpg", rng.bytes(int(n)), i) for i, n in enumerate(rng.integers(1, 3000, 12))]
    monkeypatch.setattr(os, "write", short_write)
    offsets, size, sha = _write(tmp_path / "a.tar", members, batch_bytes=4096)
    monkeypatch.undo()
    _check(tmp_path / "a.tar", members, offsets, size, sha)


def test_writable_buffers_are_copied_read_only_ones_are_not(tmp_path: Path) -> None:
    buf = bytearray(b"a" * 5000)
    w = TarArchiveWriter(tmp_path / "a.tar")
    w.add("color/000000.png", buf)
    buf[:] = b"b" * 5000  # the caller reuses its buffer before the archive is written
    w.add("color/000001.png", buf)
    offsets = [512, 6144]
    _check(tmp_path / "a.tar", [("color/000000.png", b"a" * 5000, 0), ("color/000001.png", b"b" * 5000, 0)],
           offsets, *w.close())


def test_finish_returns_before_the_archive_is_written(tmp_path: Path) -> None:
    w = TarArchiveWriter(tmp_path / "a.tar", batch_bytes=4096)
    offset = w.add("color/000000.png", b"x" * 10000, 5)
    assert not w.done
    w.finish()
    with pytest.raises(ValueError, match="already finished"):
        w.finish()
    size, sha = w.result()
    assert w.done
    _check(tmp_path / "a.tar", [("color/000000.png", b"x" * 10000, 5)], [offset], size, sha)
