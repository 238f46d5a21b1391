"""Converting one source (a recording or a frame folder) into scans of a dataset being written.

Streams messages in log-time order, pairs colour and depth on header stamps, resolves poses and
writes frames as soon as they are complete: memory is bounded by the ``buffer_s`` window, not by the
recording size. Runs in the main process or in a worker process (``--jobs``); each worker writes
its scans into ``OUT.partial`` with its own :class:`DatasetWriter` opened with ``resume=True``, and
the parent adopts the finished scans.
"""

from __future__ import annotations

import bisect
import json
import logging
import math
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from psg_data.convert._config import ConvertConfig, parse_keyframes, parse_pose_source, parse_split
from psg_data.errors import ConversionError
from psg_data.loaders.raw._folders import FolderRecording, read_scannet_folder, read_tum_folder, read_tum_poses
from psg_data.loaders.raw._images import (
    EncodedInfo,
    ImageDataError,
    compressed_depth_png,
    decode_color_image,
    decode_compressed_color,
    decode_compressed_depth,
    decode_depth_image,
)
from psg_data.loaders.raw._transforms import PoseSeries, TfBuffer
from psg_data.schemas._camera_checks import intrinsics_problems
from psg_data.schemas._image_check import DamagedImage, check_image, looks_like_image
from psg_data.schemas._image_headers import parse_image_header_end, pixels_problem
from psg_data.schemas._records import CameraIntrinsics
from psg_data.writers._dataset_writer import encode_color, encode_depth

__all__ = ["ScanTask", "ScanResult", "run_task", "open_task_writer", "discover_topics", "STATE_DIR", "SKIP_REASONS",
           "SKIP_KINDS", "explain_nothing"]

log = logging.getLogger(__name__)

STATE_DIR = ".psg_convert"
"""Directory inside ``OUT.partial`` holding per-scan conversion records (removed on completion)."""

_MAX_WARNINGS = 10
"""Corrupt images warned about one by one per recording (the rest are counted in the report)."""

SKIP_REASONS = {
    "no_depth": "colour frame without a depth image within the sync tolerance",
    "no_color": "depth image without a colour frame within the sync tolerance",
    "no_pose": "no pose sample near the frame stamp (or a gap above max_pose_gap_s)",
    "nonfinite_pose": "pose with NaN or infinite values",
    "duplicate_stamp": "second colour frame with an already used header stamp",
    "out_of_order": "colour frame older than one already written (it arrived more than buffer_s late; raise "
                    "buffer_s with --config to sort such frames in)",
    "corrupt_image": "frame whose colour or depth image is truncated or damaged (see image_check)",
    "no_image": "RTAB-Map node without a colour image (no Data row, or Data.image empty)",
}

_IMAGE = "sensor_msgs/msg/Image"
_COMPRESSED = "sensor_msgs/msg/CompressedImage"
_INFO = "sensor_msgs/msg/CameraInfo"
_TF = "tf2_msgs/msg/TFMessage"
_ODOM = "nav_msgs/msg/Odometry"


@dataclass
class ScanTask:
    """One source to convert (picklable, sent to worker processes)."""

    source: str
    kind: str
    """Recording format (ros1, ros2-sqlite3, ros2-mcap, mcap) or folder format (tum, scannet)."""
    scan_id: str
    """Scan id, or the prefix of ``{prefix}_{k:03d}`` ids when splitting."""
    split_label: str | None
    config: dict[str, Any]
    out: str
    color_encoding: str
    camera_ids: dict[str, str]
    skip_scans: list[str] = field(default_factory=list)
    threads: int = 0
    """Image-encoding threads beside the reading thread (0: encode in the reading thread)."""
    image_layout: str = "tar"


