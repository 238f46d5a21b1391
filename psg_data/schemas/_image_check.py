"""Integrity of encoded PNG and JPEG images, on bytes: one module for the converter and the validator.

Levels (``image_check`` of a conversion; ``psg-data validate`` runs ``decode``):

* ``structure`` (the converter's default): PNG signature, IHDR, every chunk's length and CRC-32, an
  IDAT run with a valid zlib header, IEND; JPEG segments from SOI to the first scan (lengths, a
  frame header first) and the EOI marker at the end. Catches truncation and any flipped byte of a
  PNG, and truncation and damaged headers of a JPEG, at a fraction of the cost of decoding
  (BENCHMARKS.md).
* ``full``: ``structure`` plus PNG data inflated to the end of the zlib stream (Adler-32 checked by
  zlib) and sized to the image, and every JPEG marker through EOI (entropy-coded data free of
  stray markers) and the JPEG decoded. A flipped byte inside JPEG entropy-coded data changes
  pixels but no checksum: a decoder may still accept it, so no check catches every such flip.
* ``none``: nothing checked.

``decode_check`` is what the validator adds: the image is decoded strictly and its size, channels
and bit depth are compared with what the dataset says. A JPEG is decoded by libjpeg-turbo through
``simplejpeg`` in strict mode (libjpeg-turbo's stop-on-warning: "Corrupt JPEG data: premature end
of data segment" and every other recoverable error is a damaged image, where OpenCV would fill the
rest with grey and return it). A PNG is inflated here (zlib stream to its end with its Adler-32,
data size, every row's filter type); for a plain PNG (8 or 16 bits, not interlaced, no palette,
no critical chunk but IHDR, IDAT, IEND: what psg-data writes) that is the whole decode, since
unfiltering such data cannot fail and IHDR says the size and sample format; any other PNG is then
also decoded by OpenCV. Neither prints to the process's stderr: libjpeg-turbo reports to
simplejpeg, which raises, and libpng, which prints its own errors to file descriptor 2, is only
handed streams that already passed every check it would fail (see docs/FORMAT.md for the one
limit: libpng warnings about ancillary chunks of such other PNGs). Redirecting descriptor 2
around a decode would capture every other thread's output too, so it is not done.

A quantisation table with a zero entry (T.81 B.2.4.1 allows 1..255 / 1..65535) is refused at
``structure``: a decoder multiplies every coefficient by it and silently returns a flat image.
"""

from __future__ import annotations

import struct
import zlib
from typing import Any

import numpy as np

from psg_data.schemas._image_headers import ImageHeader, inflate_bounded, parse_image_header, pixels_problem

__all__ = ["IMAGE_CHECK_LEVELS", "DamagedImage", "check_image", "check_png", "check_jpeg", "decode_check",
           "verify_image",
           "PNG_SIGNATURE", "looks_like_image"]

IMAGE_CHECK_LEVELS = ("none", "structure", "full")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_CHUNK = struct.Struct(">I4s")
_U32 = struct.Struct(">I")
_IHDR = struct.Struct(">IIBBBBB")
_PNG_BITS = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8), 4: (8, 16), 6: (8, 16)}
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_NO_LENGTH = frozenset([0x01, 0xD8, *range(0xD0, 0xD8)])
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


class DamagedImage(ValueError):
    """An encoded image is truncated or damaged; the message says where in it and what is wrong."""


def looks_like_image(data: Any) -> str | None:
    """``png`` or ``jpeg`` when ``data`` starts with that format's signature, else None."""
    head = bytes(memoryview(data)[:8])
    if head == PNG_SIGNATURE:
        return "png"
    if head[:2] == b"\xff\xd8":
        return "jpeg"
    return None


