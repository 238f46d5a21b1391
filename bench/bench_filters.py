"""Perpetua's and process_oracle's filters against the originals they replaced (issue 45), on one scene.

Run: python bench/bench_filters.py [--quick] [--scene K] [--repeat N]

One navigation benchmark scene (house seed ``--scene``, built into the cache if needed) is scored as
``psg-eval --dataset navigation-benchmark`` does (adaptive, psg-eval's defaults): every edge's filter
gets its history, then the test week one observation at a time with a prediction before each. The
fits are made once; the per-edge runs go through the package's filters and through the references
kept in tests/estimators/_perpetua_reference.py and _process_oracle_reference.py (main 8f53f6f),
alternating, in this process. Prints CPU seconds (process time: the machine is shared), the ratio
reference / package, and whether every prediction is bit-equal. ``--quick``: 8 edges, one repeat.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE))


def _jobs(scene: Path) -> tuple[Any, list[Any], Any]:
    from psg_data.evaluation import PersistenceOptions, persistence_task_from_dataset
    from psg_data.evaluation._edge_run import ScoreConfig
    from psg_data.evaluation._persistence_task import _edge_jobs

    task = persistence_task_from_dataset(scene, labels="gt")
    opts = PersistenceOptions().resolve(task)
    cfg = ScoreConfig(opts.setting, float(opts.horizon), float(opts.threshold), opts.convention,
                      opts.sample_convention, tuple(opts.codes))
    return task, _edge_jobs(task, opts, set()), cfg


def _run(make: Any, jobs: list[Any], cfg: Any) -> tuple[float, list[Any]]:
    """CPU seconds of every edge's filter run (history, then the adaptive loop), and the predictions."""
    from psg_data.evaluation._edge_run import _predictions, _Progress

    out = []
    t = time.process_time()
    for job in jobs:
        f = make(job.edge)
        if job.hist_t.size:
            f.update_many(job.hist_t, job.hist_y)
        out.append(_predictions(f, job, cfg, _Progress())[0])
    return time.process_time() - t, out


def main() -> int:
    """Time both implementations per estimator and print the table."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="8 edges, one repeat")
    ap.add_argument("--scene", type=int, default=10, help="house seed of the scene (default 10, the first of the "
                    "adaptive protocol's)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    import numpy as np

    from psg_data.datasets import navigation_benchmark
    from psg_data.estimators import get_estimator
    from tests.estimators import _perpetua_reference, _process_oracle_reference

    scene = navigation_benchmark(which=[args.scene]) / f"scene_{args.scene:02d}"
    task, jobs, cfg = _jobs(scene)
    jobs = jobs[:8] if args.quick else jobs
    rows = [("perpetua", {}, _perpetua_reference.reference_filter),
            ("process_oracle", {"dataset": str(scene)}, _process_oracle_reference.reference_filter),
            ("process_oracle:model=train", {"dataset": str(scene), "model": "train"},
             _process_oracle_reference.reference_filter)]
    print(f"load before: {os.getloadavg()[0]:.2f} (1-min load average); scene_{args.scene:02d}, {len(jobs)} edges")
    print(f"{'estimator':28s} {'package CPU-s':>13s} {'reference CPU-s':>15s} {'ratio':>6s} {'bit-equal':>9s}")
    total_new = total_old = 0.0
    for label, kw, reference in rows:
        name = label.split(":")[0]
        fits = [get_estimator(name, **kw).fit(task.train_streams, val_streams=task.val_streams,
                                               timezone=task.timezone) for _ in range(2)]
        new, old, same = [], [], True
        for _ in range(1 if args.quick else args.repeat):
            t_new, got = _run(fits[0].make_filter, jobs, cfg)
            t_old, want = _run(lambda e, est=fits[1], ref=reference: ref(est, e), jobs, cfg)  # type: ignore[misc]
            new.append(t_new)
            old.append(t_old)
            same = same and all(np.array_equal(a, b) for a, b in zip(got, want))
        mn, mo = statistics.median(new), statistics.median(old)
        total_new, total_old = total_new + mn, total_old + mo
        print(f"{label:28s} {mn:13.2f} {mo:15.2f} {mo / mn:6.2f} {'yes' if same else 'NO':>9s}", flush=True)
    print(f"{'all three':28s} {total_new:13.2f} {total_old:15.2f} {total_old / total_new:6.2f}")
    print(f"load after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
