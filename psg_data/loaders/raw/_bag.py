"""Opening ROS 1 bags, ROS 2 bags (sqlite3 or MCAP storage) and plain MCAP files with rosbags.

:class:`RosRecording` yields ``(topic, msgtype, log_time_ns, message)``; the log time is when the
recorder wrote the message, not ``header.stamp`` (converters associate on header stamps).
Message types are normalised to ROS 2 names (``sensor_msgs/msg/Image``) for both ROS versions.
"""

from __future__ import annotations

import functools
import logging
import mmap
import sqlite3
import struct
import zlib
from collections.abc import Callable, Collection, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, NamedTuple, TypeVar

from psg_data.errors import ConversionError, NotOpenError
from psg_data.loaders.raw._wire import (
    CompressedFields,
    DecodedStrings,
    TfLayouts,
    TfSample,
    parse_compressed_image,
    parse_tf_message,
)

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.rosbag1 import Reader as Ros1BagReader
    from rosbags.rosbag2 import Reader as Ros2BagReader
    from rosbags.typesys.store import Typestore

__all__ = ["RosRecording", "recording_format", "find_recordings", "RECORDING_FORMATS", "CompressedFields",
           "parse_compressed_image", "parse_tf_message", "TfSample"]

log = logging.getLogger(__name__)

RECORDING_FORMATS = ("ros1", "ros2-sqlite3", "ros2-mcap", "mcap")
"""Formats :class:`RosRecording` opens: ROS 1 bag, ROS 2 bag directory per storage, bare MCAP file."""


def recording_format(path: str | Path) -> str | None:
    """Format of one recording (see :data:`RECORDING_FORMATS`), or None if ``path`` is none of them."""
    p = Path(path)
    if p.is_dir():
        meta = p / "metadata.yaml"
        if meta.is_file():
            text = meta.read_text(encoding="utf-8", errors="replace")
            return "ros2-mcap" if "storage_identifier: mcap" in text else "ros2-sqlite3"
        return None
    if p.suffix == ".bag":
        return "ros1"
    if p.suffix == ".mcap":
        return "mcap"
    if p.suffix == ".db3":
        return "ros2-sqlite3"
    return None


_FAMILY = {"ros1": "ROS 1 bags", "ros2-sqlite3": "ROS 2 bags", "ros2-mcap": "ROS 2 bags", "mcap": "MCAP files"}


def find_recordings(directory: str | Path) -> list[tuple[Path, str]]:
    """Recordings directly inside ``directory``, sorted by name.

    Raises:
        ConversionError: the directory mixes ROS 1 bags, ROS 2 bags and MCAP files, or holds none.
    """
    d = Path(directory)
    found = [(p, f) for p in sorted(d.iterdir()) if (f := recording_format(p)) is not None]
    families = sorted({_FAMILY[f] for _, f in found})
    if len(families) > 1:
        counts = ", ".join(f"{sum(_FAMILY[f] == fam for _, f in found)} {fam}" for fam in families)
        raise ConversionError(f"{d}: directory mixes recording formats ({counts}); expected one format per "
                              f"directory")
    return found


@functools.lru_cache(maxsize=256)
def _ros1_typestore(msgtype: str, digest: str, msgdef: str) -> Typestore:
    """A typestore holding ``msgtype`` as the recording defines it (cached across recordings).

    Built only for the types a conversion deserialises; checked against the connection's MD5 sum.
    """
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.EMPTY)
    ts.register(get_types_from_msg(msgdef, msgtype))
    have = ts.generate_msgdef(msgtype)[1]
    if digest and have != digest:
        raise ValueError(f"message definition of {msgtype} has MD5 {have}, the connection says {digest}")
    return ts


_Message = tuple["Connection", int, "memoryview | bytes"]
"""(connection, log time in nanoseconds, serialized message)."""

_U32 = struct.Struct("<I")
_RELEASE_BYTES = 8 << 20
"""Pages of chunks already read are released from the bag's memory map once this many have gathered."""
_OP_MSGDATA, _OP_CONNECTION = 2, 7


