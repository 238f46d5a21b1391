"""``convert``: raw recordings (or frame folders) -> a canonical psg-dataset, atomically.

See docs/RAW_FORMATS.md for the inputs, topics, side files, configuration and exit codes.
"""

from __future__ import annotations

import json
import logging
import shutil
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from psg_data._cpus import available_cpus
from psg_data.convert._config import ConvertConfig
from psg_data.convert._scan import (
    SKIP_KINDS,
    SKIP_REASONS,
    STATE_DIR,
    ScanResult,
    ScanTask,
    discover_topics,
    open_task_writer,
    run_task,
)
from psg_data.errors import ConversionError, PsgDataError
from psg_data.loaders.raw._bag import RosRecording, find_recordings, recording_format
from psg_data.loaders.raw._folders import _list_file, folder_format
from psg_data.loaders.raw._images import inspect_encoded
from psg_data.loaders.raw._rtabmap import RtabmapDatabase, rtabmap_format
from psg_data.loaders.raw._side import SideData, read_side_files
from psg_data.writers._safe_output import check_output

if TYPE_CHECKING:
    from psg_data.writers import DatasetWriter

__all__ = ["convert", "ConversionReport", "plan_sources", "plan_parallelism"]

log = logging.getLogger(__name__)

_STATE_FILE = "state.json"
_FORMAT_FAMILY = {"ros1": "ros1", "ros2-sqlite3": "ros2", "ros2-mcap": "ros2", "mcap": "mcap",
                  "tum": "tum", "scannet": "scannet", "rtabmap": "rtabmap"}


@dataclass
class ConversionReport:
    """What a conversion did.

    Attributes:
        output: dataset directory.
        scans: converted scan ids (including resumed ones).
        frames: frames written.
        skipped: images and frames left out, by reason (see ``SKIP_REASONS``; ``skipped_by_kind``
            groups them into colour images, depth images and frames).
        keyframe_dropped: frames left out by ``--keyframes``.
        resumed: scans kept from an interrupted run (verified by checksum).
        bytes_in: bytes of input read.
        seconds: wall time.
        passthrough: images stored without re-encoding, by kind (``color``, ``depth``).
    """

    output: str
    scans: list[str] = field(default_factory=list)
    frames: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    keyframe_dropped: int = 0
    resumed: list[str] = field(default_factory=list)
    bytes_in: int = 0
    seconds: float = 0.0
    passthrough: dict[str, int] = field(default_factory=dict)

    @property
    def mb_per_s(self) -> float:
        """Input throughput, MB (1e6 bytes) per second of wall time."""
        return self.bytes_in / 1e6 / max(self.seconds, 1e-9)

    @property
    def skipped_by_kind(self) -> dict[str, dict[str, int]]:
        """``skipped`` grouped by what each reason counts: ``color`` images, ``depth`` images, ``frames``."""
        out: dict[str, dict[str, int]] = {"color": {}, "depth": {}, "frames": {}}
        for reason, n in self.skipped.items():
            out[SKIP_KINDS.get(reason, "frames")][reason] = n
        return out

    @property
    def n_skipped(self) -> int:
        """Colour images that did not become frames (every reason but ``no_color``, which counts depth images)."""
        return sum(n for r, n in self.skipped.items() if SKIP_KINDS.get(r) != "depth")


