"""Benchmark of the navigation benchmark's build: 15 procedural houses from an empty cache.

Run: ``python bench/bench_houses.py [--quick]`` (from the repository root; ``bench/run.py`` runs it
too). Times ``psg_data.datasets.navigation_benchmark()`` into a fresh cache (every scene drawn,
written without images and labelled ``privileged``), split into its stages on scene 0, with the
demo lab's cold build (``demo()``) measured in the same run as the baseline. ``--quick``: 3 scenes.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path


def _timed(fn) -> tuple[float, object]:  # type: ignore[no-untyped-def]
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main() -> None:
    quick = "--quick" in sys.argv
    n = 3 if quick else 15
    load0 = open("/proc/loadavg").read().split()[0] if Path("/proc/loadavg").exists() else "?"
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["PSG_DATA_CACHE"] = tmp
        from psg_data.datasets import demo, navigation_benchmark
        from psg_data.labeling import label_dataset
        from psg_data.synth import HouseConfig, HouseModel, build_house

        t_model, model = _timed(lambda: HouseModel(HouseConfig(seed=0)))
        t_write, _ = _timed(lambda: build_house(Path(tmp) / "stage" / "s0", model=model))
        t_label, _ = _timed(lambda: label_dataset(Path(tmp) / "stage" / "s0", "privileged"))
        t_all, root = _timed(lambda: navigation_benchmark(scenes=n))
        size = sum(p.stat().st_size for p in Path(str(root)).rglob("*") if p.is_file())
        t_demo, _ = _timed(demo)
    load1 = open("/proc/loadavg").read().split()[0] if Path("/proc/loadavg").exists() else "?"
    print(f"navigation benchmark, {n} scenes from an empty cache: {t_all:.1f} s ({t_all / n:.2f} s per scene), "
          f"{size / 1e6:.1f} MB")
    print(f"  scene 0: model (layout, process, 672-step paths) {t_model:.2f} s, writing {t_write:.2f} s, "
          f"privileged labels {t_label:.2f} s")
    print(f"baseline in the same run: demo lab cold build {t_demo:.1f} s; ratio benchmark / demo {t_all / t_demo:.2f}")
    print(f"1-minute load average: {load0} before, {load1} after")


if __name__ == "__main__":
    main()