@dataclass
class ScanResult:
    scan_id: str
    camera: dict[str, Any]
    frames: int
    skipped: dict[str, int]
    keyframe_dropped: int
    bytes_in: int
    source: str
    seconds: float
    passthrough: dict[str, int]
    warnings: list[str] = field(default_factory=list)
    """Warnings about the scan (corrupt images skipped), printed when the whole conversion is done."""
    pose_source: str = ""
    """How the poses were obtained, where the input offers a choice (RTAB-Map: ``optimized``,
    ``pose_graph`` or ``odometry``); recorded in the manifest."""
    node_labels: dict[str, str] = field(default_factory=dict)
    """RTAB-Map ``Node.label`` by frame stamp (nanoseconds, as text); recorded in the manifest."""
    record: dict[str, Any] | None = None
    """The scan as written (``scan``, ``frames``, ``files``; see DatasetWriter.scan_record); not in
    the state file, which a resumed run reads together with the writer's own scan record."""

    def state(self) -> dict[str, Any]:
        """What the state file of the scan stores (everything but the record)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "record"}


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def discover_topics(topics: dict[str, str], cfg: ConvertConfig, where: str) -> dict[str, Any]:
    """Choose the colour, depth, camera-info, TF and odometry topics from their message types.

    Raises:
        ConversionError: no depth / colour / camera_info topic, an override that does not exist or
            has the wrong type, or an ambiguous choice.
    """
    def check(topic: str, types: tuple[str, ...], what: str) -> str:
        if topic not in topics:
            raise ConversionError(f"{where}: {topic}: no such topic for the {what}; topics are "
                                  f"{', '.join(sorted(topics))}")
        if topics[topic] not in types:
            raise ConversionError(f"{where}: {topic}: is a {topics[topic]}, expected {' or '.join(types)} for the "
                                  f"{what}")
        return topic

    images = {t: m for t, m in topics.items() if m in (_IMAGE, _COMPRESSED)}
    depth_c = [t for t in images if "depth" in t.lower()]
    color_c = [t for t in images if "depth" not in t.lower() and not any(k in t.lower() for k in ("infra", "ir/"))]

    def prefer(cands: list[str], compressed_first: bool, what: str, flag: str) -> str:
        if not cands:
            raise ConversionError(f"{where}: no {what} topic (sensor_msgs/Image or CompressedImage); expected a "
                                  f"recording with {what} (or pass {flag})")
        def rank(t: str) -> tuple[int, int, int, str]:
            comp = topics[t] == _COMPRESSED
            named = 0 if any(k in t.lower() for k in (("depth",) if what == "depth" else ("color", "rgb"))) else 1
            aligned = 0 if ("aligned" in t or what != "depth") else 1
            return (named, aligned, (0 if comp else 1) if compressed_first else (1 if comp else 0), t)
        ranked = sorted(cands, key=rank)
        return ranked[0]

    jpeg_wanted = cfg.color_encoding == "jpeg"
    color = check(cfg.color_topic, (_IMAGE, _COMPRESSED), "colour") if cfg.color_topic else \
        prefer(color_c, jpeg_wanted, "colour", "--color-topic")
    depth = check(cfg.depth_topic, (_IMAGE, _COMPRESSED), "depth") if cfg.depth_topic else \
        prefer(depth_c, True, "depth", "--depth-topic")
    infos = [t for t, m in topics.items() if m == _INFO]
    if cfg.camera_info_topic:
        info = check(cfg.camera_info_topic, (_INFO,), "camera intrinsics")
    else:
        if not infos:
            raise ConversionError(f"{where}: no sensor_msgs/CameraInfo topic; expected the colour camera's "
                                  f"camera_info (or pass --camera-info-topic)")
        ns = color.rsplit("/", 2)[0] if color.count("/") >= 2 else ""
        infos.sort(key=lambda t: (0 if ns and t.startswith(ns + "/") else 1, 0 if "color" in t else 1, t))
        info = infos[0]
    tf = [t for t, m in topics.items() if m == _TF]
    odom = sorted(t for t, m in topics.items() if m == _ODOM)
    return {"color": color, "depth": depth, "camera_info": info,
            "tf": [t for t in tf if not t.endswith("tf_static")],
            "tf_static": [t for t in tf if t.endswith("tf_static")],
            "odom": odom, "color_type": topics[color], "depth_type": topics[depth]}


class _Payload:
    """A colour or depth image as it arrived: a message, encoded bytes (a view of the message), a
    file, or an array decoded by the reader (``array``: RGB uint8 or uint16 millimetres); ``where``
    names it in errors instead of the topic (e.g. an RTAB-Map node and field).
    """

    __slots__ = ("kind", "obj", "fmt", "where")

    def __init__(self, kind: str, obj: Any, fmt: str = "", where: str = "") -> None:
        self.kind, self.obj, self.fmt, self.where = kind, obj, fmt, where


def _image_name(source: Any, payload: _Payload, topic: str, stamp: int) -> str:
    """Where an image came from: its file (frame folders), else the recording, topic and stamp."""
    if payload.kind == "file":
        return str(payload.obj)
    return f"{source}: {topic} at stamp {stamp} ns"


def _camera_from_info(msg: Any, camera_id: str, frame_id: str, where: str) -> CameraIntrinsics:
    K = np.asarray(getattr(msg, "K", None) if hasattr(msg, "K") else msg.k, dtype=float)
    D = np.asarray(getattr(msg, "D", None) if hasattr(msg, "D") else msg.d, dtype=float)
    if K.size != 9 or not np.all(np.isfinite(K)) or K[0] <= 0 or K[4] <= 0:
        raise ConversionError(f"{where}: CameraInfo K: expected a finite 3x3 matrix with fx, fy > 0, got {K.tolist()}")
    for name, what in intrinsics_problems(int(msg.width), int(msg.height), float(K[0]), float(K[4]), float(K[2]),
                                          float(K[5]))[:1]:
        raise ConversionError(f"{where}: CameraInfo {name}: {what}")
    if not np.all(np.isfinite(D)):
        raise ConversionError(f"{where}: CameraInfo D: expected finite distortion coefficients, got {D.tolist()}")
    model = str(msg.distortion_model or "")
    coeffs: tuple[float, ...] = ()
    if D.size == 0 or not np.any(D):
        model = "none"
    elif model in ("plumb_bob", "equidistant"):
        coeffs = tuple(float(v) for v in D)
    else:
        raise ConversionError(f"{where}: CameraInfo distortion_model {model!r} with non-zero D; expected "
                              f"'plumb_bob' or 'equidistant' (or an undistorted camera)")
    return CameraIntrinsics(camera_id, int(msg.width), int(msg.height), float(K[0]), float(K[4]), float(K[2]),
                            float(K[5]), model, coeffs, 0.001, frame_id.lstrip("/") or None)


def _first(item: tuple[int, Any]) -> int:
    return item[0]


class _Assembler:
    """Pairs colour and depth on header stamps within a tolerance, releasing colour frames in stamp order.

    Log time plays no part: the horizons are the newest header stamps seen per stream, and the
    caller releases the oldest colour frame once its partners can no longer arrive (see ``_run_bag``).
    """

    def __init__(self, tol_ns: int) -> None:
        self.tol = tol_ns
        self.colors: list[tuple[int, _Payload]] = []
        self.depth_stamps: list[int] = []
        self.depths: dict[int, _Payload] = {}
        self.seen_colors: set[int] = set()
        self.last_emitted = -(1 << 62)
        self.depth_h = -(1 << 62)
        """Newest depth header stamp seen."""
        self.image_h = -(1 << 62)
        """Newest colour or depth header stamp seen."""
        self.nearest_miss_ns: int | None = None
        """Smallest distance from a colour frame without depth to the nearest depth image."""
        self.skipped: Counter[str] = Counter()

    def add_color(self, stamp: int, p: _Payload) -> None:
        if stamp in self.seen_colors or stamp == self.last_emitted:
            self.skipped["duplicate_stamp"] += 1
            return
        if stamp < self.last_emitted:  # its successor was released already: it drops itself only
            self.skipped["out_of_order"] += 1
            return
        if stamp > self.image_h:
            self.image_h = stamp
        self.seen_colors.add(stamp)
        if not self.colors or stamp > self.colors[-1][0]:  # the usual case: in stamp order
            self.colors.append((stamp, p))
        else:
            bisect.insort(self.colors, (stamp, p), key=_first)

    def add_depth(self, stamp: int, p: _Payload) -> None:
        if stamp in self.depths:
            return
        if stamp > self.depth_h:
            self.depth_h = stamp
            if stamp > self.image_h:
                self.image_h = stamp
        if not self.depth_stamps or stamp > self.depth_stamps[-1]:
            self.depth_stamps.append(stamp)
        else:
            bisect.insort(self.depth_stamps, stamp)
        self.depths[stamp] = p

    def pop(self) -> tuple[int, _Payload, _Payload] | None:
        """Release the oldest colour frame with its nearest depth (None, counted, if it has none)."""
        stamp, cp = self.colors.pop(0)
        self.seen_colors.discard(stamp)  # pending stamps only: memory bounded by the window
        self.last_emitted = stamp
        ds = self.depth_stamps
        while ds and ds[0] < stamp - self.tol:  # depth older than this colour's window matches nothing now
            self.depths.pop(ds.pop(0))
            self.skipped["no_color"] += 1
        i = bisect.bisect_left(ds, stamp - self.tol)
        best = None
        for j in range(i, len(ds)):
            d = ds[j]
            if d > stamp + self.tol:
                break
            if best is None or abs(d - stamp) < abs(ds[best] - stamp):
                best = j
        if best is None:
            self.skipped["no_depth"] += 1
            near = [abs(ds[j] - stamp) for j in (i - 1, i) if 0 <= j < len(ds)]
            if near and (self.nearest_miss_ns is None or min(near) < self.nearest_miss_ns):
                self.nearest_miss_ns = min(near)
            return None
        return stamp, cp, self.depths.pop(ds.pop(best))

    def drain(self) -> Iterator[tuple[int, _Payload, _Payload]]:
        """Release every colour frame left (end of the recording); left-over depth images are counted."""
        while self.colors:
            item = self.pop()
            if item is not None:
                yield item
        self.skipped["no_color"] += len(self.depth_stamps)
        self.depth_stamps.clear()
        self.depths.clear()


class _PoseSource:
    """Camera-to-world poses (OpenCV optical axes) from TF, an odometry topic or a TUM file."""

    def __init__(self, cfg: ConvertConfig, tf: TfBuffer, topics: dict[str, Any] | None, where: str) -> None:
        self.cfg, self.tf, self.where = cfg, tf, where
        self.max_gap = int(cfg.max_pose_gap_s * 1e9)
        self.tol = int(cfg.pose_tolerance_s * 1e9)
        self.series = PoseSeries()
        self.kind: str | None = None
        self.world = self.frame = ""
        self.odom_topic: str | None = None
        if cfg.poses:
            kind, a, b = parse_pose_source(cfg.poses)
            self.kind = kind
            if kind == "tf":
                self.world, self.frame = a, b or ""
            elif kind == "odom":
                self.odom_topic = a
                if topics is not None and a not in [*topics["odom"]]:
                    raise ConversionError(f"{where}: {a}: no nav_msgs/Odometry topic of that name for --poses; "
                                          f"odometry topics: {', '.join(topics['odom']) or 'none'}")
            else:
                path = Path(a)
                if not path.is_file():
                    raise ConversionError(f"{a}: --poses tum: file not found")
                for s, t, q in read_tum_poses(path):
                    self.series.add(s, t, q)
                self.frame = cfg.tum_frame or ""
        elif topics is not None and not topics["tf"] and topics["odom"]:
            self.kind, self.odom_topic = "odom", topics["odom"][0]
        self.optical = ""
        self._resolved: tuple[Any, ...] | None = None
        self._plan: tuple[str, bool] = ("", False)

    def resolve_auto(self) -> None:
        if self.kind is None:
            frames = set(self.tf.frames)
            if "map" in frames:
                self.kind, self.world = "tf", "map"
            elif "odom" in frames:
                self.kind, self.world = "tf", "odom"
            else:
                raise ConversionError(f"{self.where}: no pose source: /tf has no 'map' or 'odom' frame and there is "
                                      f"no nav_msgs/Odometry topic; pass --poses tf:A->B, odom:/TOPIC or tum:FILE")

    def add_odom(self, msg: Any) -> None:
        p = msg.pose.pose
        if not self.frame:
            self.frame = str(msg.child_frame_id).lstrip("/")
        self.series.add(_stamp(msg.header), (p.position.x, p.position.y, p.position.z),
                        (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w))

    def _targets(self) -> tuple[str, bool]:
        """(frame looked up from the world frame, whether the optical frame is appended from TF)."""
        key = (self.kind, self.frame, self.optical)
        if self._resolved != key:  # what to look up, decided again whenever the frames change
            self.resolve_auto()
            target = self.frame or self.optical
            extra = bool(target and self.optical and target.lstrip("/") != self.optical.lstrip("/"))
            self._plan = (target, extra)
            self._resolved = (self.kind, self.frame, self.optical)
        return self._plan

    def ready(self, stamp: int) -> bool:
        """Whether every pose sample a lookup at ``stamp`` (header time) may use has arrived: each
        dynamic edge of the path has a sample at or after ``stamp`` (static paths and pose files: always).
        """
        if self.kind == "tum":
            return True
        if self.kind == "odom":
            last = self.series.last_stamp
            if last is None or last < stamp:
                return False
        elif self.kind is None and not self.tf.frames:
            return False  # no TF yet: the pose source is not known
        try:
            target, extra = self._targets()
        except ConversionError:
            return False  # no 'map' / 'odom' frame (yet)
        if self.kind == "tf":
            h = self.tf.horizon(self.world, target)
            if h is None or h < stamp:
                return False
        if extra:
            h = self.tf.horizon(target, self.optical)
            if h is None or h < stamp:
                return False
        return True

    def span(self) -> tuple[int, int] | None:
        """First and last stamp of the pose samples seen (dynamic ones), or None."""
        if self.kind in ("odom", "tum"):
            st = self.series.stamps
            return (st[0], st[-1]) if st else None
        stamps = [s for series in self.tf.dynamic.values() for s in (series.stamps[:1] + series.stamps[-1:])]
        return (min(stamps), max(stamps)) if stamps else None

    def at(self, stamp: int) -> NDArray[np.float64] | None:
        target, extra = self._targets()
        if self.kind == "tf":
            T = self.tf.lookup(self.world, target, stamp, self.where)
        else:
            T = self.series.at(stamp, self.max_gap, self.tol)
        if T is None:
            return None
        if extra:
            E = self.tf.lookup(target, self.optical, stamp, self.where)
            if E is None:
                return None
            T = T @ E
        return T


_A = TypeVar("_A", bound=np.ndarray)


def _decoded(image: _A | None) -> _A:
    """An image the frame writer decoded (it returns the bytes or the array of each image)."""
    if image is None:
        raise AssertionError("neither encoded bytes nor a decoded array")
    return image


def _passthrough_ok(info: EncodedInfo, encoding: str) -> bool:
    """Whether an encoded colour image can be stored as is in a dataset of ``encoding``."""
    if encoding == "jpeg":
        return info.kind == "jpeg" and info.channels == 3 and info.bit_depth == 8
    return info.kind == "png" and info.channels == 3 and info.bit_depth == 8


class _FrameWriter:
    """Turns a (colour, depth) payload pair into stored images, passing encoded bytes through.

    Every encoded image is checked at ``image_check`` (:mod:`psg_data.schemas._image_check`) whether
    it is passed through or decoded; a damaged one raises :class:`ImageDataError` (the frame is
    skipped, or refused with ``strict``).
    """

    def __init__(self, encoding: str, depth_scale_m: float, where: str, image_check: str = "structure") -> None:
        self.encoding = encoding
        self.depth_scale_m = depth_scale_m
        self.scale_is_mm = abs(depth_scale_m - 0.001) < 1e-12
        self.where = where
        self.level = image_check
        self._headers: dict[str, tuple[bytes, EncodedInfo]] = {}
        self._cd_formats: dict[str, bool] = {}
        """format string -> whether it names a compressedDepth payload."""
        self._wheres: dict[str, str] = {}
        self.passthrough: Counter[str] = Counter()

    def _inspect(self, slot: str, data: Any) -> EncodedInfo | None:
        """inspect_encoded, skipping the parse when the header bytes equal the previous image's."""
        prev = self._headers.get(slot)
        if prev is not None and bytes(data[:len(prev[0])]) == prev[0]:
            return prev[1]
        try:
            info, end = parse_image_header_end(data)
        except ValueError:
            return None
        self._headers[slot] = (bytes(data[:end]), info)
        return info

    def _where(self, topic: str, p: _Payload) -> str:
        if p.kind == "file":
            return str(p.obj)
        if p.where:
            return p.where
        where = self._wheres.get(topic)
        if where is None:
            where = self._wheres[topic] = f"{self.where}: {topic}"
        return where

    @staticmethod
    def _bytes(p: _Payload, where: str) -> Any:
        if p.kind == "bytes":
            return p.obj  # a view of the message
        try:
            return Path(p.obj).read_bytes()
        except OSError as exc:
            raise ConversionError(f"{p.obj}: cannot read the image ({exc.strerror or exc})") from exc

    def _encoded(self, slot: str, data: Any, fmt: str, where: str, what: str,
                 size: tuple[int, int] | None) -> EncodedInfo:
        """Header of an encoded image, checked against the pixel cap and the camera's ``size`` (width,
        height; None: the cap only) before anything is inflated or decoded, then at the configured level.

        Raises:
            ConversionError: a size that does not fit (as any image of the wrong size).
            ImageDataError: a damaged image.
        """
        info = self._inspect(slot, data)
        if info is None:
            kind = looks_like_image(data) or next((k for k in ("png", "jpeg") if k in fmt.lower()), None)
            if kind is None and fmt != "file":
                raise ConversionError(f"{where}: unknown {what} format {fmt!r}: the data is neither PNG nor JPEG "
                                      f"(starts with {bytes(memoryview(data)[:4]).hex()}); expected PNG or JPEG data")
            raise ImageDataError(where, f"corrupt {(kind or 'image').upper()}: unreadable header")
        problem = pixels_problem(info.width, info.height, size)
        if problem:
            raise ConversionError(f"{where}: {problem} ({what}); not decoded")
        if self.level != "none":
            try:
                check_image(data, self.level, header=info)
            except DamagedImage as exc:
                raise ImageDataError(where, f"corrupt {info.kind.upper()}: {exc}") from None
        return info

    def color(self, p: _Payload, topic: str, size: tuple[int, int] | None = None
              ) -> tuple[Any, NDArray[np.uint8] | None, tuple[int, int]]:
        where = self._where(topic, p)
        if p.kind == "msg" or p.kind == "array":
            arr = decode_color_image(p.obj, where) if p.kind == "msg" else p.obj
            return None, arr, (arr.shape[1], arr.shape[0])
        data = self._bytes(p, where)
        info = self._encoded("color", data, p.fmt or "file", where, "colour image", size)
        if _passthrough_ok(info, self.encoding):
            self.passthrough["color"] += 1
            return data, None, (info.width, info.height)
        arr = decode_compressed_color(data, p.fmt or "file", where)
        return None, arr, (arr.shape[1], arr.shape[0])

    def depth(self, p: _Payload, topic: str, size: tuple[int, int] | None = None
              ) -> tuple[Any, NDArray[np.uint16] | None, tuple[int, int]]:
        where = self._where(topic, p)
        if p.kind == "msg" or p.kind == "array":
            arr = decode_depth_image(p.obj, where, self.depth_scale_m) if p.kind == "msg" else p.obj
            return None, arr, (arr.shape[1], arr.shape[0])
        fmt = p.fmt
        data = self._bytes(p, where)
        compressed_depth = self._cd_formats.get(fmt)
        if compressed_depth is None:
            compressed_depth = self._cd_formats[fmt] = "compresseddepth" in fmt.lower()
        png, src = data, "16UC1"
        if compressed_depth:
            png, src, _ = compressed_depth_png(data, fmt, where)
        info = self._encoded("depth", png, fmt or "file", where, "depth image", size)
        if info.kind != "png":
            raise ConversionError(f"{where}: depth image is a {info.kind.upper()}; expected a 16-bit PNG "
                                  f"('16UC1; compressedDepth png')")
        if self.scale_is_mm and src.upper() in ("16UC1", "MONO16") and info.bit_depth == 16 and info.channels == 1:
            self.passthrough["depth"] += 1
            return png, None, (info.width, info.height)
        if info.bit_depth != 16:
            raise ConversionError(f"{where}: depth PNG is {info.bit_depth}-bit; expected 16-bit depth")
        arr = decode_compressed_depth(data, fmt if compressed_depth else "png", where, self.depth_scale_m)
        return None, arr, (arr.shape[1], arr.shape[0])


