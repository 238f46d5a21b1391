"""Perpetua*'s training EM: the batched EM of psg_data against the per-problem EM it replaced.

Run: python bench/bench_interval_em.py [--quick] [--repeat N] [--baseline-ref REV]

The mixture fits of one ``perpetua_star`` training (the built-in lab's, and unless ``--quick`` one
persistence-benchmark draw's) are recorded, then replayed in this process through
``fit_interval_mixtures`` (all fits batched) and through the reference kept in
tests/estimators/_interval_em_reference.py (main 9ca2d8e: one fit after the other), alternating.
Prints CPU seconds (process time: the machine is shared) and the ratio reference / batched, and the
largest parameter difference between the two. ``--baseline-ref REV`` also replays them through REV's
``psg_data/estimators/_interval_em.py`` (loaded beside this tree's) and prints its CPU seconds, the
ratio REV / this tree and whether the fits are equal to the bit.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE))


def _problems(which: str) -> list[Any]:
    import psg_data.estimators._survival_training as training
    from psg_data.estimators import get_estimator

    if which == "lab":
        from psg_data.datasets import demo
        from psg_data.evaluation import persistence_task_from_dataset

        task = persistence_task_from_dataset(demo(), labels="gt")
        data = (task.train_streams, task.val_streams, task.timezone)
    else:
        from psg_data.synth import make_persistence_benchmark

        bm = make_persistence_benchmark(seed=0)
        data = (bm.train_streams, bm.val_streams, bm.timezone)
    seen: list[Any] = []
    real = training.fit_interval_mixtures

    def recording(probs: list[Any], **kw: Any) -> Any:
        seen.extend(probs)
        return real(probs, **kw)

    training.fit_interval_mixtures = recording
    try:
        get_estimator("perpetua_star").fit(data[0], val_streams=data[1], timezone=data[2])
    finally:
        training.fit_interval_mixtures = real
    return seen


def _baseline(rev: str) -> Any:
    """REV's interval EM module, loaded under another name (its imports resolve to this tree)."""
    src = subprocess.run(["git", "-C", str(HERE), "show", f"{rev}:psg_data/estimators/_interval_em.py"],
                         capture_output=True, check=True, text=True).stdout
    spec = importlib.util.spec_from_loader("_baseline_interval_em", loader=None)
    assert spec is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up
    exec(compile(src, f"{rev}:_interval_em.py", "exec"), mod.__dict__)
    return mod


def _same(a: list[Any], b: list[Any]) -> bool:
    import numpy as np

    return all(x.trace == y.trace and all(np.array_equal(getattr(x.mixture, f), getattr(y.mixture, f))
                                          for f in ("weights", "p1", "p2")) for x, y in zip(a, b))


def main() -> int:
    """Replay the recorded fits through both EMs and print the table."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="the built-in lab only, one repeat")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--baseline-ref", default=None, help="git revision whose batched EM is timed too")
    args = ap.parse_args()
    base = _baseline(args.baseline_ref) if args.baseline_ref else None
    import numpy as np

    from psg_data.estimators._interval_em import fit_interval_mixtures
    from tests.estimators import _interval_em_reference as ref

    print(f"load before: {os.getloadavg()[0]:.2f} (1-min load average)")
    print(f"{'data':10s} {'fits':>5s} {'batched CPU-s':>13s} {'reference CPU-s':>15s} {'ratio':>6s} "
          f"{'max |diff|':>10s}")
    for which in ("lab",) if args.quick else ("lab", "benchmark"):
        probs = _problems(which)
        new, old, diff = [], [], 0.0
        b_cpu: list[float] = []
        equal = True
        for _ in range(1 if args.quick else args.repeat):
            t = time.process_time()
            got = fit_interval_mixtures(probs)
            new.append(time.process_time() - t)
            t = time.process_time()
            want = [ref.fit_interval_mixture(lo, hi, weights=w, max_components=k) for lo, hi, w, k in probs]
            old.append(time.process_time() - t)
            for a, b in zip(got, want):
                for x, y in ((a.mixture.weights, b.mixture.weights), (a.mixture.p1, b.mixture.p1),
                             (a.mixture.p2, b.mixture.p2)):
                    diff = max(diff, float(np.max(np.abs(x - y))) if x.shape == y.shape else float("inf"))
            if base is not None:
                t = time.process_time()
                b_fits = base.fit_interval_mixtures(probs)
                b_cpu.append(time.process_time() - t)
                equal = equal and _same(got, b_fits)
        mn, mo = statistics.median(new), statistics.median(old)
        print(f"{which:10s} {len(probs):5d} {mn:13.2f} {mo:15.2f} {mo / mn:6.2f} {diff:10.1e}", flush=True)
        if base is not None:
            mb = statistics.median(b_cpu)
            print(f"{'':10s} baseline {args.baseline_ref}: {mb:.2f} CPU-s, ratio baseline / this {mb / mn:.2f}, "
                  f"fits equal to the bit: {equal}", flush=True)
    print(f"load after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
