"""Plausibility of pinhole intrinsics: one rule for the validator and for every reader of raw input.

A converter applies the same checks as ``psg-data validate``, so it never writes a dataset the
validator rejects (CameraInfo messages and folder intrinsics files alike).
"""

from __future__ import annotations

import math

from psg_data.schemas._image_headers import MAX_IMAGE_PIXELS

__all__ = ["intrinsics_problems", "MAX_FOCAL_PER_PIXEL"]

MAX_FOCAL_PER_PIXEL = 50
"""A focal length above this many times the image size (a field of view under ~1.1 degrees) is an error."""


def _finite(v: object) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def intrinsics_problems(width: object, height: object, fx: object, fy: object, cx: object, cy: object
                        ) -> list[tuple[str, str]]:
    """``(field, what is wrong and what was expected)`` for every implausible value (empty: plausible).

    Args:
        width: image width, pixels.
        height: image height, pixels.
        fx: focal length along x, pixels.
        fy: focal length along y, pixels.
        cx: principal point x, pixels (OpenCV convention: pixel centres at integers).
        cy: principal point y, pixels.
    """
    out: list[tuple[str, str]] = []
    if not (isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0):
        out.append(("width/height", f"image size {width}x{height}, expected positive"))
        return out
    if width * height > MAX_IMAGE_PIXELS:  # no image of the camera could be decoded (docs/SECURITY.md)
        out.append(("width/height", f"image size {width}x{height} = {width * height} pixels, over the limit of "
                                    f"{MAX_IMAGE_PIXELS} pixels per image"))
        return out
    for name, v in (("fx", fx), ("fy", fy)):
        if not (_finite(v) and 0 < v <= MAX_FOCAL_PER_PIXEL * max(width, height)):  # type: ignore[operator]
            out.append((name, f"focal length {v}, expected a finite value in (0, {MAX_FOCAL_PER_PIXEL} x image "
                              f"size]"))
    if not (_finite(cx) and -0.5 <= cx <= width - 0.5 + 1e-9):  # type: ignore[operator]
        out.append(("cx", f"principal point x {cx}, expected within [-0.5, width - 0.5] = [-0.5, {width - 0.5}]"))
    if not (_finite(cy) and -0.5 <= cy <= height - 0.5 + 1e-9):  # type: ignore[operator]
        out.append(("cy", f"principal point y {cy}, expected within [-0.5, height - 0.5] = [-0.5, {height - 0.5}]"))
    return out
