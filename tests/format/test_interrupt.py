"""Ctrl-C with ``--jobs``: every process of the run stops, one ``error: interrupted`` line, exit 130, and
"resume" is said only where a rerun resumes (convert). The exit latency itself is measured by
``bench/bench_interrupt.py`` (speed is never asserted here; the timeout only catches a hang)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.convert.conftest import write_bag

pytestmark = [pytest.mark.slow, pytest.mark.skipif(os.name != "posix", reason="process groups and SIGINT")]

HANG_S = 30.0


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupt_when(args: list[str], ready: Path, cwd: Path, after_s: float = 0.5) -> tuple[int, str, float]:
    """Run ``args`` in a new process group, send SIGINT to the group ``after_s`` after ``ready`` appears.

    Returns (exit code, stderr, seconds from the signal to the exit).
    """
    # a test run started in the background by a non-interactive shell inherits SIGINT ignored, and so
    # would the command (which then rightly ignores the Ctrl-C): give it the default disposition
    proc = subprocess.Popen(args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=_default_sigint)
    t_end = time.monotonic() + 120
    while not ready.exists() and proc.poll() is None and time.monotonic() < t_end:
        time.sleep(0.05)
    time.sleep(after_s)
    assert proc.poll() is None, f"finished before the interrupt: {proc.communicate()}"
    t0 = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: every process of the group
    try:
        _, err = proc.communicate(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise AssertionError("still running after Ctrl-C") from None
    return proc.returncode, err, time.monotonic() - t0


def _cli(name: str) -> list[str]:
    return [sys.executable, "-c", f"import sys; from psg_data.cli.{name} import main; sys.exit(main())"]


def test_psg_eval_jobs_stops_at_once(tmp_path: Path) -> None:
    out = tmp_path / "res"
    code, err, dt = interrupt_when(
        [*_cli("psg_eval_cmd"), "--dataset", "persistence-benchmark", "-j", "2", "--no-plots", "-q", "--out", str(out)],
        tmp_path / "res.partial", tmp_path, after_s=2.0)
    print(f"psg-eval -j 2: exited {dt:.2f} s after Ctrl-C")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 130 and lines == ["error: interrupted"], err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing left: results are written at the end


def test_convert_jobs_stops_and_resumes(tmp_path: Path) -> None:
    recs = tmp_path / "recs"
    recs.mkdir()
    for k in range(4):
        write_bag(recs / f"r{k}.bag", n=60, w=320, h=240)
    out = tmp_path / "out"
    args = [*_cli("psg_data_cmd"), "convert", str(recs), str(out), "-j", "2", "-q"]
    code, err, dt = interrupt_when(args, out.with_name("out.partial") / ".psg_convert", tmp_path, after_s=0.3)
    print(f"convert -j 2: exited {dt:.2f} s after Ctrl-C")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 130 and len(lines) == 1, err
    assert lines[0] == f"error: interrupted; {out}.partial is kept: rerun the same command to resume"
    assert not out.exists() and out.with_name("out.partial").is_dir()
    res = subprocess.run(args, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and "converted 4 scans, 240 frames" in res.stdout, res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "recs"]
