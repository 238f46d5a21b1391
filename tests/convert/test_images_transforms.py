"""Image decoding (incl. the known 16-bit / compressedDepth traps) and transform maths."""

from __future__ import annotations

import struct
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from psg_data.errors import ConversionError
from psg_data.loaders.raw import (
    TfBuffer,
    decode_color_image,
    decode_compressed_color,
    decode_compressed_depth,
    decode_depth_image,
    inspect_encoded,
    make_compressed_depth,
    make_transform,
    matrix_to_quat_xyzw,
)

RNG = np.random.default_rng(0)
RGB = RNG.integers(0, 256, (5, 7, 3), dtype=np.uint8)
DEPTH = RNG.integers(0, 65536, (5, 7)).astype(np.uint16)


def msg(arr: np.ndarray, encoding: str, pad: int = 0, big: bool = False) -> SimpleNamespace:
    h = arr.shape[0]
    rows = np.ascontiguousarray(arr).view(np.uint8).reshape(h, -1)
    if pad:
        rows = np.concatenate([rows, np.full((h, pad), 77, np.uint8)], axis=1)
    data = rows.reshape(-1).copy()
    data.flags.writeable = False  # as rosbags gives it: a read-only view of the bag buffer
    return SimpleNamespace(height=h, width=arr.shape[1], encoding=encoding, step=rows.shape[1],
                           is_bigendian=int(big), data=data)


@pytest.mark.parametrize("enc,make", [
    ("rgb8", lambda c: c), ("bgr8", lambda c: c[:, :, ::-1]),
    ("rgba8", lambda c: np.dstack([c, np.full(c.shape[:2], 9, np.uint8)])),
    ("bgra8", lambda c: np.dstack([c[:, :, ::-1], np.full(c.shape[:2], 9, np.uint8)])),
])
@pytest.mark.parametrize("pad", [0, 3])
def test_color_encodings(enc: str, make, pad: int) -> None:  # type: ignore[no-untyped-def]
    out = decode_color_image(msg(make(RGB), enc, pad), "t")
    assert out.dtype == np.uint8 and np.array_equal(out, RGB)
    out[0, 0] = 1  # writable copy, not a view of the read-only bag buffer


def test_mono8() -> None:
    g = RGB[:, :, 0]
    assert np.array_equal(decode_color_image(msg(g, "mono8"), "t"), np.dstack([g, g, g]))


@pytest.mark.parametrize("big", [False, True])
def test_depth_16uc1_and_32fc1(big: bool) -> None:
    d = DEPTH.astype(">u2" if big else "<u2")
    out = decode_depth_image(msg(d, "16UC1", pad=2, big=big), "t")
    assert np.array_equal(out, DEPTH)
    out[0, 0] = 0
    m = (DEPTH.astype(np.float32) / 1000.0)
    m[0, 0], m[0, 1], m[0, 2] = np.nan, np.inf, -1.0
    out = decode_depth_image(msg(m.astype(">f4" if big else "<f4"), "32FC1", big=big), "t")
    exp = np.rint(DEPTH.astype(np.float64)).astype(np.uint16)
    exp[0, :3] = 0
    assert np.array_equal(out, exp)


def test_depth_scale_applied_to_16uc1() -> None:
    raw = np.array([[0, 5000, 12345]], np.uint16)  # TUM units: 1/5000 m
    assert decode_depth_image(msg(raw, "16UC1"), "t", depth_scale_m=0.0002).tolist() == [[0, 1000, 2469]]


def test_unknown_encodings_are_errors() -> None:
    with pytest.raises(ConversionError, match="t: unknown colour image encoding 'yuv422'"):
        decode_color_image(msg(RGB[:, :, :2].copy(), "yuv422"), "t")
    with pytest.raises(ConversionError, match="unknown depth image encoding '8UC1'"):
        decode_depth_image(msg(RGB[:, :, 0].copy(), "8UC1"), "t")
    with pytest.raises(ConversionError, match="compressedDepth rvl"):
        decode_compressed_depth(b"\0" * 40, "16UC1; compressedDepth rvl", "t")