def plan_sources(path: Path, cfg: ConvertConfig) -> list[tuple[Path, str]]:
    """Sources (path, kind) of an input path: one recording/folder or a directory of them.

    Raises:
        ConversionError: nothing convertible, a zero-byte file, or a directory mixing formats.
    """
    if not path.exists():
        raise ConversionError(f"{path}: input not found; expected a recording, a frame folder or a directory of them")
    if path.is_file() and path.stat().st_size == 0:
        raise ConversionError(f"{path}: zero-byte file; expected a ROS 1 bag, ROS 2 bag, MCAP file or RTAB-Map "
                              f"database")
    fmt = recording_format(path) or folder_format(path) or rtabmap_format(path)
    if fmt is not None:
        sources = [(path, fmt)]
    elif path.is_dir():
        recs = find_recordings(path)
        folders = [(p, f) for p in sorted(path.iterdir()) if (f := folder_format(p)) is not None]
        dbs = [(p, "rtabmap") for p in sorted(path.iterdir()) if rtabmap_format(p)]
        if sum(1 for group in (recs, folders, dbs) if group) > 1:
            raise ConversionError(f"{path}: directory mixes recording formats ({len(recs)} recordings, "
                                  f"{len(folders)} frame folders, {len(dbs)} RTAB-Map databases); expected one "
                                  f"format per directory")
        fams = {_FORMAT_FAMILY[f] for _, f in folders}
        if len(fams) > 1:
            raise ConversionError(f"{path}: directory mixes recording formats ({', '.join(sorted(fams))} folders); "
                                  f"expected one format per directory")
        sources = recs or folders or dbs
        tum_without_depth = [p for p in (path, *sorted(path.iterdir())) if (p / "rgb.txt").is_file()
                             and not (p / "depth.txt").is_file()] if not sources else []
        if tum_without_depth:
            raise ConversionError(f"{tum_without_depth[0] / 'depth.txt'}: missing; expected a TUM RGB-D folder with "
                                  f"rgb.txt and depth.txt (psg-data converts RGB-D recordings)")
        if not sources:
            raise ConversionError(f"{path}: no recordings found; expected .bag files, ROS 2 bag directories, .mcap "
                                  f"files, TUM RGB-D or ScanNet folders, or RTAB-Map .db databases")
    else:
        raise ConversionError(f"{path}: not a recording; expected a .bag, .mcap or .db3 file, a ROS 2 bag directory, "
                              f"a TUM RGB-D / ScanNet folder or an RTAB-Map .db database")
    want = cfg.input_format
    for p, f in sources:
        if want != "auto" and _FORMAT_FAMILY[f] != want:
            raise ConversionError(f"{p}: is {f}, but input_format is {want!r}")
        if p.is_file() and p.stat().st_size == 0:
            raise ConversionError(f"{p}: zero-byte file; expected a {f} recording")
        if p.is_dir() and f.startswith("ros2"):
            for db in p.iterdir():
                if db.suffix in (".db3", ".mcap") and db.stat().st_size == 0:
                    raise ConversionError(f"{db}: zero-byte file; expected a {f} recording")
    return sources


def _input_paths(src: Path, cfg: ConvertConfig) -> list[Path]:
    """Every path a conversion reads (the output may not be, contain or lie inside one)."""
    paths = [src]
    if cfg.side_dir:
        paths.append(Path(cfg.side_dir))
    if cfg.poses and cfg.poses.startswith("tum:"):
        paths.append(Path(cfg.poses[4:]))
    return paths


def _auto_color_encoding(src: Path, kind: str, cfg: ConvertConfig) -> str:
    if cfg.color_encoding != "auto":
        return cfg.color_encoding
    if kind == "tum":
        first = _list_file(src / "rgb.txt")[:1]
        return "jpeg" if first and first[0][-1].lower().endswith((".jpg", ".jpeg")) else "png"
    if kind == "scannet":
        return "jpeg" if any((src / "color").glob("*.jpg")) else "png"
    if kind == "rtabmap":
        with RtabmapDatabase(src) as db:
            image = db.first_image()
        info = inspect_encoded(image) if image else None
        return "jpeg" if info is not None and info.kind == "jpeg" else "png"
    with RosRecording(src) as rec:
        topics = discover_topics(rec.topics, cfg, str(src))
        if topics["color_type"] != "sensor_msgs/msg/CompressedImage":
            return "png"
        for conn, _, raw in rec.raw_messages({topics["color"]}):
            info = inspect_encoded(rec.compressed_image(raw, conn.topic).data)
            return "jpeg" if info is not None and info.kind == "jpeg" else "png"
        return "png"


