"""How fast Ctrl-C stops a run with worker processes (target: within 2 s, any ``--jobs``).

Usage::

    python bench/bench_interrupt.py [--repeat 3]

Runs ``psg-eval --dataset persistence-benchmark -j 2`` and ``psg-data convert DIR OUT -j 2`` (four
generated ROS 1 bags) in their own process group, sends SIGINT to the group (what a terminal's
Ctrl-C does) once the work is under way, and measures the time from the signal to the exit of the
last process. Prints each run, the median and the load average.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _cli(module: str) -> list[str]:
    return [sys.executable, "-c", f"import sys; from psg_data.cli.{module} import main; sys.exit(main())"]


def interrupt(args: list[str], ready: Path, after_s: float, cwd: Path) -> tuple[float, float, int, str, list[str]]:
    """(seconds to the command's exit, seconds until every process of its group is gone, exit code,
    stderr, commands of the processes still alive when the command exited)."""
    proc = subprocess.Popen(args, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    while not ready.exists() and proc.poll() is None:
        time.sleep(0.02)
    time.sleep(after_s)
    t0 = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    t_exit = time.monotonic() - t0
    left = _group(proc.pid)
    while _group(proc.pid):  # until every process of the group (workers included) has ended
        time.sleep(0.01)
    return t_exit, time.monotonic() - t0, proc.returncode, err.strip(), left


def _group(pgid: int) -> list[str]:
    """Command lines of the running processes of process group ``pgid`` (Linux /proc; zombies, which
    have ended and wait only to be reaped, are not counted)."""
    out = []
    for p in Path("/proc").glob("[0-9]*"):
        try:
            if os.getpgid(int(p.name)) == pgid and (p / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                out.append((p / "cmdline").read_bytes().replace(b"\0", b" ").decode()[:80])
        except (OSError, ValueError, IndexError):
            continue
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=None, help="runs of each (default 3; --quick: 1)")
    ap.add_argument("--quick", action="store_true", help="one run of each (bench/run.py --quick)")
    args = ap.parse_args()
    args.repeat = args.repeat or (1 if args.quick else 3)
    from tests.convert.conftest import write_bag

    with tempfile.TemporaryDirectory(prefix="psg_bench_interrupt_") as tmp:
        t = Path(tmp)
        recs = t / "recs"
        recs.mkdir()
        for k in range(4):
            write_bag(recs / f"r{k}.bag", n=120, w=320, h=240)
        rows: dict[str, list[tuple[float, float]]] = {"psg-eval -j 2": [], "convert -j 2": []}
        for k in range(args.repeat):
            for name, cmd, ready, after in (
                ("psg-eval -j 2", [*_cli("psg_eval_cmd"), "--dataset", "persistence-benchmark", "-j", "2",
                                   "--no-plots", "-q", "--out", str(t / f"res{k}")], t / f"res{k}.partial", 2.0),
                ("convert -j 2", [*_cli("psg_data_cmd"), "convert", str(recs), str(t / f"out{k}"), "-j", "2", "-q"],
                 t / f"out{k}.partial" / ".psg_convert", 0.3),
            ):
                t_exit, t_all, code, err, left = interrupt(cmd, ready, after, t)
                rows[name].append((t_exit, t_all))
                print(f"{name}: exit {code} {t_exit:.2f} s after SIGINT, every process gone after {t_all:.2f} s; "
                      f"stderr {err!r}; still alive at exit: {left}")
    print(f"\nload average {os.getloadavg()[0]:.2f}; {os.cpu_count()} CPUs")
    for name, v in rows.items():
        print(f"{name:16s} command exits after median {statistics.median(x for x, _ in v):.2f} s "
              f"({' '.join(f'{x:.2f}' for x, _ in v)}), all its processes after "
              f"{statistics.median(y for _, y in v):.2f} s ({' '.join(f'{y:.2f}' for _, y in v)}); target <= 2 s")


if __name__ == "__main__":
    main()