def _record_op(header: bytes) -> int:
    """The ``op`` field of a ROS 1 record header (fields: uint32 length, then ``name=value``)."""
    i, n = 0, len(header)
    while i + 4 <= n:
        (flen,) = _U32.unpack_from(header, i)
        if header[i + 4:i + 7] == b"op=" and flen == 4:
            return header[i + 7]
        i += 4 + flen
    raise ValueError("record header without an op field")


class _Ros1Internals(NamedTuple):
    identity: Callable[[bytes], bytes]
    """rosbags' decompressor of uncompressed chunks (``decompressors["none"]``)."""


@functools.lru_cache(maxsize=1)
def _rosbags_ros1_internals() -> _Ros1Internals | None:
    """The one place that reaches into rosbags' ROS 1 reader beyond its public API, or None.

    The zero-copy loop of :class:`_Ros1Reader` reads ``rosbags.rosbag1.reader.decompressors``,
    ``Reader.indexes``, ``Reader.chunks`` and ``Chunk.datapos/datasize/decompressor``, none of which
    rosbags exports (tested with the rosbags versions pyproject.toml admits). When the import fails
    (an upstream rename) this returns None and messages come from the public ``Reader.messages``
    instead; the attributes are checked per bag in ``_Ros1Reader._index`` with the same fallback.
    """
    try:
        from rosbags.rosbag1.reader import decompressors

        identity = decompressors["none"]
    except (ImportError, AttributeError, KeyError, TypeError):
        log.debug("rosbags' ROS 1 reader internals not found: reading messages through Reader.messages")
        return None
    return _Ros1Internals(identity)


_Bag = TypeVar("_Bag", "Ros1BagReader", "Ros2BagReader")


class _Reader(Generic[_Bag]):
    """A rosbags reader with its connections, and the first connection of each message type."""

    def __init__(self, path: Path, bag: _Bag) -> None:
        self.path = path
        self._bag: _Bag = bag
        self.connections: list[Connection] = []
        self._by_type: dict[str, Connection] = {}

    def open(self) -> None:
        self._bag.open()
        self.connections = list(self._bag.connections)
        for c in self.connections:
            self._by_type.setdefault(c.msgtype, c)

    def close(self) -> None:
        self._bag.close()