class _ScanSink:
    """Receives complete frames; splits them into scans, applies keyframes, writes them."""

    def __init__(self, task: ScanTask, cfg: ConvertConfig, writer: Any, fw: _FrameWriter, names: tuple[str, str],
                 progress: Callable[..., Any] | None) -> None:
        self.task, self.cfg, self.w, self.fw = task, cfg, writer, fw
        self.names = names
        self.progress = progress
        self.split = parse_split(cfg.split)
        self.keyframes = parse_keyframes(cfg.keyframes)
        self.camera: CameraIntrinsics | None = None
        self.results: list[ScanResult] = []
        self.sw: Any = None
        self.scan_id: str | None = None
        self.k = 0
        self.last_stamp: int | None = None
        self.last_key_T: NDArray[np.float64] | None = None
        self.n_seen = 0
        self.kf_dropped = 0
        self.skipped: Counter[str] = Counter()
        self.t0 = time.perf_counter()
        self.bytes_mark = 0
        self.bytes_in = 0
        self.skip_current = False
        self.warnings: list[str] = []
        self.stamp_span: tuple[int, int] | None = None
        """First and last stamp of the colour + depth pairs received."""
        self.diagnosis: dict[str, Any] = {"names": names}
        """What explains a conversion without frames (filled in by the runner)."""
        self.result_fields: Callable[[str], dict[str, Any]] | None = None
        """Extra :class:`ScanResult` fields of a scan, by scan id (set by runners that have them)."""

    def _scan_for(self, stamp: int) -> str:
        if self.split is None:
            return self.task.scan_id
        kind, ns = self.split
        if kind == "slot":
            return f"{self.task.scan_id}_{stamp // ns:06d}"
        if self.last_stamp is not None and stamp - self.last_stamp > ns:
            self.k += 1
        return f"{self.task.scan_id}_{self.k:03d}"

    def _close_scan(self) -> None:
        if self.scan_id is None:
            return
        if self.sw is not None:
            if self.sw.n_frames == 0:
                raise ConversionError(f"{self.task.source}: scan {self.scan_id}: no frame could be converted: "
                                      f"{explain_nothing(self.skipped, self.cfg, self.diagnosis)}")
            self.sw.close()
            assert self.camera is not None
            res = ScanResult(self.scan_id, asdict(self.camera), self.sw.n_frames, dict(self.skipped),
                             self.kf_dropped, self.bytes_in - self.bytes_mark, self.task.source,
                             time.perf_counter() - self.t0, dict(self.fw.passthrough), list(self.warnings),
                             **(self.result_fields(self.scan_id) if self.result_fields else {}))
            state = Path(self.w.tmp) / STATE_DIR
            state.mkdir(exist_ok=True)
            (state / f"{self.scan_id}.json").write_text(json.dumps(res.state()))
            self.results.append(res)
        self.sw = None
        self.scan_id = None
        self.warnings = []
        self.skipped = Counter()
        self.kf_dropped = 0
        self.bytes_mark = self.bytes_in
        self.t0 = time.perf_counter()
        self.fw.passthrough.clear()

    def _keep(self, T: NDArray[np.float64]) -> bool:
        if self.keyframes is None:
            return True
        kind, a, b = self.keyframes
        self.n_seen += 1
        if kind == "every":
            return (self.n_seen - 1) % int(a) == 0
        if self.last_key_T is None:
            return True
        dT = np.linalg.inv(self.last_key_T) @ T
        ang = math.acos(max(-1.0, min(1.0, (np.trace(dT[:3, :3]) - 1) / 2)))
        return bool(np.linalg.norm(dT[:3, 3]) >= a or ang >= b)

    def frame(self, stamp: int, T: NDArray[np.float64] | None, cp: _Payload, dp: _Payload, nbytes: int) -> None:
        if self.stamp_span is None:
            self.stamp_span = (stamp, stamp)
        else:
            self.stamp_span = (self.stamp_span[0], stamp)
        scan_id = self.task.scan_id if self.split is None else self._scan_for(stamp)
        self.last_stamp = stamp
        if scan_id != self.scan_id:
            self._close_scan()
            self.scan_id = scan_id
            self.n_seen = 0
            self.last_key_T = None
            self.skip_current = scan_id in self.task.skip_scans
            if not self.skip_current:
                self.sw = self.w.scan(scan_id, source=Path(self.task.source).name, split=self.task.split_label)
        self.bytes_in += nbytes
        if self.skip_current:
            return
        if T is None:
            self.skipped["no_pose"] += 1
            return
        if not math.isfinite(sum(T.ravel().tolist())):  # NaN and inf propagate into the sum
            self.skipped["nonfinite_pose"] += 1
            return
        if self.keyframes is not None and not self._keep(T):
            self.kf_dropped += 1
            return
        self.last_key_T = T
        cam = self.camera
        assert cam is not None
        if cam.camera_id not in self.w.cameras:
            self.w.add_camera(cam)
        size = (cam.width, cam.height)
        try:  # ScanNet's colour images are larger than its depth (the camera's size): resized below
            cb, ca, csize = self.fw.color(cp, self.names[0], None if self.task.kind == "scannet" else size)
            db, da, dsize = self.fw.depth(dp, self.names[1], size)
        except ImageDataError as exc:
            self._corrupt(stamp, exc)
            return
        if ca is not None and self.task.kind == "scannet" and csize != dsize:
            import cv2

            ca = np.asarray(cv2.resize(ca, dsize, interpolation=cv2.INTER_AREA), dtype=np.uint8)
            csize = dsize
        if csize != dsize:
            raise ConversionError(f"{_image_name(self.task.source, dp, self.names[1], stamp)}: depth is "
                                  f"{dsize[0]}x{dsize[1]} but colour is {csize[0]}x{csize[1]}; expected depth "
                                  f"registered to colour (aligned_depth_to_color)")
        if csize != (cam.width, cam.height):
            raise ConversionError(f"{_image_name(self.task.source, cp, self.names[0], stamp)}: images are "
                                  f"{csize[0]}x{csize[1]} but the camera is {cam.width}x{cam.height}; expected the "
                                  f"colour camera's size (CameraInfo, or the first frame of a folder)")
        if type(T) is not np.ndarray or T.dtype != np.float64:
            T = np.asarray(T, dtype=np.float64)
        if cb is not None and db is not None:
            self.sw.add_encoded_frame(stamp, T, cb, db, cam.camera_id)
        elif ca is not None and da is not None:
            self.sw.add_frame(stamp, T, ca, da, cam.camera_id)
        else:  # one image passed through, the other decoded: encode that one
            color = cb if cb is not None else encode_color(_decoded(ca), self.fw.encoding)
            self.sw.add_encoded_frame(stamp, T, color, db if db is not None else encode_depth(_decoded(da)),
                                      cam.camera_id)
        if self.progress is not None:
            self.progress(1, nbytes)

    def _corrupt(self, stamp: int, exc: ImageDataError) -> None:
        """A damaged image: refused with ``strict``, else the frame is skipped with a warning."""
        where = f"{exc.where}: frame at stamp {stamp // 10**9}.{stamp % 10**9:09d} s"
        if self.cfg.strict:
            raise ConversionError(f"{where}: {exc.reason}; refused by --strict (without it the frame is skipped)")
        self.skipped["corrupt_image"] += 1
        n = self.skipped["corrupt_image"]
        if n == 1:
            self.diagnosis["first_corrupt"] = f"{where}: {exc.reason}"
        if n <= _MAX_WARNINGS:  # printed once the conversion is done (an error then stays one line)
            self.warnings.append(f"{where}: {exc.reason}; frame skipped"
                                 + ("" if n < _MAX_WARNINGS else " (further corrupt images of this scan are only "
                                                                 "counted)"))

    def abort_scan(self) -> None:
        """Drop the scan being written (an error stops the task)."""
        if self.sw is not None:
            self.sw.abort()
            self.sw = None

    def finish(self, asm_skipped: Counter[str]) -> list[ScanResult]:
        self.skipped.update(asm_skipped)
        if self.scan_id is None and not self.results:
            raise ConversionError(f"{self.task.source}: no frame could be converted: "
                                  f"{explain_nothing(self.skipped, self.cfg, self.diagnosis)}")
        self._close_scan()
        return self.results


