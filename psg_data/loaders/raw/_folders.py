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

from psg_data._settings import STAMP_MAX_NS, shown
from psg_data.errors import ConversionError
from psg_data.schemas._paths import path_problem

_STAMP_MAX_S = Decimal(STAMP_MAX_NS) / 1_000_000_000

__all__ = ["FolderRecording", "folder_format", "read_tum_folder", "read_scannet_folder", "parse_stamp_s",
           "read_tum_poses", "check_intrinsics"]


_STAMP_RANGE = f"a timestamp in seconds from 0 to {STAMP_MAX_NS / 1e9:.0f} (int64 nanoseconds)"


def parse_stamp_s(text: str, where: str) -> int:
    """Decimal seconds (as text) -> int nanoseconds, exactly.

    Raises:
        ConversionError: naming ``where`` (file and line): not a number, not finite (``nan``,
            ``inf``), or outside ``[0, STAMP_MAX_NS]`` ns.
    """
    try:
        d = Decimal(text)
        ok = d.is_finite() and 0 <= d <= _STAMP_MAX_S
    except (InvalidOperation, ArithmeticError):
        ok = False
    if not ok:
        raise ConversionError(f"{where}: expected {_STAMP_RANGE}, got {shown(text)}")
    return int((d * 1_000_000_000).to_integral_value())


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
        """Bytes of every image file listed, in total."""
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


def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ConversionError(f"{path}: not a text file (byte {exc.start} is not UTF-8); expected {what}") from exc
    except OSError as exc:
        raise ConversionError(f"{path}: cannot read ({exc.strerror or exc}); expected {what}") from exc


def _list_file(path: Path) -> list[list[str]]:
    if not path.is_file():
        raise ConversionError(f"{path}: missing; expected a TUM RGB-D list file")
    rows = []
    for n, line in enumerate(_read_text(path, "a TUM RGB-D list file").splitlines(), start=1):
        line = line.strip()
        if line and not line.startswith("#"):
            rows.append([f"{path}:{n}", *line.split()])
    return rows


def _image_list(folder: Path, name: str) -> list[tuple[int, Path]]:
    """``timestamp filename`` rows of a TUM list file, every listed image present."""
    out = []
    for where, *cols in _list_file(folder / name):
        if len(cols) != 2:
            raise ConversionError(f"{where}: expected 'timestamp filename', got {len(cols)} value(s)")
        outside = path_problem(str(folder), cols[1], resolve=False)
        if outside is not None:
            raise ConversionError(f"{where}: {cols[1]}: {outside}; expected a path relative to {folder}")
        f = folder / cols[1]
        if not f.is_file():
            raise ConversionError(f"{where}: {cols[1]}: listed image not found in {folder}; expected every image "
                                  f"listed in {name} to exist")
        out.append((parse_stamp_s(cols[0], where), f))
    return out


def _numbers(text: str, where: str, what: str) -> NDArray[np.float64]:
    """Whitespace- or comma-separated numbers (NaN and inf are refused)."""
    try:
        vals = np.array([float(t) for t in text.replace(",", " ").split()], dtype=float)
    except ValueError as exc:
        raise ConversionError(f"{where}: expected {what} as numbers ({exc})") from exc
    if not np.all(np.isfinite(vals)):
        raise ConversionError(f"{where}: expected {what} as finite numbers, got {text.split()}")
    return vals


def read_tum_poses(path: str | Path) -> list[tuple[int, NDArray[np.float64], NDArray[np.float64]]]:
    """``timestamp tx ty tz qx qy qz qw`` lines (TUM / RTAB-Map export) -> samples."""
    out = []
    for where, *cols in _list_file(Path(path)):
        if len(cols) != 8:
            raise ConversionError(f"{where}: expected 'timestamp tx ty tz qx qy qz qw', got {len(cols)} values")
        vals = _numbers(" ".join(cols[1:]), where, "'tx ty tz qx qy qz qw'")
        out.append((parse_stamp_s(cols[0], where), vals[:3], vals[3:]))
    return out


def _image_size(path: Path) -> tuple[int, int]:
    from psg_data.loaders.raw._images import inspect_encoded

    try:
        with open(path, "rb") as fh:
            info = inspect_encoded(fh.read(65536))
    except OSError as exc:
        raise ConversionError(f"{path}: cannot read ({exc.strerror or exc}); expected a PNG or JPEG image") from exc
    if info is None:
        raise ConversionError(f"{path}: not a PNG or JPEG image (unreadable header); expected the first frame's image")
    return info.width, info.height


