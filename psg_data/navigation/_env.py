"""The navigation environment: grid, receptacles, doors, map observations and dense ground truth.

A :class:`NavigationEnv` is what the agent and the scorer need from a dataset:

- the occupancy grid (:mod:`psg_data.maps._grid`) and the receptacle / door records;
- the *map*: the observations of every (object, receptacle) edge up to the last map update
  ``t_map_s`` (one :class:`~psg_data.estimators.EdgeStream` per edge), which estimators are fitted
  and updated on, and the state of every object and door at that update;
- the dense ground truth: ``gt_at(object_id, t_s) -> receptacle_id | None`` and
  ``doors_at(t_s) -> dict[door_id, bool]`` (True = open).

Edges: for every object, the receptacles it was seen on during the mapping scans (the paper's
"previously observed receptacles"). The observations come from a label source
(:mod:`psg_data.graph._sources`): with ``labels="gt"`` (default) every mapping scan yields, for
each of those edges, ``y = 1`` if the object was on that receptacle and ``y = 0`` otherwise, stamped
at the scan start; other sources observe what they saw. The door observations of the same source
(``door_streams``) drive predicted door states, and its sighting model (``observation``) what the
agent sees on the way. The ground truth (``gt_at`` / ``doors_at``) is always the schedule: the
physical state at the query time for a synthetic lab (its generator knows the state at any instant),
else the ``schedule`` / ``door_states`` rows of the latest scan (all a recording knows). Queries are
drawn inside the dataset's scoring windows (``windows``, its operating hours).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.graph._layout import SceneLayout
from psg_data.graph._sources import ObservationModel, source_observations
from psg_data.graph._timeline import WEEK_S, DatasetTimeline
from psg_data.maps._grid import OccupancyGrid, grid_from_dataset, grid_from_geometry
from psg_data.schemas._records import Door, ObjectInfo, Receptacle

__all__ = ["NavigationEnv", "DatasetTimeline", "streams_from_states", "WEEK_S"]

log = logging.getLogger(__name__)



def streams_from_states(times_s: Sequence[float], states: Sequence[Mapping[str, str | None]],
                        object_ids: Sequence[str]) -> list[EdgeStream]:
    """Edge streams from a sequence of full object placements.

    Args:
        times_s: (N,) observation times, float seconds (UTC), non-decreasing.
        states: N mappings ``object_id -> receptacle_id | None``.
        object_ids: objects to build edges for.

    Returns:
        One stream per (object, receptacle) pair seen at least once, with ``y = 1`` when the object
        was on the receptacle and ``y = 0`` otherwise (including when the object was absent).
    """
    t = np.asarray(times_s, dtype=np.float64)
    out: list[EdgeStream] = []
    for o in object_ids:
        seq = [s.get(o) for s in states]
        for r in sorted({x for x in seq if x is not None}):
            y = np.array([x == r for x in seq], dtype=np.int8)
            out.append(EdgeStream((o, r), t, y))
    return out


@dataclass
class NavigationEnv:
    """Everything the navigation harness needs from one dataset (or synthetic lab).

    Attributes:
        name: short name (used in stored file names).
        grid: occupancy grid.
        receptacles: receptacle_id -> record.
        doors: door_id -> record.
        object_ids: target objects.
        gt_at: ``(object_id, t_s) -> receptacle_id | None`` ground truth.
        doors_at: ``t_s -> {door_id: is_open}`` ground truth.
        map_streams: observations up to the last map update (one stream per edge).
        t_map_s: time of the last map update, float seconds UTC.
        t_end_s: latest time with ground truth, float seconds UTC.
        map_state: object -> receptacle (None = absent) at the last map update.
        map_doors: door -> is_open at the last map update.
        timezone: IANA site timezone.
        extra: provenance (source, map scans, label info).
        door_streams: ``(door_id, 'open')`` observations up to the last map update, from the
            same label source as ``map_streams``.
        observation: the agent's sighting model of that source.
        labels: the label source of ``map_streams`` / ``door_streams``.
        start_xy: world (x, y) of the recordings' first camera pose, metres (the robot's dock;
            the fixed start of the real-world protocol), or None.
        windows: the scoring windows (a :class:`~psg_data.evaluation.DailyWindows`; queries are
            drawn inside them), or None.
        truth: where ``gt_at`` comes from (``physical state (generator)`` or ``latest scan row``).
    """

    name: str
    grid: OccupancyGrid
    receptacles: dict[str, Receptacle]
    doors: dict[str, Door]
    object_ids: list[str]
    gt_at: Callable[[str, float], str | None]
    doors_at: Callable[[float], dict[str, bool]]
    map_streams: list[EdgeStream]
    t_map_s: float
    t_end_s: float
    map_state: dict[str, str | None]
    map_doors: dict[str, bool]
    timezone: str = "UTC"
    extra: dict[str, Any] = field(default_factory=dict)
    door_streams: list[EdgeStream] = field(default_factory=list)
    observation: ObservationModel = field(default_factory=ObservationModel)
    labels: str = "gt"
    start_xy: tuple[float, float] | None = None
    windows: Any = None
    truth: str = "latest scan row"

    @property
    def layout(self) -> SceneLayout:
        """The environment's receptacles, doors and objects as a :class:`~psg_data.graph.SceneLayout`
        (no rooms: the grid is given), the layout of its predictive graphs.
        """
        return SceneLayout(receptacles=self.receptacles, doors=self.doors,
                           objects={o: ObjectInfo(o, o) for o in self.object_ids}, timezone=self.timezone)

    @property
    def edges(self) -> list[EdgeKey]:
        """The edges (object, receptacle) of the map streams."""
        return [s.edge for s in self.map_streams]

    # -- constructors ---------------------------------------------------------------------------
    @classmethod
    def from_dataset(
        cls,
        dataset: Any,
        *,
        grid: OccupancyGrid | None = None,
        grid_source: str = "geometry",
        map_scans: Sequence[str] | None = None,
        gt_at: Callable[[str, float], str | None] | None = None,
        doors_at: Callable[[float], dict[str, bool]] | None = None,
        resolution_m: float = 0.05,
        robot_radius_m: float = 0.25,
        name: str | None = None,
        labels: str = "gt",
        label_seed: int = 0,
    ) -> NavigationEnv:
        """Environment of a psg-dataset (a :class:`~psg_data.loaders.Dataset` or its path).

        Args:
            dataset: dataset or directory.
            grid: a prebuilt grid (default: :func:`grid_from_dataset` with ``grid_source``).
            map_scans: scans forming the map (default: split 'train'; if no scan has a split, the
                first two thirds of the scans).
            grid_source: ``geometry`` (rooms, receptacles, doors) or ``scans`` (fused point clouds).
            gt_at: dense ground truth of the objects, ``gt_at(object_id, t_s)`` -> receptacle or None;
                default: the ``schedule`` row of the latest scan starting at or before ``t``.
            doors_at: dense ground truth of the doors, ``doors_at(t_s)`` -> {door_id: open};
                default: the ``door_states`` of that scan (state 'unknown' counts as open).
            resolution_m: grid cell size, metres.
            robot_radius_m: robot radius the obstacles are inflated by, metres.
            name: environment name (default: the dataset name).
            labels: label source of the map and door observations (``gt``, ``privileged``,
                ``noisy:P[,P_F]``, ``detections:FILE``; :mod:`psg_data.graph._sources`).
            label_seed: seed of the ``noisy`` flips and of the agent's sighting draws.

        Raises:
            EvaluationError: no schedule, no scans, no map scans, or labels missing.
        """
        if isinstance(dataset, (str, Path)):
            from psg_data.loaders._dataset import open_dataset

            dataset = open_dataset(dataset)
        if grid is None:
            grid = grid_from_dataset(dataset, source=grid_source, resolution_m=resolution_m,
                                     robot_radius_m=robot_radius_m)
        tl = DatasetTimeline.from_dataset(dataset, map_scans, need_schedule=True)
        objects = sorted(dataset.objects) if dataset.has_table("objects") and len(dataset.objects) else sorted(
            dataset.df("schedule")["object_id"].unique())
        map_ids, last = tl.map_ids, tl.map_ids[-1]
        src = source_observations(dataset, labels, map_ids, seed=label_seed)
        from psg_data.evaluation._windows import dataset_windows

        truth = "given" if gt_at is not None else "latest scan row"
        if gt_at is None and doors_at is None and dataset.info.extra.get("generator") == "psg_data.synth":
            from psg_data.synth import LabModel

            gt_at, doors_at = schedule_truth(LabModel.from_dataset(dataset).schedule)
            truth = "physical state (generator)"
        return cls(
            name=name or dataset.info.name or str(dataset.root.name),
            grid=grid,
            receptacles=dict(dataset.receptacles),
            doors=dict(dataset.doors) if dataset.has_table("doors") else {},
            object_ids=objects,
            gt_at=gt_at or tl.gt_at,
            doors_at=doors_at or tl.doors_at,
            map_streams=src.object_streams,
            t_map_s=tl.t_map_s,
            t_end_s=tl.t_end_s,
            map_state={o: tl.by_scan[last].get(o) for o in objects},
            map_doors=tl.doors_of(last),
            timezone=dataset.info.timezone or "UTC",
            extra={"source": "dataset", "root": str(dataset.root), "map_scans": len(map_ids), "labels": src.info},
            door_streams=src.door_streams,
            observation=src.observation,
            labels=labels,
            start_xy=_first_pose_xy(dataset, tl.ids[0]),
            windows=dataset_windows(dataset),
            truth=truth,
        )

    @classmethod
    def from_lab(cls, lab: Any, *, grid: OccupancyGrid | None = None, resolution_m: float = 0.05,
                 robot_radius_m: float = 0.25, name: str | None = None) -> NavigationEnv:
        """Environment of a synthetic lab (:class:`psg_data.synth.LabModel`), with its continuous-time
        ground truth (``lab.schedule.objects_at`` / ``doors_at``) and its training scans as the map.
        """
        L = lab.layout
        if grid is None:
            grid = grid_from_geometry(L.rooms, L.receptacles, L.doors, openings=L.openings, resolution_m=resolution_m,
                                      robot_radius_m=robot_radius_m)
        plans = [p for p in lab.scans if p.split == "train"]
        if not plans:
            raise EvaluationError("synthetic lab: no training scans")
        sched = lab.schedule
        objects = list(L.object_ids)
        _gt, _doors = schedule_truth(sched)

        times = [p.start_ns / 1e9 for p in plans]
        streams = streams_from_states(times, [p.state.objects for p in plans], objects)
        door_streams = [EdgeStream((d.door_id, "open"), np.asarray(times, np.float64),
                                   np.array([bool(p.state.doors_open.get(d.door_id, True)) for p in plans], np.int8),
                                   {"source": "gt"}) for d in L.doors]
        last = plans[-1]
        first = lab.scans[0].poses[0]
        return cls(
            name=name or f"lab_seed{lab.config.seed}",
            grid=grid,
            receptacles={r.receptacle_id: r for r in L.receptacles},
            doors={d.door_id: d for d in L.doors},
            object_ids=objects,
            gt_at=_gt,
            doors_at=_doors,
            map_streams=streams,
            t_map_s=float(last.stamps_ns.max()) / 1e9,
            t_end_s=float(sched.end_ns) / 1e9,
            map_state=dict(last.state.objects),
            map_doors=dict(last.state.doors_open),
            timezone=lab.config.timezone,
            extra={"source": "synth", "seed": lab.config.seed, "roles": dict(sched.roles)},
            door_streams=door_streams,
            start_xy=(float(first[0, 3]), float(first[1, 3])),
            windows=_lab_windows(lab),
            truth="physical state (generator)",
        )

    def start_cell(self) -> tuple[int, int]:
        """The fixed start cell: the free cell (with every door closed, in the main free component)
        nearest to :attr:`start_xy` (the grid centre when there is no recorded pose).
        """
        from psg_data.navigation._queries import start_cells

        cells = start_cells(self.grid, self.name)
        W = self.grid.shape[1]
        ij = np.stack(np.divmod(cells, W), axis=1)
        xy = self.grid.cell_to_world(ij)
        target = np.asarray(self.start_xy if self.start_xy is not None else xy.mean(axis=0))
        k = int(np.argmin(np.linalg.norm(xy - target, axis=1)))
        return (int(ij[k, 0]), int(ij[k, 1]))

    @classmethod
    def coerce(cls, obj: Any, **kwargs: Any) -> NavigationEnv:
        """A :class:`NavigationEnv` from an env, a dataset, a dataset path or a synthetic ``LabModel``."""
        if isinstance(obj, NavigationEnv):
            return obj
        if hasattr(obj, "layout") and hasattr(obj, "schedule"):
            if kwargs.get("labels", "gt") != "gt":
                raise EvaluationError(f"labels {kwargs['labels']!r}: a synthetic LabModel has only its ground truth; "
                                      "build the dataset (psg-data synth) and label it to use other sources")
            return cls.from_lab(obj, **{k: v for k, v in kwargs.items()
                                        if k in ("grid", "resolution_m", "robot_radius_m", "name")})
        return cls.from_dataset(obj, **kwargs)


def schedule_truth(sched: Any) -> tuple[Callable[[str, float], str | None], Callable[[float], dict[str, bool]]]:
    """``gt_at`` / ``doors_at`` from a synthetic lab's schedule: the physical state at any instant."""
    cache: dict[int, dict[str, str | None]] = {}

    def gt_at(o: str, t_s: float) -> str | None:
        ns = int(round(t_s * 1e9))
        if ns not in cache:
            if len(cache) > 4096:
                cache.clear()
            cache[ns] = sched.objects_at(ns)
        return cache[ns].get(o)

    def doors_at(t_s: float) -> dict[str, bool]:
        return dict(sched.doors_at(int(round(t_s * 1e9))))

    return gt_at, doors_at


def _lab_windows(lab: Any) -> Any:
    from psg_data.evaluation._windows import DailyWindows, _synth_hours

    hours = _synth_hours(lab.config.to_extra())
    return DailyWindows((hours,), lab.config.timezone, source="the lab's scan steps") if hours else None


def _first_pose_xy(dataset: Any, scan_id: str) -> tuple[float, float] | None:
    """World (x, y) of the first camera pose of a scan (camera-to-world translation), metres."""
    from psg_data.errors import PsgDataError

    try:
        poses = dataset.scan(scan_id).poses
    except (PsgDataError, KeyError, IndexError) as exc:  # a scan without frames: no recorded start
        log.debug("no first pose for scan %s: %s", scan_id, exc)
        return None
    if len(poses) == 0:
        return None
    return (float(poses[0][0, 3]), float(poses[0][1, 3]))
