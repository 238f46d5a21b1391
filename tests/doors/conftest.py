"""Fixtures of the door tests: a small synthetic lab whose scans see the doors, and the loop world."""

from __future__ import annotations

from pathlib import Path

import pytest

# 12 keyframes per scan at 96 x 72 over 3 days: door B-C is seen in every scan (the robot starts in
# room B next to it), door A-B in a few.
DOOR_LAB = dict(seed=0, days=3, frames_per_scan=12, width=96, height=72)


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


@pytest.fixture(scope="session")
def loop_world():  # type: ignore[no-untyped-def]
    from psg_data.navigation import door_loop_world

    return door_loop_world(seed=0, pattern="weekly")