def check_intrinsics(K: tuple[float, ...], width: int, height: int, where: str) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` checked like CameraInfo and like ``psg-data validate``.

    Raises:
        ConversionError: naming ``where``, the field and the range expected.
    """
    from psg_data.schemas._camera_checks import intrinsics_problems

    try:
        fx, fy, cx, cy = (float(v) for v in K)
    except (TypeError, ValueError) as exc:
        raise ConversionError(f"{where}: expected numbers fx, fy, cx, cy, got {list(K)}") from exc
    problems = intrinsics_problems(int(width), int(height), fx, fy, cx, cy)
    if problems:
        field, what = problems[0]
        raise ConversionError(f"{where}: {field}: {what} (images are {width}x{height})")
    return fx, fy, cx, cy


def _intrinsics_file(path: Path) -> tuple[float, float, float, float] | None:
    if not path.is_file():
        return None
    vals = _numbers(_read_text(path, "intrinsics"), str(path), "'fx fy cx cy' or a 3x3/4x4 intrinsic matrix")
    if vals.size == 4:
        return tuple(float(v) for v in vals)  # type: ignore[return-value]
    if vals.size in (9, 16):
        M = vals.reshape(3, 3) if vals.size == 9 else vals.reshape(4, 4)
        return float(M[0, 0]), float(M[1, 1]), float(M[0, 2]), float(M[1, 2])
    raise ConversionError(f"{path}: expected 'fx fy cx cy' or a 3x3/4x4 intrinsic matrix, got {vals.size} values")


def read_tum_folder(path: str | Path, intrinsics: list[float] | None, depth_scale_m: float | None) -> FolderRecording:
    """A TUM RGB-D folder (``rgb.txt``, ``depth.txt``, ``groundtruth.txt``) with its images and poses.

    Raises:
        ConversionError: no frames listed, a listed image missing, or no intrinsics.
    """
    p = Path(path)
    colors = _image_list(p, "rgb.txt")
    depths = _image_list(p, "depth.txt")
    if not colors:
        raise ConversionError(f"{p / 'rgb.txt'}: no colour frames listed")
    if not depths:
        raise ConversionError(f"{p / 'depth.txt'}: no depth frames listed; expected a recording with depth")
    K_file = _intrinsics_file(p / "intrinsics.txt")
    K = K_file or (tuple(intrinsics) if intrinsics else None)
    if K is None or len(K) != 4:
        raise ConversionError(f"{p}: no camera intrinsics; add intrinsics.txt ('fx fy cx cy') or set "
                              f"'intrinsics: [fx, fy, cx, cy]' in the config")
    w, h = _image_size(colors[0][1])
    K = check_intrinsics(K, w, h, str(p / "intrinsics.txt") if K_file else "config: intrinsics")
    gt = p / "groundtruth.txt"
    poses = read_tum_poses(gt) if gt.is_file() else []
    return FolderRecording(p, "tum", sorted(colors), sorted(depths), w, h, K,
                           depth_scale_m or 1.0 / 5000.0, poses_tum=poses)


def _pose_values(f: Path) -> NDArray[np.float64]:
    """The numbers of a ScanNet pose file (non-finite ones kept: SensReader writes -inf for a frame
    without a pose, and such frames are skipped as ``nonfinite_pose``).
    """
    text = _read_text(f, "a 4x4 camera-to-world matrix")
    try:
        return np.array([float(t) for t in text.replace(",", " ").split()], dtype=float)
    except ValueError as exc:
        raise ConversionError(f"{f}: expected a 4x4 camera-to-world matrix as numbers ({exc})") from exc


def read_scannet_folder(path: str | Path, fps: float, start_stamp_ns: int, depth_scale_m: float | None,
                        intrinsics: list[float] | None) -> FolderRecording:
    """A ScanNet folder (``color/``, ``depth/``, ``pose/``, ``intrinsic/``).

    Frame N is stamped ``start_stamp_ns + N / fps`` (ScanNet stores no stamps).

    Raises:
        ConversionError: no frames, no intrinsics, or a malformed pose or intrinsics file.
    """
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
    if not (isinstance(fps, (int, float)) and 0 < fps < float("inf")):
        raise ConversionError(f"config: fps: expected a finite number > 0 (frames per second), got {fps!r}")
    period = 1e9 / fps
    last = max(max(cols), max(deps))
    if not 0 <= start_stamp_ns + last * period <= STAMP_MAX_NS:
        raise ConversionError(f"{p}: frame {last} would be stamped {start_stamp_ns} + {last} / {fps:g} s, beyond "
                              f"{STAMP_MAX_NS} ns; expected start_stamp_ns and fps (config) that keep every stamp "
                              f"within int64 nanoseconds")
    stamp = {i: int(start_stamp_ns + round(i * period)) for i in cols}
    exact: dict[int, NDArray[np.float64]] = {}
    for i, f in poses.items():
        if i in stamp:
            vals = _pose_values(f)
            if vals.size != 16:
                raise ConversionError(f"{f}: expected a 4x4 camera-to-world matrix, got {vals.size} values")
            exact[stamp[i]] = vals.reshape(4, 4)
    w, h = _image_size(deps[min(deps)])
    sources = [p / "intrinsic" / "intrinsic_depth.txt", p / "intrinsics.txt"]
    K, where = None, "config: intrinsics"
    for src in sources:
        K = _intrinsics_file(src)
        if K is not None:
            where = str(src)
            break
    if K is None and intrinsics and len(intrinsics) == 4:
        fx, fy, cx, cy = (float(v) for v in intrinsics)
        K = (fx, fy, cx, cy)
    if K is None or len(K) != 4:
        raise ConversionError(f"{p}: no camera intrinsics; expected intrinsic/intrinsic_depth.txt")
    K = check_intrinsics(K, w, h, where)
    return FolderRecording(p, "scannet", [(stamp[i], cols[i]) for i in sorted(cols)],
                           [(int(start_stamp_ns + round(i * period)), deps[i]) for i in sorted(deps)],
                           w, h, K, depth_scale_m or 0.001, poses_exact=exact)
