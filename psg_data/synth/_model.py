"""``LabModel``: the synthetic lab (geometry, schedules, camera, scan trajectories) from a seed.

Scan trajectories: the robot starts every scan in the dock room (room B) and visits the rooms it
can reach through open doors and open passages (a closed door is never crossed; in the ``chain``
layout a closed door hides the room behind it for that scan, in ``two_routes`` and ``corridor`` the
passages reach every room). Keyframe viewpoints are chosen greedily from a grid of
candidate poses (positions in the free centre of each room, yaw every 15 deg, camera 1.25 m above
the floor pitched 28 deg down) so that the top surfaces of as many receptacles as possible are seen;
the frame budget is shared between the reachable rooms in proportion to their receptacles. In the
``corridor`` layout every scan also takes one door keyframe per door, beyond the budget (in the first
room of the route that the door joins, after its receptacle views: the candidate that sees most of
the doorway), so that every scan sees the doors' states (``frames_per_scan`` + 2 frames per scan);
the corridor itself holds no receptacles and gets no views.

Odometry drift: the stored ``T_world_camera`` is exactly the pose the renderer used (images and
poses are consistent). What a real robot's drift would do is represented by the trajectory itself
being irregular: every keyframe is perturbed by a random walk (2 cm per frame in x/y, 0.7 deg in
yaw) plus independent jitter (3 cm, 2 deg yaw, 1 deg pitch and roll, 1 cm height).
"""

from __future__ import annotations

import datetime as dt
import logging
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data._settings import INT64_MAX, Integral, Options, Real, TimeZone, check_settings
from psg_data.errors import PsgDataError
from psg_data.schemas._records import CameraIntrinsics, Door
from psg_data.synth._lab_process import ProcessParams, StepSchedule
from psg_data.synth._lab_schedule import LabSchedule
from psg_data.synth._layout import DOOR_ID0, LAYOUTS, RECEPTACLE_ID0, LabLayout, make_layout
from psg_data.synth._render import DepthNoise, LabRenderer, RenderedFrame, SceneState, d435_intrinsics
from psg_data.synth._schedule import SHIFTS, WEEKDAYS, local_time_ns

__all__ = ["LabConfig", "LAB_SETTINGS", "memory_needed", "check_memory", "LabModel", "ScanPlan", "camera_pose",
           "SYNTH_VERSION", "GENERATORS"]

log = logging.getLogger(__name__)

SYNTH_VERSION = "2"
"""Version of the generator; part of the manifest ``extra`` and of the demo cache key.

"1": continuous-time schedules only; "2": the step process (``steps-v2``) is the default and its
model is stored with the dataset (``generator/process.json``)."""

GENERATORS = ("steps-v2", "continuous-v1")
"""Schedule generators: ``steps-v2`` (default; bi-hourly steps with routines, exact model stored)
and ``continuous-v1`` (the first generator, kept so that old datasets rebuild identically)."""

CAMERA_HEIGHT_M = 1.25
CAMERA_PITCH_DEG = 28.0