def _resolve_side(path: Path, cfg: ConvertConfig) -> tuple[SideData, Path | None]:
    """Side files: from ``side_dir`` when given, else from INPUT when it is a directory of recordings.

    A single recording or frame folder converts on its own: the files beside it are not read.
    """
    if cfg.side_dir:
        d: Path | None = Path(cfg.side_dir)
        if not d.is_dir():  # type: ignore[union-attr]
            raise ConversionError(f"{cfg.side_dir}: side_dir: not a directory; expected the folder holding "
                                  f"site.json, door_states.csv, schedule.csv or scans.csv")
    elif path.is_dir() and recording_format(path) is None and folder_format(path) is None:
        d = path
    else:
        return SideData(), None
    return read_side_files(d), d


def _init_worker() -> None:
    """Worker set-up: one OpenCV thread per worker (the workers already use the cores; OpenCV's own
    thread pool on top would oversubscribe them), and the heavy imports done once, up front.
    """
    import cv2

    cv2.setNumThreads(1)
    import rosbags.highlevel  # noqa: F401

    import psg_data.writers._dataset_writer  # noqa: F401

def _run_parallel(tasks: list[ScanTask], procs: int, progress: Callable[..., Any] | None,
                  scheduler: str | None = None) -> list[ScanResult]:
    """Convert each source in a worker: the local spawn pool of ``procs`` processes, or Dask
    (``scheduler``, see :func:`psg_data._executors.open_executor`).
    """
    from concurrent.futures import FIRST_EXCEPTION, wait

    from psg_data._executors import open_executor

    results: list[ScanResult] = []
    with open_executor(procs, scheduler, initializer=_init_worker) as pool:
        futs = {pool.submit(run_task, t): t for t in tasks}
        pending = set(futs)
        while pending:
            done, pending = wait(pending, return_when=FIRST_EXCEPTION)
            for f in done:
                exc = f.exception()
                if exc is not None:
                    for p in pending:
                        p.cancel()
                    raise exc
                for r in f.result():
                    results.append(r)
                    if progress is not None:
                        progress(r.frames, r.bytes_in)
    return results


def _run_here(tasks: list[ScanTask], progress: Callable[..., Any] | None) -> list[ScanResult]:
    """Convert in this process, OpenCV limited to one thread meanwhile (``--jobs`` counts the cores).

    The tasks share one writer, so a scan's archive completes while the next recording is read.
    """
    import cv2

    before = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        writer = open_task_writer(tasks[0])
        try:
            results = [r for t in tasks for r in run_task(t, progress, writer)]
            for r in results:
                r.record = writer.scan_record(r.scan_id)
        finally:
            writer.abort(keep_partial=True)  # our writer finishes the dataset
        return results
    finally:
        cv2.setNumThreads(before)


def plan_parallelism(jobs: int, n_tasks: int, threads: int | None = None) -> tuple[int, int]:
    """(worker processes, encoding threads per process) for ``--jobs jobs`` over ``n_tasks`` sources.

    ``jobs`` CPUs are shared out: one process per source up to ``jobs`` (1: convert in this
    process), and the CPUs left per process become image-encoding threads beside its reading thread
    (0 threads: the reading thread encodes). ``jobs`` = -1 means every CPU this process may use.
    """
    if jobs == -1:
        jobs = available_cpus()
    if jobs < 1:
        raise ConversionError(f"jobs: {jobs}, expected a number of CPUs >= 1 or -1 for all")
    procs = max(1, min(jobs, n_tasks))
    per = jobs // procs if threads is None else threads
    return procs, (0 if per <= 1 else per)


