"""Benchmark of ``psg-data convert`` against baselines measured side by side in the same run.

Usage::

    python bench/bench_convert.py                          # small and fast (~60 MB, 320x240)
    python bench/bench_convert.py --size-mb 1000           # full comparison (640x480, 8 recordings)
    python bench/bench_convert.py --size-mb 1000 --out-dir /dev/shm   # outputs on tmpfs
    python bench/bench_convert.py --memory-mb 2000         # peak RSS converting one 2 GB recording
    python bench/bench_convert.py --size-mb 1000 --baseline-tree /tmp/base   # before/after, side by side

Rows (ratios are throughput in MB/s of input, higher is better; each repeat measures the baseline
and the conversion back to back, so they share the machine's conditions):
  compressed vs iterate:  convert --jobs 1 (JPEG colour + compressedDepth passed through) vs
                          iterating all raw messages of the same recordings with rosbags' AnyReader
                          (no output); also shown against rosbags' lower-level rosbag1.Reader
  compressed vs minimal:  the same conversion vs a minimal pass-through loop (AnyReader over the
                          image topics, each payload appended to one file per recording and
                          SHA-256'd, one thread): what a straightforward script gets
  raw vs minimal loop:    convert --jobs 1 (rgb8 + 16UC1 -> PNG level 1) vs a minimal loop doing the
                          same read / deserialise / encode / write (one file per recording) steps
  raw --jobs 2 vs 1:      the same conversion with two worker processes vs --jobs 1 (one core)
  checks (--cases checks): the compressed conversion with each image_check level (structure, the
                          default; full) vs image_check none, in rotating order within each repeat:
                          throughput, and CPU time of the process (all threads) as a ratio none / level
  memory:                 peak RSS of a conversion in a fresh subprocess (ru_maxrss, workers included)
  --baseline-tree DIR:    convert --jobs 1 of the compressed and the raw set with this tree's psg_data
                          and with the one in DIR (e.g. ``git worktree add /tmp/base main``), each
                          conversion in a fresh process, in alternating order within each repeat;
                          the archives of both must be identical byte for byte

Recordings are ROS 1 bags exported from one synthetic canonical scan and hard-linked ``--recordings``
times (each recording is a separate scan of the output). They are built in ``--tmp`` and deleted.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

COLOR_TOPICS = ("/camera/color/image_raw", "/camera/aligned_depth_to_color/image_raw")


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


def build_recordings(tmp: Path, name: str, n_rec: int, n_frames: int, w: int, h: int, images: str) -> Path:
    """``n_rec`` hard links of one exported recording of ``n_frames`` frames, alone in a directory."""
    from psg_data.synth._raw_export import export_raw

    canon = make_canonical(tmp / f"canon_{name}", 1, n_frames, w, h)
    exported = export_raw(canon, tmp / f"export_{name}", "ros1", images=images)
    shutil.rmtree(canon)
    out = tmp / name
    out.mkdir()
    bag = exported / "scan_000.bag"
    for k in range(n_rec):
        os.link(bag, out / f"rec_{k:02d}.bag")
    shutil.rmtree(exported)
    return out


def bytes_per_frame(tmp: Path, w: int, h: int) -> dict[str, float]:
    """Recording bytes per frame for compressed and raw images, from a short probe export."""
    from psg_data.synth._raw_export import export_raw

    n = 8
    canon = make_canonical(tmp / "probe", 1, n, w, h)
    out = {k: dir_size(export_raw(canon, tmp / f"probe_{k}", "ros1", images=k)) / n for k in ("compressed", "raw")}
    for d in ("probe", "probe_compressed", "probe_raw"):
        shutil.rmtree(tmp / d)
    return out


def iterate_raw(rec_dir: Path) -> float:
    """Iterate every raw message of every recording with rosbags' AnyReader (no deserialisation, no output)."""
    from rosbags.highlevel import AnyReader

    t = time.perf_counter()
    n = 0
    for bag in sorted(rec_dir.glob("*.bag")):
        with AnyReader([bag]) as r:
            for _, _, raw in r.messages():
                n += len(raw)
    return time.perf_counter() - t


def iterate_raw_lowlevel(rec_dir: Path) -> float:
    """The same with rosbags' ROS 1 reader (``rosbags.rosbag1.Reader``: no typestore set-up)."""
    from rosbags.rosbag1 import Reader

    t = time.perf_counter()
    n = 0
    for bag in sorted(rec_dir.glob("*.bag")):
        with Reader(bag) as r:
            for _, _, raw in r.messages():
                n += len(raw)
    return time.perf_counter() - t


