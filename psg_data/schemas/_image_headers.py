"""Reading image size and sample format from PNG / JPEG headers without decoding pixels.

One parser serves the validator (stored images, whole files or byte ranges of a scan archive) and
the converter (encoded payloads of ``CompressedImage`` messages, checked before pass-through).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["ImageHeader", "parse_image_header", "parse_image_header_end", "read_image_header", "header_problems",
           "MAX_IMAGE_PIXELS", "max_encoded_bytes", "inflate_bounded", "pixels_problem"]

_PNG_SIG = b"\x89PNG\r\n\x1a\n"
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_HEAD_BYTES = 64 * 1024
"""Enough for the frame header of any JPEG short of one carrying a large EXIF thumbnail first."""
MAX_IMAGE_PIXELS = 1 << 26
"""Pixels an image of a dataset may have (8192 x 8192; 192 MiB as 8-bit RGB): the second line of the
checks before decoding, after the camera's own size (docs/SECURITY.md)."""


@dataclass(frozen=True)
class ImageHeader:
    """What an encoded image holds, read from its header."""

    kind: str
    """``png`` or ``jpeg``."""
    width: int
    height: int
    channels: int
    bit_depth: int

    @property
    def dtype(self) -> str:
        return "uint16" if self.bit_depth == 16 else "uint8"


