"""Reading image size and sample format from PNG / JPEG headers without decoding pixels."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ImageHeader", "read_image_header"]

_PNG_SIG = b"\x89PNG\r\n\x1a\n"
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}


@dataclass(frozen=True)
class ImageHeader:
    kind: str  # "png" or "jpeg"
    width: int
    height: int
    channels: int
    bit_depth: int

    @property
    def dtype(self) -> str:
        return "uint16" if self.bit_depth == 16 else "uint8"


def read_image_header(path: str | Path) -> ImageHeader:
    """Parse the header of a PNG or JPEG file.

    Raises:
        ValueError: not a PNG/JPEG file, or a truncated header.
    """
    with open(path, "rb") as fh:
        head = fh.read(64 * 1024)
    if head.startswith(_PNG_SIG):
        if len(head) < 33 or head[12:16] != b"IHDR":
            raise ValueError("truncated PNG header")
        width, height, bit_depth, color_type = struct.unpack(">IIBB", head[16:26])
        return ImageHeader("png", width, height, _PNG_CHANNELS.get(color_type, 0), bit_depth)
    if head.startswith(b"\xff\xd8"):
        i = 2
        while i + 9 < len(head):
            if head[i] != 0xFF:
                raise ValueError("corrupt JPEG marker")
            marker = head[i + 1]
            if marker == 0xFF:
                i += 1
                continue
            (seglen,) = struct.unpack(">H", head[i + 2:i + 4])
            if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
                bits, height, width, comps = struct.unpack(">BHHB", head[i + 4:i + 10])
                return ImageHeader("jpeg", width, height, comps, bits)
            i += 2 + seglen
        raise ValueError("JPEG without a frame header")
    raise ValueError("not a PNG or JPEG file")
