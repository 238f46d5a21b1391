"""Loader throughput: psg-data frame iteration vs a plain ``cv2.imread`` loop over the same images.

The same frames are written in both image layouts (one tar archive per scan, the default, and one
file per image); the baseline decodes the files layout's files with ``cv2.imread``.

Also measures ``import psg_data`` time in fresh interpreters. Run:

    python bench/bench_loader.py [--quick] [--baseline-ref main --repeat 5]

Prints a table with the ratio loader / baseline measured in the same run (target >= 0.8x) and
writes bench/out/loader.json. With ``--baseline-ref REF`` the loader of git revision REF reads the
same datasets too, in child processes alternating with this tree's (``time ratio`` = this tree's
time / REF's, median over the pairs: above 1 is slower).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def make_dataset(root: Path, frames: int, width: int, height: int, layout: str = "tar") -> Path:
    from psg_data.schemas import CameraIntrinsics
    from psg_data.writers import DatasetWriter

    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:height, 0:width]
    cam = CameraIntrinsics("cam", width, height, 0.9 * width, 0.9 * width, width / 2 - 0.5, height / 2 - 0.5)
    with DatasetWriter(root, timezone="UTC", image_layout=layout) as w:
        w.add_camera(cam)
        with w.scan("s0") as sw:
            for i in range(frames):
                depth = (1500 + 2 * u + 3 * v + rng.normal(0, 8, (height, width))).astype(np.uint16)
                color = np.stack([(u * 255 / width), (v * 255 / height), np.full_like(u, 40 + i)], -1).astype(np.uint8)
                sw.add_frame(i * 10**8, np.eye(4), color, depth, "cam")
    return root


def time_loader(root: Path, prefetch: int = 2) -> tuple[float, int]:
    import psg_data

    scan = psg_data.open_dataset(root).scan("s0")
    t = time.perf_counter()
    n = 0
    for fr in scan.frames(prefetch=prefetch):
        n += fr.color.shape[0] > 0
    return time.perf_counter() - t, n


def time_imread(root: Path) -> tuple[float, int]:
    import cv2

    files = sorted((root / "images/s0/color").glob("*.png"))
    dfiles = sorted((root / "images/s0/depth").glob("*.png"))
    t = time.perf_counter()
    n = 0
    for c, d in zip(files, dfiles):
        a = cv2.imread(str(c), cv2.IMREAD_COLOR)
        b = cv2.imread(str(d), cv2.IMREAD_UNCHANGED)
        n += a is not None and b is not None
    return time.perf_counter() - t, n


_CHILD = """
import json, sys, time
sys.path.insert(0, sys.argv[1])
import psg_data
out = {}
for spec in sys.argv[2:]:
    root, prefetch = spec.rsplit(":", 1)
    def once():
        scan = psg_data.open_dataset(root).scan("s0")
        t = time.perf_counter()
        for fr in scan.frames(prefetch=int(prefetch)):
            pass
        return time.perf_counter() - t
    once()
    out[spec] = min(once() for _ in range(3))