def passthrough_minimal(rec_dir: Path, out: Path) -> float:
    """Iterate the image topics, append each payload to one file per recording, SHA-256 it; one thread.

    The payload is the serialized message tail (the image to within a few bytes), no parsing.
    """
    from rosbags.highlevel import AnyReader

    t = time.perf_counter()
    out.mkdir(parents=True)
    for k, bag in enumerate(sorted(rec_dir.glob("*.bag"))):
        h = hashlib.sha256()
        with open(out / f"rec_{k:02d}.bin", "wb") as fh, AnyReader([bag]) as r:
            conns = [c for c in r.connections if c.msgtype == "sensor_msgs/msg/CompressedImage"]
            for _, _, raw in r.messages(connections=conns):
                data = memoryview(raw)[64:]
                fh.write(data)
                h.update(data)
        h.hexdigest()
    return time.perf_counter() - t


def minimal_raw_loop(rec_dir: Path, out: Path) -> float:
    """Read, deserialise, decode rgb8/16UC1, encode PNG level 1, append to one file per recording."""
    import cv2
    from rosbags.highlevel import AnyReader

    from psg_data.writers._dataset_writer import PNG_LEVEL

    t = time.perf_counter()
    out.mkdir(parents=True)
    for k, bag in enumerate(sorted(rec_dir.glob("*.bag"))):
        with open(out / f"rec_{k:02d}.bin", "wb") as fh, AnyReader([bag]) as r:
            conns = [c for c in r.connections if c.topic in COLOR_TOPICS]
            for c, _, raw in r.messages(connections=conns):
                m = r.deserialize(raw, c.msgtype)
                if m.encoding == "rgb8":
                    img = cv2.cvtColor(m.data.reshape(m.height, m.width, 3), cv2.COLOR_RGB2BGR)
                else:
                    img = m.data.view(np.uint16).reshape(m.height, m.width)
                fh.write(cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])[1])
    return time.perf_counter() - t


def timed_convert(src: Path, out: Path, jobs: int, image_check: str = "structure") -> float:
    return cpu_timed_convert(src, out, jobs, image_check)[0]


def cpu_timed_convert(src: Path, out: Path, jobs: int, image_check: str = "structure") -> tuple[float, float]:
    """(wall seconds, CPU seconds of this process: every thread, user + system) of one conversion."""
    from psg_data.convert import ConvertConfig, convert

    t, c = time.perf_counter(), time.process_time()
    convert(src, out, jobs=jobs, config=ConvertConfig(image_check=image_check))
    return time.perf_counter() - t, time.process_time() - c



def checks_cpu_share(src: Path, out: Path) -> float:
    """Share of one --jobs 1 conversion's CPU time (every thread) spent inside the image checks at the
    default level, each check call timed with its thread's CPU clock (which includes that clock's own
    system calls: an upper bound)."""
    from psg_data.convert import _scan

    real, spent = _scan.check_image, [0.0]

    def timed(*a: object, **k: object) -> object:
        c0 = time.thread_time()
        try:
            return real(*a, **k)
        finally:
            spent[0] += time.thread_time() - c0

    _scan.check_image = timed  # type: ignore[assignment]
    try:
        _, total = cpu_timed_convert(src, out, 1)
    finally:
        _scan.check_image = real  # type: ignore[assignment]
    return spent[0] / total


_RSS_CODE = """
import json, resource, sys, time
sys.path.insert(0, {root!r})
from psg_data.convert import convert
t = time.perf_counter()
convert({src!r}, {out!r}, jobs={jobs})
print(json.dumps({{"seconds": time.perf_counter() - t,
                  "self_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  "children_kib": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}}))
"""


def peak_rss_convert(src: Path, out: Path, jobs: int = 1) -> dict[str, float]:
    """Peak RSS (MiB) of a conversion run in a fresh interpreter (largest of parent and workers)."""
    code = _RSS_CODE.format(root=str(ROOT), src=str(src), out=str(out), jobs=jobs)
    res = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    r = json.loads(res.stdout.strip().splitlines()[-1])
    return {"seconds": r["seconds"], "peak_rss_mib": max(r["self_kib"], r["children_kib"]) / 1024.0}