SKIP_KINDS = {"no_depth": "color", "duplicate_stamp": "color", "out_of_order": "color", "no_color": "depth",
              "no_pose": "frames", "nonfinite_pose": "frames", "corrupt_image": "frames", "no_image": "frames"}
"""What each skip reason counts: colour images, depth images or (colour + depth) frames."""


def _span_s(span: tuple[int, int] | None) -> str:
    return "none" if span is None else f"[{span[0] / 1e9:.3f}, {span[1] / 1e9:.3f}] s"


def explain_nothing(skipped: Counter[str], cfg: ConvertConfig, diag: dict[str, Any]) -> str:
    """Why no frame was converted, and which settings would help (one line)."""
    color_topic, depth_topic = diag.get("names", ("colour", "depth"))
    counts = ", ".join(f"{k} {v}" for k, v in sorted(skipped.items()) if v) or "none"
    main = max(((v, k) for k, v in skipped.items() if v and k != "no_color"), default=(0, ""))[1]
    own = diag.get("hints", {}).get(main)  # an input's own words (RTAB-Map has no topics or --poses)
    if own:
        hint = own
    elif not main:
        hint = (f"no colour image was read from {color_topic}" if not skipped.get("no_color") else
                f"{skipped['no_color']} depth images but no colour image on {color_topic}; check --color-topic")
    elif main == "no_depth":
        near = diag.get("nearest_miss_ns")
        hint = (f"no depth image within sync_tolerance_s = {cfg.sync_tolerance_s:g} s of the colour stamps"
                + (f" (the nearest was {near / 1e9:.3f} s away)" if near is not None else
                   f" (no depth image on {depth_topic} near them)")
                + "; raise --sync-tolerance or check --depth-topic")
    elif main == "no_pose":
        hint = (f"no pose within max_pose_gap_s = {cfg.max_pose_gap_s:g} s / pose_tolerance_s = "
                f"{cfg.pose_tolerance_s:g} s of the frame stamps (pose samples span "
                f"{_span_s(diag.get('pose_span'))}, frames {_span_s(diag.get('frame_span'))}); check --poses, or "
                f"raise max_pose_gap_s, pose_tolerance_s or buffer_s (now {cfg.buffer_s:g} s) with --config")
    elif main == "nonfinite_pose":
        hint = "every pose has NaN or infinite values; check the pose source (--poses)"
    elif main == "no_image":
        hint = "no node has a colour image in Data.image (a map saved without images?)"
    elif main == "corrupt_image":
        hint = (f"every frame has a damaged image (the first: {diag.get('first_corrupt', '?')}; --image-check "
                f"sets the check)")
    else:
        hint = (f"colour header stamps repeat or go backwards by more than buffer_s = {cfg.buffer_s:g} s; "
                f"raise buffer_s with --config")
    return f"{hint} (skipped: {counts})"


