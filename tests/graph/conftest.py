"""Fixtures of the graph tests: the small two-room dataset of the navigation tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.navigation.conftest import T0_S, write_nav_dataset

__all__ = ["T0_S"]


@pytest.fixture(scope="session")
def graph_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_nav_dataset(tmp_path_factory.mktemp("graphds") / "navds")
