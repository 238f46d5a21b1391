"""Small synthetic labs shared by the synth tests (2 days, 3 frames per scan, 80x60)."""

from __future__ import annotations

from pathlib import Path

import pytest

from psg_data.loaders import open_dataset
from psg_data.synth import LabConfig, LabModel, build_lab

SMALL = LabConfig(seed=3, days=2, frames_per_scan=3, width=80, height=60)


@pytest.fixture(scope="session")
def small_config() -> LabConfig:
    return SMALL


@pytest.fixture(scope="session")
def small_lab() -> LabModel:
    return LabModel(SMALL)


@pytest.fixture(scope="session")
def small_dataset_path(tmp_path_factory: pytest.TempPathFactory, small_lab: LabModel) -> Path:
    return build_lab(tmp_path_factory.mktemp("synth") / "lab", SMALL, lab=small_lab)


@pytest.fixture()
def small_dataset(small_dataset_path: Path):  # type: ignore[no-untyped-def]
    return open_dataset(small_dataset_path)
