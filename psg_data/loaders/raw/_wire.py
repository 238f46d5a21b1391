"""Direct parsers of the serialized messages a conversion reads most (no generic deserialiser).

rosbags' deserialiser builds a full message object per message, which costs more than everything
else the converter does with a ``CompressedImage`` or a ``TFMessage``. These functions read just
the needed fields from ROS 1 or little-endian CDR bytes, and return None whenever the bytes do not
follow the expected layout exactly: the caller then falls back to the deserialiser, which reports
errors. Both are tested field for field against rosbags' serialiser (tests/convert/test_fast_paths.py).
"""

from __future__ import annotations

import struct
from typing import NamedTuple

__all__ = ["CompressedFields", "parse_compressed_image", "TfSample", "parse_tf_message"]


class CompressedFields(NamedTuple):
    """The fields of a ``sensor_msgs/CompressedImage`` the converter needs."""

    stamp_ns: int
    """``header.stamp`` as int64 nanoseconds."""
    frame_id: str
    format: str
    data: memoryview
    """The encoded image: a zero-copy view of the serialized message."""
    data_offset: int | None = None
    """Offset of ``data`` in the serialized message (None if it is not a view of it)."""


class TfSample(NamedTuple):
    """One ``geometry_msgs/TransformStamped`` of a TF message: ``T_parent_child`` at ``stamp_ns``."""

    parent: str
    child: str
    stamp_ns: int
    translation: tuple[float, float, float]
    """metres"""
    rotation_xyzw: tuple[float, float, float, float]


_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_STAMP1 = struct.Struct("<III")
_SEVEN_DOUBLES = struct.Struct("<7d")


def parse_compressed_image(raw: bytes | memoryview, cdr: bool) -> CompressedFields | None:
    """Read header stamp, frame id, format and data of a serialized ``CompressedImage`` directly.

    The image bytes stay a view of ``raw``.

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
            base = 4
        else:
            b = mv
            _, sec, nsec = _STAMP1.unpack_from(b, 0)
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
            base = 0
        (ln,) = _U32.unpack_from(b, o)
        end = o + 4 + ln
        if end > n or n - end > 3:  # CDR may pad the end to 4 bytes; nothing else may follow
            return None
        return CompressedFields(int(sec) * 1_000_000_000 + int(nsec), frame_id, fmt, b[o + 4:end], base + o + 4)
    except (struct.error, UnicodeDecodeError):
        return None


def _string(b: memoryview | bytes, o: int, n: int, cdr: bool) -> tuple[str, int] | None:
    (ln,) = _U32.unpack_from(b, o)
    o += 4
    if cdr:
        if ln < 1 or o + ln > n or b[o + ln - 1] != 0:
            return None
        return bytes(b[o:o + ln - 1]).decode(), (o + ln + 3) & ~3
    if o + ln > n:
        return None
    return bytes(b[o:o + ln]).decode(), o + ln


def parse_tf_message(raw: bytes | memoryview, cdr: bool) -> list[TfSample] | None:
    """The transforms of a serialized ``tf2_msgs/TFMessage`` (ROS 1 or little-endian CDR).

    Returns None when ``raw`` does not have exactly the expected layout (see the module docstring).
    """
    b = memoryview(raw)
    n = len(b)
    try:
        if cdr:
            if n < 8 or b[0] != 0 or b[1] != 1:
                return None
            b = b[4:]
            n -= 4
        (count,) = _U32.unpack_from(b, 0)
        if count > n // 60:  # each transform takes at least 60 bytes: reject garbage counts early
            return None
        o = 4
        out: list[TfSample] = []
        for _ in range(count):
            if cdr:
                sec, nsec = _STAMP.unpack_from(b, o)
                o += 8
            else:
                _, sec, nsec = _STAMP1.unpack_from(b, o)
                o += 12
            r = _string(b, o, n, cdr)
            if r is None:
                return None
            parent, o = r
            r = _string(b, o, n, cdr)
            if r is None:
                return None
            child, o = r
            if cdr:
                o = (o + 7) & ~7
            if o + 56 > n:
                return None
            tx, ty, tz, qx, qy, qz, qw = _SEVEN_DOUBLES.unpack_from(b, o)
            o += 56
            out.append(TfSample(parent, child, int(sec) * 1_000_000_000 + int(nsec), (tx, ty, tz), (qx, qy, qz, qw)))
        if n - o > (3 if cdr else 0):
            return None
        return out
    except (struct.error, UnicodeDecodeError):
        return None
