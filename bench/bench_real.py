"""The real benchmarks' default commands, timed from an offline copy (issue 42: each within 2 minutes on 2 cores).

Runs, each in its own process (wall time, and CPU time of the process and its workers):

- ``psg-eval --dataset door-benchmark -e perpetua_star -e fremen --jobs -1`` (the patrol protocol);
- ``psg-eval --dataset room-presence-benchmark -e perpetua_star -e fremen --jobs -1``;
- the same two with ``--no-references -e last_seen`` in the same run: the fixed cost (imports,
  reading and checking the files, writing results), to which the first two compare.

Needs ``PSG_DATA_SOURCES`` (a folder holding ``greg_door_2016_min/`` and ``aruba_location/``); without
it the benchmark says so and exits 0. The 1-minute load average is printed beside each number.
Run: ``python bench/bench_real.py [--quick]`` (``--quick``: the door only); writes bench/out/real.json.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMANDS = {
    "door-benchmark": ["--dataset", "door-benchmark", "-e", "perpetua_star", "-e", "fremen"],
    "room-presence-benchmark": ["--dataset", "room-presence-benchmark", "-e", "perpetua_star", "-e", "fremen"],
}
BUDGET_S = 120.0


def _time(args: list[str]) -> tuple[float, float, float]:
    """(wall s, CPU s of the children, load average) of one psg-eval run in a new process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "from psg_data.cli.psg_eval_cmd import main; main()", *args, "--jobs", "-1", "--quiet",
                        "--no-plots", "--out", str(Path(tmp) / "out")], check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, load


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the door benchmark only")
    args = ap.parse_args()
    if not os.environ.get("PSG_DATA_SOURCES"):
        print("bench_real: skipped: set PSG_DATA_SOURCES to a folder holding greg_door_2016_min/ and aruba_location/")
        return 0
    rows = []
    for name, cmd in COMMANDS.items():
        if args.quick and name != "door-benchmark":
            continue
        wall, cpu, load = _time(cmd)
        fixed_wall, fixed_cpu, _ = _time(["--dataset", name, "--no-references", "-e", "last_seen"])
        rows.append({"benchmark": name, "wall_s": wall, "cpu_s": cpu, "load1": load, "fixed_wall_s": fixed_wall,
                     "fixed_cpu_s": fixed_cpu, "budget_ratio": wall / BUDGET_S})
        print(f"{name:26s} wall {wall:6.1f} s  cpu {cpu:6.1f} s  (fixed cost {fixed_wall:5.1f} s wall, "
              f"{fixed_cpu:5.1f} s cpu; x{wall / max(fixed_wall, 1e-9):.1f})  {wall / BUDGET_S:.2f} of the 2-minute "
              f"budget  load {load:.1f}")
    out = Path(__file__).resolve().parent / "out"
    out.mkdir(exist_ok=True)
    (out / "real.json").write_text(json.dumps({"date": time.strftime("%Y-%m-%d %H:%M"), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
