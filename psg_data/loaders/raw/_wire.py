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


class TfSample(NamedTuple):
    """One ``geometry_msgs/TransformStamped`` of a TF message: ``T_parent_child`` at ``stamp_ns``."""

    parent: str
    child: str
    stamp_ns: int
    translation: tuple[float, float, float]
    """metres"""
    rotation_xyzw: tuple[float, float, float, float]


DecodedStrings = dict[tuple[bool, bytes], tuple[str, str]]
"""A cache of :func:`parse_compressed_image`: (frame_id, format) by their serialized bytes."""
TfLayouts = dict[tuple[bool, int], "_TfLayout"]
"""A cache of :func:`parse_tf_message`: message shapes by (CDR, length)."""

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_STAMP1 = struct.Struct("<III")
_SEVEN_DOUBLES = struct.Struct("<7d")


def parse_compressed_image(raw: bytes | memoryview, cdr: bool,
                           cache: DecodedStrings | None = None) -> CompressedFields | None:
    """Read header stamp, frame id, format and data of a serialized ``CompressedImage`` directly.

    The image bytes stay a view of ``raw``.

    Args:
        raw: one serialized message: ROS 1 (``cdr=False``) or little-endian CDR with its 4-byte
            encapsulation header (``cdr=True``).
        cdr: serialization of ``raw``.
        cache: the caller's dictionary of decoded frame ids and formats by their serialized bytes
            (the same in every message of a topic), kept between calls; at most 64 entries.
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
            start, o = 8, (12 + ln + 3) & ~3
            (ln2,) = _U32.unpack_from(b, o)
            if ln2 < 1 or o + 4 + ln2 > n:
                return None
            o2 = (o + 4 + ln2 + 3) & ~3
        else:
            b = mv
            _, sec, nsec = _STAMP1.unpack_from(b, 0)
            (ln,) = _U32.unpack_from(b, 12)
            if 16 + ln > n:
                return None
            start, o = 12, 16 + ln
            (ln2,) = _U32.unpack_from(b, o)
            if o + 4 + ln2 > n:
                return None
            o2 = o + 4 + ln2
        key = (cdr, bytes(b[start:o2]))  # both strings with their lengths: the same in every message of a topic
        names = None if cache is None else cache.get(key)
        if names is None:
            if cdr:
                names = bytes(b[12:12 + ln - 1]).decode(), bytes(b[o + 4:o + 3 + ln2]).decode()
            else:
                names = bytes(b[16:16 + ln]).decode(), bytes(b[o + 4:o + 4 + ln2]).decode()
            if cache is not None:
                if len(cache) >= 64:
                    cache.clear()
                cache[key] = names
        o = o2
        (ln,) = _U32.unpack_from(b, o)
        end = o + 4 + ln
        if end > n or n - end > 3:  # CDR may pad the end to 4 bytes; nothing else may follow
            return None
        return CompressedFields(int(sec) * 1_000_000_000 + int(nsec), names[0], names[1], b[o + 4:end])
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


class _TfLayout:
    """Where the numbers of one TF message shape are: for the next message of the same length whose
    other bytes (counts, frame names, padding) are equal, a single struct unpack reads them all.
    """

    __slots__ = ("fixed", "numbers", "frames")

    def __init__(self, raw: bytes, numeric: list[tuple[int, str]], frames: list[tuple[str, str]]) -> None:
        fmt, pos, fixed = "<", 0, []
        for off, code in numeric:  # (offset in raw, struct code; "4x": changing bytes to skip), in order
            if off > pos:
                fmt += f"{off - pos}x"
                fixed.append((pos, raw[pos:off]))
            fmt += code
            pos = off + struct.calcsize("<" + code)
        if pos < len(raw):
            fixed.append((pos, raw[pos:]))
        self.fixed = [(a, a + len(v), v) for a, v in fixed]
        self.numbers = struct.Struct(fmt)
        self.frames = frames

    def read(self, mv: memoryview) -> list[TfSample] | None:
        for a, e, v in self.fixed:
            if bytes(mv[a:e]) != v:  # (faster than comparing the memoryview)
                return None
        vals = self.numbers.unpack_from(mv, 0)
        out = []
        for k, (parent, child) in enumerate(self.frames):
            sec, nsec, tx, ty, tz, qx, qy, qz, qw = vals[9 * k:9 * k + 9]
            out.append(TfSample(parent, child, sec * 1_000_000_000 + nsec, (tx, ty, tz), (qx, qy, qz, qw)))
        return out


def parse_tf_message(raw: bytes | memoryview, cdr: bool,
                     cache: TfLayouts | None = None) -> list[TfSample] | None:
    """The transforms of a serialized ``tf2_msgs/TFMessage`` (ROS 1 or little-endian CDR).

    Returns None when ``raw`` does not have exactly the expected layout (see the module docstring).

    Args:
        raw: one serialized message.
        cdr: serialization of ``raw``.
        cache: the caller's dictionary of recent message shapes by (CDR, length), kept between
            calls (a stream repeats one or two; at most 8 entries): a message with the shape of a
            recent one (same length, same bytes outside the stamps and the numbers: same frames)
            is read with one struct unpack.
    """
    b = memoryview(raw)
    n = len(b)
    layout = None if cache is None else cache.get((cdr, n))
    if layout is not None:
        got = layout.read(b)
        if got is not None:
            return got
    try:
        base = 0
        if cdr:
            if n < 8 or b[0] != 0 or b[1] != 1:
                return None
            b = b[4:]
            n -= 4
            base = 4
        (count,) = _U32.unpack_from(b, 0)
        if count > n // 60:  # each transform takes at least 60 bytes: reject garbage counts early
            return None
        o = 4
        out: list[TfSample] = []
        numeric: list[tuple[int, str]] = []
        for _ in range(count):
            if cdr:
                sec, nsec = _STAMP.unpack_from(b, o)
                numeric.append((base + o, "iI"))
                o += 8
            else:
                _, sec, nsec = _STAMP1.unpack_from(b, o)
                numeric.append((base + o, "4x"))  # the ROS 1 header's seq counts up: skipped, not compared
                numeric.append((base + o + 4, "II"))
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
            numeric.append((base + o, "7d"))
            o += 56
            out.append(TfSample(parent, child, int(sec) * 1_000_000_000 + int(nsec), (tx, ty, tz), (qx, qy, qz, qw)))
        if n - o > (3 if cdr else 0):
            return None
        if cache is not None:
            if len(cache) >= 8:
                cache.clear()
            cache[(cdr, len(raw))] = _TfLayout(bytes(raw), numeric, [(t.parent, t.child) for t in out])
        return out
    except (struct.error, UnicodeDecodeError):
        return None