def check_png(data: Any, *, inflate: bool = False) -> bool:
    """Check a PNG's chunk structure and CRCs (and with ``inflate`` its zlib stream, data size and
    row filter types).

    Returns:
        Whether the PNG is plain: not interlaced, not a palette image, and no critical chunk but
        IHDR, IDAT and IEND (its IHDR then says everything a decoder returns; see :func:`decode_check`).

    Raises:
        DamagedImage: what is wrong and at which byte.
    """
    mv = data if type(data) is memoryview and data.format == "B" else memoryview(data).cast("B")
    n = len(mv)
    if mv[:8] != PNG_SIGNATURE:
        raise DamagedImage("not a PNG (bad signature)")
    crc32, unpack, u32 = zlib.crc32, _CHUNK.unpack_from, _U32.unpack_from
    parts: list[tuple[int, int]] = []  # (start, end) of each IDAT chunk's data
    run = 0  # IDAT run: 0 not started, 1 in it, 2 over
    o, ihdr = 8, None
    other_critical = False
    while True:
        if o + 12 > n:
            raise DamagedImage(f"truncated: no IEND chunk ({n} bytes)" if o >= n else
                               f"truncated: chunk header at byte {o} runs past the end ({n} bytes)")
        length, ctype = unpack(mv, o)
        end = o + 8 + length
        if length > 0x7FFFFFFF or end + 4 > n:
            raise DamagedImage(f"truncated: chunk {ctype!r} at byte {o} ({length} bytes) runs past the end ({n} bytes)")
        if (crc32(mv[o + 4:end]) if length < _CRC_PIECE else _crc(mv, o + 4, end)) != u32(mv, end)[0]:
            raise DamagedImage(f"chunk {ctype.decode('latin-1')!r} at byte {o}: CRC mismatch (damaged data)")
        if ctype == b"IDAT":
            if run == 2 or ihdr is None:
                raise DamagedImage(f"IDAT chunk at byte {o} " + ("after the image data ended" if run == 2 else
                                                                  "before IHDR"))
            run = 1
            parts.append((o + 8, end))
        elif ihdr is None:
            if ctype != b"IHDR" or length != 13:
                raise DamagedImage("first chunk is not a 13-byte IHDR")
            ihdr = _IHDR.unpack_from(mv, o + 8)
            w, h, bits, color, comp, filt, lace = ihdr
            if not w or not h or bits not in _PNG_BITS.get(color, ()) or comp or filt or lace > 1:
                raise DamagedImage(f"IHDR: invalid image description {ihdr}")
        elif ctype == b"IEND":
            break
        else:
            if not ctype[0] & 0x20:  # critical: a decoder must refuse one it does not know
                if ctype != b"PLTE":
                    raise DamagedImage(f"unknown critical chunk {ctype.decode('latin-1')!r} at byte {o}")
                other_critical = True
            if run == 1:
                run = 2
        o = end + 4
    if not parts:
        raise DamagedImage("no IDAT chunk (no image data)")
    a0, b0 = parts[0]
    head = mv[a0:a0 + 2] if b0 - a0 >= 2 else b"".join(mv[a:b] for a, b in parts[:2])[:2]
    if len(head) < 2 or head[0] & 0x0F != 8 or (head[0] << 8 | head[1]) % 31 or head[1] & 0x20:
        raise DamagedImage("image data does not start with a zlib header")
    if inflate:
        _inflate_png([mv[a:b] for a, b in parts], ihdr)
    return not (other_critical or ihdr[3] == 3 or ihdr[6])


_CRC_PIECE = 4096
"""CRCs are computed in pieces this small: ``zlib.crc32`` releases the GIL for buffers above 5 KiB, and
getting it back behind the converter's I/O threads costs more than the CRC (measured in bench_convert)."""


def _crc(mv: memoryview, a: int, b: int) -> int:
    crc, crc32, step = 0, zlib.crc32, _CRC_PIECE
    for k in range(a, b, step):
        crc = crc32(mv[k:min(k + step, b)], crc)
    return crc


_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))
"""Adam7 passes: first column, first row, column step, row step."""


