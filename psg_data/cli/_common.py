"""Shared CLI plumbing: the --quiet option, logging set-up and progress output (from
:mod:`psg_data.cli._progress`); the error contract (exit codes, one ``error:`` line) is in
:mod:`psg_data.cli._errors`.
"""

from __future__ import annotations

from pathlib import Path

import click

from psg_data.cli._errors import EXIT_OK, EXIT_PROBLEMS, EXIT_USAGE, handle_errors
from psg_data.cli._progress import Progress, setup_logging

__all__ = ["handle_errors", "setup_logging", "Progress", "quiet_option", "EXIT_OK", "EXIT_PROBLEMS", "EXIT_USAGE",
           "dataset_path", "DATASET_HELP"]


quiet_option = click.option("--quiet", "-q", is_flag=True, help="Only print warnings, errors and results.")

DATASET_HELP = "DATASET is a dataset directory, or demo for the built-in lab (built once into the cache)."


def dataset_path(value: str, *, command: str, quiet: bool = False) -> Path:
    """The directory of a DATASET argument: a path, or a built-in name (``psg_data.datasets.BUILTIN``)
    built on first use with progress; a built-in that is not a directory is refused in one line.
    """
    from psg_data.datasets import BUILTIN, resolve

    entry = BUILTIN.get(value)
    with Progress(f"building {value} (once)", total=entry.scans if entry else None, unit="scans",
                  quiet=quiet) as prog:
        return resolve(value, command=command, progress=prog)
