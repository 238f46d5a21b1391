"""Shared CLI plumbing: turning PsgDataError into exit codes, the --quiet option; logging set-up and
progress output (from :mod:`psg_data.cli._progress`)."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import click

from psg_data.cli._progress import Progress, setup_logging
from psg_data.errors import PsgDataError

__all__ = ["handle_errors", "setup_logging", "Progress", "quiet_option", "EXIT_OK", "EXIT_PROBLEMS", "EXIT_USAGE"]

EXIT_OK = 0
EXIT_PROBLEMS = 1
"""Input was read but is invalid / a run finished with errors."""
EXIT_USAGE = 2
"""Bad command line (click's own convention)."""

F = TypeVar("F", bound=Callable[..., Any])


def handle_errors(fn: F) -> F:
    """Print a :class:`PsgDataError` as one ``error: ...`` line on stderr and exit 1."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except PsgDataError as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(EXIT_PROBLEMS)
        except KeyboardInterrupt:
            click.echo("error: interrupted; rerun the same command to resume", err=True)
            sys.exit(130)

    return wrapper  # type: ignore[return-value]


quiet_option = click.option("--quiet", "-q", is_flag=True, help="Only print warnings, errors and results.")