def _rm(*paths: Path) -> None:
    for p in paths:
        shutil.rmtree(p, ignore_errors=True)
        shutil.rmtree(p.with_name(p.name + ".partial"), ignore_errors=True)


def run_comparison(tmp: Path, out_dir: Path, size_mb: float, n_rec: int, repeat: int,
                   cases: tuple[str, ...] = ("compressed", "raw")) -> dict[str, object]:
    w, h = (640, 480) if size_mb >= 500 else (320, 240)
    per = bytes_per_frame(tmp, w, h)
    n_cmp = max(4, round(size_mb * 1e6 / per["compressed"] / n_rec))
    n_raw = max(4, round(size_mb * 1e6 / per["raw"] / n_rec))
    print(f"building {n_rec} recordings x {n_cmp} frames (compressed) and x {n_raw} frames (raw), {w}x{h}, "
          f"in {tmp} ...", file=sys.stderr)
    rec_cmp = build_recordings(tmp, "rec_cmp", n_rec, n_cmp, w, h, "compressed") if "compressed" in cases else None
    if "checks" in cases and rec_cmp is None:
        rec_cmp = build_recordings(tmp, "rec_cmp", n_rec, n_cmp, w, h, "compressed")
    rec_raw = build_recordings(tmp, "rec_raw", n_rec, n_raw, w, h, "raw") if "raw" in cases else None
    mb_cmp = dir_size(rec_cmp) / 1e6 if rec_cmp else 0.0
    mb_raw = dir_size(rec_raw) / 1e6 if rec_raw else 0.0
    o = out_dir
    reps: list[dict[str, float]] = []
    import cv2

    cv2.setNumThreads(1)  # the minimal loops and --jobs 1 run on one core
    for k in range(repeat):
        r: dict[str, float] = {}
        if rec_cmp is not None:
            r["iterate"] = iterate_raw(rec_cmp)
            r["convert_cmp"] = timed_convert(rec_cmp, o / "out_cmp", 1)
            _rm(o / "out_cmp")
            r["iterate_lowlevel"] = iterate_raw_lowlevel(rec_cmp)
            r["minimal_cmp"] = passthrough_minimal(rec_cmp, o / "minimal_cmp")
            _rm(o / "minimal_cmp")
        if "checks" in cases:
            levels = ["none", "structure", "full"]
            for lvl in levels[k % 3:] + levels[:k % 3]:
                r[f"check_{lvl}"], r[f"cpu_{lvl}"] = cpu_timed_convert(rec_cmp, o / "out_chk", 1, image_check=lvl)
                _rm(o / "out_chk")
            r["checks_cpu_share"] = checks_cpu_share(rec_cmp, o / "out_chk")
            _rm(o / "out_chk")
        if rec_raw is not None:
            r["minimal_raw"] = minimal_raw_loop(rec_raw, o / "minimal")
            _rm(o / "minimal")
            r["convert_raw_j1"] = timed_convert(rec_raw, o / "out_raw1", 1)
            _rm(o / "out_raw1")
            r["convert_raw_j2"] = timed_convert(rec_raw, o / "out_raw2", 2)
            _rm(o / "out_raw2")
        reps.append(r)
        print(f"repeat {k + 1}/{repeat}: " + ", ".join(f"{n} {v:.3f}" if n.endswith("share") else f"{n} {v:.2f}s"
                                                      for n, v in r.items()), file=sys.stderr)
    rows = []
    for name, mb, conv, base, tgt in (
        ("compressed: convert vs iterate (AnyReader)", mb_cmp, "convert_cmp", "iterate", 0.5),
        ("compressed: convert vs iterate (rosbag1.Reader)", mb_cmp, "convert_cmp", "iterate_lowlevel", None),
        ("compressed: convert vs minimal pass-through", mb_cmp, "convert_cmp", "minimal_cmp", None),
        ("raw: convert vs minimal loop", mb_raw, "convert_raw_j1", "minimal_raw", 0.7),
        ("raw: --jobs 2 vs --jobs 1", mb_raw, "convert_raw_j2", "convert_raw_j1", 1.6),
        ("compressed: image_check structure vs none", mb_cmp, "check_structure", "check_none", 0.9),
        ("compressed: image_check structure vs none, CPU", mb_cmp, "cpu_structure", "cpu_none", 0.9),
        ("compressed: image_check full vs none", mb_cmp, "check_full", "check_none", None),
    ):
        if conv not in reps[0]:
            continue
        ratios = [r[base] / r[conv] for r in reps]
        rows.append({"case": name, "mb": mb, "convert_s": [r[conv] for r in reps], "base_s": [r[base] for r in reps],
                     "ratios": ratios, "target": tgt})
    print(f"\ninput: compressed {mb_cmp:.0f} MB ({n_rec} x {n_cmp} frames), raw {mb_raw:.0f} MB "
          f"({n_rec} x {n_raw} frames), {w}x{h}; outputs in {out_dir}; {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"{'case':48s} {'MB/s':>8s} {'base MB/s':>10s} {'ratio (median, each repeat)':>30s} {'target':>7s}")
    for row in rows:
        c, b = float(np.median(row["convert_s"])), float(np.median(row["base_s"]))
        each = " ".join(f"{x:.2f}" for x in row["ratios"])
        tgt = f">={row['target']}" if row["target"] else "-"
        print(f"{row['case']:48s} {row['mb'] / c:8.1f} {row['mb'] / b:10.1f} "
              f"{float(np.median(row['ratios'])):7.2f} ({each}) {tgt:>7s}")
    if "checks_cpu_share" in reps[0]:
        shares = [100 * r["checks_cpu_share"] for r in reps]
        print(f"{'compressed: share of convert CPU inside the checks':48s} {'':8s} {'':10s} "
              f"{float(np.median(shares)):6.1f} % ({' '.join(f'{x:.1f}' for x in shares)})  <=10 %")
    return {"size": {"mb_cmp": mb_cmp, "mb_raw": mb_raw, "recordings": n_rec, "frames_cmp": n_cmp,
                     "frames_raw": n_raw, "width": w, "height": h}, "repeats": reps, "rows": rows}


def run_memory(tmp: Path, out_dir: Path, memory_mb: float, jobs: int) -> dict[str, object]:
    w, h = 640, 480
    per = bytes_per_frame(tmp, w, h)["raw"]
    n = max(4, round(memory_mb * 1e6 / per))
    print(f"building one raw recording of {n} frames {w}x{h} in {tmp} ...", file=sys.stderr)
    rec = build_recordings(tmp, "rec_mem", 1, n, w, h, "raw")
    mb = dir_size(rec) / 1e6
    r = peak_rss_convert(rec / "rec_00.bag", out_dir / "out_mem", jobs)
    _rm(out_dir / "out_mem")
    print(f"\nmemory: converting one {mb:.0f} MB raw recording ({n} frames {w}x{h}, --jobs {jobs}) took "
          f"{r['seconds']:.1f} s; peak RSS {r['peak_rss_mib']:.0f} MiB (target <= 1024 MiB)")
    return {"mb": mb, "frames": n, **r}


_AB_CODE = """
import json, sys, time
sys.path.insert(0, {tree!r})
import psg_data
from psg_data.convert import convert
from psg_data.loaders import Dataset
t = time.perf_counter()
convert({src!r}, {out!r}, jobs={jobs})
seconds = time.perf_counter() - t
files = Dataset({out!r}).table("files").to_pylist()
print(json.dumps({{"seconds": seconds, "package": psg_data.__file__,
                  "archives": {{f["path"]: f["sha256"] for f in files if f["path"].endswith(".tar")}}}}))
"""


def _convert_in(tree: Path, src: Path, out: Path, jobs: int) -> dict[str, object]:
    """One conversion in a fresh interpreter importing psg_data from ``tree``: seconds and archive digests."""
    code = _AB_CODE.format(tree=str(tree), src=str(src), out=str(out), jobs=jobs)
    res = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, cwd="/")
    r = json.loads(res.stdout.strip().splitlines()[-1])
    if not str(r["package"]).startswith(str(tree)):
        raise RuntimeError(f"psg_data came from {r['package']}, not from {tree}")
    _rm(out)
    return r


