"""Benchmark of ``psg-data convert`` on an RTAB-Map database against a plain ``sqlite3`` read of the
same blobs, measured side by side in the same run.

Usage::

    python bench/bench_rtabmap.py                  # small and fast (~60 MB)
    python bench/bench_rtabmap.py --size-mb 500    # the acceptance size of issue 32
    python bench/bench_rtabmap.py --out-dir /dev/shm

Rows (throughput in MB/s of database bytes, higher is better; each repeat measures the baseline and
the conversion back to back, so they share the machine's conditions):
  convert vs sqlite3 read:  ``convert(db, out)`` (--jobs 1: JPEG colour and 16-bit PNG depth passed
                            through, checked at image_check ``structure``, archived and hashed) vs
                            ``SELECT image, depth, calibration FROM Data`` over every row with Python's
                            sqlite3 (each blob fetched into a bytes object, nothing written): the
                            floor any reader of the database pays (the issue's baseline).
  convert vs minimal copy:  the same conversion vs a minimal pass-through script: the sqlite3 read,
                            every image appended to one file, SHA-256'd, the file fsync'd (what a
                            dataset writer cannot do without): the headroom left above the I/O floor.

The database (three sessions, 640x480, optimized poses saved) is written with the tests' writer of
RTAB-Map databases into ``--tmp`` and deleted afterwards.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def make_database(path: Path, size_mb: float, w: int = 640, h: int = 480) -> int:
    """An RTAB-Map 0.23.0 database of about ``size_mb`` MB; returns its node count."""
    import cv2

    from tests.convert.rtabmap_writer import OPTICAL, Node, camera_blob, write_database

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:h, 0:w]
    blobs = []
    for v in range(8):  # a few distinct frames, cycled (the database still holds every byte)
        c = np.stack([(xx + 7 * v) % 256, (yy + 3 * v) % 256, ((xx * yy) >> 7) % 256], -1).astype(np.uint8)
        c = np.clip(c.astype(int) + rng.integers(0, 24, c.shape), 0, 255).astype(np.uint8)
        d = (900 + 2 * xx + 3 * yy + rng.integers(0, 40, (h, w))).astype(np.uint16)
        blobs.append((cv2.imencode(".jpg", c, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes(),
                      cv2.imencode(".png", d)[1].tobytes()))
    per = sum(len(a) + len(b) for a, b in blobs) / len(blobs)
    n = max(3, int(size_mb * 1e6 / per))
    calib = camera_blob("0.23.0", 0.9 * w, 0.9 * w, w / 2 - 0.5, h / 2 - 0.5, w, h, OPTICAL)
    nodes, opt = [], {}
    for i in range(n):
        T = np.eye(4)
        T[:3, 3] = [0.01 * i, 0.0, 0.0]
        c, d = blobs[i % len(blobs)]
        nodes.append(Node(i + 1, 3 * i // n, 1_700_000_000.0 + 0.5 * i, T, c, d, calib))
        opt[i + 1] = T
    write_database(path, "0.23.0", nodes, [], optimized=opt)
    return n


def sqlite_read(db: Path) -> int:
    """Every blob of ``Data`` (and the ``Node`` rows) read with Python's sqlite3; returns the bytes."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    total = sum(len(p or b"") for (p,) in con.execute("SELECT pose FROM Node"))
    for image, depth, calib in con.execute("SELECT image, depth, calibration FROM Data"):
        total += len(image) + len(depth) + len(calib)
    con.close()
    return total


def minimal_copy(db: Path, out: Path) -> int:
    """The sqlite3 read, each image appended to one file and SHA-256'd, the file fsync'd; returns the bytes."""
    import hashlib

    h = hashlib.sha256()
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    total = 0
    with open(out, "wb") as fh:
        for image, depth, _calib in con.execute("SELECT image, depth, calibration FROM Data"):
            for blob in (image, depth):
                fh.write(blob)
                h.update(blob)
                total += len(blob)
        fh.flush()
        os.fsync(fh.fileno())
    con.close()
    out.unlink()
    return total


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size-mb", type=float, default=60.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tmp", default=None, help="where the database is built (default: a temporary folder)")
    ap.add_argument("--out-dir", default=None, help="where the datasets are written (default: --tmp)")
    ap.add_argument("--quick", action="store_true", help="small database, one repeat")
    args, _ = ap.parse_known_args()
    if args.quick:
        args.size_mb, args.repeats = min(args.size_mb, 30.0), 1

    from psg_data.convert import convert

    tmp = Path(tempfile.mkdtemp(dir=args.tmp))
    out_dir = Path(tempfile.mkdtemp(dir=args.out_dir)) if args.out_dir else tmp
    try:
        db = tmp / "map.db"
        t0 = time.perf_counter()
        n = make_database(db, args.size_mb)
        size = db.stat().st_size
        print(f"database: {size / 1e6:.0f} MB, {n} nodes in 3 sessions, 640x480 JPEG + 16-bit PNG "
              f"(built in {time.perf_counter() - t0:.0f} s); load {os.getloadavg()[0]:.2f}")
        sqlite_read(db)  # both read from the page cache
        convert(db, out_dir / "warm")  # and one-time imports are not measured
        shutil.rmtree(out_dir / "warm")
        rows = []
        for r in range(args.repeats):
            t = time.perf_counter()
            sqlite_read(db)
            base = time.perf_counter() - t
            t = time.perf_counter()
            minimal_copy(db, out_dir / "copy.bin")
            copy = time.perf_counter() - t
            out = out_dir / f"out{r}"
            t = time.perf_counter()
            rep = convert(db, out)
            conv = time.perf_counter() - t
            assert rep.frames == n and rep.passthrough == {"color": n, "depth": n}, rep
            shutil.rmtree(out)
            rows.append((size / 1e6 / base, size / 1e6 / copy, size / 1e6 / conv))
        print(f"{'repeat':>6} {'sqlite3 read MB/s':>18} {'minimal copy MB/s':>18} {'convert MB/s':>13} "
              f"{'vs read':>8} {'vs copy':>8}")
        for r, (b, m, c) in enumerate(rows):
            print(f"{r:>6} {b:>18.0f} {m:>18.0f} {c:>13.0f} {c / b:>8.2f} {c / m:>8.2f}")
        med = float(np.median([c / b for b, _, c in rows]))
        medm = float(np.median([c / m for _, m, c in rows]))
        print(f"median ratio convert / sqlite3 read: {med:.2f}x (target >= 0.5x); convert / minimal copy: "
              f"{medm:.2f}x; load {os.getloadavg()[0]:.2f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if out_dir != tmp:
            shutil.rmtree(out_dir, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