def convert(
    input_path: str | Path,
    out: str | Path,
    *,
    config: ConvertConfig | None = None,
    overwrite: bool = False,
    jobs: int = 1,
    threads: int | None = None,
    progress: Callable[..., Any] | None = None,
    scheduler: str | None = None,
) -> ConversionReport:
    """Convert raw recordings into a psg-dataset at ``out``.

    An interrupted conversion (``OUT.partial`` left behind) resumes when rerun with the same input
    and config: scans already complete are verified by checksum and kept.

    Args:
        input_path: a recording, a frame folder, or a directory of them (plus side files).
        out: output dataset directory.
        config: settings (default :class:`ConvertConfig`).
        overwrite: replace ``out`` if it exists (only once the new dataset is complete).
        jobs: CPUs to use (-1: all), see :func:`plan_parallelism`: ``jobs`` = 1 converts on one
            core; more run that many sources in parallel worker processes and give the CPUs left
            over to image-encoding threads. Archive writing and hashing run in two I/O threads
            either way.
        threads: image-encoding threads per process (default: from ``jobs``).
        progress: called as ``progress(n_frames, nbytes)``.
        scheduler: run the sources on Dask distributed instead of local worker processes:
            ``"local"`` (a cluster of ``jobs`` workers here) or ``"tcp://HOST:PORT"``, whose
            workers must see ``input_path`` and ``out``; the dataset is the same byte for byte.

    Returns:
        A :class:`ConversionReport`.

    Raises:
        ConversionError: bad input (one line: file, topic/field, what was expected); nothing is
            left behind.
        DatasetExistsError: ``out`` exists and ``overwrite`` is False.
    """
    if scheduler is not None:
        from psg_data._executors import check_scheduler

        check_scheduler(scheduler)
    return _convert(input_path, out, config, overwrite, jobs, threads, progress, scheduler)


def _convert(input_path: str | Path, out: str | Path, config: ConvertConfig | None, overwrite: bool, jobs: int,
             threads: int | None, progress: Callable[..., Any] | None,
             scheduler: str | None = None) -> ConversionReport:
    t_start = time.perf_counter()
    cfg = config or ConvertConfig()
    src, out = Path(input_path), Path(out)
    inputs = _input_paths(src, cfg)
    check_output(out, overwrite=overwrite, kind="dataset", inputs=inputs)
    sources = plan_sources(src, cfg)
    side, side_dir = _resolve_side(src, cfg)
    color_encoding = _auto_color_encoding(sources[0][0], sources[0][1], cfg)
    tmp = out.with_name(out.name + ".partial")
    state = {"input": str(src.resolve()), "config": cfg.to_dict(), "color_encoding": color_encoding}
    resume = _can_resume(tmp, state)
    writer = _open_writer(out, cfg.name or side.name or (src.stem if src.is_file() else src.name),
                          cfg.timezone or side.timezone or "UTC", color_encoding, overwrite, resume, cfg, inputs,
                          {"operating_hours": side.operating_hours} if side.operating_hours else None)
    report = ConversionReport(output=str(out))
    try:
        (tmp / STATE_DIR).mkdir(exist_ok=True)
        (tmp / STATE_DIR / _STATE_FILE).write_text(json.dumps(state))
        completed = writer.completed_scans() if resume else {}
        tasks = _plan_tasks(sources, side, cfg, str(out), color_encoding, completed)
        procs, worker_threads = plan_parallelism(jobs, len(tasks), threads)
        for t in tasks:
            t.threads, t.image_layout = worker_threads, cfg.image_layout
        if tasks and (procs > 1 or scheduler is not None):
            results = _run_parallel(tasks, procs, progress, scheduler)
        else:
            results = _run_here(tasks, progress) if tasks else []
        by_scan = _adopt_scans(writer, report, results, completed, tmp)
        if not report.scans:
            raise ConversionError(f"{src}: no scan could be converted")
        _set_side_tables(writer, side, side_dir, set(report.scans))
        report.seconds = time.perf_counter() - t_start
        writer.extra["convert"] = {
            "input": str(src), "config": state["config"], "side_files": side.files,
            "report": {"frames": report.frames, "skipped": report.skipped,
                       "keyframe_dropped": report.keyframe_dropped, "passthrough": report.passthrough},
        }
        _record_scan_sources(writer.extra["convert"], report.scans, by_scan)
        shutil.rmtree(tmp / STATE_DIR, ignore_errors=True)
        writer.close()
    except KeyboardInterrupt as exc:
        writer.abort(keep_partial=True)
        exc.resume_hint = f"{tmp} is kept: rerun the same command to resume"  # type: ignore[attr-defined]
        raise
    except OSError as exc:  # disk full, permissions, a file gone mid-run: scans done so far are kept
        writer.abort(keep_partial=True)
        raise ConversionError(f"{out}: conversion stopped: {exc}; fix that and rerun the same command to "
                              f"resume") from exc
    except BaseException:
        writer.abort(keep_partial=False)
        raise
    report.seconds = time.perf_counter() - t_start
    _log_warnings(src, report, by_scan)
    return report


