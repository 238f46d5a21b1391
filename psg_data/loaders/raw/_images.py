"""Decoding ROS image messages into numpy arrays, and inspecting encoded PNG/JPEG bytes.

Colour comes out as (H, W, 3) uint8 RGB, depth as (H, W) uint16 millimetres (0 = invalid).
Deserialised ``uint8[]`` fields are read-only views of the bag buffer: every function here returns
a fresh, writable array. 16-bit PNGs are decoded with ``cv2.IMREAD_UNCHANGED`` (decoding them as
8-bit would silently lose the depth), and the 12-byte ``compressedDepth`` header is skipped here.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import ConversionError
from psg_data.schemas._image_headers import ImageHeader, parse_image_header

__all__ = [
    "COLOR_ENCODINGS",
    "DEPTH_ENCODINGS",
    "COMPRESSED_DEPTH_HEADER_SIZE",
    "EncodedInfo",
    "ImageDataError",
    "inspect_encoded",
    "decode_color_image",
    "decode_depth_image",
    "decode_compressed_color",
    "decode_compressed_depth",
    "compressed_depth_png",
    "make_compressed_depth",
    "depth_m_to_mm",
]

COLOR_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8")
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")
COMPRESSED_DEPTH_HEADER_SIZE = 12
"""``compressed_depth_image_transport`` ConfigHeader: int32 format, float32 depthQuantA, depthQuantB."""

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


class ImageDataError(ConversionError):
    """The data of one image is damaged or does not fit its description (``where``: recording and
    topic or file; ``reason``: what is wrong). Unlike other ConversionErrors it concerns one frame.
    """

    def __init__(self, where: str, reason: str) -> None:
        super().__init__(f"{where}: {reason}")
        self.where, self.reason = where, reason


EncodedInfo = ImageHeader
"""What an encoded image holds (kind, width, height, channels, bit depth), read from its header."""


def inspect_encoded(data: bytes | memoryview | NDArray[np.uint8]) -> EncodedInfo | None:
    """Header of a PNG or baseline/progressive JPEG; None if neither (or malformed).

    Reads only the header bytes of ``data`` (no copy of the image).
    """
    try:
        return parse_image_header(data)
    except ValueError:
        return None


def _rows(msg: Any, bpp: int, where: str) -> NDArray[np.uint8]:
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if h <= 0 or w <= 0:
        raise ImageDataError(where, f"image of {w}x{h} pixels; expected a positive size")
    if step < w * bpp or data.size < h * step:
        raise ImageDataError(where, f"image data holds {data.size} bytes, expected {h}x{step} "
                                    f"(height x step) for {w} pixels of {bpp} bytes per row")
    return data[: h * step].reshape(h, step)[:, : w * bpp]


def decode_color_image(msg: Any, where: str) -> NDArray[np.uint8]:
    """``sensor_msgs/Image`` (rgb8, bgr8, rgba8, bgra8, mono8) -> (H, W, 3) uint8 RGB."""
    enc = str(msg.encoding).lower()
    h, w = int(msg.height), int(msg.width)
    bpp = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1, "8uc3": 3, "8uc1": 1}.get(enc)
    if bpp is None:
        raise ConversionError(f"{where}: unknown colour image encoding {msg.encoding!r}; expected one of "
                              f"{', '.join(COLOR_ENCODINGS)}")
    px = _rows(msg, bpp, where).reshape(h, w, bpp)
    if enc in ("rgb8",):
        return px.copy()
    if enc in ("bgr8", "8uc3"):
        return px[:, :, ::-1].copy()
    if enc == "rgba8":
        return px[:, :, :3].copy()
    if enc == "bgra8":
        return px[:, :, 2::-1].copy()
    return np.repeat(px, 3, axis=2)


def depth_m_to_mm(depth_m: NDArray[np.floating[Any]]) -> NDArray[np.uint16]:
    """Float metres -> uint16 millimetres; NaN, inf, <= 0 and > 65.535 m become 0 (invalid)."""
    mm = np.asarray(depth_m, dtype=np.float64) * 1000.0
    ok = np.isfinite(mm) & (mm > 0) & (mm <= 65535.0)
    out = np.zeros(mm.shape, np.uint16)
    out[ok] = np.rint(mm[ok]).astype(np.uint16)
    return out


def _scale_to_mm(raw: NDArray[np.uint16], depth_scale_m: float) -> NDArray[np.uint16]:
    if abs(depth_scale_m - 0.001) < 1e-12:
        return raw
    return depth_m_to_mm(raw.astype(np.float64) * depth_scale_m)


def decode_depth_image(msg: Any, where: str, depth_scale_m: float = 0.001) -> NDArray[np.uint16]:
    """``sensor_msgs/Image`` (16UC1 / mono16 in units of ``depth_scale_m``, 32FC1 metres) -> uint16 mm."""
    enc = str(msg.encoding)
    h, w = int(msg.height), int(msg.width)
    big = bool(msg.is_bigendian)
    if enc.upper() in ("16UC1", "MONO16"):
        px = _rows(msg, 2, where).copy().view(">u2" if big else "<u2").reshape(h, w)
        return _scale_to_mm(px.astype(np.uint16), depth_scale_m)
    if enc.upper() == "32FC1":
        px = _rows(msg, 4, where).copy().view(">f4" if big else "<f4").reshape(h, w)
        return depth_m_to_mm(px)
    raise ConversionError(f"{where}: unknown depth image encoding {enc!r}; expected one of "
                          f"{', '.join(DEPTH_ENCODINGS)}")


def decode_compressed_color(data: Any, fmt: str, where: str) -> NDArray[np.uint8]:
    """``sensor_msgs/CompressedImage`` colour (JPEG or 8-bit PNG) -> (H, W, 3) uint8 RGB."""
    import cv2

    buf = np.frombuffer(memoryview(data), dtype=np.uint8)
    info = inspect_encoded(buf)
    if info is None:
        head = bytes(buf[:8])
        if head[:2] != b"\xff\xd8" and head != _PNG_MAGIC and not any(k in fmt.lower() for k in ("jpeg", "jpg", "png")):
            raise ConversionError(f"{where}: unknown compressed image format {fmt!r}: the data is neither JPEG nor "
                                  f"PNG (starts with {head[:4].hex()}); expected JPEG or PNG data")
        raise ImageDataError(where, f"corrupt image (format {fmt!r}): unreadable JPEG/PNG header")
    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageDataError(where, f"corrupt {info.kind.upper()}: OpenCV cannot decode it (format {fmt!r})")
    if img.dtype != np.uint8:
        raise ConversionError(f"{where}: colour {info.kind.upper()} is {img.dtype}; expected 8 bits per channel")
    if img.ndim == 2:
        return np.repeat(img[:, :, None], 3, axis=2)
    code = cv2.COLOR_BGRA2RGB if img.shape[2] == 4 else cv2.COLOR_BGR2RGB
    return np.asarray(cv2.cvtColor(img, code), dtype=np.uint8)


def compressed_depth_png(data: Any, fmt: str, where: str) -> tuple[memoryview, str, tuple[float, float]]:
    """Split a ``compressedDepth`` payload into (PNG bytes, source encoding, (quantA, quantB)).

    The payload is the 12-byte ConfigHeader followed by the PNG (older writers omit the header).
    The PNG comes back as a zero-copy view of ``data``.

    Raises:
        ConversionError: not PNG (e.g. ``compressedDepth rvl``) or too short.
    """
    raw = memoryview(data).cast("B")
    src_enc = fmt.split(";")[0].strip() or "16UC1"
    if "rvl" in fmt.lower():
        raise ConversionError(f"{where}: unknown compressedDepth format {fmt!r}; expected "
                              f"'16UC1; compressedDepth png' or '32FC1; compressedDepth png'")
    n = COMPRESSED_DEPTH_HEADER_SIZE
    if raw[:8] == _PNG_MAGIC:
        return raw, src_enc, (0.0, 0.0)
    if len(raw) > n and raw[n:n + 8] == _PNG_MAGIC:
        _, qa, qb = struct.unpack_from("<iff", raw, 0)
        return raw[n:], src_enc, (float(qa), float(qb))
    raise ImageDataError(where, f"compressedDepth payload ({len(raw)} bytes, format {fmt!r}) is not a PNG "
                                f"after the {n}-byte header; expected '16UC1; compressedDepth png'")


def decode_compressed_depth(data: Any, fmt: str, where: str, depth_scale_m: float = 0.001) -> NDArray[np.uint16]:
    """Depth ``CompressedImage`` (compressedDepth or plain 16-bit PNG) -> (H, W) uint16 millimetres.

    16UC1 payloads are in units of ``depth_scale_m``; 32FC1 ones hold quantised inverse depth
    (``depth_m = quantA / (v - quantB)``, v = 0 invalid).
    """
    import cv2

    if "compresseddepth" in fmt.lower():
        png, src_enc, (qa, qb) = compressed_depth_png(data, fmt, where)
    else:
        png, src_enc, qa, qb = memoryview(data).cast("B"), "16UC1", 0.0, 0.0
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageDataError(where, f"corrupt PNG: OpenCV cannot decode it (format {fmt!r})")
    if img.dtype != np.uint16 or img.ndim != 2:
        raise ConversionError(f"{where}: depth PNG is {img.dtype} with shape {img.shape}; expected single-channel "
                              f"16-bit (format {fmt!r})")
    if src_enc.upper() == "32FC1":
        v = img.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.where(img > 0, qa / (v - qb), 0.0)
        return depth_m_to_mm(d)
    return _scale_to_mm(np.asarray(img, dtype=np.uint16), depth_scale_m)


def make_compressed_depth(png_16u: bytes) -> bytes:
    """``compressedDepth`` payload of a 16UC1 PNG: zeroed ConfigHeader then the PNG bytes."""
    return struct.pack("<iff", 0, 0.0, 0.0) + bytes(png_16u)
