"""Every subpackage has a curated ``__all__``: it resolves, has no duplicates, and lists every public
name the package's ``__init__`` imports (nothing is exported by accident or forgotten)."""

from __future__ import annotations

import importlib
import pkgutil
import types

import pytest

import psg_data

SUBPACKAGES = ["schemas", "loaders", "writers", "labeling", "estimators", "metrics", "synth", "navigation", "convert"]


@pytest.mark.parametrize("name", SUBPACKAGES)
def test_all_resolves_and_is_complete(name: str) -> None:
    pkg = importlib.import_module(f"psg_data.{name}")
    assert hasattr(pkg, "__all__"), f"psg_data.{name} has no __all__"
    for attr in pkg.__all__:
        assert hasattr(pkg, attr), f"psg_data.{name}.__all__ lists {attr!r}, which does not exist"
    assert len(set(pkg.__all__)) == len(pkg.__all__), f"psg_data.{name}.__all__ has duplicates"
    submodules = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    public = {a for a, v in vars(pkg).items()
              if not a.startswith("_") and a not in submodules and not isinstance(v, types.ModuleType)
              and a != "annotations"}
    missing = sorted(public - set(pkg.__all__))
    assert not missing, f"psg_data.{name} imports public names that __all__ does not list: {missing}"


def test_top_level_lazy_names() -> None:
    for attr in psg_data.__all__:
        assert getattr(psg_data, attr) is not None
    assert psg_data.datasets.demo is not None
