"""README's main job, ``psg-eval --estimator perpetua_star --jobs -1``, warm (the demo lab cached).

Run: python bench/bench_main_job.py [--baseline-ref REV] [--repeat N] [--jobs J] [--quick]

Each repeat runs the command once with this tree's psg_data and, with ``--baseline-ref``, once with
the psg_data of git revision REV (exported to a temporary folder), alternating so that both see the
same machine load. Prints per run the wall time and the CPU time of the command and its workers
(children's rusage), then the medians and the ratios baseline / this (> 1: this tree is faster). The
machine is shared: the 1-minute load average is printed before and after; compare CPU-s when it is
high. One untimed run first builds or checks the cached demo lab.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
_CMD = "import sys; sys.path.insert(0, sys.argv.pop(1)); from psg_data.cli.psg_eval_cmd import main; sys.exit(main())"


def _run(src: Path, out: Path, jobs: int) -> tuple[float, float]:
    """(wall s, CPU s of the command and everything it waited for) of one main job with ``src``'s psg_data."""
    env = dict(os.environ, PYTHONPATH=str(src))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", _CMD, str(src), "--estimator", "perpetua_star", "--jobs", str(jobs),
                    "--out", str(out), "-q"], env=env, cwd=out.parent, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> int:
    """Time the main job with this tree (and a baseline revision) and print the table."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline-ref", default=None, help="git revision timed alternately with this tree")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one repeat (as bench/run.py --quick passes)")
    ap.add_argument("--jobs", type=int, default=-1, help="psg-eval --jobs (default -1, as README)")
    args = ap.parse_args()
    if args.quick:
        args.repeat = 1
    with tempfile.TemporaryDirectory(prefix="psg-main-job-") as tmp:
        trees = {"this": HERE}
        if args.baseline_ref:
            base = Path(tmp) / "base"
            base.mkdir()
            arc = subprocess.run(["git", "-C", str(HERE), "archive", args.baseline_ref, "psg_data"],
                                 capture_output=True, check=True)
            subprocess.run(["tar", "-x", "-C", str(base)], input=arc.stdout, check=True)
            trees["base"] = base
        print(f"load before: {os.getloadavg()[0]:.2f} (1-min load average), {os.cpu_count()} CPUs")
        _run(HERE, Path(tmp) / "warm", args.jobs)
        res: dict[str, list[tuple[float, float]]] = {k: [] for k in trees}
        for i in range(args.repeat):
            for key, src in trees.items():
                res[key].append(_run(src, Path(tmp) / f"{key}{i}", args.jobs))
                print(f"run {i} {key:4s}: {res[key][-1][0]:6.2f} s wall, {res[key][-1][1]:6.2f} CPU-s "
                      f"(load {os.getloadavg()[0]:.2f})", flush=True)
        med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in res.items()}
        for k, (w, c) in med.items():
            name = "this tree" if k == "this" else f"baseline {args.baseline_ref}"
            print(f"median {name}: {w:.2f} s wall, {c:.2f} CPU-s")
        if "base" in med:
            print(f"ratio baseline / this: wall {med['base'][0] / med['this'][0]:.2f}, "
                  f"CPU {med['base'][1] / med['this'][1]:.2f}")
        print(f"load after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
