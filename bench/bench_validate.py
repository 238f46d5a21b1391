"""``psg-data validate`` (default level) of the demo: strict decoding vs the check it replaced.

Usage: ``python bench/bench_validate.py [--quick] [--repeat N]``

Since issue 28 the default validate decodes a JPEG with libjpeg-turbo in strict mode (simplejpeg,
warnings are errors) and inflates a PNG (zlib stream, size, row filter types), which is the whole
decode of a plain PNG (other PNGs are then decoded by OpenCV too). The baseline, measured in the same process in alternating order, is the decode it
replaced (OpenCV's ``imdecode`` alone, copied below). Printed: the median CPU and wall time of
each, their ratio (target <= 1.3x), and per image the CPU cost of each decoder on a 640x480 JPEG
and PNG.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from typing import Any

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))


def baseline_decode_check(data: Any, expect: Any) -> None:
    """``decode_check`` as it was before issue 28 (OpenCV decode, size and sample format compared)."""
    import cv2

    from psg_data.schemas._image_check import DamagedImage

    img = cv2.imdecode(np.frombuffer(memoryview(data).cast("B"), np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DamagedImage(f"OpenCV cannot decode this {expect.kind.upper()}")
    h, w = img.shape[:2]
    ch = 1 if img.ndim == 2 else img.shape[2]
    bits = 16 if img.dtype == np.uint16 else 8
    want_bits = 16 if expect.bit_depth == 16 else 8
    if (w, h) != (expect.width, expect.height) or bits != want_bits or (expect.channels in (1, 3, 4) and
                                                                        ch != expect.channels):
        raise DamagedImage("decodes to another size or format")


def time_validate(root: Any, strict: bool) -> tuple[float, float]:
    from psg_data.schemas import _image_check
    from psg_data.schemas.validate import validate_dataset

    current = _image_check.decode_check
    if not strict:
        _image_check.decode_check = baseline_decode_check
    try:
        t, c = time.perf_counter(), time.process_time()
        problems = validate_dataset(root)
        dt, dc = time.perf_counter() - t, time.process_time() - c
    finally:
        _image_check.decode_check = current
    assert not problems, problems[:3]
    return dt, dc


def per_image(n: int) -> list[tuple[str, float, float]]:
    import cv2
    import simplejpeg

    from psg_data.schemas._image_check import check_png

    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur((rng.random((480, 640, 3)) * 255).astype(np.uint8), (9, 9), 3)
    jpg = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()
    depth = (cv2.GaussianBlur(rng.random((480, 640)), (31, 31), 9) * 60000).astype(np.uint16)
    png = cv2.imencode(".png", depth)[1].tobytes()

    def best(fn: Any) -> float:  # CPU time: the machine may be shared
        out = []
        for _ in range(3):
            t = time.process_time()
            for _ in range(n):
                fn()
            out.append((time.process_time() - t) / n * 1e6)
        return min(out)

    def cv(b: bytes) -> Any:
        return lambda: cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_UNCHANGED)

    return [("JPEG q95 colour 640x480: simplejpeg strict vs cv2.imdecode",
             best(lambda: simplejpeg.decode_jpeg(jpg, colorspace="BGR", strict=True)), best(cv(jpg))),
            ("16-bit PNG depth 640x480: inflate check (the decode of a plain PNG) vs cv2.imdecode",
             best(lambda: check_png(png, inflate=True)), best(cv(png)))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    from psg_data.datasets import demo

    root = demo()
    repeat = 2 if args.quick else args.repeat
    times: dict[bool, list[tuple[float, float]]] = {True: [], False: []}
    for k in range(repeat):
        for strict in ((True, False) if k % 2 else (False, True)):
            times[strict].append(time_validate(root, strict))
    with open("/proc/loadavg") as fh:
        load = fh.read().split()[0]
    print(f"load average (1 min) {load}; {repeat} repeats, alternating")
    print("| measure | strict (this tree) | baseline (OpenCV only) | ratio |")
    print("|---|---:|---:|---:|")
    for j, what in ((1, "CPU"), (0, "wall")):
        new = statistics.median(t[j] for t in times[True])
        old = statistics.median(t[j] for t in times[False])
        print(f"| validate demo (default level), median {what} s | {new:.2f} | {old:.2f} | {new / old:.2f}x |")
    for name, a, b in per_image(30 if args.quick else 200):
        print(f"| {name}, best us | {a:.0f} | {b:.0f} | {a / b:.2f}x |")


if __name__ == "__main__":
    main()
