"""``psg-eval --jobs 2`` leaves no process of its run behind when it exits (the pool's workers and
multiprocessing's resource tracker are reaped before it returns), and ``bench/run.py --help`` prints
its help instead of running the benchmarks (issue 45, point 4)."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _group(pgid: int) -> list[str]:
    """``pid state command`` of every process (zombies included) whose process group is ``pgid``."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # ended while we looked
            continue
        name_end = text.rindex(")")
        fields = text[name_end + 2:].split()
        if int(fields[2]) == pgid:
            out.append(f"{stat.parent.name} {fields[0]} {text[text.index('(') + 1:name_end]}")
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process groups from /proc")
def test_psg_eval_jobs_leaves_no_process_behind(tmp_path: Path) -> None:
    args = [sys.executable, "-c", "import sys; from psg_data.cli.psg_eval_cmd import main; sys.exit(main())",
            "--dataset", "persistence-benchmark", "-e", "last_seen", "--no-references", "-j", "2", "--no-plots",
            "-q", "--out", str(tmp_path / "res")]
    proc = subprocess.Popen(args, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # its own process group, whose id is its pid
    try:
        _, err = proc.communicate(timeout=600)
    finally:
        left = _group(proc.pid)
    assert proc.returncode == 0, err
    assert (tmp_path / "res" / "results.json").is_file()
    assert left == [], f"still in the run's process group after psg-eval exited: {left}; stderr: {err}"


_BUSY_POOL = """
import signal, sys, time
signal.signal(signal.SIGHUP, signal.SIG_DFL)  # as a terminal starts it, even when the tests run under nohup
from psg_data._pool import process_pool
with process_pool(2) as pool:
    futures = [pool.submit(time.sleep, 300) for _ in range(2)]
    print("busy", flush=True)
    time.sleep(300)
"""


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process groups from /proc")
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP", "SIGKILL"])
def test_workers_end_when_their_parent_is_killed(sig: str) -> None:
    """A killed psg-eval (kill, a closed terminal, the OOM killer) cannot stop its pool: the workers, busy with a
    five-minute task, must end by themselves (they used to run it to the end, re-parented to init)."""
    import signal
    import time

    proc = subprocess.Popen([sys.executable, "-c", _BUSY_POOL], cwd=ROOT, stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "busy"
        workers = [p for p in _group(proc.pid) if not p.startswith(f"{proc.pid} ")]
        assert len(workers) >= 2, workers  # two workers (and multiprocessing's resource tracker)
        proc.send_signal(getattr(signal, sig))
        proc.wait(timeout=30)
        deadline = time.monotonic() + 30
        while _group(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        left = _group(proc.pid)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        assert proc.stdout is not None
        proc.stdout.close()
    assert left == [], f"still running after the parent got {sig}: {left}"


def test_bench_run_help_prints_help_and_runs_nothing() -> None:
    res = subprocess.run([sys.executable, str(ROOT / "bench" / "run.py"), "--help"], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("usage: run.py") and "--quick" in res.stdout
    assert "# psg-data benchmarks" not in res.stdout and "## bench_" not in res.stdout  # nothing was run
