"""``psg-eval --jobs 2`` leaves no process of its run behind when it exits (the pool's workers and
multiprocessing's resource tracker are reaped before it returns), and ``bench/run.py --help`` prints
its help instead of running the benchmarks (issue 45, point 4)."""

from __future__ import annotations

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


def test_bench_run_help_prints_help_and_runs_nothing() -> None:
    res = subprocess.run([sys.executable, str(ROOT / "bench" / "run.py"), "--help"], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("usage: run.py") and "--quick" in res.stdout
    assert "# psg-data benchmarks" not in res.stdout and "## bench_" not in res.stdout  # nothing was run
