"""psg-data: data and evaluation toolkit for long-term semi-static robotics datasets.

Every subpackage is an attribute, imported on first use (PEP 562): ``import psg_data`` imports no
numpy, pyarrow, OpenCV or Open3D and stays fast (bench/bench_import.py), and
``psg_data.evaluation.load_results(DIR)`` works after ``import psg_data`` alone.

Main entry points:
    open_dataset(path) -> Dataset        read a psg-dataset directory
    DatasetWriter(path, ...)             write one (used by synth and convert)
    validate_dataset(path) -> problems   check one

Subpackages (``dir(psg_data)`` lists them with the names above): ``datasets`` (the built-in
datasets), ``schemas`` (the format), ``loaders``, ``writers``, ``convert``, ``synth``,
``labeling``, ``estimators`` (plugin interface, registry, built-ins), ``maps`` (occupancy grids
and planners), ``metrics``, ``graph`` (the predictive scene graph), ``evaluation`` (the task
harnesses and results files), ``navigation``, ``viewer`` (Rerun, ``psg-data[viewer]``) and
``errors``.
"""

from __future__ import annotations

import logging as _logging
from typing import TYPE_CHECKING, Any

__version__ = "0.2.0"

__all__ = ["__version__", "open_dataset", "Dataset", "DatasetWriter", "validate_dataset"]

_logging.getLogger(__name__).addHandler(_logging.NullHandler())

_LAZY = {
    "open_dataset": ("psg_data.loaders", "open_dataset"),
    "Dataset": ("psg_data.loaders", "Dataset"),
    "DatasetWriter": ("psg_data.writers", "DatasetWriter"),
    "validate_dataset": ("psg_data.schemas.validate", "validate_dataset"),
}

if TYPE_CHECKING:  # pragma: no cover - what a type checker sees of the lazy attributes
    from psg_data import convert as convert
    from psg_data import datasets as datasets
    from psg_data import errors as errors
    from psg_data import estimators as estimators
    from psg_data import evaluation as evaluation
    from psg_data import graph as graph
    from psg_data import labeling as labeling
    from psg_data import loaders as loaders
    from psg_data import maps as maps
    from psg_data import metrics as metrics
    from psg_data import navigation as navigation
    from psg_data import schemas as schemas
    from psg_data import synth as synth
    from psg_data import viewer as viewer
    from psg_data import writers as writers
    from psg_data.loaders import Dataset, open_dataset
    from psg_data.schemas.validate import validate_dataset
    from psg_data.writers import DatasetWriter


_SUBPACKAGES = ("datasets", "schemas", "loaders", "writers", "convert", "synth", "labeling", "estimators", "maps",
                "metrics", "graph", "evaluation", "navigation", "viewer", "errors")
"""The public subpackages, each an attribute of ``psg_data`` imported on first use."""


def __getattr__(name: str) -> Any:
    if name in _SUBPACKAGES:
        import importlib

        return importlib.import_module(f"psg_data.{name}")  # importing binds it here: one import each
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'psg_data' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The public API: the names of ``__all__`` and the subpackages (not this module's own imports)."""
    return sorted({*__all__, *_SUBPACKAGES})