print(json.dumps(out))
"""


def baseline_ratios(ref: str, specs: list[str], repeat: int) -> dict[str, dict[str, float]]:
    """Loader time of this tree and of git revision ``ref`` on each ``ROOT:PREFETCH`` of ``specs``,
    in alternating child processes; per spec the medians and the median ratio this / ref."""
    here = Path(__file__).resolve().parents[1]
    runs: dict[str, list[dict[str, float]]] = {"this": [], "base": []}
    with tempfile.TemporaryDirectory(prefix="psg-loader-bench-") as tmp:
        arc = subprocess.run(["git", "-C", str(here), "archive", ref, "psg_data"], capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", tmp], input=arc.stdout, check=True)
        for _ in range(repeat):
            for key, src in (("this", str(here)), ("base", tmp)):
                out = subprocess.run([sys.executable, "-c", _CHILD, src, *specs], capture_output=True, text=True,
                                     check=True, cwd=tmp)
                runs[key].append(json.loads(out.stdout))
    return {s: {"this_s": statistics.median(r[s] for r in runs["this"]),
                "base_s": statistics.median(r[s] for r in runs["base"]),
                "ratio": statistics.median(a[s] / b[s] for a, b in zip(runs["this"], runs["base"]))} for s in specs}


def import_time(reps: int) -> float:
    times = []
    for _ in range(reps):
        out = subprocess.run([sys.executable, "-c", "import time; t=time.perf_counter(); import psg_data; "
                              "print(time.perf_counter()-t)"], capture_output=True, text=True, check=True,
                             cwd=str(Path(__file__).resolve().parents[1]))
        times.append(float(out.stdout))
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="fewer, smaller frames")
    ap.add_argument("--baseline-ref", default=None, help="git revision whose loader reads the same datasets")
    ap.add_argument("--repeat", type=int, default=5, help="alternating child pairs with --baseline-ref")
    args = ap.parse_args()
    frames, (w, h) = (20, (320, 240)) if args.quick else (60, (640, 480))
    with tempfile.TemporaryDirectory() as tmp:
        root = make_dataset(Path(tmp) / "ds", frames, w, h)
        files_root = make_dataset(Path(tmp) / "ds_files", frames, w, h, layout="files")
        size_mb = sum(p.stat().st_size for p in (files_root / "images").rglob("*.png")) / 1e6
        time_loader(root), time_loader(files_root), time_imread(files_root)  # warm the page cache
        lo, lo0, lf, im = [], [], [], []
        for _ in range(3):  # interleave to share machine noise
            lo.append(time_loader(root)[0])
            lo0.append(time_loader(root, prefetch=0)[0])
            lf.append(time_loader(files_root)[0])
            im.append(time_imread(files_root)[0])
        t_lo, t_lo0, t_lf, t_im = min(lo), min(lo0), min(lf), min(im)
        versus = {}
        if args.baseline_ref:
            specs = [f"{r}:{p}" for r in (root, files_root) for p in (2, 0)]
            versus = baseline_ratios(args.baseline_ref, specs, args.repeat)
    imp = import_time(5)
    rows = [
        ("psg_data loader, tar layout", frames / t_lo, size_mb / t_lo),
        ("plain cv2.imread loop (baseline)", frames / t_im, size_mb / t_im),
        ("psg_data loader, tar layout, prefetch=0", frames / t_lo0, size_mb / t_lo0),
        ("psg_data loader, files layout", frames / t_lf, size_mb / t_lf),
    ]
    print(f"frames: {frames} x {w}x{h}, {size_mb:.1f} MB of PNG; machine: {platform.machine()}, "
          f"{platform.python_version()}")
    print(f"{'reader':42s} {'frames/s':>10s} {'MB/s':>8s} {'ratio':>7s}")
    for name, fps, mbs in rows:
        print(f"{name:42s} {fps:10.1f} {mbs:8.1f} {fps / rows[1][1]:7.2f}x")
    print(f"import psg_data: {imp * 1000:.1f} ms (median of 5 fresh interpreters)")
    if versus:
        print(f"\nthis tree vs {args.baseline_ref} ({args.repeat} alternating child pairs, best of 3 passes each; "
              f"load {Path('/proc/loadavg').read_text().split()[0] if Path('/proc/loadavg').exists() else '?'})")
        print(f"{'loader':34s} {'this s':>8s} {'ref s':>8s} {'time ratio':>11s}")
        for spec, v in versus.items():
            layout = "files" if spec.rsplit(":", 1)[0].endswith("ds_files") else "tar"
            name = f"{layout} layout, prefetch={spec.rsplit(':', 1)[1]}"
            print(f"{name:34s} {v['this_s']:8.3f} {v['base_s']:8.3f} {v['ratio']:10.3f}x")
    out = Path(__file__).parent / "out"
    out.mkdir(exist_ok=True)
    (out / "loader.json").write_text(json.dumps({
        "frames": frames, "resolution": [w, h], "loader_fps": rows[0][1], "imread_fps": rows[1][1],
        "ratio": rows[0][1] / rows[1][1], "ratio_no_prefetch": rows[2][1] / rows[1][1],
        "ratio_files_layout": rows[3][1] / rows[1][1], "import_s": imp,
        "baseline_ref": args.baseline_ref, "versus_baseline": {
            ("files" if k.rsplit(":", 1)[0].endswith("ds_files") else "tar") + ":prefetch=" + k.rsplit(":", 1)[1]: v
            for k, v in versus.items()}}, indent=2))


if __name__ == "__main__":
    main()
