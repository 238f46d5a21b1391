"""The door world of a dataset: its own grid, doors, door states and door streams.

:func:`door_world_from_dataset` turns a psg-dataset (a converted recording or the built-in lab)
into a :class:`~psg_data.navigation.DoorWorld`:

- grid: :func:`~psg_data.navigation.grid_from_dataset` (room polygons, or the fused depth with
  ``grid_source="scans"``), door cells from the ``doors`` table;
- truth: a synthetic lab's physical door states at the query time (its generator), else the
  ``door_states`` table, a step function between scans (state 'unknown' counts open);
- training streams: the ``(door_id, 'open')`` observations of a label source on the map scans
  (:func:`~psg_data.navigation.source_observations`: ``gt`` / ``noisy:P`` from the door states,
  ``privileged`` and ``observed`` from the labels table, ``detections:FILE`` from ``observed``);
- start cells: per room, the free cells inside its floor polygon (free with every door closed, in
  the main free component); goals: per room, its receptacles with a non-empty approach set;
- query hours: the dataset's scoring windows (:func:`psg_data.evaluation.dataset_windows`: the
  lab's 9:00-17:00, else the local hours the recordings cover).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError
from psg_data.evaluation._door_report import DOOR_MODE_LABELS, walk_summary
from psg_data.graph._sources import source_observations
from psg_data.maps._grid import grid_from_dataset, points_in_polygon
from psg_data.maps._planner import PlanningCache
from psg_data.navigation._doors import DoorWorld
from psg_data.navigation._env import DatasetTimeline
from psg_data.navigation._queries import start_cells

__all__ = ["door_world_from_dataset", "DoorTaskOptions", "DoorTaskResult", "run_door_task", "DOOR_MODE_LABELS",
           "walk_summary"]

log = logging.getLogger(__name__)


def door_world_from_dataset(dataset: Any, *, labels: str = "gt", label_seed: int = 0, grid_source: str = "geometry",
                            resolution_m: float = 0.05, robot_radius_m: float = 0.25,
                            map_scans: list[str] | None = None, reach_m: float = 1.0) -> DoorWorld:
    """Door world of a psg-dataset (module docstring).

    Args:
        dataset: a :class:`~psg_data.loaders.Dataset` or its path.
        labels: label source of the training door streams (``gt``, ``privileged``, ``noisy:P``,
            ``observed``, ``detections:FILE``).
        label_seed: seed of on-the-fly noise.
        grid_source: where the occupancy grid comes from (see :meth:`NavigationEnv.from_dataset`).
        resolution_m: grid cell size, metres.
        robot_radius_m: robot radius the obstacles are inflated by, metres.
        map_scans: training scans (default: split 'train', else the first two thirds).
        reach_m: success radius of the goals' approach sets, metres.

    Raises:
        EvaluationError: no doors, no door states, no rooms with start cells and goals in two
            rooms, or labels missing.
    """
    if isinstance(dataset, (str, Path)):
        from psg_data.loaders import open_dataset

        dataset = open_dataset(dataset)
    ds = dataset
    if not (ds.has_table("doors") and len(ds.doors)):
        raise EvaluationError(f"{ds.root}/tables/doors.parquet: missing or empty; the door task needs doors")
    if not (ds.has_table("door_states") and ds.table("door_states").num_rows):
        raise EvaluationError(f"{ds.root}/tables/door_states.parquet: missing or empty; the door task scores "
                              "against the true door states")
    tl = DatasetTimeline.from_dataset(ds, map_scans, need_schedule=False)
    grid = grid_from_dataset(ds, source=grid_source, resolution_m=resolution_m, robot_radius_m=robot_radius_m)
    src = source_observations(ds, labels, tl.map_ids, seed=label_seed, objects=False)
    cells = start_cells(grid, str(ds.root))
    W = grid.shape[1]
    ij = np.stack(np.divmod(cells, W), axis=1).astype(np.int64)
    xy = grid.cell_to_world(ij)
    cache = PlanningCache(grid, reach_m=reach_m)
    all_open = cache.key({d: True for d in grid.door_ids})
    starts: dict[str, np.ndarray] = {}
    goals: dict[str, list[str]] = {}
    for rid, room in ds.rooms.items():
        if room.floor_polygon_m is None or len(room.floor_polygon_m) < 3:
            continue
        starts[rid] = ij[points_in_polygon(xy, np.asarray(room.floor_polygon_m, float))]
        goals[rid] = sorted(r for r, rec in ds.receptacles.items() if rec.room_id == rid
                            and r in grid.receptacle_cells and cache.approach(r, all_open).any())
    if sum(1 for r in starts if len(starts[r])) < 1 or sum(1 for r in goals if goals[r]) < 2:
        raise EvaluationError(f"{ds.root}: the door task needs start cells and goal receptacles in at least two rooms "
                              "(rooms with floor polygons and receptacles)")
    tz = ds.info.timezone or "UTC"
    from psg_data.evaluation._windows import dataset_windows

    windows = dataset_windows(ds)
    doors_at: Callable[[float], dict[str, bool]] = tl.doors_at
    truth = "latest scan row"
    if ds.info.extra.get("generator") == "psg_data.synth":
        from psg_data.navigation._env import schedule_truth
        from psg_data.synth import LabModel

        doors_at, truth = schedule_truth(LabModel.from_dataset(ds).schedule)[1], "physical state (generator)"
    return DoorWorld(grid, doors_at, list(src.door_streams), tl.t_map_s, tl.t_end_s, tz, starts, goals,
                     name=f"{ds.info.name or ds.root.name} (doors from {labels})", hours=windows.hours[0],
                     info={"dataset": str(ds.root), "labels": labels, **src.info, "map_scans": len(tl.map_ids),
                           "truth": truth, "windows": windows.to_dict()},
                     _cache=cache)


@dataclass(frozen=True)
class DoorTaskOptions:
    """Settings of the door task on a dataset (``psg-eval --task doors``).

    Attributes:
        labels: label source of the training door streams (and of the object map when
            ``objects`` is on; ``observed`` then takes the object map from ``gt``).
        label_seed: seed of on-the-fly noise.
        seeds: one door query set (and object query set) per seed.
        n_queries: door queries per seed (also the object queries per seed).
        threshold: doors with predicted P(open) below it are planned closed (the ``threshold`` rule).
        no_path: ``decline`` or ``optimistic`` (:func:`~psg_data.navigation.run_door_episode`).
        rules: door rules of the estimator rows: ``threshold`` (row ``NAME``) and ``expected_cost``
            (row ``NAME (expected cost)``, :func:`psg_data.maps.expected_cost_route`).
        objects: also run object navigation with each estimator's predicted doors next to all
            doors open and the true doors (objects behind predicted-closed doors).
        setting: agent setting of the object runs.
        grid_source, resolution_m, robot_radius_m: the occupancy grid.
        windows: ``auto`` (the dataset's scoring windows) or local hours (``9-16``): door query times.
    """

    labels: str = "gt"
    label_seed: int = 0
    seeds: tuple[int, ...] = (0,)
    n_queries: int = 250
    threshold: float = 0.5
    no_path: str = "decline"
    rules: tuple[str, ...] = ("threshold", "expected_cost")
    objects: bool = True
    setting: str = "adaptive"
    grid_source: str = "geometry"
    resolution_m: float = 0.05
    robot_radius_m: float = 0.25
    windows: str = "auto"

    def __post_init__(self) -> None:
        if not self.seeds:
            raise EvaluationError("door task options: no seeds")
        if not 0.0 < self.threshold < 1.0:
            raise EvaluationError(f"threshold: {self.threshold}, expected in (0, 1)")
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))
        object.__setattr__(self, "rules", tuple(str(r) for r in self.rules))

    def to_dict(self) -> dict[str, Any]:
        """The options as a JSON-ready dictionary (stored with the results)."""
        return {**asdict(self), "seeds": list(self.seeds), "rules": list(self.rules)}


@dataclass
class DoorTaskResult:
    """Output of :func:`run_door_task`.

    Attributes:
        summary: one row per method: the door table (mean over seeds; ``*_std`` across seeds).
        per_seed: the door table of every seed.
        records: one row per (seed, method, door query).
        world: the door world; first: the first seed's :class:`DoorNavigationResult`.
        objects: object navigation with the doors each method plans with (None when off).
        options: the settings.
        errors: per failed plugin estimator its failure (``estimator``, ``stage``, ``message``): its
            rows are left out, the other methods are scored.
    """

    summary: Any
    per_seed: Any
    records: Any
    world: DoorWorld
    first: Any
    objects: Any
    options: DoorTaskOptions
    errors: list[dict[str, Any]] = field(default_factory=list)

    def format_table(self) -> str:
        """The door table and the objects table as plain text (:func:`psg_data.evaluation.door_results`)."""
        from psg_data.evaluation._door_report import door_results
        from psg_data.evaluation._tables import format_results

        return format_results(door_results(self))


def run_door_task(dataset: Any, estimators: list[tuple[str, Any]], options: DoorTaskOptions | None = None, *,
                  settings: Mapping[str, Mapping[str, Any]] | None = None,
                  objects_for: list[str] | None = None,
                  progress: Callable[[int, int], None] | None = None) -> DoorTaskResult:
    """The door task on a dataset: door queries per seed, and objects behind predicted-closed doors.

    Args:
        dataset: a dataset or its path.
        estimators: ``(label, registry name or estimator)`` pairs.
        options: settings (default :class:`DoorTaskOptions`).
        settings: label -> estimator settings.
        objects_for: labels whose object runs are made (default: every estimator).
        progress: called as ``progress(done, total)`` after each seed and after the object runs.
    """
    import pandas as pd

    from psg_data.navigation._doors import run_door_navigation

    o = options or DoorTaskOptions()
    if isinstance(dataset, (str, Path)):
        from psg_data.loaders import open_dataset

        dataset = open_dataset(dataset)
    world = door_world_from_dataset(dataset, labels=o.labels, label_seed=o.label_seed, grid_source=o.grid_source,
                                    resolution_m=o.resolution_m, robot_radius_m=o.robot_radius_m)
    if o.windows != "auto":
        from psg_data.evaluation._windows import parse_windows

        world.hours = parse_windows(o.windows, world.timezone).hours[0]
    tables, records, first = [], [], None
    errors: list[dict[str, Any]] = []
    obj_est = [e for e in estimators if objects_for is None or e[0] in objects_for]
    steps = len(o.seeds) + int(bool(o.objects and obj_est))
    for k, seed in enumerate(o.seeds):
        res = run_door_navigation(world, estimators, n_queries=o.n_queries, seed=seed, threshold=o.threshold,
                                  settings=settings, no_path=o.no_path, rules=o.rules)
        errors += [e for e in res.errors if e not in errors]
        tables.append(res.table.assign(seed=seed))
        records.append(res.records.assign(seed=seed))
        if first is None:
            first = res
        if progress:
            progress(k + 1, steps)
    per_seed = pd.concat(tables, ignore_index=True)
    recs = pd.concat(records, ignore_index=True)
    summary = _door_summary(per_seed, recs, len(o.seeds))
    failed = {e["estimator"] for e in errors}
    obj_est = [e for e in obj_est if e[0] not in failed]
    objects = _objects_behind_doors(dataset, obj_est, o, settings) if o.objects and obj_est else None
    if objects is not None:
        errors += [e for e in objects.errors if e not in errors]
        if progress:
            progress(steps, steps)
    return DoorTaskResult(summary, per_seed, recs, world, first, objects, o, errors)


def _door_summary(per_seed: Any, records: Any, n_seeds: int) -> Any:
    """One row per method: the metrics pooled over the seeds' queries (:mod:`psg_data.evaluation._door_report`),
    ``*_std`` across seeds, the summed counts.
    """
    import pandas as pd

    from psg_data.evaluation._door_report import summarise_doors

    cols = ["blocked_rate", "mean_extra_distance_m", "SR", "SPL", "wasted_m", "SR_all", "extra_blocked_m"]
    g = per_seed.groupby("estimator", sort=False)
    names = list(g.groups)
    scores = summarise_doors(records, names)
    rows = []
    for n in names:
        row: dict[str, Any] = {"estimator": n}
        for c in ("queries", "blocked_first_plans", "n_reachable", "declined", "declined_reachable"):
            row[c] = int(g.get_group(n)[c].sum())
        for c in cols:
            row[c], row[f"{c}_std"] = scores[n][c].mean, scores[n][c].std
            row[f"{c}_ci_low"], row[f"{c}_ci_high"] = scores[n][c].ci_low, scores[n][c].ci_high
        row["seeds"], row["unseen_doors"] = n_seeds, g.get_group(n)["unseen_doors"].iloc[0]
        rows.append(row)
    return pd.DataFrame(rows)


def _objects_behind_doors(dataset: Any, estimators: list[tuple[str, Any]], o: DoorTaskOptions,
                          settings: Mapping[str, Mapping[str, Any]] | None) -> Any:
    """Object navigation where each estimator plans with all doors open, its predicted doors, the truth."""
    from psg_data.navigation._options import NavigationOptions
    from psg_data.navigation._runner import run_navigation

    labels = "gt" if o.labels == "observed" else o.labels
    methods: dict[str, Any] = {"oracle": "oracle"}
    modes: dict[str, str] = {"oracle": "truth"}
    est_settings: dict[str, Mapping[str, Any]] = {}
    for label, est in estimators:
        for mode, text in DOOR_MODE_LABELS.items():
            name = f"{label} [{text}]"
            methods[name], modes[name] = est, mode
            if settings and label in settings:
                est_settings[name] = settings[label]
    opts = NavigationOptions.preset("sim", labels=labels, label_seed=o.label_seed, seeds=o.seeds,
                                    n_queries=o.n_queries, setting=o.setting, grid_source=o.grid_source,
                                    resolution_m=o.resolution_m, robot_radius_m=o.robot_radius_m)
    return run_navigation(dataset, methods, opts, door_modes=modes, estimator_settings=est_settings or None)