def _jpeg_frame_header(head: bytes) -> tuple[ImageHeader, int] | None:
    """SOFn segment of a JPEG and the offset just past it; None when ``head`` ends before it."""
    i = 2
    n = len(head)
    while i + 1 < n:
        if head[i] != 0xFF:
            raise ValueError("corrupt JPEG marker")
        marker = head[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # markers without a length
            i += 2
            continue
        if i + 4 > n:
            return None
        (seglen,) = struct.unpack_from(">H", head, i + 2)
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            if i + 10 > n:
                return None
            bits, height, width, comps = struct.unpack_from(">BHHB", head, i + 4)
            return ImageHeader("jpeg", width, height, comps, bits), i + 10
        if marker == 0xD9 or seglen < 2:
            raise ValueError("JPEG without a frame header")
        i += 2 + seglen
    return None


def parse_image_header(data: Any) -> ImageHeader:
    """Header of an encoded PNG or JPEG (``bytes``, ``memoryview`` or uint8 array).

    Reads only the first bytes: 33 for a PNG, up to the frame header for a JPEG (a short prefix
    first, the whole buffer only if the frame header lies further in).

    Raises:
        ValueError: not a PNG or JPEG, or a truncated or corrupt header.
    """
    return parse_image_header_end(data)[0]


def parse_image_header_end(data: Any) -> tuple[ImageHeader, int]:
    """:func:`parse_image_header` and the number of leading bytes it depends on: images whose first
    that many bytes are equal have the same header (a stream of frames can skip the parse).
    """
    mv = memoryview(data).cast("B") if not isinstance(data, bytes) else data
    head = bytes(mv[:1024])
    if head.startswith(_PNG_SIG):
        if len(head) < 33 or head[12:16] != b"IHDR":
            raise ValueError("truncated PNG header")
        width, height, bit_depth, color_type = struct.unpack_from(">IIBB", head, 16)
        return ImageHeader("png", width, height, _PNG_CHANNELS.get(color_type, 0), bit_depth), 33
    if head.startswith(b"\xff\xd8"):
        hdr = _jpeg_frame_header(head)
        if hdr is None and len(mv) > len(head):
            hdr = _jpeg_frame_header(bytes(mv))
        if hdr is None:
            raise ValueError("JPEG without a frame header")
        return hdr
    raise ValueError("not a PNG or JPEG file")


def read_image_header(path: str | Path, offset: int = 0, size: int | None = None) -> ImageHeader:
    """Parse the header of a PNG or JPEG file, or of the image at ``offset`` (``size`` bytes) in it.

    Raises:
        ValueError: not a PNG/JPEG, or a truncated header.
        OSError: the file cannot be read.
    """
    with open(path, "rb") as fh:
        fh.seek(offset)
        head = fh.read(_HEAD_BYTES if size is None else min(size, _HEAD_BYTES))
        try:
            return parse_image_header(head)
        except ValueError:
            if size is None or size <= len(head) or not head.startswith(b"\xff\xd8"):
                raise
            fh.seek(offset)
            return parse_image_header(fh.read(size))


def header_problems(hdr: ImageHeader, kind: str, width: int, height: int, color_format: str | None = None
                    ) -> list[tuple[str, str]]:
    """``(field, what is wrong and what was expected)`` for each way a stored image's header does not
    fit its camera (empty: it fits); the loader refuses such an image before decoding a pixel.

    Args:
        hdr: the parsed header.
        kind: ``color`` (8-bit, 3 channels) or ``depth`` (16-bit single-channel PNG).
        width: the camera's image width, pixels.
        height: the camera's image height, pixels.
        color_format: ``png`` or ``jpeg`` for a colour image when the format matters too (the
            dataset's ``color_encoding``); None accepts either.
    """
    out: list[tuple[str, str]] = []
    pixels = hdr.width * hdr.height
    if pixels > MAX_IMAGE_PIXELS:
        out.append(("size", f"{hdr.width}x{hdr.height} = {pixels} pixels, over the limit of {MAX_IMAGE_PIXELS} "
                            "pixels per image"))
    if (hdr.width, hdr.height) != (width, height):
        out.append(("size", f"{hdr.width}x{hdr.height}, expected the camera's {width}x{height}"))
    if kind == "depth" and (hdr.kind != "png" or hdr.bit_depth != 16 or hdr.channels != 1):
        out.append(("dtype", f"{hdr.kind} {hdr.dtype} with {hdr.channels} channel(s), "
                             "expected a 16-bit single-channel PNG (uint16 millimetres)"))
    if kind == "color":
        want = color_format or hdr.kind
        if hdr.kind != want or hdr.bit_depth != 8 or hdr.channels != 3:
            out.append(("dtype", f"{hdr.kind} {hdr.dtype} with {hdr.channels} channel(s), expected an 8-bit "
                                 f"3-channel {color_format or 'PNG or JPEG'}"
                                 f"{' (dataset color_encoding)' if color_format else ''}"))
    return out


def max_encoded_bytes(width: int, height: int, kind: str) -> int:
    """Most bytes a stored image of a ``width`` x ``height`` camera may take: twice its raw pixels
    plus 1 MiB (PNG of noise and JPEG at quality 100 stay far below); the loader reads no more.
    """
    per_pixel = 3 if kind == "color" else 2
    return 2 * max(width, 0) * max(height, 0) * per_pixel + (1 << 20)


def pixels_problem(width: int, height: int, expect: tuple[int, int] | None = None) -> str | None:
    """Why an image declaring ``width`` x ``height`` must not be decoded (None: it may be): over
    :data:`MAX_IMAGE_PIXELS`, or not the ``expect`` (width, height) of its camera. The one check every
    reader makes on a header or a declared shape before it inflates or decodes a pixel.
    """
    if width * height > MAX_IMAGE_PIXELS:
        return f"{width}x{height} = {width * height} pixels, over the limit of {MAX_IMAGE_PIXELS} pixels per image"
    if expect is not None and (width, height) != tuple(expect):
        return f"{width}x{height} pixels, expected the camera's {expect[0]}x{expect[1]}"
    return None


def inflate_bounded(parts: Iterable[Any], size: int) -> bytes:
    """A zlib stream (given in ``parts``) that must inflate to exactly ``size`` bytes; the inflater is
    told its maximum output, so a stream that inflates further is stopped at ``size + 1`` bytes.

    Raises:
        ValueError: the stream is damaged, ends early, inflates to fewer bytes, or to more.
    """
    d = zlib.decompressobj()
    out: list[bytes] = []
    have = 0
    try:
        for part in parts:
            piece = d.decompress(part, size + 1 - have)  # max_length >= 1 (0 would mean unbounded)
            out.append(piece)
            have += len(piece)
            if have > size:
                raise ValueError(f"zlib stream inflates to more than {size} bytes")
            if d.eof:
                break
    except zlib.error as exc:
        raise ValueError(f"zlib stream is damaged ({exc})") from None
    if not d.eof:
        raise ValueError(f"zlib stream ends early (cut short after {have} bytes)")
    if have != size:
        raise ValueError(f"zlib stream inflates to {have} bytes, expected {size}")
    return b"".join(out)
