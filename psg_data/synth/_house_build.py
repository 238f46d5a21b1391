"""A procedural house as a model (geometry, schedules, patrol visibility) and as a psg-dataset without images.

:class:`HouseModel` draws everything from a :class:`HouseConfig`; :func:`build_house` writes it:

* ``rooms`` (floor polygons), ``receptacles``, ``doors`` (boxes), ``objects``: the geometry
  :func:`psg_data.navigation.grid_from_geometry` builds the occupancy grid from;
* ``scans``: one per hourly step (672 = 4 weeks x 24 h; ``step_000`` ...), no frames: each
  "scan" is the step's interval ``[start, start + 1 h - 1 s]``; ``split`` train (weeks 1-2), val
  (week 3), test (week 4);
* ``schedule`` and ``door_states``: the sampled state of every object and door at every step (the
  ground truth; the ``gt`` label source observes every receptacle at every step);
* ``visibility``: what the hourly patrol saw (:meth:`HouseLayout.patrol_visibility`): per step
  and receptacle (kind ``receptacle``) or door (kind ``door``) ``frames_seen`` = the number of
  visited patrol points with a line of sight to it, ``seen_fraction`` 1 or 0, ``pixels`` 0 (no
  images), ``visible`` = seen. ``psg-data label PATH --source privileged`` (and
  ``psg_data.labeling.label_dataset``) reuse it: the privileged codes are the ground truth where
  the patrol saw the receptacle (an object is seen when its receptacle is), -1 elsewhere;
* ``generator/process.json``: the generating model, the training model plus the test-week regime
  of the shifted objects (``process.base_model()`` is the training model);
* manifest ``extra``: every generator parameter, the house's room kinds, patrol and objects.
"""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.schemas._generator_model import PROCESS_FILE, StepProcess
from psg_data.schemas._records import ObjectInfo
from psg_data.synth._house_layout import HouseLayout, HouseParams, make_house
from psg_data.synth._house_process import SPLITS, HouseProcessParams, house_process
from psg_data.synth._process import EntityPath, sample_entity

__all__ = ["HouseConfig", "HouseModel", "build_house", "HOUSE_GENERATOR", "HOUSE_VERSION"]

HOUSE_GENERATOR = "psg_data.synth.house"
"""Manifest ``extra.generator`` of a house dataset."""
HOUSE_VERSION = 1


@dataclass(frozen=True)
class HouseConfig:
    """Everything a house dataset is drawn from (stored in the manifest's ``extra``).

    Attributes:
        seed: house seed (geometry, objects, schedules, paths).
        geometry: floor plan, doors, receptacles, objects, patrol.
        schedules: routine strength, dwell, the test-time shift knob.
        start_date: a Monday, the first local day (week 1).
        timezone: IANA zone of the local hours.
        weeks: weeks of hourly steps (4: train, train, validation, test).
    """

    seed: int = 0
    geometry: HouseParams = field(default_factory=HouseParams)
    schedules: HouseProcessParams = field(default_factory=HouseProcessParams)
    start_date: str = "2024-01-08"
    timezone: str = "America/Toronto"
    weeks: int = 4

    def to_extra(self) -> dict[str, Any]:
        """The configuration as the manifest's ``extra`` (generator, parameters, splits, process file)."""
        return {"generator": HOUSE_GENERATOR, "house_version": HOUSE_VERSION, "seed": self.seed,
                "geometry": asdict(self.geometry), "schedules": asdict(self.schedules),
                "shift": self.schedules.shift, "start_date": self.start_date, "timezone": self.timezone,
                "weeks": self.weeks, "step_hours": list(range(24)), "process_file": PROCESS_FILE,
                "splits": [list(s) for s in SPLITS]}