class _Ros1Reader(_Reader["Ros1BagReader"]):
    """A ROS 1 bag: opened and indexed by ``rosbags.rosbag1.Reader``, messages read zero-copy.

    Two costs of rosbags' own ROS 1 path are avoided:

    * AnyReader parses the message definition of every connection into a new typestore each time
      a bag is opened, then compiles deserialisers for it: here types are built only when a
      message of that type is deserialised, once per definition for all recordings of a process.
    * ``Reader.messages`` copies every message twice (chunk into a BytesIO, record out of it) and
      merges the index in Python-level comparisons. Here the bag is memory-mapped and each message
      is a ``memoryview`` of the mapping (uncompressed chunks) or of the decompressed chunk, in the
      same order (rosbags' index, merged by time with ties in connection order). Pages of chunks
      already read are released from the mapping, so resident memory stays bounded.

    If rosbags' parsed index does not look as expected (another rosbags version), the messages
    come from ``Reader.messages`` instead.
    """

    is2 = False

    def __init__(self, path: Path) -> None:
        from rosbags.rosbag1 import Reader

        super().__init__(path, Reader(path))
        self._mm: mmap.mmap | None = None

    def close(self) -> None:
        if self._mm is not None:
            try:
                self._mm.close()
            except BufferError:  # views of it still alive (e.g. images queued for an archive): unmapped with them
                pass
            self._mm = None
        self._bag.close()

    def _map(self) -> mmap.mmap:
        if self._mm is None:
            with open(self.path, "rb") as fh:
                self._mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        return self._mm

    def _index(self, connections: Collection[Connection]
               ) -> tuple[list[tuple[int, int, int, int, int, Connection]], Callable[[bytes], bytes]] | None:
        """``(entries, identity)`` for the zero-copy loop, or None when rosbags' internals differ."""
        internals = _rosbags_ros1_internals()
        if internals is None:
            return None
        try:
            indexes, chunks = self._bag.indexes, self._bag.chunks
            entries = [(e.time, k, j, e.chunk_pos, e.offset, c)
                       for k, c in enumerate(connections) for j, e in enumerate(indexes[c.id])]
            for _, _, _, pos, _, _ in entries[:1]:
                ch = chunks[pos]
                _ = (ch.datapos, ch.datasize, ch.decompressor)
        except (AttributeError, KeyError, TypeError):
            return None
        entries.sort()  # (time, connection order, index order): rosbags' merge order, ties included
        return entries, internals.identity

    def messages(self, connections: Collection[Connection] = ()) -> Iterator[_Message]:
        """``(connection, time_ns, view)`` in log-time order."""
        conns = list(connections) or self.connections
        fast = self._index(conns)
        if fast is None:  # rosbags' public reader (copies each message)
            yield from self._bag.messages(connections=conns)
            return
        entries, identity = fast
        if not entries:
            return
        mm = self._map()
        whole = memoryview(mm)
        chunks = self._bag.chunks
        page = mmap.PAGESIZE
        release = getattr(mm, "madvise", None)
        cur_pos, cur, cur_span = -1, whole, (0, 0)
        lo = hi = 0  # pages of chunks left and not yet released: [lo, hi)
        u32 = _U32.unpack_from
        try:
            for time_ns, _, _, pos, offset, conn in entries:
                if pos != cur_pos:
                    if release is not None and cur_span[1] > 0:  # (start, length) of the chunk left
                        s0, s1 = cur_span[0], cur_span[0] + cur_span[1]
                        lo, hi = (s0, s1) if hi == 0 else (min(lo, s0), max(hi, s1))
                        if hi - lo >= _RELEASE_BYTES:  # in batches: each call costs a TLB shootdown
                            release(mmap.MADV_DONTNEED, lo, hi - lo)
                            lo = hi = 0
                    ch = chunks[pos]
                    end = ch.datapos + ch.datasize
                    if end > len(whole):
                        raise ValueError(f"chunk at byte {pos} ends beyond the end of the file")
                    if ch.decompressor is identity:
                        cur = whole[ch.datapos:end]
                        start = ch.datapos - ch.datapos % page
                        cur_span = (start, end - start)
                    else:
                        cur = memoryview(ch.decompressor(bytes(whole[ch.datapos:end])))
                        cur_span = (0, 0)
                    cur_pos = pos
                o = offset
                while True:  # skip connection records that precede the message in the chunk
                    (hlen,) = u32(cur, o)
                    op = _record_op(bytes(cur[o + 4:o + 4 + hlen]))
                    o += 4 + hlen
                    (dlen,) = u32(cur, o)
                    o += 4
                    if o + dlen > len(cur):
                        raise ValueError(f"message record at chunk offset {offset} is truncated")
                    if op == _OP_MSGDATA:
                        break
                    if op != _OP_CONNECTION:
                        raise ValueError(f"expected message data at chunk offset {offset}, found record op {op}")
                    o += dlen
                yield conn, time_ns, cur[o:o + dlen]
        finally:
            del cur, whole

    def deserialize(self, raw: memoryview | bytes, msgtype: str) -> object:
        c = self._by_type[msgtype]
        return _ros1_typestore(msgtype, c.digest, c.msgdef.data).deserialize_ros1(bytes(raw), msgtype)


@functools.lru_cache(maxsize=256)
def _ros2_typestore(msgtype: str, fmt: str, msgdef: str) -> Typestore:
    """A typestore holding ``msgtype`` from its connection's definition (ROS 2 / MCAP recordings).

    Built only for the types a conversion deserialises, so that a topic whose definition rosbags
    cannot parse (e.g. rosbag2 service events, whose schema is the raw ``.srv`` text) does not
    make the recording unreadable. Without a definition, the ROS 2 Humble types are used.
    """
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    if fmt not in ("MSG", "IDL") or not msgdef.strip():
        return get_typestore(Stores.ROS2_HUMBLE)
    ts = get_typestore(Stores.EMPTY)
    if fmt == "MSG":
        ts.register(get_types_from_msg(msgdef, msgtype))
    else:
        sep = "=" * 80 + "\n"
        parts = [p.split("\n", 1)[1] for p in msgdef.split(sep)[1:]] if msgdef.startswith(f"{sep}IDL: ") else [msgdef]
        for idl in parts:
            ts.register(get_types_from_idl(idl))
    return ts


