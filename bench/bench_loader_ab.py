"""Per-frame cost of this tree's loader against git revision REF, in ONE process (less noise than
child processes on a shared machine): REF's ``psg_data`` is imported under another name and
``scan.frame(i)`` of both alternates on the same files. Run:

    python bench/bench_loader_ab.py REF [--resolution 160] [--frames 20] [--rounds 7]

Prints, per layout, the best time per frame of each tree and the ratio this / REF (above 1 is
slower), and the load average.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def import_ref(ref: str, into: Path):  # type: ignore[no-untyped-def]
    """REF's psg_data, imported as ``psg_data_ref``."""
    here = Path(__file__).resolve().parents[1]
    arc = subprocess.run(["git", "-C", str(here), "archive", ref, "psg_data"], capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(into)], input=arc.stdout, check=True)
    pkg = into / "psg_data_ref"
    (into / "psg_data").rename(pkg)
    for f in pkg.rglob("*.py"):
        f.write_text(re.sub(r"\bpsg_data\b", "psg_data_ref", f.read_text()))
    sys.path.insert(0, str(into))
    import psg_data_ref

    return psg_data_ref


def best_per_frame(scan, n: int, rounds: int) -> float:  # type: ignore[no-untyped-def]
    best = float("inf")
    for _ in range(rounds):
        t = time.perf_counter()
        for _ in range(n):
            for i in range(len(scan)):
                scan.frame(i)
        best = min(best, (time.perf_counter() - t) / (n * len(scan)))
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("ref")
    ap.add_argument("--resolution", type=int, default=160, help="image width (height = 3/4 of it)")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--rounds", type=int, default=7, help="alternating rounds; the best of each tree counts")
    args = ap.parse_args()
    import psg_data
    from bench_loader import make_dataset

    w, h = args.resolution, args.resolution * 3 // 4
    with tempfile.TemporaryDirectory(prefix="psg-loader-ab-") as tmp:
        ref = import_ref(args.ref, Path(tmp))
        print(f"{args.frames} frames of {w}x{h}; load {Path('/proc/loadavg').read_text().split()[0]}")
        print(f"{'layout':8s} {'this us/frame':>14s} {args.ref[:12] + ' us/frame':>22s} {'ratio':>7s}")
        for layout in ("tar", "files"):
            root = make_dataset(Path(tmp) / layout, args.frames, w, h, layout=layout)
            scans = {"this": psg_data.open_dataset(root).scan("s0"), "ref": ref.open_dataset(root).scan("s0")}
            best = {k: float("inf") for k in scans}
            for _ in range(args.rounds):
                for k, scan in scans.items():
                    best[k] = min(best[k], best_per_frame(scan, 3, 1))
            print(f"{layout:8s} {best['this'] * 1e6:14.0f} {best['ref'] * 1e6:22.0f} "
                  f"{best['this'] / best['ref']:6.3f}x")
        print(f"load after: {Path('/proc/loadavg').read_text().split()[0]}")


if __name__ == "__main__":
    main()
