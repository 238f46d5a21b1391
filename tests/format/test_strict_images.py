"""Images that cannot fool ``validate`` (issue 28, D6 and the codec-stderr minor).

The default validate decodes every JPEG with libjpeg-turbo's warnings as errors and inflates every
PNG before OpenCV sees it; nothing a codec prints reaches the process's stderr (file descriptor 2,
captured here with ``capfd``).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.schemas._image_check import DamagedImage, verify_image
from psg_data.schemas._image_headers import parse_image_header
from tests.convert.test_hostile_values import _scannet


def _smooth(h: int = 120, w: int = 160) -> np.ndarray:
    rng = np.random.default_rng(1)
    return cv2.GaussianBlur((rng.random((h, w, 3)) * 255).astype(np.uint8), (9, 9), 3)


def _jpeg() -> bytes:
    return cv2.imencode(".jpg", _smooth(), [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()


def _eoi_pairs(data: bytes) -> bytes:
    """64 bytes of the entropy-coded data replaced by FF D9 pairs (the reported damage)."""
    b = bytearray(data)
    sos = b.find(b"\xff\xda")
    start = sos + 2 + (b[sos + 2] << 8 | b[sos + 3])
    m = (start + len(b) - 2 - 64) // 2
    assert m >= start
    b[m:m + 64] = b"\xff\xd9" * 32
    return bytes(b)


def _zero_quant(data: bytes) -> bytes:
    b = bytearray(data)
    i = b.find(b"\xff\xdb")
    b[i + 5:i + 5 + 64] = bytes(64)
    return bytes(b)


def _png_chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    out, o = [], 8
    while o < len(data):
        n, t = struct.unpack_from(">I4s", data, o)
        out.append((t, data[o + 8:o + 8 + n]))
        o += 12 + n
    return out


def _png(chunks: list[tuple[bytes, bytes]]) -> bytes:
    body = b"".join(struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d)) for t, d in chunks)
    return b"\x89PNG\r\n\x1a\n" + body


def _png_with(raw_edit: object = None, stream_edit: object = None) -> bytes:
    """A PNG whose inflated rows or zlib stream are edited, every CRC recomputed (so only decoding finds it)."""
    chunks = _png_chunks(cv2.imencode(".png", _smooth())[1].tobytes())
    idat = b"".join(d for t, d in chunks if t == b"IDAT")
    if raw_edit is not None:
        raw = bytearray(zlib.decompress(idat))
        raw_edit(raw)  # type: ignore[operator]
        idat = zlib.compress(bytes(raw))
    if stream_edit is not None:
        idat = stream_edit(bytearray(idat))  # type: ignore[operator]
    rest = [c for c in chunks if c[0] != b"IDAT"]
    return _png([rest[0], (b"IDAT", bytes(idat)), *rest[1:]])


def _bad_filter(raw: bytearray) -> None:
    raw[(len(raw) // 120) * 60] = 7  # row 60's filter type


def _bad_stream(s: bytearray) -> bytes:
    s[10:40] = bytes(range(200, 230))
    return bytes(s)


def _unknown_critical() -> bytes:
    chunks = _png_chunks(cv2.imencode(".png", _smooth())[1].tobytes())
    return _png([chunks[0], (b"ABCD", b"xyz"), *chunks[1:]])


CASES = {
    "png: unknown critical chunk": (_unknown_critical(), "unknown critical chunk 'ABCD'"),
    "jpeg: FF D9 pairs in the entropy-coded data": (_eoi_pairs(_jpeg()), "Corrupt JPEG data"),
    "jpeg: zeroed quantisation table": (_zero_quant(_jpeg()), "quantisation table 0 has a zero entry"),
    "png: row filter type 7 (CRCs valid)": (_png_with(raw_edit=_bad_filter), "row 60 has filter type 7"),
    "png: damaged zlib stream (CRCs valid)": (_png_with(stream_edit=_bad_stream), "zlib stream"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_verify_image_refuses_and_prints_nothing(name: str, capfd: pytest.CaptureFixture[str]) -> None:
    data, match = CASES[name]
    hdr = parse_image_header(data)
    with pytest.raises(DamagedImage, match=match):
        verify_image(data, hdr)
    assert capfd.readouterr().err == ""


def test_good_images_pass() -> None:
    for data in (_jpeg(), cv2.imencode(".jpg", _smooth()[:, :, 0])[1].tobytes(),
                 cv2.imencode(".png", _smooth())[1].tobytes(),
                 cv2.imencode(".png", (_smooth()[:, :, 0].astype(np.uint16) * 200))[1].tobytes()):
        verify_image(data, parse_image_header(data))


@pytest.mark.damaged_passthrough
def test_damaged_passthrough_jpeg_fails_validate(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """The reported case: a ScanNet colour JPEG with damaged entropy-coded data converts (the default
    ``structure`` check does not decode a passed-through JPEG), and validate now refuses it."""
    d = _scannet(tmp_path / "scene0000_00")
    f = d / "color" / "1.jpg"
    f.write_bytes(_eoi_pairs(f.read_bytes()))
    out = tmp_path / "out"
    r = CliRunner().invoke(psg_data, ["convert", str(d), str(out), "--quiet", "--image-layout", "files"])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(psg_data, ["validate", str(out)])
    assert r.exit_code == 1
    assert "Corrupt JPEG data: premature end of data segment" in r.output
    cap = capfd.readouterr()
    assert "Corrupt JPEG" not in cap.err and "libpng" not in cap.err


def test_zeroed_quantisation_table_is_caught_at_convert(tmp_path: Path) -> None:
    d = _scannet(tmp_path / "scene0000_00")
    f = d / "color" / "1.jpg"
    f.write_bytes(_zero_quant(f.read_bytes()))
    r = CliRunner().invoke(psg_data, ["convert", str(d), str(tmp_path / "out"), "--quiet", "--strict"])
    assert r.exit_code == 1 and "zero entry" in r.stderr, r.output
