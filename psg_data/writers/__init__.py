"""Writing psg-datasets: :class:`DatasetWriter` is used by every producer (synth, convert).

The names below are imported on first use, so that a command that only checks an output path
(:mod:`psg_data.writers._safe_output`) does not import pyarrow's Parquet writer.
"""

from __future__ import annotations

import typing as _typing

__all__ = ["add_tables", "DatasetWriter", "ScanWriter", "sha256_file", "to_arrow", "PNG_LEVEL", "JPEG_QUALITY"]

_LAZY = {"add_tables": "psg_data.writers._add_tables", **dict.fromkeys(
    ("DatasetWriter", "ScanWriter", "sha256_file", "to_arrow", "PNG_LEVEL", "JPEG_QUALITY"),
    "psg_data.writers._dataset_writer")}

if _typing.TYPE_CHECKING:  # pragma: no cover - what a type checker sees of the lazy names
    from psg_data.writers._add_tables import add_tables
    from psg_data.writers._dataset_writer import (
        JPEG_QUALITY,
        PNG_LEVEL,
        DatasetWriter,
        ScanWriter,
        sha256_file,
        to_arrow,
    )


def __getattr__(name: str) -> _typing.Any:
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value  # bound here: the next look-up is an ordinary attribute
        return value
    raise AttributeError(f"module 'psg_data.writers' has no attribute {name!r}")