def run_ab(tmp: Path, out_dir: Path, size_mb: float, n_rec: int, repeat: int, baseline: Path,
           cases: tuple[str, ...]) -> dict[str, object]:
    """Before/after: this tree's convert --jobs 1 against ``baseline``'s, on the same recordings."""
    w, h = (640, 480) if size_mb >= 500 else (320, 240)
    per = bytes_per_frame(tmp, w, h)
    sets = {}
    for case in cases:
        n = max(4, round(size_mb * 1e6 / per[case] / n_rec))
        print(f"building {n_rec} recordings x {n} frames ({case}), {w}x{h}, in {tmp} ...", file=sys.stderr)
        rec = build_recordings(tmp, f"rec_{case}", n_rec, n, w, h, case)
        sets[case] = (rec, dir_size(rec) / 1e6, n)
    trees = {"baseline": baseline.resolve(), "current": ROOT}
    secs: dict[str, dict[str, list[float]]] = {c: {"baseline": [], "current": []} for c in cases}
    loads = []
    for k in range(repeat):
        for case, (rec, mb, _) in sets.items():
            order = ["baseline", "current"] if k % 2 == 0 else ["current", "baseline"]
            got = {}
            for which in order:
                got[which] = _convert_in(trees[which], rec, out_dir / f"out_{which}", 1)
                secs[case][which].append(float(got[which]["seconds"]))  # type: ignore[arg-type]
            if got["baseline"]["archives"] != got["current"]["archives"]:
                raise RuntimeError(f"{case}: the archives differ between the baseline and the current tree")
            loads.append(os.getloadavg()[0])
            print(f"repeat {k + 1}/{repeat} {case}: " + ", ".join(f"{x} {secs[case][x][-1]:.2f}s" for x in order)
                  + f" (archives identical), load {loads[-1]:.2f}", file=sys.stderr)
    print(f"\nbefore/after, convert --jobs 1, {n_rec} recordings each, {w}x{h}; {os.cpu_count()} CPUs, "
          f"load average {min(loads):.2f}-{max(loads):.2f}; archives identical byte for byte")
    print(f"{'case':12s} {'MB':>7s} {'baseline MB/s':>14s} {'current MB/s':>13s} {'current/baseline':>17s} (each repeat)")
    rows = []
    for case, (rec, mb, n) in sets.items():
        b, c = secs[case]["baseline"], secs[case]["current"]
        ratios = [x / y for x, y in zip(b, c)]
        print(f"{case:12s} {mb:7.0f} {mb / float(np.median(b)):14.1f} {mb / float(np.median(c)):13.1f} "
              f"{float(np.median(b)) / float(np.median(c)):17.3f} ({' '.join(f'{r:.2f}' for r in ratios)})")
        rows.append({"case": case, "mb": mb, "frames": n, "baseline_s": b, "current_s": c, "ratios": ratios})
    return {"baseline_tree": str(baseline), "rows": rows, "load": loads}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size-mb", type=float, default=None, help="total size of each set of recordings (default 60)")
    ap.add_argument("--quick", action="store_true", help="smoke run: 20 MB sets (bench/run.py --quick)")
    ap.add_argument("--recordings", type=int, default=8, help="recordings per set")
    ap.add_argument("--repeat", type=int, default=None, help="repeats of each comparison (default 1 small, 3 full)")
    ap.add_argument("--memory-mb", type=float, default=None, help="run only the memory test on a recording this big")
    ap.add_argument("--jobs", type=int, default=1, help="--jobs of the memory test")
    ap.add_argument("--cases", default="compressed,raw", help="comparisons to run: compressed, raw or both")
    ap.add_argument("--tmp", type=Path, default=None, help="where to build the recordings (default: system tmp)")
    ap.add_argument("--out-dir", type=Path, default=None, help="where conversions write (default: beside inputs)")
    ap.add_argument("--baseline-tree", type=Path, default=None,
                    help="source tree of a baseline psg_data: before/after runs of --cases (see above)")
    args = ap.parse_args()
    if args.size_mb is None:
        args.size_mb = 20.0 if args.quick else 60.0
    tmp = Path(tempfile.mkdtemp(prefix="psg_bench_convert_", dir=args.tmp))
    out_dir = Path(tempfile.mkdtemp(prefix="psg_bench_out_", dir=args.out_dir)) if args.out_dir else tmp
    try:
        cases = tuple(c.strip() for c in args.cases.split(",") if c.strip())
        if args.memory_mb:
            res = run_memory(tmp, out_dir, args.memory_mb, args.jobs)
        elif args.baseline_tree:
            res = run_ab(tmp, out_dir, args.size_mb, args.recordings, args.repeat or 3, args.baseline_tree, cases)
        else:
            repeat = args.repeat or (3 if args.size_mb >= 500 else 1)
            res = run_comparison(tmp, out_dir, args.size_mb, args.recordings, repeat, cases)
        print(json.dumps(res))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(out_dir, ignore_errors=True)


if __name__ == "__main__":
    main()