def open_task_writer(task: ScanTask) -> Any:
    """The dataset writer tasks write their scans with: ``OUT.partial``, resumable."""
    from psg_data.writers import DatasetWriter

    return DatasetWriter(task.out, color_encoding=task.color_encoding, overwrite=True, resume=True,
                         threads=task.threads, image_layout=task.image_layout)


def _release_rule(asm: _Assembler, poses: _PoseSource, cfg: ConvertConfig) -> Callable[[], bool]:
    """Whether the oldest held colour frame is due, by header stamps only (log time plays no part).

    It is due once the image streams' header time has moved ``buffer_s`` past it (later colour
    frames that arrive out of order are sorted in meanwhile) and its partners are complete: a depth
    image stamped beyond its sync tolerance has arrived and every pose sample its lookup uses
    (:meth:`_PoseSource.ready`); or, whatever is missing, once the image streams have moved
    ``buffer_s + max_pose_gap_s`` past it (a partner that late is taken to be lost). Memory is
    bounded by that window of frames.
    """
    hold = int(cfg.buffer_s * 1e9)
    window = int((cfg.buffer_s + cfg.max_pose_gap_s) * 1e9)
    tol = asm.tol
    colors = asm.colors

    def due() -> bool:
        s = colors[0][0]
        late = asm.image_h - s
        if late > window:
            return True
        return late >= hold and asm.depth_h >= s + tol and poses.ready(s)

    return due


