"""``import psg_data`` time in fresh interpreters, against the interpreter's own start-up.

Run: ``python bench/bench_import.py [--quick]`` (``bench/run.py`` runs it). Prints, as medians over
fresh interpreters run in alternation: the start-up of ``python -c pass`` (the baseline), the
in-process time of ``import psg_data`` and of the first ``psg_data.evaluation`` access (a lazy
subpackage attribute), and the whole process against the baseline. Target: ``import psg_data``
< 50 ms.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_PROBE = ("import time; t = time.perf_counter(); import psg_data; t1 = time.perf_counter(); "
          "psg_data.{attr}; t2 = time.perf_counter(); print(t1 - t, t2 - t1)")


def _process_s(code: str) -> float:
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, cwd=ROOT)
    return time.perf_counter() - t


def _in_process(attr: str) -> tuple[float, float]:
    out = subprocess.run([sys.executable, "-c", _PROBE.format(attr=attr)], check=True, capture_output=True, text=True,
                         cwd=ROOT).stdout.split()
    return float(out[0]), float(out[1])


def main() -> int:
    reps = 5 if "--quick" in sys.argv else 21
    base, whole, imp, evaluation, viewer = [], [], [], [], []
    for _ in range(reps):  # alternated, so that load changes hit every measurement alike
        base.append(_process_s("pass"))
        whole.append(_process_s("import psg_data"))
        imp.append(_in_process("__version__")[0])
        evaluation.append(_in_process("evaluation")[1])
        viewer.append(_in_process("viewer")[1])
    med = statistics.median
    with open("/proc/loadavg") as fh:
        load = fh.read().split()[0]
    print(f"fresh interpreters, median of {reps}; 1-min load average {load}")
    print(f"python -c pass (baseline)                 {med(base) * 1000:7.1f} ms")
    print(f"python -c 'import psg_data'               {med(whole) * 1000:7.1f} ms  ({med(whole) / med(base):.2f}x the "
          "baseline)")
    print(f"import psg_data (in process)              {med(imp) * 1000:7.1f} ms  (target < 50 ms)")
    print(f"first psg_data.evaluation (lazy import)   {med(evaluation) * 1000:7.1f} ms")
    print(f"first psg_data.viewer (lazy import)       {med(viewer) * 1000:7.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