def _record_scan_sources(extra: dict[str, Any], scans: list[str], by_scan: dict[str, ScanResult]) -> None:
    """Per-scan facts an input offers (RTAB-Map: the pose source and ``Node.label``) in the manifest."""
    sources = {s: by_scan[s].pose_source for s in scans if by_scan[s].pose_source}
    labels = {s: by_scan[s].node_labels for s in scans if by_scan[s].node_labels}
    if sources:
        extra["pose_sources"] = sources
    if labels:
        extra["node_labels"] = labels


def _can_resume(tmp: Path, state: dict[str, Any]) -> bool:
    """Whether ``tmp`` holds a partial conversion of the same input with the same config."""
    path = tmp / STATE_DIR / _STATE_FILE
    if not path.is_file():
        return False
    try:
        same = bool(json.loads(path.read_text()) == state)
    except (OSError, json.JSONDecodeError):
        same = False
    if not same:
        log.warning("%s: found a partial conversion with another input or config; starting over", tmp)
    return same


def _open_writer(out: Path, name: str, timezone: str, color_encoding: str, overwrite: bool, resume: bool,
                 cfg: ConvertConfig, inputs: list[Path], extra: dict[str, Any] | None = None) -> DatasetWriter:
    """The writer of the whole dataset (its scans are written by the tasks' writers and adopted); ``extra``:
    the manifest's (the site's operating hours).
    """
    from psg_data.writers import DatasetWriter

    try:
        return DatasetWriter(out, name=name, timezone=timezone, color_encoding=color_encoding, overwrite=overwrite,
                             resume=resume, threads=0, image_layout=cfg.image_layout, inputs=inputs, extra=extra)
    except PsgDataError:
        raise
    except Exception as exc:
        raise ConversionError(f"{out}: cannot create the output ({exc})") from exc


MAX_SCAN_ID_BYTES = 200
"""Longest scan id (UTF-8 bytes) a conversion gives: files inside ``OUT.partial`` are named after it
(``.scans/ID.arrow``, ``images/ID_007.tar`` with a split suffix), and a name takes at most 255 bytes."""


def _plan_tasks(sources: list[tuple[Path, str]], side: SideData, cfg: ConvertConfig, out: str, color_encoding: str,
                completed: dict[str, dict[str, Any]]) -> list[ScanTask]:
    """One task per source not already complete; scan ids from ``scans.csv`` or the source names.

    Raises:
        ConversionError: two sources would get the same scan id.
    """
    scan_rows = side.scan_rows()
    cfg_dict = cfg.to_dict()
    tasks: list[ScanTask] = []
    seen_ids: dict[str, Path] = {}
    for path, kind in sources:
        row = scan_rows.get(path.name) or scan_rows.get(path.stem)
        scan_id = str(row["scan_id"]) if row else path.stem if path.is_file() else path.name
        split_label = (row.get("split") or None) if row else None
        if len(scan_id.encode()) > MAX_SCAN_ID_BYTES:
            raise ConversionError(f"{path}: scan id of {len(scan_id.encode())} bytes (the recording's name); expected "
                                  f"at most {MAX_SCAN_ID_BYTES}, as the scan's files are named after it and a file "
                                  f"name takes at most 255 bytes: rename the recording or give its scan_id in "
                                  f"scans.csv")
        if scan_id in seen_ids:
            raise ConversionError(f"{path}: scan id {scan_id!r} also used by {seen_ids[scan_id]}; expected unique "
                                  f"recording names (or scan ids in scans.csv)")
        seen_ids[scan_id] = path
        if cfg.split is None and scan_id in completed:
            continue
        tasks.append(ScanTask(str(path), kind, scan_id, split_label, cfg_dict, out, color_encoding,
                              dict(side.cameras), sorted(completed)))
    return tasks


