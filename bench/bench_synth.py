"""Benchmark of the synthetic lab: demo build time and renderer throughput.

Run: ``python bench/bench_synth.py [--quick] [--baseline-ref REF]`` (from the repository root;
``bench/run.py`` runs it too). The cold demo build is timed for the default generator (steps-v2)
and, as the baseline in the same run, for continuous-v1 (median of 3; one with ``--quick``). With
``--baseline-ref REF`` the scan planning of git revision REF (imported in the same process, see
``bench_loader_ab.py``) is timed against this tree's on the three layouts, alternating, best of 3,
and their plans compared pose for pose.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from psg_data.synth import LabConfig, LabModel, build_lab


sys.path.insert(0, str(Path(__file__).resolve().parent))


def planning_against(ref_name: str) -> None:
    """Scan planning (view candidates + plans) of this tree against REF's, per layout."""
    from bench_loader_ab import import_ref

    with tempfile.TemporaryDirectory(prefix="psg-synth-ab-") as tmp:
        ref = import_ref(ref_name, Path(tmp))
        from psg_data_ref.synth import LabConfig as RefConfig
        from psg_data_ref.synth import LabModel as RefModel

        print(f"scan planning, this tree vs {ref_name} (best of 3, alternating; load "
              f"{Path('/proc/loadavg').read_text().split()[0]})")
        for layout in ("corridor", "two_routes", "chain"):
            best = {"this": float("inf"), "ref": float("inf")}
            plans = {}
            for _ in range(3):
                for k, (M, C) in {"this": (LabModel, LabConfig), "ref": (RefModel, RefConfig)}.items():
                    t0 = time.perf_counter()
                    plans[k] = M(C(layout=layout)).scans
                    best[k] = min(best[k], time.perf_counter() - t0)
            same = all(np.array_equal(a.poses, b.poses) and a.scan_id == b.scan_id
                       for a, b in zip(plans["this"], plans["ref"], strict=True))
            print(f"  {layout:10s} this {best['this']:.2f} s, {ref_name[:12]} {best['ref']:.2f} s, "
                  f"ratio {best['this'] / best['ref']:.2f}; plans identical: {same}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one cold build per generator instead of three")
    ap.add_argument("--baseline-ref", default=None, help="git revision whose scan planning is timed alongside")
    args = ap.parse_args()
    if args.baseline_ref:
        planning_against(args.baseline_ref)
    cfg = LabConfig()
    t0 = time.perf_counter()
    lab = LabModel(cfg)
    t_model = time.perf_counter() - t0
    t0 = time.perf_counter()
    _ = lab.scans
    t_plan = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        build_lab(Path(tmp) / "demo", cfg, lab=lab)
        t_build = time.perf_counter() - t0
        size = sum(p.stat().st_size for p in (Path(tmp) / "demo").rglob("*") if p.is_file())
    n_frames = sum(len(p.poses) for p in lab.scans)
    # full cold build as demo() does it (model + planning + rendering + writing), three times, with
    # the first generator (continuous-v1) as the baseline measured in the same run
    colds: dict[str, list[float]] = {"steps-v2": [], "continuous-v1": []}
    for _ in range(1 if args.quick else 3):
        for gen in colds:
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                build_lab(Path(tmp) / "demo", LabConfig(generator=gen))
                colds[gen].append(time.perf_counter() - t0)
    t_cold = float(np.median(colds["steps-v2"]))
    t_cold_v1 = float(np.median(colds["continuous-v1"]))
    # renderer throughput: rays per second of LabRenderer.render (no encoding), two resolutions
    plan = lab.scans[0]
    rend = lab.renderer(plan.state)
    results = {}
    for w, h in ((160, 120), (640, 480)):
        cam = lab.camera.__class__(**{**lab.camera.__dict__, "width": w, "height": h,
                                      "fx": lab.camera.fx * h / 120, "fy": lab.camera.fy * h / 120,
                                      "cx": (w - 1) / 2, "cy": (h - 1) / 2})
        n = 40 if w == 160 else 6
        t0 = time.perf_counter()
        for i in range(n):
            rend.render(plan.poses[i % len(plan.poses)], cam, noise=cfg.noise, rng=np.random.default_rng(i))
        dt = time.perf_counter() - t0
        results[(w, h)] = (n * w * h / dt, n / dt)
    t0 = time.perf_counter()
    for i in range(40):
        rend.cast(np.broadcast_to(plan.poses[0][:3, 3], (19200, 3)),
                  np.random.default_rng(i).normal(size=(19200, 3)))
    raw = 40 * 19200 / (time.perf_counter() - t0)
    print(f"demo lab: {len(lab.scans)} scans, {n_frames} frames at {cfg.width}x{cfg.height}, "
          f"{size / 1e6:.1f} MB")
    print(f"  LabModel (layout + schedules): {t_model:.2f} s; scan planning: {t_plan:.2f} s; "
          f"render + write: {t_build:.2f} s")
    print(f"  cold build (what demo() does), median: {t_cold:.2f} s (steps-v2, the default); "
          f"continuous-v1 {t_cold_v1:.2f} s; ratio {t_cold / t_cold_v1:.2f}")
    for (w, h), (rps, fps) in results.items():
        print(f"  render {w}x{h}: {rps / 1e6:.2f} Mrays/s ({fps:.1f} frames/s, colour + noisy depth + ids)")
    print(f"  raw ray casting (RaycastingScene.cast_rays): {raw / 1e6:.2f} Mrays/s")


if __name__ == "__main__":
    main()