def _run_bag(task: ScanTask, cfg: ConvertConfig, progress: Callable[..., Any] | None, writer: Any
             ) -> list[ScanResult]:
    from psg_data.loaders.raw._bag import RosRecording

    rec = RosRecording(task.source)
    where = str(rec.path)
    with rec:
        topics = discover_topics(rec.topics, cfg, where)
        tf, poses = _bag_poses(cfg, topics, where)
        asm = _Assembler(int(cfg.sync_tolerance_s * 1e9))
        fw = _FrameWriter(task.color_encoding, cfg.depth_scale_m or 0.001, where, cfg.image_check)
        sink = _ScanSink(task, cfg, writer, fw, (topics["color"], topics["depth"]), progress)
        try:
            _read_camera_info(rec, topics["camera_info"], task, cfg, sink, poses, where)
            release = _Release(asm, poses, sink, cfg, f"{where}: {topics['camera_info']}")
            read_bytes = _stream_messages(rec, topics, tf, poses, asm, release, cfg)
            release(final=True)
            asm.skipped.update(Counter(no_color=len(asm.depth_stamps)))
            sink.diagnosis.update(nearest_miss_ns=asm.nearest_miss_ns, pose_span=poses.span(),
                                  frame_span=sink.stamp_span)
            # the report counts the whole recording as input (topics not needed were not read)
            sink.bytes_in += max(0, rec.size_bytes - read_bytes)
            return sink.finish(asm.skipped)
        except BaseException:
            sink.abort_scan()
            raise


