"""Labelling throughput on the demo lab (84 scans x 8 frames, 160x120), time split by stage.

Run:

    python bench/bench_label.py [--quick]

Labels a lab built fresh with the demo's configuration (``--quick``: a 7-day lab) with the privileged, noisy and detections sources and prints seconds per
stage. Target: the whole privileged labelling (visibility of every scan + codes + writing) <= 60 s
on a 2-core machine. Writes bench/out/label.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="7-day lab instead of the 21-day demo")
    args = ap.parse_args()

    from psg_data.labeling import label_dataset
    from psg_data.loaders import open_dataset

    from psg_data.synth import LabConfig, build_lab

    # built fresh (the demo's configuration), not copied from the cache: psg-eval labels the cached
    # demo lab in place when asked for privileged labels, and a labelled copy would measure nothing
    t = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix="psg_bench_label_"))
    root = build_lab(work / "lab", LabConfig(days=7) if args.quick else LabConfig())
    t_demo = time.perf_counter() - t
    ds = open_dataset(root)
    n_scans, n_frames = len(ds.scan_ids), ds.table("frames").num_rows
    results: dict[str, dict] = {}
    try:
        for source in ("privileged", "noisy:0.1"):
            t = time.perf_counter()
            s = label_dataset(root, source, seed=0)
            results[source] = {"total_s": time.perf_counter() - t, "stages_s": s.timings, "edges": s.n_edges,
                               "codes": s.codes, "rates": str(s.rates)}
        from psg_data.synth import write_detections

        t = time.perf_counter()
        det = write_detections(root, work / "detections.parquet", seed=0)
        t_det = time.perf_counter() - t
        t = time.perf_counter()
        s = label_dataset(root, f"detections:{det}")
        results["detections"] = {"total_s": time.perf_counter() - t, "stages_s": s.timings, "edges": s.n_edges,
                                 "codes": s.codes, "rates": str(s.rates), "simulating_detections_s": t_det}
    finally:
        shutil.rmtree(work, ignore_errors=True)

    print(f"dataset: {n_scans} scans, {n_frames} frames ({'7-day lab' if args.quick else 'demo'}; "
          f"build {t_demo:.1f} s, not counted)")
    print(f"{'source':<14} {'total s':>8}  stages (s)")
    for name, r in results.items():
        stages = ", ".join(f"{k} {v:.2f}" for k, v in r["stages_s"].items())
        print(f"{name:<14} {r['total_s']:>8.2f}  {stages}")
        print(f"{'':<14} {'':>8}  {r['edges']} edges, codes {r['codes']}, {r['rates']}")
    if "simulating_detections_s" in results.get("detections", {}):
        print(f"(simulating the detections file itself: {results['detections']['simulating_detections_s']:.1f} s, "
              "not part of labelling)")
    total = results["privileged"]["total_s"]
    print(f"privileged labelling of all scans: {total:.2f} s (target <= 60 s: {'met' if total <= 60 else 'NOT met'})")
    out = Path(__file__).resolve().parent / "out" / "label.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"machine": platform.node(), "python": platform.python_version(),
                               "scans": n_scans, "frames": n_frames, "quick": args.quick, "results": results},
                              indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
