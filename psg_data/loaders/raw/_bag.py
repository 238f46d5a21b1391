"""Opening ROS 1 bags, ROS 2 bags (sqlite3 or MCAP storage) and plain MCAP files with rosbags.

:class:`RosRecording` yields ``(topic, msgtype, log_time_ns, message)``; the log time is when the
recorder wrote the message, not ``header.stamp`` (converters associate on header stamps).
Message types are normalised to ROS 2 names (``sensor_msgs/msg/Image``) for both ROS versions.
"""

from __future__ import annotations

import logging
import sqlite3
import struct
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any, NamedTuple

from psg_data.errors import ConversionError

__all__ = ["RosRecording", "recording_format", "find_recordings", "RECORDING_FORMATS", "CompressedFields",
           "parse_compressed_image"]

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


class CompressedFields(NamedTuple):
    """The fields of a ``sensor_msgs/CompressedImage`` the converter needs."""

    stamp_ns: int
    """``header.stamp`` as int64 nanoseconds."""
    frame_id: str
    format: str
    data: memoryview
    """The encoded image: a zero-copy view of the serialized message."""


_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


def parse_compressed_image(raw: bytes | memoryview, cdr: bool) -> CompressedFields | None:
    """Read header stamp, frame id, format and data of a serialized ``CompressedImage`` directly.

    Skips the generic deserialiser (which builds the whole message object); the image bytes stay a
    view of ``raw``. Returns None whenever the bytes do not follow the expected layout exactly (the
    caller then falls back to the full deserialiser, which reports errors).

    Args:
        raw: one serialized message: ROS 1 (``cdr=False``) or little-endian CDR with its 4-byte
            encapsulation header (``cdr=True``).
        cdr: serialization of ``raw``.
    """
    mv = memoryview(raw)
    n = len(mv)
    try:
        if cdr:
            if n < 4 or mv[0] != 0 or mv[1] != 1:  # CDR_LE / PL_CDR_LE only
                return None
            b = mv[4:]
            n -= 4
            sec, nsec = _STAMP.unpack_from(b, 0)
            (ln,) = _U32.unpack_from(b, 8)
            if ln < 1 or 12 + ln > n:
                return None
            frame_id = bytes(b[12:12 + ln - 1]).decode()
            o = (12 + ln + 3) & ~3
            (ln,) = _U32.unpack_from(b, o)
            if ln < 1 or o + 4 + ln > n:
                return None
            fmt = bytes(b[o + 4:o + 3 + ln]).decode()
            o = (o + 4 + ln + 3) & ~3
        else:
            b = mv
            _, sec, nsec = struct.unpack_from("<III", b, 0)
            (ln,) = _U32.unpack_from(b, 12)
            if 16 + ln > n:
                return None
            frame_id = bytes(b[16:16 + ln]).decode()
            o = 16 + ln
            (ln,) = _U32.unpack_from(b, o)
            if o + 4 + ln > n:
                return None
            fmt = bytes(b[o + 4:o + 4 + ln]).decode()
            o += 4 + ln
        (ln,) = _U32.unpack_from(b, o)
        end = o + 4 + ln
        if end > n or n - end > 3:  # CDR may pad the end to 4 bytes; nothing else may follow
            return None
        return CompressedFields(int(sec) * 1_000_000_000 + int(nsec), frame_id, fmt, b[o + 4:end])
    except (struct.error, UnicodeDecodeError):
        return None


def _wrap(path: Path, exc: BaseException) -> ConversionError:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return ConversionError(f"{path}: unreadable or truncated recording ({text}); expected a complete, indexed "
                           f"ROS 1 bag, ROS 2 bag or MCAP file")


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
        self._reader: Any = None

    def __enter__(self) -> RosRecording:
        self.open()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def open(self) -> None:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        default = get_typestore(Stores.ROS1_NOETIC if self.format == "ros1" else Stores.ROS2_HUMBLE)
        try:
            self._reader = AnyReader([self.path], default_typestore=default)
            self._reader.open()
        except ConversionError:
            raise
        except Exception as exc:  # rosbags raises many types for damaged files
            self._reader = None
            raise _wrap(self.path, exc) from exc

    def close(self) -> None:
        if self._reader is not None:
            try:
                self._reader.close()
            finally:
                self._reader = None

    @property
    def topics(self) -> dict[str, str]:
        """Topic -> message type (ROS 2 style name)."""
        return {c.topic: c.msgtype for c in self._reader.connections}

    @property
    def message_counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for c in self._reader.connections:
            out[c.topic] = out.get(c.topic, 0) + int(c.msgcount)
        return out

    def raw_messages(self, topics: Collection[str] = ()) -> Iterator[tuple[Any, int, bytes]]:
        """``(connection, log_time_ns, serialized bytes)`` in log-time order (no deserialisation)."""
        conns = [c for c in self._reader.connections if not topics or c.topic in topics]
        if topics and not conns:
            return
        try:
            yield from self._reader.messages(connections=conns)
        except (OSError, EOFError, struct.error, sqlite3.DatabaseError, AssertionError, KeyError, ValueError) as exc:
            raise _wrap(self.path, exc) from exc
        except Exception as exc:
            if type(exc).__module__.startswith("rosbags"):
                raise _wrap(self.path, exc) from exc
            raise

    def deserialize(self, raw: bytes, msgtype: str, topic: str) -> Any:
        try:
            return self._reader.deserialize(raw, msgtype)
        except Exception as exc:
            raise ConversionError(f"{self.path}: {topic}: cannot deserialize a {msgtype} message ({exc})") from exc

    def compressed_image(self, raw: bytes, topic: str) -> CompressedFields:
        """Stamp, frame id, format and data of a serialized ``sensor_msgs/CompressedImage``.

        Uses :func:`parse_compressed_image` and falls back to the full deserialiser.
        """
        fields = parse_compressed_image(raw, self._reader.is2)
        if fields is not None:
            return fields
        msg = self.deserialize(raw, "sensor_msgs/msg/CompressedImage", topic)
        h = msg.header
        return CompressedFields(int(h.stamp.sec) * 1_000_000_000 + int(h.stamp.nanosec), str(h.frame_id),
                                str(msg.format), memoryview(msg.data))

    def messages(self, topics: Collection[str] = ()) -> Iterator[tuple[str, str, int, Any]]:
        """``(topic, msgtype, log_time_ns, message)`` in log-time order."""
        for conn, t, raw in self.raw_messages(topics):
            yield conn.topic, conn.msgtype, t, self.deserialize(raw, conn.msgtype, conn.topic)