class _Ros2Reader(_Reader["Ros2BagReader"]):
    """A ROS 2 bag (sqlite3 or MCAP storage) or a bare MCAP file, read with ``rosbags.rosbag2.Reader``.

    Unlike rosbags' AnyReader, message definitions are parsed per type when a message of that type
    is deserialised, not for every topic when the recording is opened.
    """

    is2 = True

    def __init__(self, path: Path) -> None:
        from rosbags.rosbag2 import Reader

        super().__init__(path, Reader(path))

    def messages(self, connections: Collection[Connection] = ()) -> Iterator[_Message]:
        yield from self._bag.messages(connections=list(connections) or self.connections)

    def deserialize(self, raw: memoryview | bytes, msgtype: str) -> object:
        c = self._by_type[msgtype]
        md = c.msgdef
        return _ros2_typestore(msgtype, md.format.name, md.data or "").deserialize_cdr(bytes(raw), msgtype)


_READ_ERRORS = (OSError, EOFError, struct.error, sqlite3.DatabaseError, AssertionError, KeyError, ValueError,
                IndexError, MemoryError, OverflowError, zlib.error)
_READER_MODULES = ("rosbags", "apsw", "mcap", "lz4", "zstandard", "backports.zstd", "zstd")
"""Exceptions of these libraries while reading a recording are the recording's fault (corrupt data)."""


def _is_read_error(exc: BaseException) -> bool:
    return isinstance(exc, _READ_ERRORS) or any(type(exc).__module__.startswith(m) for m in _READER_MODULES)


def _wrap(path: Path, exc: BaseException) -> ConversionError:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    what = type(exc).__name__ + (f": {text}" if text else "")
    return ConversionError(f"{path}: unreadable or truncated recording ({what[:200]}); expected a complete, "
                           f"indexed ROS 1 bag, ROS 2 bag or MCAP file")


