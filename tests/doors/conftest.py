"""Fixtures of the door tests: a small synthetic lab whose scans see the doors, and the loop world."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

# 12 keyframes per scan at 96 x 72 over 3 days: door B-C is seen in every scan (the robot starts in
# room B next to it), door A-B in a few. The chain layout: a closed door hides the room behind it, so
# the robot's frames stay in fewer rooms and see the doors (in the two-route lab it visits all three
# rooms every scan and its receptacle-centred viewpoints rarely see a door).
DOOR_LAB = dict(seed=0, days=3, frames_per_scan=12, width=96, height=72, layout="chain")


@pytest.fixture(scope="session")
def door_lab_model():  # type: ignore[no-untyped-def]
    from psg_data.synth import LabConfig, LabModel

    return LabModel(LabConfig(**DOOR_LAB))


@pytest.fixture(scope="session")
def door_lab_path(tmp_path_factory: pytest.TempPathFactory, door_lab_model) -> Path:  # type: ignore[no-untyped-def]
    from psg_data.synth import build_lab

    return build_lab(tmp_path_factory.mktemp("doorlab") / "lab", door_lab_model.config, lab=door_lab_model)


@pytest.fixture
def door_lab_copy(tmp_path: Path, door_lab_path: Path) -> Path:
    import shutil

    dst = tmp_path / "lab"
    shutil.copytree(door_lab_path, dst)
    return dst


def lab_door_loop_world(seed: int = 0, days: int = 21, train_days: int = 14, noise: float = 0.0,
                        scan_hours: tuple[int, ...] = (9, 11, 13, 15), lab_door: str = "door_ab"):  # type: ignore[no-untyped-def]
    """:func:`door_loop_world` whose ``door_ab`` keeps door ``lab_door`` of the synthetic lab's working-day
    pattern on Monday-Friday and is closed all weekend (a clean weekly pattern); training streams: the door
    states at the lab's scan times of the first ``train_days`` days, each flipped with probability ``noise``."""
    from psg_data.navigation import door_loop_world
    from psg_data.schemas._streams import EdgeStream
    from psg_data.synth import LabConfig, LabModel
    from psg_data.synth._lab_schedule import DOOR_OPEN
    from psg_data.synth._schedule import EntityModel, WeekPattern, generate_timeline

    lab = LabModel(LabConfig(seed=seed, days=days, train_days=train_days, scan_hours=tuple(scan_hours),
                             generator="continuous-v1"))  # the door models below are continuous-time ones
    sched = lab.schedule
    base = sched.door_models[lab_door]
    week = WeekPattern("closed_weekends", ((0.5, 0.5), (0.5, 0.5)), ((0,),) * 5 + ((1,), (1,)))
    model = EntityModel(lab_door, (base.day_patterns[0], base.day_patterns[1]), (week,))
    tl = generate_timeline(model, 1000 + sched.door_ids.index(lab_door), seed, lab.config.date, days,
                           lab.config.timezone)

    def door_ab_open(t_s: float) -> bool:
        return int(np.asarray(tl.at(np.array([int(round(t_s * 1e9))], np.int64))).reshape(-1)[0]) == DOOR_OPEN

    t = np.array([p.start_ns for p in lab.scans if p.day < train_days], np.float64) / 1e9
    rng = np.random.default_rng([int(seed), 9001])
    streams = []
    for d in ("door_ab", "door_a_hall", "door_b_hall"):
        y = np.array([door_ab_open(ti) if d == "door_ab" else True for ti in t], np.int8)
        y = np.where(rng.random(y.size) < noise, 1 - y, y).astype(np.int8)
        streams.append(EdgeStream((d, "open"), t, y, {"source": f"schedule, noise {noise:g}"}))
    return door_loop_world(door_ab_open, streams, t_train_end_s=float(sched.day_starts_ns[train_days]) / 1e9,
                           t_end_s=float(sched.end_ns) / 1e9, timezone=lab.config.timezone,
                           name=f"door_loop(lab seed {seed}, {lab_door})")


@pytest.fixture(scope="session")
def loop_world():  # type: ignore[no-untyped-def]
    return lab_door_loop_world(seed=0)
