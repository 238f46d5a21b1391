"""Conversion settings: a dataclass settable from a YAML/JSON file and from the command line.

The effective configuration is stored in the output manifest (``extra["convert"]["config"]``) so a
conversion can be repeated exactly.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from psg_data.errors import ConversionError

__all__ = ["ConvertConfig", "load_config", "parse_pose_source", "parse_keyframes", "parse_split"]


@dataclass
class ConvertConfig:
    """Settings of a conversion (every field also a key of the config file).

    Attributes:
        input_format: ``auto``, ``ros1``, ``ros2``, ``mcap``, ``tum``, ``scannet`` or ``rtabmap``.
        color_topic / depth_topic / camera_info_topic: topic overrides (default: discovered by type).
        poses: ``tf:WORLD->FRAME``, ``odom:/TOPIC`` or ``tum:FILE`` (default: TF ``map`` (else
            ``odom``) to the camera's optical frame, else the first nav_msgs/Odometry topic).
        camera_frame: optical frame of the camera (default: CameraInfo ``header.frame_id``).
        tum_frame: frame the ``tum:FILE`` poses refer to (default: the optical frame).
        camera_id: camera id in the output (default: site file mapping, else ``camera``).
        color_encoding: ``auto`` (JPEG when the colour input is JPEG, else PNG), ``png`` or ``jpeg``.
        depth_scale_m: metres per unit of 16-bit depth input (default 0.001; TUM folders 0.0002).
        sync_tolerance_s: largest |colour stamp - depth stamp| paired into one frame.
        max_pose_gap_s: largest gap between two pose samples interpolated over.
        pose_tolerance_s: largest distance to the nearest pose sample outside an interpolation gap.
        buffer_s: log-time window held back for association (bounds memory).
        split: ``gap:SECONDS`` or ``slot:SECONDS`` to split one long recording into scans.
        keyframes: ``every:N`` or ``motion:METRES,DEGREES``.
        static_transforms: extra static TF edges, each ``{parent, child, translation, rotation_xyzw}``.
        intrinsics: ``[fx, fy, cx, cy]`` for frame folders without an intrinsics file.
        fps / start_stamp_ns: stamps of ScanNet folders (no stamps on disk).
        side_dir: directory of the side files (default: the input directory).
        name / timezone: dataset name and IANA timezone (default: site file, else input name / UTC).
        image_layout: ``tar`` (one archive per scan, default) or ``files`` (one file per image).
        image_check: integrity check of every encoded input image, passed through or decoded:
            ``structure`` (PNG chunk CRCs and zlib header, JPEG markers through EOI; default),
            ``full`` (also PNG inflated, JPEG decoded) or ``none`` (see docs/RAW_FORMATS.md).
        strict: refuse the conversion at the first corrupt image instead of skipping its frame.
    """

    input_format: str = "auto"
    color_topic: str | None = None
    depth_topic: str | None = None
    camera_info_topic: str | None = None
    poses: str | None = None
    camera_frame: str | None = None
    tum_frame: str | None = None
    camera_id: str | None = None
    color_encoding: str = "auto"
    depth_scale_m: float | None = None
    sync_tolerance_s: float = 0.02
    max_pose_gap_s: float = 0.5
    pose_tolerance_s: float = 0.02
    buffer_s: float = 1.0
    split: str | None = None
    keyframes: str | None = None
    static_transforms: list[dict[str, Any]] = field(default_factory=list)
    intrinsics: list[float] | None = None
    fps: float = 30.0
    start_stamp_ns: int = 0
    side_dir: str | None = None
    name: str | None = None
    timezone: str | None = None
    image_layout: str = "tar"
    image_check: str = "structure"
    strict: bool = False

    def __post_init__(self) -> None:
        if self.image_layout not in ("tar", "files"):
            raise ConversionError(f"config: image_layout: expected tar or files, got {self.image_layout!r}")
        if self.image_check not in ("none", "structure", "full"):
            raise ConversionError(f"config: image_check: expected none, structure or full, got {self.image_check!r}")
        if not isinstance(self.strict, bool):
            raise ConversionError(f"config: strict: expected true or false, got {self.strict!r}")
        if self.input_format not in ("auto", "ros1", "ros2", "mcap", "tum", "scannet", "rtabmap"):
            raise ConversionError(f"config: input_format: expected auto, ros1, ros2, mcap, tum, scannet or rtabmap, "
                                  f"got {self.input_format!r}")
        if self.color_encoding not in ("auto", "png", "jpeg"):
            raise ConversionError(f"config: color_encoding: expected auto, png or jpeg, got {self.color_encoding!r}")
        for name in ("sync_tolerance_s", "max_pose_gap_s", "pose_tolerance_s", "buffer_s", "fps"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not v >= 0:
                raise ConversionError(f"config: {name}: expected a number >= 0, got {v!r}")
        if self.depth_scale_m is not None and not self.depth_scale_m > 0:
            raise ConversionError(f"config: depth_scale_m: expected a number > 0, got {self.depth_scale_m!r}")
        if self.poses is not None:
            parse_pose_source(self.poses)
        parse_keyframes(self.keyframes)
        parse_split(self.split)
        for i, st in enumerate(self.static_transforms):
            if not isinstance(st, dict) or not {"parent", "child", "translation", "rotation_xyzw"} <= set(st):
                raise ConversionError(f"config: static_transforms[{i}]: expected keys parent, child, translation, "
                                      f"rotation_xyzw")

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "config") -> ConvertConfig:
        """A config from a mapping (a YAML / JSON file's content).

        Raises:
            ConversionError: an unknown key or a bad value, named with ``where``.
        """
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConversionError(f"{where}: unknown keys {', '.join(unknown)}; expected some of "
                                  f"{', '.join(sorted(known))}")
        return cls(**data)

    def to_dict(self) -> dict[str, Any]:
        """The settings as a plain dictionary (what the state file and the manifest store)."""
        return asdict(self)

    def merged(self, **overrides: Any) -> ConvertConfig:
        """A copy with every non-None override applied."""
        data = self.to_dict()
        data.update({k: v for k, v in overrides.items() if v is not None})
        return ConvertConfig.from_dict(data)


def load_config(path: str | Path) -> ConvertConfig:
    """Read a YAML or JSON config file.

    Raises:
        ConversionError: unreadable file, not a mapping, unknown keys or bad values.
    """
    p = Path(path)
    if not p.is_file():
        raise ConversionError(f"{p}: config file not found; expected a YAML or JSON file of conversion settings")
    try:
        text = p.read_text(encoding="utf-8")
        if p.suffix == ".json":
            data = json.loads(text)
        else:
            from ruamel.yaml import YAML

            data = YAML(typ="safe").load(text)
    except Exception as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ConversionError(f"{p}: cannot read config ({first})") from exc
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConversionError(f"{p}: expected a mapping of config keys")
    return ConvertConfig.from_dict(data, str(p))


_TF_RE = re.compile(r"^tf:([^\s>-][^\s>]*?)\s*->\s*([^\s]+)$")


def parse_pose_source(spec: str) -> tuple[str, str, str | None]:
    """``tf:A->B`` -> ('tf', A, B); ``odom:/topic`` -> ('odom', topic, None); ``tum:FILE`` -> ('tum', FILE, None).

    ``tf:A`` (no target) means A to the camera's optical frame.
    """
    if spec.startswith("tf:"):
        body = spec[3:]
        if "->" in body:
            a, b = (x.strip() for x in body.split("->", 1))
        else:
            a, b = body.strip(), ""
        if not a:
            raise ConversionError(f"--poses: {spec!r}: expected tf:WORLD_FRAME->CAMERA_FRAME")
        return "tf", a.lstrip("/"), (b.lstrip("/") or None)
    if spec.startswith("odom:") and len(spec) > 5:
        return "odom", spec[5:], None
    if spec.startswith("tum:") and len(spec) > 4:
        return "tum", spec[4:], None
    raise ConversionError(f"--poses: {spec!r}: expected tf:FRAME_A->FRAME_B, odom:/TOPIC or tum:FILE")


def parse_keyframes(spec: str | None) -> tuple[str, float, float] | None:
    """``every:N`` -> ('every', N, 0); ``motion:M,DEG`` -> ('motion', metres, radians)."""
    if spec is None:
        return None
    import math

    try:
        kind, _, arg = spec.partition(":")
        if kind == "every":
            n = int(arg)
            if n < 1:
                raise ValueError
            return "every", float(n), 0.0
        if kind == "motion":
            m, _, deg = arg.partition(",")
            dm, dd = float(m), float(deg or "inf")
            if dm < 0 or dd < 0:
                raise ValueError
            return "motion", dm, math.radians(dd)
    except ValueError:
        pass
    raise ConversionError(f"--keyframes: {spec!r}: expected every:N (N >= 1) or motion:METRES,DEGREES")


def parse_split(spec: str | None) -> tuple[str, int] | None:
    """``gap:SECONDS`` / ``slot:SECONDS`` -> (kind, nanoseconds)."""
    if spec is None:
        return None
    kind, _, arg = spec.partition(":")
    try:
        s = float(arg)
    except ValueError:
        s = -1.0
    if kind not in ("gap", "slot") or not s > 0:
        raise ConversionError(f"--split: {spec!r}: expected gap:SECONDS or slot:SECONDS (> 0)")
    return kind, int(round(s * 1e9))
