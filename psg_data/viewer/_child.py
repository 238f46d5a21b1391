"""Child servers that end with the command that started them (the Rerun web viewer of ``view --web``).

One path for every way the command can end:

- it returns, fails, or is interrupted with Ctrl-C (SIGINT, a ``KeyboardInterrupt``): the caller's
  ``finally`` / ``with`` calls :meth:`ChildServer.stop`, which kills the child's process group;
- SIGHUP (a dropped SSH session, a closed terminal) or SIGTERM (``kill``): inside
  :func:`stop_signals` they raise :class:`Stopped` in the main thread, so the same ``finally`` runs
  (Python's default for both is to end the process at once, leaving the child running);
- psg-data itself is killed (SIGKILL, a crash: nothing of ours runs any more): on Linux the child
  is started with a parent-death signal (``prctl(PR_SET_PDEATHSIG, SIGKILL)``), so the kernel
  kills it. Elsewhere (macOS, Windows) this last case is not covered.

The child runs in a session (and process group) of its own: a terminal's Ctrl-C or hang-up does
not reach it behind our back, and killing the group reaches whatever it starts in turn.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import FrameType
from typing import Any

__all__ = ["ChildServer", "Stopped", "stop_signals"]

_DIE_WITH_PARENT = (
    "import ctypes, os, signal, sys\n"
    "ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG\n"
    "if os.getppid() != int(sys.argv[1]):\n"
    "    sys.exit(1)  # the parent died before the prctl call\n"
    "for name in ('SIGPIPE', 'SIGXFSZ'):  # Python ignores these; the server gets the defaults, as from Popen\n"
    "    signal.signal(getattr(signal, name), signal.SIG_DFL)\n"
    "os.execv(sys.argv[2], sys.argv[2:])\n"
)
"""Run (``python -c``) before the server: sets the parent-death signal, then becomes the server
(``execve`` keeps the signal). Done in a separate interpreter rather than in ``preexec_fn``, which
is unsafe in a process that runs threads (the Rerun SDK runs a dozen)."""


class Stopped(BaseException):
    """SIGHUP or SIGTERM arrived inside :func:`stop_signals` (a ``BaseException``, like
    ``KeyboardInterrupt``: no ``except Exception`` swallows it).
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _stop_signals() -> list[signal.Signals]:
    return [s for s in (getattr(signal, "SIGHUP", None), getattr(signal, "SIGTERM", None)) if s is not None]


@contextlib.contextmanager
def stop_signals() -> Iterator[None]:
    """Within the block, SIGHUP and SIGTERM raise :class:`Stopped` in the main thread; a second one
    while the first is being handled is ignored. The previous handlers are restored when the block
    ends. A signal the process ignores (``nohup``) stays ignored; outside the main thread (where
    Python cannot install handlers) nothing changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old: dict[signal.Signals, Any] = {}

    def handler(signum: int, _frame: FrameType | None) -> None:
        for sig in old:
            signal.signal(sig, lambda *_: None)  # one is enough: the cleanup that follows is not interrupted
        raise Stopped(signum)

    try:
        for sig in _stop_signals():
            previous = signal.getsignal(sig)
            if previous is not None and previous != signal.SIG_IGN:
                old[sig] = signal.signal(sig, handler)
        yield
    finally:
        for sig, previous in old.items():
            signal.signal(sig, previous)


class ChildServer:
    """A server process (``argv``) in a process group of its own, killed with everything it started
    by :meth:`stop`; on Linux also killed by the kernel if this process dies first.

    Args:
        argv: the command (an executable path first).
        log: file that receives the server's output (None: discarded).
    """

    def __init__(self, argv: Sequence[str], *, log: Path | None = None) -> None:
        self.argv, self.log = list(argv), log
        self._proc: subprocess.Popen[bytes] | None = None

    @property
    def pid(self) -> int | None:
        """The server's process id (on POSIX also its process group id), None when not running."""
        return None if self._proc is None else self._proc.pid

    def start(self) -> None:
        """Start the server (its output goes to :attr:`log`)."""
        argv = self.argv
        if sys.platform.startswith("linux"):
            argv = [sys.executable, "-I", "-c", _DIE_WITH_PARENT, str(os.getpid()), *argv]
        with open(self.log, "wb") if self.log is not None else contextlib.nullcontext(subprocess.DEVNULL) as out:
            self._proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                          start_new_session=os.name == "posix")

    def running(self) -> bool:
        """Whether the server process still runs."""
        return self._proc is not None and self._proc.poll() is None

    def stop(self, grace_s: float = 10.0) -> None:
        """SIGTERM to the server's process group, SIGKILL after ``grace_s`` seconds (idempotent)."""
        if self._proc is None:
            return
        self._signal(signal.SIGTERM)
        try:
            self._proc.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            self._signal(signal.SIGKILL if os.name == "posix" else signal.SIGTERM)
            self._proc.wait()
        self._signal(signal.SIGKILL if os.name == "posix" else signal.SIGTERM)  # the rest of the group, if any
        self._proc = None

    def _signal(self, sig: int) -> None:
        assert self._proc is not None
        with contextlib.suppress(ProcessLookupError, PermissionError):
            if os.name == "posix":
                os.killpg(self._proc.pid, sig)
            else:  # pragma: no cover - Windows
                self._proc.send_signal(sig)