class HouseModel:
    """A drawn house: layout, generating process, sampled paths, per-step states and patrol visibility.

    Attributes:
        layout: the geometry (:class:`HouseLayout`).
        process: the generating model (training model + test-week regime).
        paths: entity id -> its sampled path over ``n_steps`` hourly steps.
        step_starts_ns: (n_steps,) UTC start of every step.
    """

    def __init__(self, config: HouseConfig | None = None) -> None:
        self.config = cfg = config or HouseConfig()
        self.layout: HouseLayout = make_house(cfg.seed, cfg.geometry)
        days = 7 * cfg.weeks
        self.process: StepProcess = house_process(self.layout, cfg.schedules, dt.date.fromisoformat(cfg.start_date),
                                                  cfg.timezone, days)
        self.n_steps = days * 24
        self.step_starts_ns = np.array([int(round(self.process.clock.step_start_s(n))) * 10**9
                                        for n in range(self.n_steps)], np.int64)
        self.paths: dict[str, EntityPath] = {
            eid: sample_entity(self.process, e, self.n_steps, np.random.default_rng([cfg.seed, 2521, i]))
            for i, (eid, e) in enumerate(self.process.entities.items())}

    def state(self, entity_id: str) -> list[str | None]:
        """The entity's state label at every step."""
        e = self.process.entities[entity_id]
        return [e.states[s] for s in self.paths[entity_id].states]

    def split_of_step(self) -> list[str]:
        """Split of every step (train / val / test)."""
        out = []
        for n in range(self.n_steps):
            day = n // 24
            out.append(next(name for name, a, b in SPLITS if a <= day < b) if day < SPLITS[-1][2] else "test")
        return out

    def door_open(self) -> NDArray[np.bool_]:
        """(n_steps, doors) True where the door is open."""
        return np.stack([np.asarray(self.state(d)) == "open" for d in self.layout.door_ids], axis=1)

    def patrol(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(n_steps, receptacles) and (n_steps, doors): patrol points that saw each one at each step."""
        opens = self.door_open()
        ids = self.layout.door_ids
        cache: dict[bytes, tuple[NDArray[np.int64], NDArray[np.int64]]] = {}
        rec, door = [], []
        for row in opens:
            key = row.tobytes()
            if key not in cache:
                cache[key] = self.layout.patrol_visibility(dict(zip(ids, row.tolist())))
            rec.append(cache[key][0])
            door.append(cache[key][1])
        return np.asarray(rec, np.int64), np.asarray(door, np.int64)


def _scan_ids(n: int) -> list[str]:
    return [f"step_{i:03d}" for i in range(n)]


def build_house(out: str | Path, config: HouseConfig | None = None, *, overwrite: bool = False,
                progress: Callable[..., Any] | None = None, model: HouseModel | None = None) -> Path:
    """Write a house as a psg-dataset at ``out`` (module docstring); ``progress(1)`` once when done.

    Raises:
        DatasetExistsError: ``out`` exists and ``overwrite`` is False.
    """
    import pyarrow as pa

    from psg_data.schemas._tables import TABLES
    from psg_data.writers import DatasetWriter

    m = model or HouseModel(config)
    cfg, L = m.config, m.layout
    extra = {**cfg.to_extra(), "house": L.to_dict()}
    sids = _scan_ids(m.n_steps)
    splits = m.split_of_step()
    with DatasetWriter(out, name=Path(out).name, timezone=cfg.timezone, overwrite=overwrite, extra=extra) as w:
        w.set_rooms(L.rooms)
        w.set_receptacles(L.receptacles)
        w.set_doors(L.doors)
        w.set_objects([ObjectInfo(o.object_id, o.object_type, f"{o.object_type} ({o.role})") for o in L.objects])
        empty = TABLES["frames"].schema.empty_table()
        for sid, t0, split in zip(sids, m.step_starts_ns, splits):  # frameless scans: one per hourly step
            w.adopt_scan({"scan": {"scan_id": sid, "start_stamp_ns": int(t0), "end_stamp_ns": int(t0) + 3599 * 10**9,
                                   "source": f"{HOUSE_GENERATOR} seed={cfg.seed}", "split": split},
                          "frames": empty, "files": {}})
        sched = {o: m.state(o) for o in L.object_ids}
        w.set_table("schedule", pa.table({
            "scan_id": np.repeat(sids, len(L.object_ids)).tolist(),
            "object_id": L.object_ids * len(sids),
            "receptacle_id": [sched[o][n] for n in range(m.n_steps) for o in L.object_ids]}))
        opens = m.door_open()
        w.set_table("door_states", pa.table({
            "scan_id": np.repeat(sids, len(L.door_ids)).tolist(), "door_id": L.door_ids * len(sids),
            "state": np.where(opens.reshape(-1), "open", "closed").tolist()}))
        w.set_table("visibility", _visibility_table(sids, L, *m.patrol()))
        w.add_file(PROCESS_FILE, m.process.to_json().encode("utf-8"))
    if progress is not None:
        progress(1)
    return Path(out)


def _visibility_table(sids: list[str], L: HouseLayout, rec: NDArray[np.int64], door: NDArray[np.int64]) -> Any:
    import pyarrow as pa

    seen = np.concatenate([rec, door], axis=1)
    ids = L.receptacle_ids + L.door_ids
    kinds = ["receptacle"] * len(L.receptacle_ids) + ["door"] * len(L.door_ids)
    meta = {b"psg_visibility_params": json.dumps({"sensor": "patrol line of sight on the house walls and doors",
                                                  "view_range_m": L.view_range_m}).encode()}
    return pa.table({"scan_id": np.repeat(sids, len(ids)).tolist(), "kind": kinds * len(sids), "id": ids * len(sids),
                     "seen_fraction": (seen.reshape(-1) > 0).astype(np.float64), "pixels": np.zeros(seen.size),
                     "frames_seen": seen.reshape(-1).astype(np.int32), "visible": seen.reshape(-1) > 0}
                    ).replace_schema_metadata(meta)