def _bag_poses(cfg: ConvertConfig, topics: dict[str, Any], where: str) -> tuple[TfBuffer, _PoseSource]:
    """The TF buffer (with the configured static transforms) and the pose source of a recording.

    Raises:
        ConversionError: ``--poses tf:...`` for a recording without TF.
    """
    tf = TfBuffer(int(cfg.max_pose_gap_s * 1e9), int(cfg.pose_tolerance_s * 1e9))
    for st in cfg.static_transforms:
        tf.add(str(st["parent"]), str(st["child"]), 0, st["translation"], st["rotation_xyzw"], static=True)
    poses = _PoseSource(cfg, tf, topics, where)
    if cfg.poses and poses.kind == "tf" and not topics["tf"] and not topics["tf_static"] and not cfg.static_transforms:
        raise ConversionError(f"{where}: /tf: no tf2_msgs/TFMessage topic for --poses {cfg.poses}")
    return tf, poses


def _read_camera_info(rec: Any, info_t: str, task: ScanTask, cfg: ConvertConfig, sink: _ScanSink,
                      poses: _PoseSource, where: str) -> None:
    """The intrinsics from the first CameraInfo message (the topic is not read again)."""
    for conn, _, raw in rec.raw_messages({info_t}):
        msg = rec.deserialize(raw, conn.msgtype, info_t)
        frame_id = cfg.camera_frame or str(msg.header.frame_id).lstrip("/")
        cid = task.camera_ids.get(frame_id) or cfg.camera_id or "camera"
        sink.camera = _camera_from_info(msg, cid, frame_id, f"{where}: {info_t}")
        poses.optical = frame_id
        break


class _Release:
    """Writes the held colour frames whose partners can no longer arrive (see :func:`_release_rule`)."""

    def __init__(self, asm: _Assembler, poses: _PoseSource, sink: _ScanSink, cfg: ConvertConfig,
                 info_where: str) -> None:
        self.asm, self.poses, self.sink, self.info_where = asm, poses, sink, info_where
        self.due = _release_rule(asm, poses, cfg)
        self.pending_bytes = 0
        """Bytes read since the last frame written (counted with the next one)."""

    def __call__(self, final: bool = False) -> None:
        """Write the due frames (all of them if ``final``)."""
        asm, sink = self.asm, self.sink
        if sink.camera is None:
            if not final:
                return
            raise ConversionError(f"{self.info_where}: no CameraInfo message; expected the colour camera's intrinsics")
        colors, due = asm.colors, self.due
        while colors and (final or due()):
            item = asm.pop()
            if item is not None:
                stamp, cp, dp = item
                sink.frame(stamp, self.poses.at(stamp), cp, dp, self.pending_bytes)
                self.pending_bytes = 0