@dataclass(frozen=True)
class LabConfig:
    """Parameters of a synthetic lab (all stored in the manifest ``extra``).

    Attributes:
        seed: seed of everything (layout, schedules, trajectories, noise).
        days: number of days (4 scans a day).
        train_days: first days with split 'train', the rest 'test' (default: 2/3 of the days, 14 of 21).
        frames_per_scan: receptacle keyframes per scan (the ``corridor`` layout adds one door
            keyframe per door).
        width, height: image size, pixels.
        shift: distribution shift of the test days: None or 'long-weekend'.
        shift_weekdays: weekdays ('Mon'..'Sun') of the test days that follow the weekend pattern.
        start_date: first local date, ISO (2025-03-03 is a Monday; DST starts on day 6).
        scan_hours: local start hours of the scans of a day.
        timezone: IANA site timezone.
        noise: depth/colour noise model.
        generator: schedule generator, ``steps-v2`` (default) or ``continuous-v1``.
        routine_strength: ``steps-v2``: probability that the day's routine sets an entity's state at
            a step boundary, from 0 (affinity random walk with stays of hours or days) to 1
            (clockwork).
        day_patterns: ``steps-v2``: day patterns per entity (D; workday variants and two weekend
            patterns).
        day_persistence: ``steps-v2``: probability that the next day of the same kind keeps the
            day's pattern (diagonal of the day-level matrix).
        max_dwell_steps: ``steps-v2``: longest stay drawn for an entity's best receptacle, steps.
        layout: the lab geometry, ``corridor`` (default: doors, and a hallway along the rooms with an
            opening into each), ``two_routes`` (a door and an open passage in each inner wall; the
            default before) or ``chain`` (doors only; what datasets without ``layout`` in their
            manifest used), see :mod:`psg_data.synth._layout`.
    """

    seed: int = 0
    days: int = 21
    train_days: int | None = None
    frames_per_scan: int = 8
    width: int = 160
    height: int = 120
    shift: str | None = None
    shift_weekdays: tuple[str, ...] = ("Mon", "Fri")
    start_date: str = "2025-03-03"
    scan_hours: tuple[int, ...] = (9, 11, 13, 15)
    timezone: str = "America/Toronto"
    noise: DepthNoise = field(default_factory=DepthNoise)
    generator: str = "steps-v2"
    routine_strength: float = 0.8
    day_patterns: int = 5
    day_persistence: float = 0.6
    max_dwell_steps: int = 8
    layout: str = "corridor"

    def __post_init__(self) -> None:
        check_settings(LAB_SETTINGS, asdict(self), "synth", PsgDataError)
        bad = [d for d in self.shift_weekdays if d not in WEEKDAYS]
        if bad:
            raise PsgDataError(f"shift_weekdays: unknown {bad}, expected names from {WEEKDAYS}")
        hours = list(self.scan_hours)
        if not hours or any(b <= a for a, b in zip(hours, hours[1:])) or hours[0] < 0 or hours[-1] >= 24:
            raise PsgDataError(f"scan_hours: expected increasing local hours in [0, 24), got {hours}")

    @property
    def n_train_days(self) -> int:
        """Training days: ``train_days``, else the first two thirds of ``days``."""
        return int(self.train_days) if self.train_days is not None else int(round(self.days * 2 / 3))

    @property
    def date(self) -> dt.date:
        """The first day (``start_date``)."""
        return dt.date.fromisoformat(self.start_date)

    def shifted_days(self) -> frozenset[int]:
        """Day indices changed by the shift (test days on ``shift_weekdays``)."""
        if self.shift is None:
            return frozenset()
        return frozenset(d for d in range(self.n_train_days, self.days)
                         if WEEKDAYS[(self.date + dt.timedelta(days=d)).weekday()] in self.shift_weekdays)

    @property
    def process_params(self) -> ProcessParams:
        """The process settings of the ``steps-v2`` generator taken from this config."""
        return ProcessParams(float(self.routine_strength), int(self.day_patterns), float(self.day_persistence),
                             int(self.max_dwell_steps))

    def to_extra(self) -> dict[str, Any]:
        """JSON-able parameters for the manifest ``extra`` (every generator parameter).

        ``generator`` stays ``"psg_data.synth"`` (what readers test for); the schedule generator is
        ``schedule_generator``; ``steps-v2`` datasets also name their stored model ``process_file``.
        """
        d = asdict(self)
        d["shift_weekdays"] = list(self.shift_weekdays)
        d["scan_hours"] = list(self.scan_hours)
        d["train_days"] = self.n_train_days
        d["resolution"] = [self.width, self.height]
        d["schedule_generator"] = d.pop("generator")
        out = {"generator": "psg_data.synth", "synth_version": SYNTH_VERSION, **d}
        if self.generator == "continuous-v1":
            for k in ("routine_strength", "day_patterns", "day_persistence", "max_dwell_steps"):
                out.pop(k)
        else:
            from psg_data.schemas._generator_model import PROCESS_FILE

            out["process_file"] = PROCESS_FILE
        return out

    @staticmethod
    def from_extra(extra: dict[str, Any]) -> LabConfig:
        """Inverse of :meth:`to_extra`; datasets of synth version 1 (no ``schedule_generator``)
        rebuild with ``continuous-v1``.
        """
        if extra.get("generator") != "psg_data.synth":
            raise PsgDataError("manifest extra: not a psg_data.synth dataset (no generator 'psg_data.synth')")
        keys = {"seed", "days", "train_days", "frames_per_scan", "width", "height", "shift", "start_date",
                "timezone", "routine_strength", "day_patterns", "day_persistence", "max_dwell_steps"}
        kw: dict[str, Any] = {k: extra[k] for k in keys if k in extra}
        kw["generator"] = extra.get("schedule_generator", "continuous-v1")
        kw["layout"] = extra.get("layout", "chain")  # datasets from before the two-route lab
        kw["shift_weekdays"] = tuple(extra.get("shift_weekdays", ("Mon", "Fri")))
        kw["scan_hours"] = tuple(extra.get("scan_hours", (9, 11, 13, 15)))
        if "noise" in extra:
            kw["noise"] = DepthNoise(**extra["noise"])
        return LabConfig(**kw)