def test_compressed_depth_trap_16bit_png() -> None:
    png = cv2.imencode(".png", DEPTH)[1].tobytes()
    payload = make_compressed_depth(png)
    # the trap: a default (8-bit) decode of this PNG silently loses the depth
    lossy = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert lossy.dtype == np.uint8
    # and the 12-byte header makes the payload undecodable as a plain PNG
    assert cv2.imdecode(np.frombuffer(payload, np.uint8), cv2.IMREAD_UNCHANGED) is None
    ro = np.frombuffer(payload, np.uint8)  # read-only buffer
    assert np.array_equal(decode_compressed_depth(ro, "16UC1; compressedDepth png", "t"), DEPTH)
    assert np.array_equal(decode_compressed_depth(png, "png", "t"), DEPTH)  # plain 16-bit PNG CompressedImage
    info = inspect_encoded(png)
    assert info is not None and (info.kind, info.width, info.height, info.bit_depth, info.channels) == \
        ("png", 7, 5, 16, 1)


def test_compressed_depth_32fc1_inverse_quantisation() -> None:
    depth_m = np.array([[0.5, 1.0, 2.0, 0.0]])
    qa, qb = 100.0, -10.0  # depth = qa / (v - qb)
    v = np.where(depth_m > 0, qa / np.where(depth_m > 0, depth_m, 1) + qb, 0).astype(np.uint16)
    payload = struct.pack("<iff", 0, qa, qb) + cv2.imencode(".png", v)[1].tobytes()
    out = decode_compressed_depth(payload, "32FC1; compressedDepth png", "t")
    assert out.tolist() == [[500, 1000, 2000, 0]]


def test_8bit_depth_png_rejected() -> None:
    png = cv2.imencode(".png", RGB[:, :, 0])[1].tobytes()
    with pytest.raises(ConversionError, match="expected single-channel 16-bit"):
        decode_compressed_depth(make_compressed_depth(png), "16UC1; compressedDepth png", "t")


def test_compressed_color_jpeg_and_png() -> None:
    jpg = cv2.imencode(".jpg", cv2.cvtColor(RGB, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 100])[1].tobytes()
    info = inspect_encoded(jpg)
    assert info is not None and (info.kind, info.width, info.height, info.channels) == ("jpeg", 7, 5, 3)
    out = decode_compressed_color(np.frombuffer(jpg, np.uint8), "jpeg", "t")
    ref = cv2.cvtColor(cv2.imdecode(np.frombuffer(jpg, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert np.array_equal(out, ref)
    assert np.corrcoef(out.reshape(-1).astype(float), RGB.reshape(-1).astype(float))[0, 1] > 0.5  # RGB order kept
    png = cv2.imencode(".png", cv2.cvtColor(RGB, cv2.COLOR_RGB2BGR))[1].tobytes()
    assert np.array_equal(decode_compressed_color(png, "png", "t"), RGB)
    with pytest.raises(ConversionError, match="unknown compressed image format"):
        decode_compressed_color(b"GIF89a....", "gif", "t")


quats = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1)


@settings(max_examples=60, deadline=None)
@given(quats)
def test_quaternion_matrix_roundtrip(q: list[float]) -> None:
    q = np.array(q) / np.linalg.norm(q)
    R = make_transform([0, 0, 0], q)[:3, :3]
    np.testing.assert_allclose(R, Rotation.from_quat(q).as_matrix(), atol=1e-12)
    q2 = matrix_to_quat_xyzw(R)
    np.testing.assert_allclose(abs(np.dot(q, q2)), 1.0, atol=1e-9)


def test_tf_tree_composition_and_no_path() -> None:
    tf = TfBuffer(max_gap_ns=100, tolerance_ns=0)
    A = make_transform([1, 2, 3], Rotation.from_euler("xyz", [0.1, 0.2, 0.3]).as_quat())
    B0 = make_transform([0, 0, 0], [0, 0, 0, 1])
    B1 = make_transform([1, 0, 0], Rotation.from_euler("z", 0.4).as_quat())
    C = make_transform([0, 0.5, 0], Rotation.from_euler("y", -0.7).as_quat())
    tf.add("/map", "odom", 0, A[:3, 3], matrix_to_quat_xyzw(A[:3, :3]), static=True)
    for t, B in ((0, B0), (100, B1)):
        tf.add("odom", "base", t, B[:3, 3], matrix_to_quat_xyzw(B[:3, :3]), static=False)
    tf.add("base", "cam", 0, C[:3, 3], matrix_to_quat_xyzw(C[:3, :3]), static=True)
    np.testing.assert_allclose(tf.lookup("map", "cam", 100), A @ B1 @ C, atol=1e-12)
    np.testing.assert_allclose(tf.lookup("cam", "map", 0), np.linalg.inv(A @ B0 @ C), atol=1e-12)
    mid = tf.lookup("map", "cam", 50)
    Bm = make_transform([0.5, 0, 0], Rotation.from_euler("z", 0.2).as_quat())
    np.testing.assert_allclose(mid, A @ Bm @ C, atol=1e-12)
    assert tf.lookup("map", "cam", 250) is None  # beyond the last sample
    with pytest.raises(ConversionError, match="no path from 'map' to 'elsewhere'"):
        tf.lookup("map", "elsewhere", 0, "bag")


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.booleans(), quats, quats,
                          st.lists(st.floats(-5, 5), min_size=3, max_size=3)), min_size=1, max_size=5),
       st.floats(0, 1))