def _stream_messages(rec: Any, topics: dict[str, Any], tf: TfBuffer, poses: _PoseSource, asm: _Assembler,
                     release: _Release, cfg: ConvertConfig) -> int:
    """Read the wanted topics in log-time order into the assembler, TF and pose source, releasing
    frames as they become due; returns the bytes read.
    """
    color_t, depth_t, info_t = topics["color"], topics["depth"], topics["camera_info"]
    wanted = {color_t, depth_t, *topics["tf"], *topics["tf_static"]}
    if poses.odom_topic:
        wanted.add(poses.odom_topic)
    if info_t in (color_t, depth_t, poses.odom_topic):
        wanted.add(info_t)
    static_t = set(topics["tf_static"])
    colors = asm.colors
    read_bytes = 0
    for conn, _, raw in rec.raw_messages(wanted):
        topic = conn.topic
        n_raw = len(raw)
        release.pending_bytes += n_raw
        read_bytes += n_raw
        if topic == color_t or topic == depth_t:
            if conn.msgtype == _COMPRESSED:  # only header, format and data: no full deserialisation
                ci = rec.compressed_image(raw, topic)
                stamp, frame_id = ci.stamp_ns, ci.frame_id
                payload = _Payload("bytes", ci.data, ci.format)
            else:
                msg = rec.deserialize(raw, conn.msgtype, topic)
                stamp, frame_id, payload = _stamp(msg.header), str(msg.header.frame_id), _Payload("msg", msg)
            if topic == color_t:
                asm.add_color(stamp, payload)
                if not poses.optical:
                    poses.optical = cfg.camera_frame or frame_id.lstrip("/")
            else:
                asm.add_depth(stamp, payload)
        elif conn.msgtype == _TF:
            static = topic in static_t
            for smp in rec.tf_transforms(raw, topic):  # header, frames and 7 floats: no full message
                tf.add(smp.parent, smp.child, smp.stamp_ns, smp.translation, smp.rotation_xyzw, static=static)
        elif topic == poses.odom_topic:
            poses.add_odom(rec.deserialize(raw, conn.msgtype, topic))
        if colors:
            release()
    return read_bytes


def _run_folder(task: ScanTask, cfg: ConvertConfig, progress: Callable[..., Any] | None, writer: Any
                ) -> list[ScanResult]:
    if task.kind == "tum":
        fr: FolderRecording = read_tum_folder(task.source, cfg.intrinsics, cfg.depth_scale_m)
    else:
        fr = read_scannet_folder(task.source, cfg.fps, cfg.start_stamp_ns, cfg.depth_scale_m, cfg.intrinsics)
    where = str(fr.path)
    tf = TfBuffer(int(cfg.max_pose_gap_s * 1e9), int(cfg.pose_tolerance_s * 1e9))
    poses = _PoseSource(cfg, tf, None, where)
    if poses.kind is None:
        if fr.format == "tum" and not fr.poses_tum:
            gt = fr.path / "groundtruth.txt"
            state = "lists no poses" if gt.is_file() else "missing"
            raise ConversionError(f"{gt}: {state}; expected 'timestamp tx ty tz qx qy qz qw' lines (or pass --poses "
                                  f"tum:FILE)")
        poses.kind = "tum"
        for s, t, q in fr.poses_tum:
            poses.series.add(s, t, q)
    asm = _Assembler(int(cfg.sync_tolerance_s * 1e9))
    for s, p in fr.colors:
        asm.add_color(s, _Payload("file", p))
    for s, p in fr.depths:
        asm.add_depth(s, _Payload("file", p))
    fw = _FrameWriter(task.color_encoding, fr.depth_scale_m, where, cfg.image_check)
    sink = _ScanSink(task, cfg, writer, fw, ("rgb", "depth"), progress)
    try:
        cid = cfg.camera_id or task.camera_ids.get("") or "camera"
        sink.camera = CameraIntrinsics(cid, fr.width, fr.height, *fr.K, depth_scale_m=0.001)
        for stamp, cp, dp in asm.drain():
            if fr.poses_exact and not cfg.poses:
                T = fr.poses_exact.get(stamp)
            else:
                T = poses.at(stamp)
            nbytes = Path(cp.obj).stat().st_size + Path(dp.obj).stat().st_size
            sink.frame(stamp, T, cp, dp, nbytes)
        sink.diagnosis.update(nearest_miss_ns=asm.nearest_miss_ns, pose_span=poses.span(),
                              frame_span=sink.stamp_span)
        return sink.finish(asm.skipped)
    except BaseException:
        sink.abort_scan()
        raise


def run_task(task: ScanTask, progress: Callable[..., Any] | None = None, writer: Any = None) -> list[ScanResult]:
    """Convert one source into one or more scans inside ``OUT.partial`` (see module docstring).

    Args:
        task: the source and its settings.
        progress: called as ``progress(n_frames, nbytes)``.
        writer: a dataset writer on ``OUT.partial`` shared by the tasks of this process; its scans
            may still be completing when this returns and their results carry no record (the
            caller takes them from the writer). Default: a writer of the task's own, finished
            before returning, whose records come with the results.
    """
    cfg = ConvertConfig.from_dict(task.config)
    own = writer is None
    if own:
        writer = open_task_writer(task)
    try:
        if task.kind in ("tum", "scannet"):
            results = _run_folder(task, cfg, progress, writer)
        elif task.kind == "rtabmap":
            from psg_data.convert._rtabmap import run_rtabmap

            results = run_rtabmap(task, cfg, progress, writer)
        else:
            results = _run_bag(task, cfg, progress, writer)
        if own:
            for r in results:
                r.record = writer.scan_record(r.scan_id)
    finally:
        if own:
            writer.abort(keep_partial=True)  # the parent's writer finishes the dataset
    return results
