"""Folders of frames: the TUM RGB-D layout and ScanNet-style exported scans.

TUM RGB-D (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats)::

    rgb.txt           # "timestamp filename" per line (seconds), '#' comments
    depth.txt         # same, 16-bit PNGs; depth factor 5000 units per metre (depth_scale_m 0.0002)
    groundtruth.txt   # "timestamp tx ty tz qx qy qz qw": camera optical centre in the world frame
    intrinsics.txt    # optional "fx fy cx cy" (else the config's intrinsics)

ScanNet (SensReader export)::

    color/N.jpg  depth/N.png (mm)  pose/N.txt (4x4 camera-to-world)  intrinsic/intrinsic_depth.txt (4x4)

ScanNet has no stamps: frame N gets ``start_stamp_ns + N / fps``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import ConversionError

__all__ = ["FolderRecording", "folder_format", "read_tum_folder", "read_scannet_folder", "parse_stamp_s",
           "read_tum_poses"]


def parse_stamp_s(text: str, where: str) -> int:
    """Decimal seconds (as text) -> int nanoseconds, exactly."""
    try:
        return int((Decimal(text) * 1_000_000_000).to_integral_value())
    except InvalidOperation as exc:
        raise ConversionError(f"{where}: expected a timestamp in seconds, got {text!r}") from exc


@dataclass
class FolderRecording:
    """Frames of one folder: stamped file lists, poses and intrinsics."""

    path: Path
    format: str
    colors: list[tuple[int, Path]]
    depths: list[tuple[int, Path]]
    width: int
    height: int
    K: tuple[float, float, float, float]
    """fx, fy, cx, cy in pixels."""
    depth_scale_m: float
    poses_tum: list[tuple[int, NDArray[np.float64], NDArray[np.float64]]] = field(default_factory=list)
    """TUM: (stamp, translation, quat_xyzw) samples of camera-to-world."""
    poses_exact: dict[int, NDArray[np.float64]] = field(default_factory=dict)
    """ScanNet: stamp -> 4x4 camera-to-world."""

    @property
    def size_bytes(self) -> int:
        return sum(p.stat().st_size for _, p in (*self.colors, *self.depths))


def folder_format(path: str | Path) -> str | None:
    """``tum``, ``scannet`` or None."""
    p = Path(path)
    if not p.is_dir():
        return None
    if (p / "rgb.txt").is_file() and (p / "depth.txt").is_file():
        return "tum"
    if (p / "color").is_dir() and (p / "depth").is_dir() and (p / "pose").is_dir():
        return "scannet"
    return None


def _list_file(path: Path) -> list[list[str]]:
    if not path.is_file():
        raise ConversionError(f"{path}: missing; expected a TUM RGB-D list file")
    rows = []
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        line = line.strip()
        if line and not line.startswith("#"):
            rows.append([f"{path}:{n}", *line.split()])
    return rows


def read_tum_poses(path: str | Path) -> list[tuple[int, NDArray[np.float64], NDArray[np.float64]]]:
    """``timestamp tx ty tz qx qy qz qw`` lines (TUM / RTAB-Map export) -> samples."""
    out = []
    for where, *cols in _list_file(Path(path)):
        if len(cols) != 8:
            raise ConversionError(f"{where}: expected 'timestamp tx ty tz qx qy qz qw', got {len(cols)} values")
        try:
            vals = np.array([float(c) for c in cols[1:]])
        except ValueError as exc:
            raise ConversionError(f"{where}: expected numbers ({exc})") from exc
        out.append((parse_stamp_s(cols[0], where), vals[:3], vals[3:]))
    return out


def _image_size(path: Path) -> tuple[int, int]:
    from psg_data.loaders.raw._images import inspect_encoded

    with open(path, "rb") as fh:
        info = inspect_encoded(fh.read(65536))
    if info is None:
        raise ConversionError(f"{path}: not a PNG or JPEG image")
    return info.width, info.height


def _intrinsics_file(path: Path) -> tuple[float, float, float, float] | None:
    if not path.is_file():
        return None
    vals = np.array(path.read_text().split(), dtype=float)
    if vals.size == 4:
        return tuple(float(v) for v in vals)  # type: ignore[return-value]
    if vals.size in (9, 16):
        M = vals.reshape(3, 3) if vals.size == 9 else vals.reshape(4, 4)
        return float(M[0, 0]), float(M[1, 1]), float(M[0, 2]), float(M[1, 2])
    raise ConversionError(f"{path}: expected 'fx fy cx cy' or a 3x3/4x4 intrinsic matrix, got {vals.size} values")


def read_tum_folder(path: str | Path, intrinsics: list[float] | None, depth_scale_m: float | None) -> FolderRecording:
    p = Path(path)
    colors = [(parse_stamp_s(c[1], c[0]), p / c[2]) for c in _list_file(p / "rgb.txt")]
    depths = [(parse_stamp_s(c[1], c[0]), p / c[2]) for c in _list_file(p / "depth.txt")]
    if not colors:
        raise ConversionError(f"{p / 'rgb.txt'}: no colour frames listed")
    if not depths:
        raise ConversionError(f"{p / 'depth.txt'}: no depth frames listed; expected a recording with depth")
    K = _intrinsics_file(p / "intrinsics.txt") or (tuple(intrinsics) if intrinsics else None)
    if K is None or len(K) != 4:
        raise ConversionError(f"{p}: no camera intrinsics; add intrinsics.txt ('fx fy cx cy') or set "
                              f"'intrinsics: [fx, fy, cx, cy]' in the config")
    w, h = _image_size(colors[0][1])
    gt = p / "groundtruth.txt"
    poses = read_tum_poses(gt) if gt.is_file() else []
    return FolderRecording(p, "tum", sorted(colors), sorted(depths), w, h, K,  # type: ignore[arg-type]
                           depth_scale_m or 1.0 / 5000.0, poses_tum=poses)


def read_scannet_folder(path: str | Path, fps: float, start_stamp_ns: int, depth_scale_m: float | None,
                        intrinsics: list[float] | None) -> FolderRecording:
    p = Path(path)

    def index(d: str, ext: tuple[str, ...]) -> dict[int, Path]:
        out = {}
        for f in (p / d).iterdir():
            if f.suffix.lower() in ext and f.stem.isdigit():
                out[int(f.stem)] = f
        return out

    cols, deps, poses = index("color", (".jpg", ".jpeg", ".png")), index("depth", (".png",)), index("pose", (".txt",))
    if not cols:
        raise ConversionError(f"{p / 'color'}: no colour frames (N.jpg / N.png)")
    if not deps:
        raise ConversionError(f"{p / 'depth'}: no depth frames (N.png); expected a recording with depth")
    period = 1e9 / fps if fps > 0 else 1e9 / 30
    stamp = {i: int(start_stamp_ns + round(i * period)) for i in cols}
    exact: dict[int, NDArray[np.float64]] = {}
    for i, f in poses.items():
        if i in stamp:
            vals = np.array(f.read_text().replace(",", " ").split(), dtype=float)
            if vals.size != 16:
                raise ConversionError(f"{f}: expected a 4x4 camera-to-world matrix, got {vals.size} values")
            exact[stamp[i]] = vals.reshape(4, 4)
    w, h = _image_size(deps[min(deps)])
    K = (_intrinsics_file(p / "intrinsic" / "intrinsic_depth.txt") or _intrinsics_file(p / "intrinsics.txt")
         or (tuple(intrinsics) if intrinsics else None))
    if K is None:
        raise ConversionError(f"{p}: no camera intrinsics; expected intrinsic/intrinsic_depth.txt")
    return FolderRecording(p, "scannet", [(stamp[i], cols[i]) for i in sorted(cols)],
                           [(int(start_stamp_ns + round(i * period)), deps[i]) for i in sorted(deps)],
                           w, h, K, depth_scale_m or 0.001, poses_exact=exact)  # type: ignore[arg-type]