def _png_data_size(w: int, h: int, bits: int, ctype: int, lace: int) -> tuple[int, int]:
    """(bytes the image data inflates to, row length of a non-interlaced image) from IHDR."""
    bpp = _PNG_CHANNELS[ctype] * bits
    row = 1 + (w * bpp + 7) // 8
    if not lace:
        return h * row, row
    size = 0
    for x0, y0, dx, dy in _ADAM7:
        pw, ph = (w - x0 + dx - 1) // dx, (h - y0 + dy - 1) // dy
        if pw > 0 and ph > 0:
            size += ph * (1 + (pw * bpp + 7) // 8)
    return size, row


def _inflate_png(parts: list[memoryview], ihdr: tuple[int, ...]) -> None:
    w, h, bits, ctype, _, _, lace = ihdr
    too_big = pixels_problem(w, h)
    if too_big:
        raise DamagedImage(f"IHDR: {too_big}; not inflated")
    expect, row = _png_data_size(w, h, bits, ctype, lace)
    try:
        data = inflate_bounded(parts, expect)
    except ValueError as exc:
        raise DamagedImage(f"image data: {exc} for {w}x{h}") from None
    if not lace:
        filters = np.frombuffer(data, np.uint8)[::row]
        bad = np.flatnonzero(filters > 4)
        if bad.size:
            raise DamagedImage(f"image data: row {int(bad[0])} has filter type {int(filters[bad[0]])}, expected 0-4")


def check_jpeg(data: Any, *, scan: bool = False) -> None:
    """Check a JPEG: its segments from SOI to the first scan (lengths, a frame header first) and EOI at
    the end (only padding after it); with ``scan`` every marker through EOI (entropy-coded data free
    of stray markers, the segments between the scans of a progressive JPEG).

    Raises:
        DamagedImage: what is wrong and at which byte.
    """
    mv = data if type(data) is memoryview and data.format == "B" else memoryview(data).cast("B")
    n = len(mv)
    if n < 4 or mv[0] != 0xFF or mv[1] != 0xD8:
        raise DamagedImage("not a JPEG (no SOI marker)")
    global _VERIFIED
    o = 0
    for h in _VERIFIED:  # a header seen before is valid: a camera's frames share theirs
        if n > len(h) and mv[:len(h)] == h:
            o = len(h)
            break
    if not o or scan:
        st = _Jpeg()
        o = _segments(mv, 2, st)
        if o < 0:  # EOI before any scan
            raise DamagedImage("EOI before any frame header and scan")
        _VERIFIED = (bytes(mv[:o]), *_VERIFIED[:_VERIFIED_MAX - 1])
    if mv[n - 2:] != b"\xff\xd9":  # EOI at the very end, else only padding after it
        tail = bytes(mv[max(o, n - _TAIL):])
        k = tail.rfind(b"\xff\xd9")
        if k < 0 or tail[k + 2:].strip(b"\x00\xff"):
            raise DamagedImage(f"truncated: does not end with an EOI marker ({n} bytes)")
    if scan:
        arr = np.frombuffer(mv, np.uint8)
        while o >= 0:
            o = _end_of_scan(arr, o)
            if o < 0:
                raise DamagedImage(f"truncated: scan data runs to the end without an EOI marker ({n} bytes)")
            o = _segments(mv, o, st)


_VERIFIED: tuple[bytes, ...] = ()
"""Headers (SOI to the end of the first scan header) of the JPEGs checked last, newest first."""
_VERIFIED_MAX = 8
_TAIL = 1024
"""Bytes at the end of a JPEG searched for its EOI marker (padding may follow it)."""


class _Jpeg:
    """What the segments of a JPEG defined so far (checked as libjpeg would before decoding)."""

    __slots__ = ("components", "sof", "quant", "huff")

    def __init__(self) -> None:
        self.components: dict[int, int] = {}
        """component id -> quantisation table id (from the frame header)."""
        self.sof = -1
        self.quant: set[int] = set()
        self.huff: set[tuple[int, int]] = set()


def _segments(mv: memoryview, o: int, st: _Jpeg) -> int:
    """Walk marker segments from ``o`` to just past the next SOS header (-1: EOI reached first)."""
    n = len(mv)
    while True:
        if o + 2 > n:
            raise DamagedImage(f"truncated: no EOI marker ({n} bytes)")
        if mv[o] != 0xFF:
            raise DamagedImage(f"expected a marker at byte {o}, found 0x{mv[o]:02x}")
        m = mv[o + 1]
        if m == 0xFF:  # fill byte
            o += 1
            continue
        if m == 0xD9:
            if st.sof >= 0 and o + 2 != n and bytes(mv[o + 2:]).strip(b"\x00\xff"):
                raise DamagedImage(f"EOI at byte {o} followed by {n - o - 2} bytes of data")
            return -1
        if m in _NO_LENGTH:
            o += 2
            continue
        if m < 0xC0:  # 0x02-0xbf are reserved, 0x00 is stuffing: no segment starts with them
            raise DamagedImage(f"invalid marker 0xff{m:02x} at byte {o}")
        if o + 4 > n:
            raise DamagedImage(f"truncated: segment header at byte {o} runs past the end ({n} bytes)")
        seglen = mv[o + 2] << 8 | mv[o + 3]
        if seglen < 2 or o + 2 + seglen > n:
            raise DamagedImage(f"truncated: segment 0x{m:02x} at byte {o} ({seglen} bytes) runs past the end")
        body = bytes(mv[o + 4:o + 2 + seglen])
        check = _SEGMENT_CHECKS.get(m)
        if check is not None:
            why = check(body, st, m)
            if why:
                raise DamagedImage(f"segment 0x{m:02x} at byte {o}: {why}")
        elif m in _SOF:
            why = _sof(body, st, m)
            if why:
                raise DamagedImage(f"frame header at byte {o}: {why}")
        o += 2 + seglen
        if m == 0xDA:
            return o


def _sof(b: bytes, st: _Jpeg, m: int) -> str | None:
    if st.sof >= 0:
        return "a second frame header"
    if len(b) < 6 or len(b) != 6 + 3 * b[5]:
        return f"{len(b)} bytes, expected 6 + 3 per component"
    bits, height, width, nc = b[0], b[1] << 8 | b[2], b[3] << 8 | b[4], b[5]
    if bits not in (8, 12, 16) or not width or not height or not 1 <= nc <= 4:
        return f"{bits}-bit {width}x{height} with {nc} components"
    for k in range(nc):
        cid, hv, tq = b[6 + 3 * k:9 + 3 * k]
        if not (1 <= hv >> 4 <= 4 and 1 <= hv & 15 <= 4) or tq > 3:
            return f"component {cid}: sampling {hv >> 4}x{hv & 15}, quantisation table {tq}"
        st.components[cid] = tq
    st.sof = m
    return None


def _dht(b: bytes, st: _Jpeg, _m: int) -> str | None:
    o = 0
    while o < len(b):
        if o + 17 > len(b):
            return "Huffman table runs past the segment"
        cls, tid = b[o] >> 4, b[o] & 15
        counts = b[o + 1:o + 17]
        total = sum(counts)
        if cls > 1 or tid > 3 or total > 256 or o + 17 + total > len(b):
            return f"Huffman table class {cls} id {tid} with {total} codes"
        code, si = 0, 0
        for si, c in enumerate(counts, start=1):  # canonical codes: never the all-ones code of a length
            code += c
            if code >= (1 << si) and c:
                return f"Huffman table {cls}/{tid}: {c} codes of length {si} do not fit"
            code <<= 1
        if cls == 0 and any(v > 15 for v in b[o + 17:o + 17 + total]):
            return f"DC Huffman table {tid}: symbol above 15"
        st.huff.add((cls, tid))
        o += 17 + total
    return None


def _dqt(b: bytes, st: _Jpeg, _m: int) -> str | None:
    o = 0
    while o < len(b):
        prec, tid = b[o] >> 4, b[o] & 15
        size = 1 + 64 * (prec + 1)
        if prec > 1 or tid > 3 or o + size > len(b):
            return f"quantisation table precision {prec} id {tid} does not fit the segment"
        q = b[o + 1:o + size]
        if 0 in (q if not prec else bytes(q[k] | q[k + 1] for k in range(0, 128, 2))):
            return f"quantisation table {tid} has a zero entry (expected 1 and more: a zero erases the image)"
        st.quant.add(tid)
        o += size
    return None


def _sos(b: bytes, st: _Jpeg, _m: int) -> str | None:
    if st.sof < 0:
        return "scan before any frame header"
    ns = b[0] if b else 0
    if not 1 <= ns <= 4 or len(b) != 4 + 2 * ns:
        return f"{len(b)} bytes for {ns} components"
    missing_q = sorted({tq for tq in st.components.values()} - st.quant)
    if missing_q:
        return f"quantisation table {missing_q[0]} used but not defined"
    for k in range(ns):
        cid, tt = b[1 + 2 * k], b[2 + 2 * k]
        if cid not in st.components or tt >> 4 > 3 or tt & 15 > 3:
            return f"component {cid} (tables {tt >> 4}/{tt & 15}) is not one of the frame's"
    ss, se, a = b[1 + 2 * ns], b[2 + 2 * ns], b[3 + 2 * ns]
    if st.sof in (0xC0, 0xC1) and (ss, se, a) != (0, 63, 0):
        return f"spectral selection {ss}-{se}, approximation {a:#04x} in a sequential JPEG"
    return None


def _dri(b: bytes, _st: _Jpeg, _m: int) -> str | None:
    return None if len(b) == 2 else f"{len(b) + 2} bytes, expected 4"


_SEGMENT_CHECKS = {0xC4: _dht, 0xDB: _dqt, 0xDA: _sos, 0xDD: _dri}


def _end_of_scan(arr: np.ndarray, start: int) -> int:
    """Offset of the first marker after entropy-coded data starting at ``start`` (-1 if none)."""
    n = arr.size
    pos = start
    step = 1 << 16
    while pos < n - 1:
        seg = arr[pos:min(n, pos + step + 1)]
        ff = np.flatnonzero(seg[:-1] == 0xFF)
        if ff.size:
            nxt = seg[ff + 1]
            hit = ff[(nxt != 0) & ((nxt < 0xD0) | (nxt > 0xD7))]
            if hit.size:
                return pos + int(hit[0])
        pos += step
    return -1


def check_image(data: Any, level: str = "structure", kind: str | None = None,
                header: ImageHeader | None = None) -> ImageHeader:
    """Header of an encoded PNG or JPEG, checked at ``level`` (see the module docstring).

    Args:
        data: the encoded image (any bytes-like object).
        level: ``none``, ``structure`` or ``full``.
        kind: ``png`` or ``jpeg`` if known (else from the signature).
        header: the image's header if already parsed.

    Raises:
        DamagedImage: damaged or truncated (or neither a PNG nor a JPEG).
    """
    hdr = header
    if hdr is None:
        try:
            hdr = parse_image_header(data)
        except ValueError as exc:
            raise DamagedImage(f"unreadable header ({exc})") from None
    if kind is not None and hdr.kind != kind:
        raise DamagedImage(f"is a {hdr.kind.upper()}, expected a {kind.upper()}")
    if level == "none":
        return hdr
    if hdr.kind == "png":
        check_png(data, inflate=level == "full")
    else:
        check_jpeg(data, scan=level == "full")
        if level == "full":
            decode_check(data, hdr)
    return hdr


def verify_image(data: Any, header: ImageHeader) -> None:
    """What ``psg-data validate`` checks of a stored image: ``structure`` and a strict decode that
    agrees with the header (see :func:`decode_check`; a dataset ``convert`` wrote validates).

    Raises:
        DamagedImage: what is wrong.
    """
    check_image(data, "structure", header=header)
    decode_check(data, header)


def decode_check(data: Any, expect: ImageHeader) -> None:
    """Decode strictly and compare with ``expect`` (size, channels, 8 or 16 bits): a JPEG by
    libjpeg-turbo with warnings as errors, a PNG inflated and checked here, then by OpenCV (see the
    module docstring). Nothing is printed to stderr.

    Raises:
        DamagedImage: the decoder reports an error or a warning, or the image decodes to another
            size or sample format.
    """
    img: np.ndarray | None
    if expect.kind == "jpeg":
        img = _decode_jpeg_strict(data, expect)
    else:
        if check_png(data, inflate=True) and expect.bit_depth in (8, 16):
            return  # a plain PNG whose data inflates whole with valid filters decodes to what IHDR says
        import cv2

        img = cv2.imdecode(np.frombuffer(memoryview(data).cast("B"), np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DamagedImage(f"OpenCV cannot decode this {expect.kind.upper()}")
    h, w = img.shape[:2]
    ch = 1 if img.ndim == 2 else img.shape[2]
    bits = 16 if img.dtype == np.uint16 else 8
    want_bits = 16 if expect.bit_depth == 16 else 8
    if (w, h) != (expect.width, expect.height) or bits != want_bits or (expect.channels in (1, 3, 4) and
                                                                        ch != expect.channels):
        raise DamagedImage(f"decodes to {w}x{h} with {ch} channel(s) of {bits} bits, its header says "
                           f"{expect.width}x{expect.height} with {expect.channels} of {expect.bit_depth}")


_JPEG_COLORSPACE = {1: "GRAY", 3: "BGR", 4: "CMYK"}


def _decode_jpeg_strict(data: Any, expect: ImageHeader) -> np.ndarray:
    """The JPEG decoded by libjpeg-turbo (``simplejpeg``, strict: a recoverable error is an error).

    Raises:
        DamagedImage: libjpeg-turbo's own message ("Corrupt JPEG data: ...", "Premature end of JPEG file").
    """
    import simplejpeg

    space = _JPEG_COLORSPACE.get(expect.channels)
    if space is None:
        raise DamagedImage(f"a JPEG with {expect.channels} components; expected 1, 3 or 4")
    try:
        img = simplejpeg.decode_jpeg(bytes(memoryview(data).cast("B")), colorspace=space, strict=True)
    except ValueError as exc:
        raise DamagedImage(f"libjpeg-turbo: {_one_line(exc)}") from None
    return img[:, :, 0] if space == "GRAY" and img.ndim == 3 else img


def _one_line(exc: object) -> str:
    """A decoder's message on one line."""
    return " ".join(str(exc).split())