MAX_SIDE_PX = 65535
"""Largest image side (JPEG's limit; PNG's is larger)."""

LAB_SETTINGS = {
    "seed": Integral(0, INT64_MAX, help="seed of everything"),
    "days": Integral(1, 366),
    "train_days": Integral(0, 366, none_ok=True),
    "frames_per_scan": Integral(1, 1000),
    "width": Integral(8, MAX_SIDE_PX, help="pixels"),
    "height": Integral(8, MAX_SIDE_PX, help="pixels"),
    "shift": Options(*SHIFTS, none_ok=True),
    "timezone": TimeZone(none_ok=False),
    "generator": Options(*GENERATORS),
    "routine_strength": Real(0.0, 1.0, finite=True),
    "day_patterns": Integral(1, 12),
    "day_persistence": Real(0.0, 1.0, finite=True),
    "max_dwell_steps": Integral(1, 10**6),
    "layout": Options(*LAYOUTS),
}
"""The declared settings of :class:`LabConfig` (see :mod:`psg_data._settings`)."""

_BASE_BYTES = 320 * 2**20
_BYTES_PER_PIXEL = 420
_BYTES_PER_STORED_PIXEL = 4
"""Peak memory of ``synth``: measured 231, 334 and 660 MB at 160x120, 640x480 and 1280x960 (about
365 bytes per pixel of the image size, the renderer's per-pixel buffers, over a 225 MB base; frames
and days add about 1.5 bytes per pixel per frame), with a margin."""


def memory_needed(cfg: LabConfig) -> int:
    """Bytes ``synth`` needs at its peak for ``cfg`` (an estimate with a margin, see above)."""
    px = int(cfg.width) * int(cfg.height)
    return _BASE_BYTES + _BYTES_PER_PIXEL * px + _BYTES_PER_STORED_PIXEL * px * int(cfg.frames_per_scan)


def check_memory(cfg: LabConfig, available: int | None = None) -> None:
    """Refuse, before anything is allocated, a lab that needs more memory than the machine has.

    Args:
        cfg: the lab.
        available: bytes of memory (default: the machine's physical memory).

    Raises:
        PsgDataError: one line with the estimate, the machine's memory and what to change.
    """
    need = memory_needed(cfg)
    have = available if available is not None else _physical_memory()
    if have is not None and need > have:
        raise PsgDataError(f"resolution: {cfg.width}x{cfg.height} needs about {need / 2**30:.1f} GiB of memory, the "
                           f"machine has {have / 2**30:.1f} GiB; expected a smaller --resolution (about "
                           f"{_BYTES_PER_PIXEL} bytes per pixel)")


def _physical_memory() -> int | None:
    import os

    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # not on this system (Windows): no check
        return None


