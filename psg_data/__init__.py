"""psg-data: data and evaluation toolkit for long-term semi-static robotics datasets.

Heavy modules (pyarrow, OpenCV, Open3D) are imported lazily: ``import psg_data`` stays fast.

Main entry points:
    open_dataset(path) -> Dataset        read a psg-dataset directory
    DatasetWriter(path, ...)             write one (used by synth and convert)
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

__version__ = "0.2.0"

__all__ = ["__version__", "open_dataset", "Dataset", "DatasetWriter", "validate_dataset"]

logging.getLogger(__name__).addHandler(logging.NullHandler())

_LAZY = {
    "open_dataset": ("psg_data.loaders", "open_dataset"),
    "Dataset": ("psg_data.loaders", "Dataset"),
    "DatasetWriter": ("psg_data.writers", "DatasetWriter"),
    "validate_dataset": ("psg_data.schemas.validate", "validate_dataset"),
}

if TYPE_CHECKING:  # pragma: no cover
    from psg_data.loaders import Dataset, open_dataset
    from psg_data.schemas.validate import validate_dataset
    from psg_data.writers import DatasetWriter


_SUBPACKAGES = frozenset({"datasets", "schemas", "loaders", "writers", "labeling", "estimators", "metrics", "synth",
                          "navigation", "convert", "graph", "maps"})


def __getattr__(name: str) -> Any:
    if name in _SUBPACKAGES:
        import importlib

        return importlib.import_module(f"psg_data.{name}")
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'psg_data' has no attribute {name!r}")
