"""Benchmark of the simulation navigation protocols from an empty cache (issue 25's acceptance: <= 10 min each).

Run: ``python bench/bench_sim_navigation.py [--quick] [--jobs N]`` (from the repository root;
``bench/run.py`` runs it too). For each protocol, in a fresh temporary cache: ``psg-eval --task
navigation --dataset navigation-benchmark --protocol P -e perpetua_star -e fremen --labels
privileged --jobs N`` (a subprocess; the wall time includes building and labelling the scenes).
Baseline in the same run: building the same scenes alone (``navigation_benchmark(which=...)``) into
another fresh cache. ``--quick``: the protocols' ``--quick`` forms. Prints the 1-minute load
average before and after.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _load() -> str:
    p = Path("/proc/loadavg")
    return p.read_text().split()[0] if p.exists() else "?"


def main() -> None:
    quick = "--quick" in sys.argv
    jobs = sys.argv[sys.argv.index("--jobs") + 1] if "--jobs" in sys.argv else "2"
    from psg_data.navigation._sim_benchmark import SIM_PROTOCOLS

    load0 = _load()
    rows = []
    for name, proto in SIM_PROTOCOLS.items():
        p = proto.quick() if quick else proto
        with tempfile.TemporaryDirectory() as tmp:
            env = {**os.environ, "PSG_DATA_CACHE": str(Path(tmp) / "cache")}
            cmd = [sys.executable, "-c", "from psg_data.cli.psg_eval_cmd import main; main()", "--task", "navigation", "--dataset",
                   "navigation-benchmark", "--protocol", name, "-e", "perpetua_star", "-e", "fremen", "--labels",
                   "privileged", "--jobs", jobs, "--quiet", "--no-plots", "--out", str(Path(tmp) / "out")]
            cmd += ["--quick"] if quick else []
            t0 = time.perf_counter()
            subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
            t_run = time.perf_counter() - t0
            os.environ["PSG_DATA_CACHE"] = str(Path(tmp) / "cache-baseline")
            from psg_data.datasets import navigation_benchmark

            t0 = time.perf_counter()
            navigation_benchmark(shift=p.shift, which=p.scenes)
            t_build = time.perf_counter() - t0
        rows.append((p.name, len(p.scenes), p.n_queries, t_run, t_build))
    print(f"{'protocol':28s} {'scenes':>6s} {'queries':>7s} {'wall s':>8s} {'build s':>8s} {'ratio':>6s}")
    for n, s, q, t, b in rows:
        print(f"{n:28s} {s:6d} {q:7d} {t:8.1f} {b:8.1f} {t / b:6.1f}")
    print("wall: the whole psg-eval run from an empty cache (-e perpetua_star -e fremen, every reference row, "
          f"--jobs {jobs}); build: the same scenes built alone in the same run (baseline); ratio = wall / build")
    print(f"1-minute load average: {load0} before, {_load()} after")


if __name__ == "__main__":
    main()
