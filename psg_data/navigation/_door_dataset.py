"""The door world of a dataset: its own grid, doors, door states and door streams.

:func:`door_world_from_dataset` turns a psg-dataset (a converted recording or the built-in lab)
into a :class:`~psg_data.navigation.DoorWorld`:

- grid: :func:`~psg_data.navigation.grid_from_dataset` (room polygons, or the fused depth with
  ``grid_source="scans"``), door cells from the ``doors`` table;
- truth: the ``door_states`` table, a step function between scans (state 'unknown' counts open);
- training streams: the ``(door_id, 'open')`` observations of a label source on the map scans
  (:func:`~psg_data.navigation.source_observations`: ``gt`` / ``noisy:P`` from the door states,
  ``privileged`` and ``observed`` from the labels table, ``detections:FILE`` from ``observed``);
- start cells: per room, the free cells inside its floor polygon (free with every door closed, in
  the main free component); goals: per room, its receptacles with a non-empty approach set;
- query hours: the local hours the recordings cover (robot operating hours).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError
from psg_data.navigation._doors import DoorWorld
from psg_data.navigation._env import DatasetTimeline
from psg_data.navigation._grid import grid_from_dataset, points_in_polygon
from psg_data.navigation._planner import PlanningCache
from psg_data.navigation._queries import start_cells
from psg_data.navigation._sources import source_observations

__all__ = ["door_world_from_dataset", "DoorTaskOptions", "DoorTaskResult", "run_door_task", "DOOR_MODE_LABELS",
           "walk_summary"]

log = logging.getLogger(__name__)


def _operating_hours(ds: Any, timezone: str) -> tuple[float, float]:
    """Local hours [first scan start, last scan end) over all scans, whole hours."""
    import pandas as pd

    scans = ds.df("scans")
    start = pd.to_datetime(scans["start_stamp_ns"], utc=True).dt.tz_convert(timezone)
    end = pd.to_datetime(scans["end_stamp_ns"], utc=True).dt.tz_convert(timezone)
    lo = float((start.dt.hour + start.dt.minute / 60.0).min())
    hi = float((end.dt.hour + end.dt.minute / 60.0 + end.dt.second / 3600.0).max())
    return float(math.floor(lo)), float(min(24.0, math.ceil(hi) if hi > lo else lo + 1.0))


def door_world_from_dataset(dataset: Any, *, labels: str = "gt", label_seed: int = 0, grid_source: str = "geometry",
                            resolution_m: float = 0.05, robot_radius_m: float = 0.25,
                            map_scans: list[str] | None = None, reach_m: float = 1.0) -> DoorWorld:
    """Door world of a psg-dataset (module docstring).

    Args:
        dataset: a :class:`~psg_data.loaders.Dataset` or its path.
        labels: label source of the training door streams (``gt``, ``privileged``, ``noisy:P``,
            ``observed``, ``detections:FILE``).
        label_seed: seed of on-the-fly noise.
        grid_source, resolution_m, robot_radius_m: the occupancy grid.
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
    return DoorWorld(grid, tl.doors_at, list(src.door_streams), tl.t_map_s, tl.t_end_s, tz, starts, goals,
                     name=f"{ds.info.name or ds.root.name} (doors from {labels})", hours=_operating_hours(ds, tz),
                     info={"dataset": str(ds.root), "labels": labels, **src.info, "map_scans": len(tl.map_ids)},
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
        threshold: doors with predicted P(open) below it are planned closed.
        no_path: ``decline`` or ``optimistic`` (:func:`~psg_data.navigation.run_door_episode`).
        objects: also run object navigation with each estimator's predicted doors next to all
            doors open and the true doors (objects behind predicted-closed doors).
        setting: agent setting of the object runs.
        grid_source, resolution_m, robot_radius_m: the occupancy grid.
    """

    labels: str = "gt"
    label_seed: int = 0
    seeds: tuple[int, ...] = (0,)
    n_queries: int = 250
    threshold: float = 0.5
    no_path: str = "decline"
    objects: bool = True
    setting: str = "adaptive"
    grid_source: str = "geometry"
    resolution_m: float = 0.05
    robot_radius_m: float = 0.25

    def __post_init__(self) -> None:
        if not self.seeds:
            raise EvaluationError("door task options: no seeds")
        if not 0.0 < self.threshold < 1.0:
            raise EvaluationError(f"threshold: {self.threshold}, expected in (0, 1)")
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "seeds": list(self.seeds)}


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
    """

    summary: Any
    per_seed: Any
    records: Any
    world: DoorWorld
    first: Any
    objects: Any
    options: DoorTaskOptions

    def format_table(self) -> str:
        """The door table (percent for rates, metres for distances)."""
        shown = self.summary.copy()
        for c in ("blocked_rate", "SR", "SPL"):
            shown[c] = (100 * shown[c]).round(1)
        for c in ("mean_extra_distance_m", "wasted_m"):
            shown[c] = shown[c].round(2)
        cols = {"blocked_rate": "blocked %", "mean_extra_distance_m": "extra m", "SR": "SR %", "SPL": "SPL %",
                "n_reachable": "reachable", "declined": "declined", "wasted_m": "wasted m"}
        text = shown[["estimator", "queries", "blocked_first_plans", *cols]].rename(columns=cols).to_string(index=False)
        o = self.options
        return text + (f"\nblocked %: first plans through a door closed at the query time; SR / SPL over the reachable "
                       f"goals; declined: did not set off (the predicted doors leave no route; no_path={o.no_path}); "
                       f"wasted m: mean walked towards goals no route reached; {len(o.seeds)} seed(s), door streams "
                       f"from {o.labels} ({self.world.info.get('doors', {}).get('from', '?')})")


def run_door_task(dataset: Any, estimators: list[tuple[str, Any]], options: DoorTaskOptions | None = None, *,
                  settings: Mapping[str, Mapping[str, Any]] | None = None) -> DoorTaskResult:
    """The door task on a dataset: door queries per seed, and objects behind predicted-closed doors.

    Args:
        dataset: a dataset or its path.
        estimators: ``(label, registry name or estimator)`` pairs.
        options: settings (default :class:`DoorTaskOptions`).
        settings: label -> estimator settings.
    """
    import pandas as pd

    from psg_data.navigation._doors import run_door_navigation

    o = options or DoorTaskOptions()
    if isinstance(dataset, (str, Path)):
        from psg_data.loaders import open_dataset

        dataset = open_dataset(dataset)
    world = door_world_from_dataset(dataset, labels=o.labels, label_seed=o.label_seed, grid_source=o.grid_source,
                                    resolution_m=o.resolution_m, robot_radius_m=o.robot_radius_m)
    tables, records, first = [], [], None
    for seed in o.seeds:
        res = run_door_navigation(world, estimators, n_queries=o.n_queries, seed=seed, threshold=o.threshold,
                                  settings=settings, no_path=o.no_path)
        tables.append(res.table.assign(seed=seed))
        records.append(res.records.assign(seed=seed))
        if first is None:
            first = res
    per_seed = pd.concat(tables, ignore_index=True)
    cols = ["blocked_rate", "mean_extra_distance_m", "SR", "SPL", "wasted_m"]
    g = per_seed.groupby("estimator", sort=False)
    summary = g[cols].mean().join(g[cols].std(ddof=1).fillna(0.0).add_suffix("_std")).reset_index()
    for k, c in enumerate(("queries", "blocked_first_plans", "n_reachable", "declined", "declined_reachable")):
        summary.insert(1 + k, c, g[c].sum().to_numpy())
    summary["seeds"] = len(o.seeds)
    summary["unseen_doors"] = g["unseen_doors"].first().to_numpy()
    objects = _objects_behind_doors(dataset, estimators, o, settings) if o.objects else None
    return DoorTaskResult(summary, per_seed, pd.concat(records, ignore_index=True), world, first, objects, o)


DOOR_MODE_LABELS = {"all_open": "doors all open", "predicted": "doors predicted", "truth": "doors known"}


def walk_summary(objects: Any) -> Any:
    """Per method of the objects run: found targets, metres walked (all queries, and towards targets
    no route reaches at the query time, which the SR / SPL table leaves out), and the queries it
    lost / won against the same estimator with all doors open."""
    import pandas as pd

    rec = objects.records
    rows = []
    for name, df in rec.groupby("method", sort=False):
        d = df.set_index(["seed", "query_id"])
        row = {"method": name, "queries": len(d), "found": int(d["success"].sum()),
               "walked_m": float(d["path_m"].mean()),
               "walked_unreachable_m": float(d.loc[~d["reachable"], "path_m"].mean()) if (~d["reachable"]).any() else 0.0}
        base = name.rsplit(" [", 1)[0] + f" [{DOOR_MODE_LABELS['all_open']}]"
        if name != base and base in set(rec["method"]):
            b = rec[rec["method"] == base].set_index(["seed", "query_id"])["success"].reindex(d.index)
            row["lost_vs_all_open"] = int((b & ~d["success"]).sum())
            row["won_vs_all_open"] = int((~b & d["success"]).sum())
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
