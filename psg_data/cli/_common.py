"""Shared CLI plumbing: logging set-up, progress output and turning PsgDataError into exit codes."""

from __future__ import annotations

import functools
import logging
import sys
import time
from collections.abc import Callable
from typing import Any, TypeVar

import click

from psg_data.errors import PsgDataError

__all__ = ["handle_errors", "setup_logging", "Progress", "quiet_option", "EXIT_OK", "EXIT_PROBLEMS", "EXIT_USAGE"]

EXIT_OK = 0
EXIT_PROBLEMS = 1
"""Input was read but is invalid / a run finished with errors."""
EXIT_USAGE = 2
"""Bad command line (click's own convention)."""

F = TypeVar("F", bound=Callable[..., Any])


def setup_logging(quiet: bool = False, verbose: bool = False) -> None:
    level = logging.WARNING if quiet else (logging.DEBUG if verbose else logging.INFO)
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr, force=True)


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


class Progress:
    """Throttled one-line progress on stderr: ``label: done/total [unit] (rate/s, MB/s)``."""

    def __init__(self, label: str, total: int | None = None, unit: str = "items", quiet: bool = False,
                 every_s: float = 0.5) -> None:
        self.label, self.total, self.unit, self.quiet, self.every_s = label, total, unit, quiet, every_s
        self.done = 0
        self.bytes = 0
        self.t0 = time.perf_counter()
        self._last = 0.0

    def update(self, n: int = 1, nbytes: int = 0, **extra: Any) -> None:
        self.done += n
        self.bytes += nbytes
        now = time.perf_counter()
        if not self.quiet and (now - self._last >= self.every_s or (self.total and self.done >= self.total)):
            self._last = now
            self._print(now, extra)

    def _print(self, now: float, extra: dict[str, Any]) -> None:
        dt = max(now - self.t0, 1e-9)
        total = f"/{self.total}" if self.total else ""
        rate = f"{self.done / dt:.1f} {self.unit}/s"
        mb = f", {self.bytes / dt / 1e6:.1f} MB/s" if self.bytes else ""
        more = "".join(f", {k} {v}" for k, v in extra.items())
        click.echo(f"\r{self.label}: {self.done}{total} {self.unit} ({rate}{mb}{more})   ", err=True, nl=False)

    def close(self) -> None:
        if not self.quiet:
            self._print(time.perf_counter(), {})
            click.echo("", err=True)

    def __call__(self, n: int = 1, nbytes: int = 0, **extra: Any) -> None:
        self.update(n, nbytes, **extra)