def _adopt_scans(writer: DatasetWriter, report: ConversionReport, results: list[ScanResult],
                 completed: dict[str, dict[str, Any]], tmp: Path) -> dict[str, ScanResult]:
    """Adopt the scans written now (their records come with the results, checksummed from memory
    while writing) and those of an interrupted run (verified; their results from the state files),
    giving each distinct camera an id of its own; fills in ``report``. Returns the results by scan.
    """
    import pyarrow as pa

    from psg_data.schemas._records import CameraIntrinsics

    new_ids = {r.scan_id for r in results}
    by_scan: dict[str, ScanResult] = {}
    for f in (tmp / STATE_DIR).glob("*.json"):
        if f.name != _STATE_FILE and f.stem in completed and f.stem not in new_ids:
            by_scan[f.stem] = ScanResult(**json.loads(f.read_text()))
    for r in results:
        by_scan[r.scan_id] = r
        if r.record is not None:
            completed[r.scan_id] = r.record
    cameras: dict[str, dict[str, Any]] = {}
    skipped: Counter[str] = Counter()
    passthrough: Counter[str] = Counter()
    for scan_id, rec in sorted(completed.items()):
        res = by_scan.get(scan_id)
        if res is None:
            continue
        cid = _camera_id(cameras, dict(res.camera))
        if cid not in writer.cameras:
            writer.add_camera(CameraIntrinsics(**cameras[cid]))
        frames = rec["frames"]  # the camera id this dataset gives that camera
        frames = frames.set_column(frames.schema.get_field_index("camera_id"), frames.schema.field("camera_id"),
                                   pa.array([cid] * frames.num_rows, pa.string()))
        writer.adopt_scan({**rec, "frames": frames})
        report.scans.append(scan_id)
        report.frames += frames.num_rows
        if scan_id not in new_ids:
            report.resumed.append(scan_id)
        skipped.update(res.skipped)
        passthrough.update(res.passthrough)
        report.keyframe_dropped += res.keyframe_dropped
        report.bytes_in += res.bytes_in if scan_id in new_ids else 0
    report.skipped = {k: v for k, v in sorted(skipped.items()) if v}
    report.passthrough = dict(passthrough)
    return by_scan


def _camera_id(cameras: dict[str, dict[str, Any]], cam: dict[str, Any]) -> str:
    """The id of camera ``cam`` among ``cameras`` (added there if new): its own id, or ``ID_1``, ``ID_2``, ...
    when another camera already has it.
    """
    cam["distortion_coeffs"] = tuple(cam["distortion_coeffs"])
    cid, k = cam["camera_id"], 1
    while cid in cameras and cameras[cid] != {**cam, "camera_id": cid}:
        cid = f"{cam['camera_id']}_{k}"
        k += 1
    cameras.setdefault(cid, {**cam, "camera_id": cid})
    return cid


def _log_warnings(src: Path, report: ConversionReport, by_scan: dict[str, ScanResult]) -> None:
    """The scans' warnings and the skipped counts, once the conversion is done."""
    for scan_id in report.scans:
        for w in by_scan[scan_id].warnings:
            log.warning("%s", w)
    units = {"color": "colour images", "depth": "depth images", "frames": "frames"}
    for kind, reasons in report.skipped_by_kind.items():
        for reason, n in reasons.items():
            log.warning("%s: %d %s skipped: %s (%s)", src, n, units[kind], reason, SKIP_REASONS[reason])


def _set_side_tables(writer: DatasetWriter, side: SideData, side_dir: Path | None, scan_ids: set[str]) -> None:
    from psg_data.errors import FormatError

    for name in ("rooms", "receptacles", "doors", "openings", "objects", "door_states", "schedule"):
        rows = side.tables.get(name)
        if rows is None:
            continue
        where = side.sources.get(name, str(side_dir))
        for i, r in enumerate(rows):
            sid = r.get("scan_id")
            if sid is not None and str(sid) not in scan_ids:
                raise ConversionError(f"{where}: row {i + 1}: scan_id {sid!r} is not a converted scan; expected one "
                                      f"of {', '.join(sorted(scan_ids)[:5])}{', ...' if len(scan_ids) > 5 else ''}")
        try:
            writer.set_table(name, rows)
        except FormatError as exc:
            raise ConversionError(f"{where}: {exc}") from exc

