"""Conversion settings: a dataclass settable from a YAML/JSON file and from the command line.

Every key is declared once in :data:`CONVERT_SETTINGS` (type, finite, range with units, choices,
IANA time zones, int64-nanosecond stamps, the structure of ``split`` / ``keyframes`` / ``poses`` /
``static_transforms``): a config file and the command-line options go through the same checks
before any input is read, and a bad value is one line naming the key, the value and what is
allowed. The effective configuration is stored in the output manifest
(``extra["convert"]["config"]``) so a conversion can be repeated exactly.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from psg_data._settings import (
    DURATION_MAX_S,
    STAMP_MAX_NS,
    Boolean,
    Integral,
    Options,
    Param,
    Real,
    Reals,
    Records,
    Text,
    TimeZone,
    check_settings,
)
from psg_data.errors import ConversionError

__all__ = ["ConvertConfig", "load_config", "parse_pose_source", "parse_keyframes", "parse_split", "CONVERT_SETTINGS",
           "STAMP_MAX_NS", "DURATION_MAX_S"]



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
        check_settings(CONVERT_SETTINGS, asdict(self), "config", ConversionError)

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "config") -> ConvertConfig:
        """A config from a mapping (a YAML / JSON file's content).

        Raises:
            ConversionError: an unknown key or a bad value, named with ``where``.
        """
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known, key=str)
        if unknown:
            raise ConversionError(f"{where}: unknown keys {', '.join(map(str, unknown))}; expected some of "
                                  f"{', '.join(sorted(known))}")
        check_settings(CONVERT_SETTINGS, data, where, ConversionError)
        return cls(**data)

    def to_dict(self) -> dict[str, Any]:
        """The settings as a plain dictionary (what the state file and the manifest store)."""
        return asdict(self)

    def merged(self, where: str = "config", names: dict[str, str] | None = None, **overrides: Any) -> ConvertConfig:
        """A copy with every non-None override applied (checked first, named as ``where`` and ``names``:
        the command line and its option names).
        """
        given = {k: v for k, v in overrides.items() if v is not None}
        check_settings(CONVERT_SETTINGS, given, where, ConversionError, names)
        data = self.to_dict()
        data.update(given)
        return ConvertConfig.from_dict(data, where)


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
_POSES = "tf:WORLD_FRAME->CAMERA_FRAME, odom:/TOPIC or tum:FILE"


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
    raise ConversionError(f"--poses: {spec!r}: expected {_POSES}")


_KEYFRAMES = "every:N (N an integer >= 1) or motion:METRES,DEGREES (finite numbers >= 0)"
_EVERY_MAX = 10**9


def parse_keyframes(spec: str | None) -> tuple[str, float, float] | None:
    """``every:N`` -> ('every', N, 0); ``motion:M,DEG`` -> ('motion', metres, radians)."""
    if spec is None:
        return None
    import math

    try:
        kind, _, arg = spec.partition(":")
        if kind == "every":
            n = int(arg)
            if not 1 <= n <= _EVERY_MAX:
                raise ValueError
            return "every", float(n), 0.0
        if kind == "motion":
            m, _, deg = arg.partition(",")
            dm, dd = float(m), float(deg or "inf")
            if not (math.isfinite(dm) and dm >= 0 and dd >= 0 and (math.isfinite(dd) or not deg)):
                raise ValueError
            return "motion", dm, math.radians(dd)
    except ValueError:
        pass
    raise ConversionError(f"--keyframes: {spec!r}: expected {_KEYFRAMES}")


_SPLIT_MIN_S = 1e-3
_SPLIT = f"gap:SECONDS or slot:SECONDS (SECONDS in [{_SPLIT_MIN_S:g}, {DURATION_MAX_S:g}])"


def parse_split(spec: str | None) -> tuple[str, int] | None:
    """``gap:SECONDS`` / ``slot:SECONDS`` -> (kind, nanoseconds)."""
    if spec is None:
        return None
    kind, _, arg = spec.partition(":")
    try:
        s = float(arg)
    except ValueError:
        s = -1.0
    if kind not in ("gap", "slot") or not _SPLIT_MIN_S <= s <= DURATION_MAX_S:
        raise ConversionError(f"--split: {spec!r}: expected {_SPLIT}")
    return kind, int(round(s * 1e9))


def _form(parser: Any, expected: str) -> Any:
    def form(value: Any) -> str | None:
        try:
            parser(value)
        except ConversionError:
            return expected
        return None

    return form


_TRANSFORMS = ("a list of {parent: FRAME, child: FRAME, translation: [x, y, z] metres, rotation_xyzw: "
               "[x, y, z, w] (a non-zero quaternion)}")


def _static_transforms_problem(items: Any) -> str | None:
    import math

    for i, st in enumerate(items):
        if not isinstance(st, dict) or set(st) != {"parent", "child", "translation", "rotation_xyzw"}:
            return f"{_TRANSFORMS}; item {i} is not such a mapping"
        for key in ("parent", "child"):
            if not isinstance(st[key], str) or not st[key].strip("/"):
                return f"{_TRANSFORMS}; item {i}: {key} is not a frame name"
        for key, n in (("translation", 3), ("rotation_xyzw", 4)):
            v = st[key]
            if not Reals(n).is_valid(v):
                return f"{_TRANSFORMS}; item {i}: {key} is not {n} finite numbers"
        if not math.fsum(float(q) ** 2 for q in st["rotation_xyzw"]) > 1e-12:
            return f"{_TRANSFORMS}; item {i}: rotation_xyzw is zero"
    return None


_FRAME_RATE = (1e-3, 1e6)

CONVERT_SETTINGS: dict[str, Param] = {
    "input_format": Options("auto", "ros1", "ros2", "mcap", "tum", "scannet", "rtabmap"),
    "color_topic": Text(help="colour topic"),
    "depth_topic": Text(help="depth topic"),
    "camera_info_topic": Text(help="CameraInfo topic"),
    "poses": Text(form=_form(parse_pose_source, _POSES), expected=_POSES, help="pose source"),
    "camera_frame": Text(help="optical frame of the camera"),
    "tum_frame": Text(help="frame of tum:FILE poses"),
    "camera_id": Text(help="camera id in the output"),
    "color_encoding": Options("auto", "png", "jpeg"),
    "depth_scale_m": Real(1e-6, 1.0, none_ok=True, finite=True, help="metres per unit of 16-bit depth"),
    "sync_tolerance_s": Real(0.0, DURATION_MAX_S, finite=True, help="seconds"),
    "max_pose_gap_s": Real(0.0, DURATION_MAX_S, finite=True, help="seconds"),
    "pose_tolerance_s": Real(0.0, DURATION_MAX_S, finite=True, help="seconds"),
    "buffer_s": Real(0.0, DURATION_MAX_S, finite=True, help="seconds of log time"),
    "split": Text(form=_form(parse_split, _SPLIT), expected=_SPLIT),
    "keyframes": Text(form=_form(parse_keyframes, _KEYFRAMES), expected=_KEYFRAMES),
    "static_transforms": Records(_static_transforms_problem, expected=_TRANSFORMS),
    "intrinsics": Reals(4, help="fx, fy, cx, cy in pixels"),
    "fps": Real(*_FRAME_RATE, finite=True, help="frames per second of a ScanNet folder"),
    "start_stamp_ns": Integral(0, STAMP_MAX_NS, help="stamp of a ScanNet folder's frame 0, ns since the epoch"),
    "side_dir": Text(help="folder of side files"),
    "name": Text(help="dataset name"),
    "timezone": TimeZone(help="IANA site time zone"),
    "image_layout": Options("tar", "files"),
    "image_check": Options("none", "structure", "full"),
    "strict": Boolean(),
}
"""Every key of :class:`ConvertConfig`, declared (see :mod:`psg_data._settings`)."""
