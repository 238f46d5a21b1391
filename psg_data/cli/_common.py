"""Shared CLI plumbing: the --quiet option, logging set-up and progress output (from
:mod:`psg_data.cli._progress`); the error contract (exit codes, one ``error:`` line) is in
:mod:`psg_data.cli._errors`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from psg_data.cli._errors import EXIT_OK, EXIT_PROBLEMS, EXIT_USAGE, handle_errors
from psg_data.cli._progress import Progress, setup_logging

__all__ = ["handle_errors", "setup_logging", "Progress", "quiet_option", "EXIT_OK", "EXIT_PROBLEMS", "EXIT_USAGE",
           "dataset_path", "DATASET_HELP", "old_spelling", "from_old_spelling"]


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


def old_spelling(old: str, new: str, dest: str, **kwargs: Any) -> Any:
    """A hidden option ``old`` that is a renamed option's former spelling, kept for one release (one name
    per idea: ``psg-data label --seed`` is ``--label-seed`` as in psg-eval). Its value arrives as ``dest``
    (default None); :func:`from_old_spelling` merges it into the new option's.
    """
    return click.option(old, dest, default=None, hidden=True,
                        help=f"Former spelling of {new} (kept for one release).", **kwargs)


def from_old_spelling(old_value: Any, value: Any, *, old: str, new: str, new_param: str) -> Any:
    """The value of a renamed option: ``old_value`` when the old spelling was used (with a one-line
    ``warning:``), else ``value``; both given is a usage error (exit 2).
    """
    if old_value is None:
        return value
    ctx = click.get_current_context()
    if ctx.get_parameter_source(new_param) == click.core.ParameterSource.COMMANDLINE:
        raise click.UsageError(f"{old} is the former spelling of {new}; give one of them")
    click.echo(f"warning: {old} is now {new}; the old spelling goes in the next release", err=True)
    return old_value