@dataclass
class ScanPlan:
    """One scan: when, where the robot looked and the lab state during the scan.

    Attributes:
        scan_id: ``scan_DDD_HH`` (day index, local start hour).
        index: scan index (0-based, chronological).
        day: day index.
        split: 'train' or 'test'.
        start_ns: scan start (the state of objects and doors is taken at this instant).
        stamps_ns: (N,) frame stamps, int64 UTC nanoseconds.
        poses: (N, 4, 4) camera-to-world poses used for rendering.
        state: object placement and door states during the scan.
        reachable_rooms: rooms the robot could enter.
    """

    scan_id: str
    index: int
    day: int
    split: str
    start_ns: int
    stamps_ns: NDArray[np.int64]
    poses: NDArray[np.float64]
    state: SceneState
    reachable_rooms: list[str]


def camera_pose(x_m: float, y_m: float, yaw_rad: float, *, height_m: float = CAMERA_HEIGHT_M,
                pitch_deg: float = CAMERA_PITCH_DEG, roll_deg: float = 0.0) -> NDArray[np.float64]:
    """Camera-to-world pose (OpenCV axes) of a camera at (x, y, height) whose optical axis points
    along ``yaw_rad`` (from +x towards +y), pitched down by ``pitch_deg`` and rolled by ``roll_deg``.
    """
    fwd = np.array([np.cos(yaw_rad), np.sin(yaw_rad), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    p, r = np.deg2rad(pitch_deg), np.deg2rad(roll_deg)
    ez = np.cos(p) * fwd - np.sin(p) * up  # optical axis
    ey0 = -(np.sin(p) * fwd + np.cos(p) * up)  # image down
    ex0 = np.cross(ey0, ez)  # image right
    ex = np.cos(r) * ex0 + np.sin(r) * ey0
    ey = -np.sin(r) * ex0 + np.cos(r) * ey0
    T = np.eye(4)
    T[:3, :3] = np.stack([ex, ey, ez], axis=1)
    T[:3, 3] = [x_m, y_m, height_m]
    return T


def _candidate_poses(C: NDArray[np.float64]) -> NDArray[np.float64]:
    """(C, 4, 4) camera-to-world poses of (x, y, yaw) rows: :func:`camera_pose` of each row, its
    rotation computed once per distinct yaw (the same numbers as one call per row).
    """
    rot = {yaw: camera_pose(0.0, 0.0, yaw) for yaw in np.unique(C[:, 2]).tolist()}
    T = np.stack([rot[yaw] for yaw in C[:, 2].tolist()])
    T[:, 0, 3], T[:, 1, 3] = C[:, 0], C[:, 1]
    return T


class LabModel:
    """The synthetic lab: geometry, ground-truth schedules, camera and scan plans, from a seed.

    Args:
        config: lab parameters, or None for the defaults with ``seed``.
        seed: shortcut for ``LabConfig(seed=seed)``.

    Example::

        lab = LabModel(seed=0)
        dense = lab.schedule.dense(step_s=3600)      # hourly ground truth of all 21 objects
        plan = lab.scans[0]                           # poses and scene state of the first scan
    """

    def __init__(self, config: LabConfig | None = None, *, seed: int | None = None) -> None:
        if config is None:
            config = LabConfig(seed=0 if seed is None else int(seed))
        elif seed is not None:
            raise PsgDataError("LabModel: pass either config or seed, not both")
        self.config = config
        self.layout: LabLayout = make_layout(config.seed, config.layout)
        self.schedule: LabSchedule | StepSchedule
        if config.generator == "continuous-v1":
            self.schedule = LabSchedule(self.layout, config.seed, config.date, config.days, config.timezone,
                                        config.shifted_days())
        else:
            self.schedule = StepSchedule(self.layout, config.seed, config.date, config.days, config.timezone,
                                         tuple(float(h) for h in config.scan_hours), config.process_params,
                                         config.shifted_days())
        self.camera: CameraIntrinsics = d435_intrinsics(config.width, config.height)
        self._scans: list[ScanPlan] | None = None
        self._candidates: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] | None = None

    @staticmethod
    def from_dataset(dataset: Any) -> LabModel:
        """Rebuild the lab of a dataset written by :func:`build_lab` (from its manifest ``extra``)."""
        return LabModel(LabConfig.from_extra(dict(dataset.info.extra)))

    # -- scans ----------------------------------------------------------------------------------
    @property
    def scans(self) -> list[ScanPlan]:
        """Plans of all scans (computed on first use)."""
        if self._scans is None:
            self._scans = self._plan_scans()
        return self._scans

    def scan_plan(self, scan: int | str) -> ScanPlan:
        """The plan of a scan by index or id.

        Raises:
            KeyError: no such scan.
        """
        if isinstance(scan, str):
            for p in self.scans:
                if p.scan_id == scan:
                    return p
            raise KeyError(f"no scan {scan!r} in this lab")
        return self.scans[scan]

    def state_at(self, stamp_ns: int) -> SceneState:
        """Lab state (object placement, door states) at ``stamp_ns`` from the dense schedule."""
        return SceneState(self.schedule.objects_at(stamp_ns), self.schedule.doors_at(stamp_ns))

    def reachable_rooms(self, doors_open: dict[str, bool]) -> list[str]:
        """Rooms reachable from the dock room through open doors and open passages (breadth-first order)."""
        seen = [self.layout.dock_room]
        frontier = [self.layout.dock_room]
        links = [(d.room_a, d.room_b) for d in self.layout.doors if doors_open.get(d.door_id, False)]
        links += [(o.room_a, o.room_b) for o in self.layout.openings]
        while frontier:
            room = frontier.pop(0)
            for ra, rb in links:
                for a, b in ((ra, rb), (rb, ra)):
                    if a == room and b not in seen:
                        seen.append(b)
                        frontier.append(b)
        return seen

    def _view_targets(self) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Points the scan views try to see, (K, 5, 3) world metres, and each target's instance id: 5
        points on every receptacle top, and (layouts whose scans look at the doors) 5 points on every
        closed door leaf's doorway plane.
        """
        L = self.layout
        five = np.array([[0, 0], [-.3, -.3], [.3, -.3], [-.3, .3], [.3, .3]])  # centre and 4 inner points
        tops = []
        for r in L.receptacles:  # on the top face (box z is up)
            c, e, R = np.asarray(r.box.center_m), np.asarray(r.box.extent_m), np.asarray(r.box.rotation)
            tops.append(np.column_stack([five * e[:2], np.full(5, e[2] / 2 + 0.01)]) @ R.T + c)
        ids = [RECEPTACLE_ID0 + i for i in range(len(L.receptacles))]
        for i, d in enumerate(self._viewed_doors()):  # on the doorway plane (box x is the wall normal)
            c, e = np.asarray(d.box.center_m), np.asarray(d.box.extent_m)
            tops.append(np.column_stack([np.zeros(5), five * e[1:]]) @ np.asarray(d.box.rotation).T + c)
            ids.append(DOOR_ID0 + i)
        return np.asarray(tops), np.asarray(ids, np.int64)

    def _viewed_doors(self) -> list[Door]:
        """The doors each scan takes a door keyframe of (layouts whose scans look at the doors), in
        layout order; their view targets follow the receptacles' (:meth:`_view_targets`).
        """
        return list(self.layout.doors) if self.layout.scans_look_at_doors else []

    def _view_candidates(self) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per room with receptacles: candidate (x, y, yaw) rows and their (C, K) visibility scores of
        the view targets (:meth:`_view_targets`): the share of a target's 5 points that are in the
        160 x 120 image, 0.4-6 m ahead, and seen unoccluded (one ray cast per room for all).
        """
        if self._candidates is not None:
            return self._candidates
        L = self.layout
        rend = LabRenderer(L, SceneState({}, {d: False for d in L.door_ids}))
        cam = d435_intrinsics(160, 120)
        tops_a, target_ids = self._view_targets()
        pts = tops_a.reshape(-1, 3)
        out: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
        for room in L.room_ids:
            if not any(r.room_id == room for r in L.receptacles):
                continue
            C = self._room_candidates(room)
            if len(C) == 0:  # no free spot on the grid: nothing to score
                out[room] = (C, np.zeros((0, len(target_ids))))
                continue
            T = _candidate_poses(C)
            Tinv = np.linalg.inv(T)
            pc = np.matmul(pts[None], Tinv[:, :3, :3].transpose(0, 2, 1)) + Tinv[:, None, :3, 3]  # (C, 5K, 3)
            z = pc[..., 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                u = cam.fx * pc[..., 0] / z + cam.cx
                v = cam.fy * pc[..., 1] / z + cam.cy
            inimg = (z > 0.4) & (z < 6.0) & (u > 2) & (u < cam.width - 3) & (v > 2) & (v < cam.height - 3)
            origins = np.broadcast_to(T[:, None, :3, 3], pc.shape).reshape(-1, 3)
            t, iid, _ = rend.cast(origins, (pts[None] - T[:, None, :3, 3]).reshape(-1, 3))
            vis = inimg & (iid.reshape(z.shape) == np.repeat(target_ids, 5)) & (t.reshape(z.shape) > 0.97)
            out[room] = (C, vis.reshape(len(C), -1, 5).mean(axis=2))
        self._candidates = out
        return out

    def _room_candidates(self, room: str) -> NDArray[np.float64]:
        """(C, 3) candidate views (x m, y m, yaw rad) of a room: a 0.5 m grid 0.9 m inside its walls,
        away from the receptacles, 24 yaws each.
        """
        L = self.layout
        x0, x1, y0, y1 = L.room_bounds(room, inset_m=0.9)
        xs, ys = np.arange(x0, x1 + 1e-9, 0.5), np.arange(y0, y1 + 1e-9, 0.5)
        cands = []
        for x in xs:
            for y in ys:
                p = np.array([x, y, 0.3])
                if any(r.box.contains(p[None], margin_m=0.45)[0] for r in L.receptacles):
                    continue
                for yaw in np.deg2rad(np.arange(0, 360, 15)):
                    cands.append((x, y, yaw))
        return np.asarray(cands, float).reshape(-1, 3)

    def _plan_scans(self) -> list[ScanPlan]:
        cfg = self.config
        cands = self._view_candidates()
        L = self.layout
        rec_room = np.array([r.room_id for r in L.receptacles])
        door_pos = {d.door_id: np.asarray(d.box.center_m)[:2] for d in L.doors}
        n_rec_cols = len(L.receptacles)  # the view targets' columns: receptacles, then the viewed doors
        viewed = self._viewed_doors()
        plans: list[ScanPlan] = []
        idx = 0
        for day in range(cfg.days):
            date = cfg.date + dt.timedelta(days=day)
            for hour in cfg.scan_hours:
                rng = np.random.default_rng([cfg.seed, 401, day, hour])
                start = local_time_ns(date, hour, cfg.timezone) + int(rng.uniform(0, 480)) * 1_000_000_000
                state = self.state_at(start)
                rooms = self.reachable_rooms(state.doors_open)
                n_rec = np.array([np.sum(rec_room == r) for r in rooms], float)
                budget = np.floor(cfg.frames_per_scan * n_rec / n_rec.sum()).astype(int)
                for i in np.argsort(-(cfg.frames_per_scan * n_rec / n_rec.sum() - budget), kind="stable"):
                    if budget.sum() >= cfg.frames_per_scan:
                        break
                    budget[i] += 1
                views: list[tuple[float, float, float]] = []
                # each viewed door from the first room of the route that it joins
                door_room = [next((r for r in rooms if r in (d.room_a, d.room_b) and r in cands), None) for d in viewed]
                for room, b in zip(rooms, budget):
                    if room not in cands:
                        continue
                    C, S = cands[room]
                    views += self._room_views(C, S[:, :n_rec_cols], int(b), rng)
                    views += [self._door_view(C, S[:, n_rec_cols + i], rng)
                              for i, r in enumerate(door_room) if r == room]
                poses = []
                walk = np.zeros(3)
                stamps = []
                t = start
                prev = None
                for (x, y, yaw) in views:
                    walk += rng.normal(0, [0.02, 0.02, np.deg2rad(0.7)])
                    jit = rng.normal(0, [0.03, 0.03, np.deg2rad(2.0)])
                    T = camera_pose(x + walk[0] + jit[0], y + walk[1] + jit[1], yaw + walk[2] + jit[2],
                                    height_m=CAMERA_HEIGHT_M + rng.normal(0, 0.01),
                                    pitch_deg=CAMERA_PITCH_DEG + rng.normal(0, 1.0), roll_deg=rng.normal(0, 1.0))
                    if prev is not None:
                        dist = float(np.linalg.norm(T[:2, 3] - prev[:2, 3]))
                        ra, rb = L.room_of_point(prev[:2, 3]), L.room_of_point(T[:2, 3])
                        if ra != rb:  # through the doorway(s)
                            via = [door_pos[d.door_id] for d in L.doors if {d.room_a, d.room_b} & {ra, rb}]
                            dist = float(np.linalg.norm(prev[:2, 3] - via[0]) + np.linalg.norm(T[:2, 3] - via[-1])
                                         + (np.linalg.norm(via[0] - via[-1]) if len(via) > 1 else 0.0))
                        t += int((dist / 0.4 + rng.uniform(4.0, 8.0)) * 1e9)
                    poses.append(T)
                    stamps.append(t)
                    prev = T
                split = "train" if day < cfg.n_train_days else "test"
                plans.append(ScanPlan(f"scan_{day:03d}_{hour:02d}", idx, day, split, int(start),
                                      np.asarray(stamps, np.int64), np.asarray(poses), state, rooms))
                idx += 1
        return plans

    @staticmethod
    def _room_views(C: NDArray[np.float64], S: NDArray[np.float64], n: int, rng: np.random.Generator
                    ) -> list[tuple[float, float, float]]:
        """``n`` receptacle views of one room: greedy coverage of the (C, R) receptacle scores ``S``,
        visited by bearing around their centre.
        """
        if n == 0:
            return []
        covered = np.zeros(S.shape[1])
        order: list[int] = []
        for _ in range(n):
            gain = np.minimum(S + covered, 1.0).sum(axis=1) - np.minimum(covered, 1.0).sum()
            gain = gain + 0.05 * S.sum(axis=1) + rng.uniform(0, 0.3, len(C))
            gain[order] = -np.inf
            k = int(np.argmax(gain))
            order.append(k)
            covered = covered + S[k]
        pts = C[order]
        cxy = pts[:, :2].mean(axis=0)
        ang = np.arctan2(pts[:, 1] - cxy[1], pts[:, 0] - cxy[0])
        return [tuple(pts[i]) for i in np.argsort(ang)]

    @staticmethod
    def _door_view(C: NDArray[np.float64], s: NDArray[np.float64], rng: np.random.Generator
                   ) -> tuple[float, float, float]:
        """The door keyframe of one room: the candidate that sees most of the doorway (``s``, per
        candidate), a small random tie-break.
        """
        return tuple(C[int(np.argmax(s + rng.uniform(0, 0.02, len(C))))])

    # -- rendering --------------------------------------------------------------------------------
    def renderer(self, state: SceneState) -> LabRenderer:
        """A ray-casting scene of the lab in ``state``."""
        return LabRenderer(self.layout, state)

    def noise_rng(self, scan_index: int, frame_index: int) -> np.random.Generator:
        """Random generator of the sensor noise of one stored frame."""
        return np.random.default_rng([self.config.seed, 501, int(scan_index), int(frame_index)])

    def render_frame(self, T_world_camera: NDArray[np.float64], state: SceneState | int, *,
                     camera: CameraIntrinsics | None = None, noise: DepthNoise | None | str = "config",
                     rng: np.random.Generator | None = None) -> RenderedFrame:
        """Render the lab in ``state`` (or the state at a stamp, int UTC ns) from ``T_world_camera``.

        Args:
            T_world_camera: (4, 4) camera-to-world pose, OpenCV axes.
            state: a :class:`SceneState` or a stamp (int64 UTC ns) whose ground-truth state is used.
            camera: intrinsics (default: the lab's camera).
            noise: noise model; ``"config"`` uses the lab's, None renders noise-free.
            rng: noise generator.
        """
        st = self.state_at(state) if isinstance(state, (int, np.integer)) else state
        nz = self.config.noise if isinstance(noise, str) else noise
        return self.renderer(st).render(T_world_camera, camera or self.camera, noise=nz, rng=rng)

