"""Progress output: a bar only on a terminal, plain separate lines otherwise, log lines never
inside a bar, nothing with --quiet."""

from __future__ import annotations

import io
import logging
import re
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from psg_data.cli import _progress
from psg_data.cli._progress import Progress, setup_logging

_PSG_DATA = str(Path(sys.executable).with_name("psg-data"))  # the console script pip installed
_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


@pytest.fixture
def term(monkeypatch: pytest.MonkeyPatch):  # type: ignore[no-untyped-def]
    """Route the shared console to a buffer: ``term(tty)`` returns the buffer."""
    def make(tty: bool) -> io.StringIO:
        buf = io.StringIO()
        con = Console(file=buf, force_terminal=tty, width=100, soft_wrap=True, highlight=False, emoji=False)
        monkeypatch.setattr(_progress, "_console", con)
        monkeypatch.setattr(_progress, "console", lambda: con)
        return buf
    yield make
    logging.getLogger().handlers.clear()


def test_plain_lines_when_not_a_terminal(term, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    buf = term(False)
    handler = _progress._ConsoleHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    log = logging.getLogger("psg_data.test_progress")
    monkeypatch.setattr(log, "handlers", [handler])
    monkeypatch.setattr(log, "propagate", False)
    log.setLevel(logging.INFO)
    clock = iter(range(0, 1000, 3))
    monkeypatch.setattr(_progress.time, "perf_counter", lambda: float(next(clock)))
    with Progress("synth", total=10, unit="scans", every_s=5.0) as p:
        for i in range(10):
            p(1)
            if i == 4:
                log.info("wrote something")
    text = buf.getvalue()
    assert "\r" not in text and "\x1b" not in text
    lines = text.splitlines()
    assert "INFO: wrote something" in lines
    progress_lines = [ln for ln in lines if ln.startswith("synth: ")]
    assert 2 <= len(progress_lines) <= 6  # throttled: one line per >= 5 s of (fake) time, not per update
    assert re.fullmatch(r"synth: 10/10 scans, done in \d+\.\d s \((\d+\.\d scans/s|\d+\.\d s each)\)",
                        progress_lines[-1])  # under one unit a second: seconds each
    assert all(ln.startswith(("synth: ", "INFO: ")) for ln in lines)


def test_bar_on_a_terminal_keeps_log_lines_on_their_own_lines(term) -> None:  # type: ignore[no-untyped-def]
    buf = term(True)
    setup_logging()
    _progress._console = None  # setup_logging resets it; the fixture's console stays in use
    p = Progress("convert", total=4, unit="frames")
    for i in range(4):
        p(1)
        if i == 1:
            logging.getLogger("psg_data.x").warning("a log line during the bar")
    p.close()
    text = buf.getvalue()
    assert "━" in text  # a bar was drawn
    rows = [_ANSI.sub("", r).split("\r")[-1].strip() for r in text.split("\n")]
    assert "WARNING: a log line during the bar" in rows  # alone on its row
    assert not any("a log line" in r and "frames" in r for r in rows)
    assert any(re.search(r"convert .*4/4 frames", r) for r in rows)


def test_quiet_prints_nothing(term) -> None:  # type: ignore[no-untyped-def]
    for tty in (False, True):
        buf = term(tty)
        with Progress("x", total=3, quiet=True) as p:
            p(3)
        assert buf.getvalue() == ""


def test_a_task_with_nothing_to_do_prints_nothing(term) -> None:  # type: ignore[no-untyped-def]
    buf = term(False)
    Progress("building the demo lab", total=84).close()
    assert buf.getvalue() == ""


def test_synth_redirected_to_a_file_writes_separate_lines(tmp_path: Path) -> None:
    """``psg-data synth OUT > log.txt 2>&1``: whole lines, no carriage returns, no escape codes."""
    log = tmp_path / "log.txt"
    with log.open("wb") as f:
        r = subprocess.run([_PSG_DATA, "synth", str(tmp_path / "lab"),
                            "--days", "1", "--frames-per-scan", "1", "--resolution", "40x30"],
                           stdout=f, stderr=subprocess.STDOUT, check=False)
    text = log.read_text()
    assert r.returncode == 0, text
    assert "\r" not in text and "\x1b" not in text
    lines = text.splitlines()
    assert any(re.fullmatch(r"synth: 4/4 scans, done in .*", ln) for ln in lines), text
    assert lines[-1] == f"wrote {tmp_path / 'lab'} (4 scans)"
    assert all(ln.startswith(("synth: ", "INFO: ", "wrote ")) for ln in lines), text
    q = subprocess.run([_PSG_DATA, "synth", str(tmp_path / "lab2"),
                        "--days", "1", "--frames-per-scan", "1", "--resolution", "40x30", "--quiet"],
                       capture_output=True, text=True, check=False)
    assert q.returncode == 0 and q.stderr == "" and q.stdout.strip() == f"wrote {tmp_path / 'lab2'} (4 scans)"


def test_slow_units_show_seconds_each_not_zero_per_second(term, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    """Two scenes in 56 s: '28.0 s each', never '0.0 scenes/s'."""
    buf = term(False)
    clock = iter([0.0, 28.0, 56.0, 56.0])
    monkeypatch.setattr(_progress.time, "perf_counter", lambda: next(clock))
    with Progress("scenes", total=2, unit="scenes", every_s=5.0) as p:
        p(1)
        p(1)
    last = buf.getvalue().splitlines()[-1]
    assert last == "scenes: 2/2 scenes, done in 56.0 s (28.0 s each)"


def test_a_started_task_speaks_before_its_first_unit(term) -> None:  # type: ignore[no-untyped-def]
    """start(): off a terminal, the plain line comes every every_s while the first unit is still running."""
    import threading

    buf = term(False)
    seen = threading.Event()
    with Progress("navigation", total=2, unit="scenes", every_s=0.01) as p:
        p.start()
        for _ in range(60_000):  # wait (not timed: until the line shows) for the heartbeat's line
            if "navigation: 0/2 scenes" in buf.getvalue():
                seen.set()
                break
            threading.Event().wait(0.001)
        assert seen.is_set(), buf.getvalue()
        assert "(the first scene still running)" in buf.getvalue()  # not "0.0 scenes/s"
        p(2)
    assert buf.getvalue().splitlines()[-1].startswith("navigation: 2/2 scenes, done in")
    buf = term(False)
    with Progress("navigation: filters and episodes", unit="runs", every_s=60.0) as q:
        q.start()  # nothing counted: the final line gives the time only
    assert re.fullmatch(r"navigation: filters and episodes: done in \d+\.\d s", buf.getvalue().strip())


def test_fit_summary_lines_once_per_command(term) -> None:  # type: ignore[no-untyped-def]
    """A run refits an estimator per seed and scene: its identical summary lines are printed once."""
    from psg_data.estimators._common import log_fit_summary

    buf = term(False)
    setup_logging()
    summary = {"settings": {"n_periods": {"value": 41, "source": "cadence"}},
               "error_rates": {"p_m": 0.1, "p_f": 0.2, "source": "pooled"}}
    for _ in range(3):
        log_fit_summary("fremen", summary)
    log_fit_summary("fremen", {"settings": {"n_periods": {"value": 84, "source": "cadence"}}})
    lines = buf.getvalue().splitlines()
    assert lines == ["INFO: fremen: n_periods = 41 (cadence)", "INFO: fremen: P_M = 0.1000, P_F = 0.2000 (pooled)",
                     "INFO: fremen: n_periods = 84 (cadence)"]