class RosRecording:
    """One recording opened for streaming (use as a context manager).

    Args:
        path: a ``.bag`` file, a ROS 2 bag directory, or a ``.mcap`` / ``.db3`` file.

    Raises:
        ConversionError: missing, empty, truncated or unindexed recording.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        fmt = recording_format(self.path)
        if fmt is None:
            raise ConversionError(f"{self.path}: not a recording; expected a .bag file, a ROS 2 bag directory "
                                  f"(metadata.yaml) or a .mcap file")
        self.format = fmt
        files = [self.path] if self.path.is_file() else [p for p in self.path.iterdir()
                                                            if p.suffix in (".db3", ".mcap")]
        for f in files:
            if f.stat().st_size == 0:
                raise ConversionError(f"{f}: zero-byte file; expected a {fmt} recording")
        self.size_bytes = sum(f.stat().st_size for f in files)
        self._reader_: _Ros1Reader | _Ros2Reader | None = None
        self._strings: DecodedStrings = {}
        self._tf_layouts: TfLayouts = {}

    def __enter__(self) -> RosRecording:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> None:
        """Open and index the recording.

        Raises:
            ConversionError: the recording is unreadable, truncated or not indexed.
        """
        try:
            reader = _Ros1Reader(self.path) if self.format == "ros1" else _Ros2Reader(self.path)
            reader.open()
        except ConversionError:
            raise
        except Exception as exc:  # rosbags raises many types for damaged files
            if not _is_read_error(exc):
                raise
            raise _wrap(self.path, exc) from exc
        self._reader_ = reader

    def close(self) -> None:
        """Close the recording (views of its messages stay valid while they are referenced)."""
        if self._reader_ is not None:
            try:
                self._reader_.close()
            finally:
                self._reader_ = None

    @property
    def _reader(self) -> _Ros1Reader | _Ros2Reader:
        if self._reader_ is None:
            raise NotOpenError(f"{self.path}: the recording is not open; call open() or use it in a with block")
        return self._reader_

    @property
    def topics(self) -> dict[str, str]:
        """Topic -> message type (ROS 2 style name)."""
        return {c.topic: c.msgtype for c in self._reader.connections}

    def raw_messages(self, topics: Collection[str] = ()) -> Iterator[tuple[Connection, int, memoryview | bytes]]:
        """``(connection, log_time_ns, serialized bytes)`` in log-time order (no deserialisation).

        The bytes are a ``memoryview`` of the recording where it allows (ROS 1 bags), else ``bytes``.

        Raises:
            ConversionError: corrupt data found while reading.
        """
        reader = self._reader
        conns = [c for c in reader.connections if not topics or c.topic in topics]
        if topics and not conns:
            return
        try:
            for conn, t_ns, raw in reader.messages(connections=conns):
                if raw is None:  # a damaged ROS 2 sqlite3 bag: a message row whose data is NULL
                    raise ConversionError(f"{self.path}: message on {conn.topic} at log time {t_ns} ns has no data "
                                          "(damaged recording); expected its serialized bytes")
                yield conn, t_ns, raw
        except Exception as exc:  # corrupt data found while reading (every reader library's own types)
            if not _is_read_error(exc):
                raise
            raise _wrap(self.path, exc) from exc

    def deserialize(self, raw: memoryview | bytes, msgtype: str, topic: str) -> object:
        """A message object of ``msgtype`` from its serialized bytes.

        Raises:
            ConversionError: the bytes do not deserialize as ``msgtype``.
        """
        try:
            return self._reader.deserialize(raw, msgtype)
        except Exception as exc:
            raise ConversionError(f"{self.path}: {topic}: cannot deserialize a {msgtype} message ({exc})") from exc

    def compressed_image(self, raw: memoryview | bytes, topic: str) -> CompressedFields:
        """Stamp, frame id, format and data of a serialized ``sensor_msgs/CompressedImage``.

        Uses :func:`parse_compressed_image` and falls back to the full deserialiser.
        """
        fields = parse_compressed_image(raw, self.is_cdr, cache=self._strings)
        if fields is not None:
            return fields
        msg: Any = self.deserialize(raw, "sensor_msgs/msg/CompressedImage", topic)  # a generated message class
        h = msg.header
        return CompressedFields(int(h.stamp.sec) * 1_000_000_000 + int(h.stamp.nanosec), str(h.frame_id),
                                str(msg.format), memoryview(msg.data))

    @property
    def is_cdr(self) -> bool:
        """Whether messages are CDR (ROS 2) rather than ROS 1 serialized."""
        return self._reader.is2

    def tf_transforms(self, raw: memoryview | bytes, topic: str) -> list[TfSample]:
        """The transforms of a serialized ``tf2_msgs/TFMessage``.

        Uses :func:`parse_tf_message` and falls back to the full deserialiser.
        """
        fast = parse_tf_message(raw, self.is_cdr, cache=self._tf_layouts)
        if fast is not None:
            return fast
        msg: Any = self.deserialize(raw, "tf2_msgs/msg/TFMessage", topic)
        out = []
        for tr in msg.transforms:
            t, q = tr.transform.translation, tr.transform.rotation
            out.append(TfSample(str(tr.header.frame_id), str(tr.child_frame_id),
                                int(tr.header.stamp.sec) * 1_000_000_000 + int(tr.header.stamp.nanosec),
                                (float(t.x), float(t.y), float(t.z)),
                                (float(q.x), float(q.y), float(q.z), float(q.w))))
        return out

    def messages(self, topics: Collection[str] = ()) -> Iterator[tuple[str, str, int, object]]:
        """``(topic, msgtype, log_time_ns, message)`` in log-time order."""
        for conn, t, raw in self.raw_messages(topics):
            yield conn.topic, conn.msgtype, t, self.deserialize(raw, conn.msgtype, conn.topic)
