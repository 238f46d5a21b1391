"""The error contract of every command: one ``error: ...`` line on stderr and a documented exit code.

======  ==========================================================================================
code    meaning
======  ==========================================================================================
0       done (warnings, e.g. skipped frames, may have been printed)
1       bad input or output: a file, recording, dataset or output path cannot be used (one line
        naming the file, the field and what was expected), or problems were found (``validate``,
        estimators returning invalid predictions)
2       bad command line: unknown option, missing argument, an option value of the wrong type or
        out of range (one line, and where to find the help)
130     interrupted (Ctrl-C); "rerun ... to resume" is said only where a rerun resumes (convert)
129     ``view --web`` ended by SIGHUP (its terminal or SSH session gone), silently; 143: by SIGTERM
        (``kill``); its Rerun server ends with it in every case (``psg_data/viewer/_child.py``)
======  ==========================================================================================

A reader that leaves early (``psg-eval ... | head``, quitting ``less``) does not stop a command: the
rest of its standard output is dropped (:class:`ReaderGoneStdout`), its work and files are finished
and it exits with its own code, printing nothing about the closed pipe.

A traceback means a bug in psg-data: anything a user or a recording can hand us ends in one line.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import click

from psg_data.errors import PsgDataError

__all__ = ["EXIT_OK", "EXIT_PROBLEMS", "EXIT_USAGE", "EXIT_INTERRUPTED", "handle_errors", "OneLineErrors",
           "ContractCommand", "ContractGroup", "check_jobs", "one_line", "ReaderGoneStdout"]

EXIT_OK = 0
EXIT_PROBLEMS = 1
"""Input or output cannot be used / problems were found."""
EXIT_USAGE = 2
"""Bad command line (click's own convention, kept for every command)."""
EXIT_INTERRUPTED = 130
"""Interrupted by Ctrl-C (128 + SIGINT)."""

F = TypeVar("F", bound=Callable[..., Any])


def one_line(text: object) -> str:
    """``text`` with its lines joined (an error is always printed as one line)."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def _interrupted(exc: BaseException) -> None:
    hint = getattr(exc, "resume_hint", None)
    click.echo(f"error: interrupted{'; ' + hint if hint else ''}", err=True)
    sys.exit(EXIT_INTERRUPTED)


def handle_errors(fn: F) -> F:
    """Print a :class:`PsgDataError` (or an OS error: permissions, disk full, a file gone) as one
    ``error: ...`` line and exit 1; Ctrl-C as ``error: interrupted`` with exit 130.
    """

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except PsgDataError as exc:
            click.echo(f"error: {one_line(exc)}", err=True)
            sys.exit(EXIT_PROBLEMS)
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            click.echo(f"error: {where}{one_line(exc.strerror or exc)}", err=True)
            sys.exit(EXIT_PROBLEMS)
        except KeyboardInterrupt as exc:
            _interrupted(exc)

    return wrapper  # type: ignore[return-value]


class ReaderGoneStdout:
    """``sys.stdout`` while a command runs: once its reader has closed the pipe (``| head``), the rest of
    the output is dropped instead of raising :class:`BrokenPipeError` into the work.

    The descriptor is then pointed at the null device, so the text still buffered in the original
    stream (flushed at interpreter exit) goes nowhere instead of raising again. Everything else is
    the wrapped stream's.
    """

    def __init__(self, stream: Any) -> None:
        self._stream = stream
        self.reader_gone = False

    def _gone(self) -> None:
        self.reader_gone = True
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(null, self._stream.fileno())
            finally:
                os.close(null)
        except (OSError, ValueError, AttributeError):  # no descriptor (a test's stream): dropping is enough
            pass

    def write(self, text: str) -> int:
        if not self.reader_gone:
            try:
                n = self._stream.write(text)
                return len(text) if n is None else int(n)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.reader_gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._gone()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


class OneLineErrors:
    """click's command-line errors as one line with exit 2 (click prints a usage block otherwise); a
    closed standard output (``| head``) as nothing at all (:class:`ReaderGoneStdout`).
    """

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        if not standalone_mode or isinstance(sys.stdout, ReaderGoneStdout):
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)  # type: ignore[misc]
        stdout, sys.stdout = sys.stdout, ReaderGoneStdout(sys.stdout)  # type: ignore[assignment]
        try:
            self._main(args, prog_name, complete_var, **extra)
        finally:
            sys.stdout.flush()
            sys.stdout = stdout

    def _main(self, args: Any, prog_name: str | None, complete_var: str | None, **extra: Any) -> None:
        try:
            rv = super().main(args, prog_name, complete_var, False, **extra)  # type: ignore[misc]
        except click.UsageError as exc:
            ctx = exc.ctx
            if type(exc).__name__ == "NoArgsIsHelpError" and ctx is not None:  # bare command: its help
                click.echo(ctx.get_help())
                sys.exit(EXIT_USAGE)
            hint = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
            click.echo(f"error: {one_line(exc.format_message())}{hint}", err=True)
            sys.exit(EXIT_USAGE)
        except click.ClickException as exc:
            click.echo(f"error: {one_line(exc.format_message())}", err=True)
            sys.exit(exc.exit_code)
        except (click.exceptions.Abort, KeyboardInterrupt) as exc:
            _interrupted(exc.__cause__ or exc)
        sys.exit(rv if isinstance(rv, int) else EXIT_OK)


class ContractCommand(OneLineErrors, click.Command):
    """A click command following the error contract."""


class ContractGroup(OneLineErrors, click.Group):
    """A click group following the error contract (its subcommands are reached through it)."""

    command_class = ContractCommand


def check_jobs(_ctx: click.Context, _param: click.Parameter, value: int) -> int:
    """``--jobs``: a number of CPUs >= 1, or -1 for all (else a usage error, exit 2)."""
    if value == 0 or value < -1:
        raise click.BadParameter(f"{value}: expected a number of CPUs >= 1, or -1 for all")
    return value
