"""Benchmark of ``psg-data convert`` against baselines measured side by side in the same run.

Usage::

    python bench/bench_convert.py                 # small (~60 MB of recordings)
    python bench/bench_convert.py --size-mb 1000  # full run (640x480 frames)

Rows (ratios are throughput in MB/s of input, higher is better):
  compressed: convert (JPEG colour + compressedDepth passed through) vs iterating the raw messages
  raw:        convert (rgb8 + 16UC1, PNG level 1) vs a minimal read/decode/encode/write loop
  jobs:       --jobs 2 vs --jobs 1 on the raw recordings
  memory:     peak RSS of a conversion subprocess (resource.getrusage RUSAGE_CHILDREN)
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def make_canonical(root: Path, n_scans: int, n_frames: int, w: int, h: int) -> Path:
    from psg_data.schemas._records import CameraIntrinsics
    from psg_data.writers import DatasetWriter

    cam = CameraIntrinsics("cam0", w, h, 0.9 * w, 0.9 * w, w / 2 - 0.5, h / 2 - 0.5,
                           frame_id="camera_color_optical_frame")
    yy, xx = np.mgrid[0:h, 0:w]
    rng = np.random.default_rng(0)
    with DatasetWriter(root, name="bench", color_encoding="png", threads=2) as wr:
        wr.add_camera(cam)
        for s in range(n_scans):
            with wr.scan(f"scan_{s:03d}") as sw:
                for i in range(n_frames):
                    c = np.stack([(xx + 3 * i) % 256, (yy + 5 * s) % 256, ((xx * yy) >> 6) % 256], -1).astype(np.uint8)
                    c = np.clip(c + rng.integers(0, 8, c.shape, dtype=np.uint8), 0, 255).astype(np.uint8)
                    d = (1000 + 3 * xx + 2 * yy + 10 * np.sin(i + xx / 20.0)).astype(np.uint16)
                    T = np.eye(4)
                    T[:3, 3] = [0.01 * i, 0.1 * s, 1.0]
                    sw.add_frame(1_700_000_000_000_000_000 + s * 10**12 + i * 33_333_333, T, c, d, "cam0")
    return root


def dir_size(p: Path) -> int:
    return sum(f.stat().st_size for f in p.rglob("*") if f.is_file() and f.suffix in (".bag", ".db3", ".mcap"))


def iterate_raw(rec_dir: Path) -> float:
    from rosbags.highlevel import AnyReader

    t = time.perf_counter()
    n = 0
    for bag in sorted(rec_dir.glob("*.bag")):
        with AnyReader([bag]) as r:
            for _, _, raw in r.messages():
                n += len(raw)
    return time.perf_counter() - t


def minimal_raw_loop(rec_dir: Path, out: Path) -> float:
    """Read, deserialise, decode rgb8/16UC1, encode PNG level 1, write files: the floor of the work."""
    import cv2
    from rosbags.highlevel import AnyReader

    from psg_data.writers._dataset_writer import PNG_LEVEL

    t = time.perf_counter()
    out.mkdir(parents=True)
    k = 0
    for bag in sorted(rec_dir.glob("*.bag")):
        with AnyReader([bag]) as r:
            conns = [c for c in r.connections if c.topic in ("/camera/color/image_raw",
                                                              "/camera/aligned_depth_to_color/image_raw")]
            for c, _, raw in r.messages(connections=conns):
                m = r.deserialize(raw, c.msgtype)
                if m.encoding == "rgb8":
                    img = cv2.cvtColor(m.data.reshape(m.height, m.width, 3), cv2.COLOR_RGB2BGR)
                else:
                    img = m.data.view(np.uint16).reshape(m.height, m.width)
                buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])[1]
                (out / f"{k}.png").write_bytes(buf.tobytes())
                k += 1
    return time.perf_counter() - t


def timed_convert(src: Path, out: Path, jobs: int) -> float:
    from psg_data.convert import convert

    t = time.perf_counter()
    convert(src, out, jobs=jobs)
    return time.perf_counter() - t


def peak_rss_convert(src: Path, out: Path) -> float:
    code = ("import sys; sys.path.insert(0, %r); from psg_data.convert import convert; convert(%r, %r)"
            % (str(Path(__file__).resolve().parents[1]), str(src), str(out)))
    subprocess.run([sys.executable, "-c", code], check=True)
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0  # MiB (Linux: KiB)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size-mb", type=float, default=60.0, help="target size of the raw recordings")
    ap.add_argument("--scans", type=int, default=4)
    ap.add_argument("--tmp", type=Path, default=None)
    args = ap.parse_args()
    from psg_data.synth._raw_export import export_raw

    w, h = (640, 480) if args.size_mb >= 500 else (320, 240)
    per_frame = w * h * 5 * 1.02  # rgb8 + 16UC1 message bytes
    n_frames = max(4, int(args.size_mb * 1e6 / per_frame / args.scans))
    tmp = Path(tempfile.mkdtemp(dir=args.tmp))
    try:
        print(f"building {args.scans} scans x {n_frames} frames of {w}x{h} in {tmp} ...", file=sys.stderr)
        canon = make_canonical(tmp / "canon", args.scans, n_frames, w, h)
        rec_raw = export_raw(canon, tmp / "rec_raw", "ros1", images="raw")
        rec_cmp = export_raw(canon, tmp / "rec_cmp", "ros1", images="compressed")
        mb_raw, mb_cmp = dir_size(rec_raw) / 1e6, dir_size(rec_cmp) / 1e6
        rows = []
        t_it = iterate_raw(rec_cmp)
        t_cv = timed_convert(rec_cmp, tmp / "out_cmp", 1)
        rows.append(("compressed: convert vs iterate raw msgs", mb_cmp / t_cv, mb_cmp / t_it, t_it / t_cv, 0.5))
        t_min = minimal_raw_loop(rec_raw, tmp / "minimal")
        t_cr = timed_convert(rec_raw, tmp / "out_raw1", 1)
        rows.append(("raw: convert vs minimal loop", mb_raw / t_cr, mb_raw / t_min, t_min / t_cr, 0.7))
        t_j2 = timed_convert(rec_raw, tmp / "out_raw2", 2)
        rows.append(("raw: --jobs 2 vs --jobs 1", mb_raw / t_j2, mb_raw / t_cr, t_cr / t_j2, 1.6))
        shutil.rmtree(tmp / "out_raw2")
        rss = peak_rss_convert(rec_raw, tmp / "out_mem")
        print(f"\ninput: raw {mb_raw:.0f} MB, compressed {mb_cmp:.0f} MB, {args.scans * n_frames} frames {w}x{h}")
        print(f"{'case':42s} {'MB/s':>8s} {'base MB/s':>10s} {'ratio':>7s} {'target':>7s}")
        for name, a, b, r, tgt in rows:
            print(f"{name:42s} {a:8.1f} {b:10.1f} {r:7.2f} {'>=' + str(tgt):>7s}")
        print(f"{'peak RSS converting ' + f'{mb_raw:.0f} MB (MiB)':42s} {rss:8.0f}")
        print(json.dumps({"rows": rows, "peak_rss_mib": rss, "mb_raw": mb_raw, "mb_cmp": mb_cmp}))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
