"""Training cost of Perpetua* and Perpetua: fit time for the whole built-in lab and per edge.

Run: python bench/bench_training.py [--quick] [--repeat N] [--baseline SRC]

Each fit runs in a fresh process (imports excluded from the timing) on the built-in lab's training
weeks (66 edges, 4 scans a day) and, unless ``--quick``, on one draw of the persistence benchmark
(8 edges, a scan every 10-30 min for four weeks). ``--baseline SRC`` also times the same fits with
the psg_data package found in the source tree SRC (e.g. an export of an earlier commit: ``git
archive main | tar -x -C /tmp/main``), interleaved with the current tree's repeats so that both see
the same machine load, and prints the ratio of the medians (baseline / current: > 1 means the current
tree is faster).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]

_CHILD = r"""
import json, pickle, sys, time
which, name = sys.argv[1], sys.argv[2]
if which == "lab":
    from psg_data.cli._eval_inputs import persistence_tasks, resolve_dataset
    task = persistence_tasks(resolve_dataset(None, quiet=True), labels="gt", seeds=[0], quiet=True)[0][0]
    streams, val, tz = task.train_streams, task.val_streams, task.timezone
else:
    from psg_data.synth import make_persistence_benchmark
    bm = make_persistence_benchmark(seed=0)
    streams, val, tz = bm.train_streams, bm.val_streams, bm.timezone
from psg_data.estimators import get_estimator
est = get_estimator(name)
t0 = time.perf_counter()
est.fit(streams, val_streams=val, timezone=tz)
print(json.dumps({"seconds": time.perf_counter() - t0, "edges": len(streams)}))
"""


def _fit_once(src: Path, which: str, name: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = subprocess.run([sys.executable, "-c", _CHILD, which, name], env=env, capture_output=True, text=True,
                         cwd="/", check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--baseline", type=Path, default=None, help="source tree of the baseline psg_data")
    args = ap.parse_args()
    cases = [("lab", "perpetua_star"), ("lab", "perpetua")]
    if not args.quick:
        cases += [("benchmark", "perpetua_star"), ("benchmark", "perpetua")]
    repeat = 1 if args.quick else args.repeat
    print(f"load before: {os.getloadavg()[0]:.2f} (1-min load average)")
    print(f"{'data':10s} {'estimator':14s} {'edges':>5s} {'current s':>10s} {'per edge ms':>11s}"
          + (f" {'baseline s':>10s} {'ratio':>6s}" if args.baseline else ""))
    for which, name in cases:
        cur, base, edges = [], [], 0
        for _ in range(repeat):
            r = _fit_once(HERE, which, name)
            cur.append(r["seconds"])
            edges = r["edges"]
            if args.baseline:
                base.append(_fit_once(args.baseline, which, name)["seconds"])
        mc = statistics.median(cur)
        line = f"{which:10s} {name:14s} {edges:5d} {mc:10.2f} {1000 * mc / edges:11.1f}"
        if args.baseline:
            mb = statistics.median(base)
            line += f" {mb:10.2f} {mb / mc:6.2f}"
        print(line, flush=True)
    print(f"load after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
