"""What the commands print while they work: log lines and progress, through one rich console on stderr.

- stderr is a terminal: a live progress bar (rich) at the bottom; log lines are printed above it by
  the same console, so the two never share a line.
- stderr is a file or a pipe (``psg-data synth OUT > log.txt 2>&1``, CI): no bar and no carriage
  returns; one plain line every ``every_s`` seconds (default 5) and a final line per task.
- ``--quiet``: neither progress nor INFO lines (warnings and errors still print).

A task whose first unit may take long (a scene, a seed) calls :meth:`Progress.start`: the bar shows at
once (its clock runs) or, off a terminal, the plain line is printed every ``every_s`` seconds until
the task ends, so no task is silent. A rate under one unit a second is shown as seconds per unit.
"""

from __future__ import annotations

import atexit
import logging
import threading
import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["Progress", "console", "setup_logging"]

_console: Console | None = None


def console() -> Console:
    """The console that log lines and progress share (stderr, whatever ``sys.stderr`` is when it writes)."""
    global _console
    if _console is None:
        from rich.console import Console  # on first output: a quiet command does not import rich

        _console = Console(stderr=True, soft_wrap=True, highlight=False, emoji=False)
    return _console


class _ConsoleHandler(logging.Handler):
    """Writes log records through :func:`console`: above a live bar, never into it. A record marked
    ``say_once`` (an estimator's fit summary, repeated by every refit) is printed once per command.
    """

    def __init__(self) -> None:
        super().__init__()
        self._said: set[str] = set()

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record)
            if getattr(record, "say_once", False):
                if text in self._said:
                    return
                self._said.add(text)
            console().print(text, markup=False, highlight=False, emoji=False)
        except Exception:  # noqa: BLE001 - logging must not raise
            self.handleError(record)


def setup_logging(quiet: bool = False, verbose: bool = False) -> None:
    """``LEVEL: message`` lines on stderr (WARNING and up with ``quiet``, DEBUG with ``verbose``)."""
    global _console
    _console = None  # a new command: stderr may be another stream (tests) or terminal now
    handler = _ConsoleHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    level = logging.WARNING if quiet else (logging.DEBUG if verbose else logging.INFO)
    logging.basicConfig(level=level, handlers=[handler], force=True)


class Progress:
    """Progress of one long task: ``label: done/total unit (rate/s, MB/s, extra)``.

    Call it (or :meth:`update`) with the units done since the last call; set ``done`` directly for
    absolute counts. The bar appears at the first call; :meth:`close` (or leaving a ``with``
    block) prints the final state.

    Args:
        label: what is being done (``synth``, ``convert``, ``evaluating``).
        total: units expected, None if unknown (the bar then shows activity only).
        unit: name of a unit (``scans``, ``frames``).
        quiet: print nothing.
        every_s: seconds between plain lines when stderr is not a terminal.
    """

    def __init__(self, label: str, total: int | None = None, unit: str = "items", quiet: bool = False,
                 every_s: float = 5.0) -> None:
        self.label, self.total, self.unit, self.quiet, self.every_s = label, total, unit, quiet, every_s
        self.done = 0
        self.bytes = 0
        self.t0 = time.perf_counter()
        self._last = self.t0
        self._extra: dict[str, Any] = {}
        self._bar: Any = None
        self._started = self._closed = False
        self._heartbeat: threading.Event | None = None

    def _start_bar(self) -> None:
        from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
        from rich.progress import Progress as RichProgress

        counts = MofNCompleteColumn() if self.total else TextColumn("{task.completed}")
        self._bar = RichProgress(TextColumn("{task.description}"), BarColumn(), counts,
                                 TextColumn(self.unit), TextColumn("{task.fields[rate]}"), TimeElapsedColumn(),
                                 TimeRemainingColumn(), console=console(), transient=False)
        self._task = self._bar.add_task(self.label, total=self.total, rate="")
        self._bar.start()
        atexit.register(self.close)  # an error exit still restores the terminal

    def _rate(self, now: float) -> str:
        dt = max(now - self.t0, 1e-9)
        mb = f", {self.bytes / dt / 1e6:.1f} MB/s" if self.bytes else ""
        more = "".join(f", {k} {v}" for k, v in self._extra.items())
        if not self.done:  # a started task whose first unit is still running (start())
            return f"the first {self.unit.rstrip('s') or self.unit} still running{mb}{more}"
        if self.done / dt < 1.0:  # slow units: "28.1 s each", not "0.0 scenes/s"
            return f"{dt / self.done:.1f} s each{mb}{more}"
        return f"{self.done / dt:.1f} {self.unit}/s{mb}{more}"

    def _line(self, now: float, final: bool) -> str:
        if final and not self.done:  # a started task that counted nothing: its time only
            return f"{self.label}: done in {now - self.t0:.1f} s"
        total = f"/{self.total}" if self.total else ""
        when = f"done in {now - self.t0:.1f} s" if final else f"{now - self.t0:.0f} s"
        return f"{self.label}: {self.done}{total} {self.unit}, {when} ({self._rate(now)})"

    def update(self, n: int = 1, nbytes: int = 0, **extra: Any) -> None:
        self.done += n
        self.bytes += nbytes
        self._extra.update(extra)
        if self.quiet or self._closed:
            return
        if not self._started:  # on first use: a task that turns out to have nothing to do shows nothing
            self._started = True
            if console().is_terminal:
                self._start_bar()
        now = time.perf_counter()
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done, rate=f"({self._rate(now)})")
        elif now - self._last >= self.every_s and not (self.total and self.done >= self.total):
            self._last = now
            console().print(self._line(now, final=False), markup=False)

    __call__ = update

    def start(self) -> Progress:
        """Show the task now, before its first unit is done (module docstring); returns ``self``."""
        if self.quiet or self._started or self._closed:
            return self
        self._started = True
        if console().is_terminal:
            self._start_bar()
            return self
        self._heartbeat = stop = threading.Event()

        def beat() -> None:
            while not stop.wait(self.every_s):
                now = time.perf_counter()
                if now - self._last >= self.every_s * 0.99:
                    self._last = now
                    console().print(self._line(now, final=False), markup=False)

        threading.Thread(target=beat, name=f"progress: {self.label}", daemon=True).start()
        return self

    def close(self) -> None:
        """Stop the bar (it stays on screen) or print the final line; idempotent. Prints nothing
        if no progress was ever reported.
        """
        if self.quiet or self._closed or not self._started:
            return
        self._closed = True
        if self._heartbeat is not None:
            self._heartbeat.set()
        now = time.perf_counter()
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done, rate=f"({self._rate(now)})")
            self._bar.stop()
        else:
            console().print(self._line(now, final=True), markup=False)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
