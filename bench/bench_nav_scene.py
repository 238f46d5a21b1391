"""Persistence on one navigation benchmark scene, as ``psg-eval --dataset navigation-benchmark -e perpetua_star``.

Run: python bench/bench_nav_scene.py [--scene K] [--baseline-ref REV] [--repeat N] [--quick]

One scene (house seed ``--scene``, default 10; built into the cache if needed) is scored the way each
worker of ``psg-eval --dataset navigation-benchmark -e perpetua_star`` scores a scene (``_scene_job``:
the user's row, the paper's methods and the reference rows, psg-eval's defaults), in a new process
with this tree's psg_data and, with ``--baseline-ref``, alternately with the psg_data of git revision
REV (``git archive`` into a temporary folder). Prints per run the wall time and the CPU time of the
process (the machine is shared: compare CPU-s), the medians, the ratio baseline / this, and whether
both trees gave the same edge results and breakdown rows (every number compared as stored).
``--quick``: one repeat.
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

_CHILD = """
import sys
sys.path.insert(0, sys.argv[1])
from psg_data.evaluation._hints import EstimatorSpec
from psg_data.evaluation._options import PersistenceOptions
from psg_data.evaluation._persistence_job import _scene_job, persistence_rows
from psg_data.cli._eval_inputs import available_hints
rows, _ = persistence_rows([EstimatorSpec.of("perpetua_star")], available_hints("navigation-benchmark"))
res, _ = _scene_job(sys.argv[2], 0, "gt", rows, PersistenceOptions(), False)
with open(sys.argv[3], "w") as fh:  # repr: every float exactly (NaN equal to NaN)
    fh.write(repr((res.edges, res.breakdown_rows, [e.message for e in res.errors])))
"""


def _run(src: Path, scene: Path, out: Path) -> tuple[float, float]:
    """(wall s, CPU s) of one scene job with ``src``'s psg_data, its results written (repr) to ``out``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", _CHILD, str(src), str(scene), str(out)], check=True,
                   env=dict(os.environ, PYTHONPATH=str(src)))
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> int:
    """Time the scene job with this tree (and a baseline revision) and print the table."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", type=int, default=10, help="house seed of the scene (default 10)")
    ap.add_argument("--baseline-ref", default=None, help="git revision timed alternately with this tree")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--quick", action="store_true", help="one repeat (as bench/run.py --quick passes)")
    args = ap.parse_args()
    sys.path.insert(0, str(HERE))
    from psg_data.datasets import navigation_benchmark

    scene = navigation_benchmark(which=[args.scene]) / f"scene_{args.scene:02d}"
    repeat = 1 if args.quick else args.repeat
    with tempfile.TemporaryDirectory(prefix="psg-nav-scene-") as tmp:
        trees = {"this": HERE}
        if args.baseline_ref:
            base = Path(tmp) / "base"
            base.mkdir()
            arc = subprocess.run(["git", "-C", str(HERE), "archive", args.baseline_ref, "psg_data"],
                                 capture_output=True, check=True)
            subprocess.run(["tar", "-x", "-C", str(base)], input=arc.stdout, check=True)
            trees["base"] = base
        print(f"load before: {os.getloadavg()[0]:.2f} (1-min load average), {os.cpu_count()} CPUs; "
              f"scene_{args.scene:02d}")
        res: dict[str, list[tuple[float, float]]] = {k: [] for k in trees}
        outs: dict[str, Path] = {}
        for i in range(repeat):
            for key, src in trees.items():
                outs[key] = Path(tmp) / f"{key}{i}.txt"
                res[key].append(_run(src, scene, outs[key]))
                print(f"run {i} {key:4s}: {res[key][-1][0]:7.2f} s wall, {res[key][-1][1]:7.2f} CPU-s "
                      f"(load {os.getloadavg()[0]:.2f})", flush=True)
        med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in res.items()}
        for k, (w, c) in med.items():
            name = "this tree" if k == "this" else f"baseline {args.baseline_ref}"
            print(f"median {name}: {w:.2f} s wall, {c:.2f} CPU-s")
        if "base" in med:
            same = outs["this"].read_text() == outs["base"].read_text()
            print(f"ratio baseline / this: wall {med['base'][0] / med['this'][0]:.2f}, "
                  f"CPU {med['base'][1] / med['this'][1]:.2f}; results equal: {'yes' if same else 'NO'}")
        print(f"load after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