def test_tf_lookup_equals_brute_force_chain(edges: list, a: float) -> None:  # type: ignore[type-arg]
    """A chain f0 - f1 - ... of static/dynamic edges stored in either direction, looked up at a time
    between the two samples of every dynamic edge, against composing scipy-slerped matrices."""
    from scipy.spatial.transform import Slerp

    tf = TfBuffer(max_gap_ns=1000, tolerance_ns=0)
    expected = np.eye(4)
    t_query = int(round(a * 1000))
    for k, (static, stored_forward, q0, q1, t) in enumerate(edges):
        parent, child = (f"f{k}", f"f{k + 1}") if stored_forward else (f"f{k + 1}", f"f{k}")
        q0 = np.array(q0) / np.linalg.norm(q0)
        q1 = np.array(q1) / np.linalg.norm(q1)
        if static:
            tf.add(parent, child, 0, t, q0, static=True)
            E = make_transform(t, q0)
        else:
            # a half-turn between the two samples has no unique shortest arc: both directions are right
            assume(abs(float(np.dot(q0, q1))) > 1e-6)
            t1 = np.array(t) + 1.0
            tf.add(parent, child, 0, t, q0, static=False)
            tf.add(parent, child, 1000, t1, q1, static=False)
            w = t_query / 1000
            E = np.eye(4)
            E[:3, :3] = Slerp([0, 1], Rotation.from_quat([q0, q1]))(w).as_matrix()
            E[:3, 3] = (1 - w) * np.array(t) + w * t1
        expected = expected @ (E if stored_forward else np.linalg.inv(E))
    got = tf.lookup("f0", f"f{len(edges)}", t_query)
    np.testing.assert_allclose(got, expected, atol=1e-7)
    np.testing.assert_allclose(tf.lookup(f"f{len(edges)}", "f0", t_query), np.linalg.inv(expected), atol=1e-6)


def test_header_cache_sees_every_change_of_header() -> None:
    """The converter skips re-parsing a header whose bytes equal the previous image's; a change of
    size, channels or codec in the stream must still be seen."""
    from psg_data.convert._scan import _FrameWriter
    from psg_data.loaders.raw._images import inspect_encoded

    rng = np.random.default_rng(3)
    fw = _FrameWriter("jpeg", 0.001, "t")
    imgs = [rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), rng.integers(0, 255, (48, 64, 3), dtype=np.uint8),
            rng.integers(0, 255, (24, 32, 3), dtype=np.uint8), rng.integers(0, 255, (48, 64), dtype=np.uint8)]
    for img in imgs + imgs[::-1]:
        for ext in (".jpg", ".png"):
            data = memoryview(cv2.imencode(ext, img)[1].tobytes())
            assert fw._inspect("color", data) == inspect_encoded(data)
    assert fw._inspect("color", memoryview(b"not an image at all")) is None
