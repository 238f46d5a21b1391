"""Ready-made datasets: :func:`demo` builds the default synthetic lab once and caches it.

:func:`door_benchmark` and :func:`room_presence_benchmark` read the two public real long-term
benchmarks (the FreMEn line of work's office door and the CASAS Aruba room presence; not shipped
with psg-data: they carry no licence). Their files come from ``$PSG_DATA_SOURCES`` (a folder laid
out as ``greg_door_2016_min/`` and ``aruba_location/``), else from the cache, fetched once from
their public repositories at a pinned commit and checked file by file against a pinned SHA-256
(:data:`REAL_SOURCES`, :func:`psg_data._fetch.ensure_source`).

:data:`BUILTIN` is the one table of built-in dataset names that commands accept where they take a
dataset (``psg-data info demo``, ``psg-eval --dataset persistence-benchmark``); :func:`resolve`
turns a name or a path into a dataset directory, or refuses a name that is not one (saying which
commands accept it). A new built-in dataset is one entry of :data:`BUILTIN`.

:func:`navigation_benchmark` builds the paper's simulation benchmark (15 procedural houses, one
psg-dataset per scene) once into the cache.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["demo", "cache_dir", "DEMO_VERSION", "BuiltinDataset", "BUILTIN", "resolve", "navigation_benchmark",
           "navigation_benchmark_scenes", "NAVIGATION_BENCHMARK_VERSION", "NAVIGATION_BENCHMARK_SCENES",
           "REAL_SOURCES", "real_benchmark_root", "door_benchmark", "room_presence_benchmark", "STATE_BENCHMARKS"]

log = logging.getLogger(__name__)

DEMO_VERSION = "synth2-steps-corridor-seed0-d21-f8d2-160x120-fmt2"
"""Cache key of the demo dataset; bumped whenever the generator's output (or its format) changes."""

NAVIGATION_BENCHMARK_VERSION = "house1-shift0.5-fmt2"
"""Cache key of the navigation benchmark; bumped whenever the house generator's output changes."""

NAVIGATION_BENCHMARK_SCENES = 15
"""Scenes of the navigation benchmark (house seeds 0..14), as the paper's 15 ProcTHOR scenes."""


def cache_dir() -> Path:
    """psg-data's cache directory.

    ``$PSG_DATA_CACHE``, else ``$XDG_CACHE_HOME/psg-data``, else ``~/.cache/psg-data``.
    """
    if os.environ.get("PSG_DATA_CACHE"):
        return Path(os.environ["PSG_DATA_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "psg-data"


def _is_complete(root: Path) -> bool:
    """Manifest readable, checksum of the files table as recorded, every listed file present with its size."""
    from psg_data.errors import FormatError
    from psg_data.schemas._checksum import sha256_file
    from psg_data.schemas._manifest import read_manifest
    from psg_data.schemas._tables import table_path

    try:
        info = read_manifest(root)
        files = root / table_path("files")
        if not files.is_file() or sha256_file(files) != info.files_sha256:
            return False
        import pyarrow.parquet as pq

        t = pq.ParquetFile(files).read().to_pylist()  # one file: read_table's dataset layer (and pandas) not needed
        return all((root / r["path"]).is_file() and (root / r["path"]).stat().st_size == r["size_bytes"] for r in t)
    except (FormatError, OSError, ValueError):
        return False


@contextlib.contextmanager
def _lock(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl
    except ImportError:  # pragma: no cover - non-POSIX
        yield
        return
    with open(path, "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def demo(*, rebuild: bool = False, progress: Callable[..., Any] | None = None) -> Path:
    """Path of the demo dataset: the default synthetic lab (84 scans, 8 frames each, 160x120).

    Built on first use (about 15 s) into :func:`cache_dir` under :data:`DEMO_VERSION`; rebuilt if
    the cached copy is incomplete or corrupted (manifest, files-table checksum, file sizes).

    Args:
        rebuild: rebuild even if a valid copy is cached.
        progress: called as ``progress(1)`` per scan built (only when it is built).
    """
    root = cache_dir() / f"demo-{DEMO_VERSION}"
    with _lock(cache_dir() / f".demo-{DEMO_VERSION}.lock"):
        if rebuild or not _is_complete(root):
            from psg_data.synth import LabConfig, build_lab

            log.info("building the demo dataset into %s", root)
            build_lab(root, LabConfig(), overwrite=True, progress=progress)
    return root


def navigation_benchmark(*, rebuild: bool = False, progress: Callable[..., Any] | None = None,
                         scenes: int = NAVIGATION_BENCHMARK_SCENES, shift: float | None = None,
                         which: Sequence[int] | None = None) -> Path:
    """Folder of the navigation benchmark: ``scene_00`` ... ``scene_14``, one psg-dataset per house.

    Each scene is :func:`psg_data.synth.build_house` of ``HouseConfig(seed=k)`` (5-8 rooms, 100-150
    m2 navigable, 4 weeks of hourly steps: weeks 1-2 train, week 3 validation, week 4 test with the
    default test-time shift; no images) labelled with the ``privileged`` source (the hourly
    patrol's line of sight; ``gt`` needs no labels). Built on first use into :func:`cache_dir`
    under :data:`NAVIGATION_BENCHMARK_VERSION`; a scene whose cached copy is incomplete is rebuilt.

    Args:
        rebuild: rebuild every scene even if a valid copy is cached.
        progress: called as ``progress(1)`` per scene built.
        scenes: number of scenes (house seeds 0..scenes-1).
        shift: the test-time shift knob (None: the default, 0.5; 0: no shift, the test week follows the
            training dynamics, as the predictive navigation protocol needs); its own cache folder.
        which: build only these house seeds (default ``range(scenes)``).
    """
    version = _benchmark_version(shift)
    root = cache_dir() / f"navigation-benchmark-{version}"
    with _lock(cache_dir() / f".navigation-benchmark-{version}.lock"):
        for k in (range(scenes) if which is None else which):
            scene = root / f"scene_{k:02d}"
            if rebuild or not _is_complete(scene) or not _has_labels(scene):
                from psg_data.labeling import label_dataset
                from psg_data.synth import build_house

                log.info("building navigation-benchmark scene %d into %s", k, scene)
                build_house(scene, _house_config(k, shift), overwrite=True)
                label_dataset(scene, "privileged")
            if progress is not None:
                progress(1)
    return root


def navigation_benchmark_scenes(root: Path | None = None, scenes: int = NAVIGATION_BENCHMARK_SCENES, *,
                                shift: float | None = None) -> list[Path]:
    """The scene folders of the navigation benchmark (built if needed), in seed order."""
    root = root or navigation_benchmark(scenes=scenes, shift=shift)
    return [root / f"scene_{k:02d}" for k in range(scenes)]


def _benchmark_version(shift: float | None) -> str:
    """Cache key of the benchmark at a shift knob (the default keeps :data:`NAVIGATION_BENCHMARK_VERSION`)."""
    if shift is None:
        return NAVIGATION_BENCHMARK_VERSION
    return NAVIGATION_BENCHMARK_VERSION.replace("-shift0.5-", f"-shift{float(shift):g}-")


def _house_config(seed: int, shift: float | None) -> Any:
    from psg_data.synth import HouseConfig
    from psg_data.synth._house_process import HouseProcessParams

    if shift is None:
        return HouseConfig(seed=seed)
    return HouseConfig(seed=seed, schedules=HouseProcessParams(shift=float(shift)))


def _has_labels(root: Path) -> bool:
    return (root / "tables" / "labels.parquet").is_file()


@dataclass(frozen=True)
class BuiltinDataset:
    """A dataset name every command that takes a dataset knows.

    Attributes:
        name: what the user types (``demo``).
        description: one line, for listings and refusals.
        build: returns the dataset directory, building and caching it on first use (called as
            ``build(progress=...)``); None for a built-in that is not a dataset directory
            (observation streams drawn in memory), which only ``accepted_by`` reads.
        accepted_by: the commands that take the name, in words (shown when another refuses it).
        scans: scans a build makes (progress total); 0 when unknown or not built.
    """

    name: str
    description: str
    build: Callable[..., Path] | None
    accepted_by: str
    scans: int = 0


BUILTIN: dict[str, BuiltinDataset] = {
    "demo": BuiltinDataset(
        "demo", "the built-in synthetic lab (3 rooms, 2 doors, 28 receptacles, 21 objects, 84 RGB-D scans; built "
        "once into the cache)", demo, "every command that takes a dataset", scans=84),
    "persistence-benchmark": BuiltinDataset(
        "persistence-benchmark", "the paper's Sec. V-A simulation benchmark: observation streams drawn in memory, "
        "no dataset directory", None, "psg-eval --dataset persistence-benchmark (the persistence task)"),
    "navigation-benchmark": BuiltinDataset(
        "navigation-benchmark", "the paper's simulation benchmark: 15 procedural houses, one dataset per scene "
        "(navigation_benchmark_scenes), built once into the cache", None,
        "psg-eval --dataset navigation-benchmark (the persistence task over its scenes; --task navigation with "
        "--protocol paper-sim-predictive or paper-sim-adaptive)",
        scans=NAVIGATION_BENCHMARK_SCENES),
    "door-benchmark": BuiltinDataset(
        "door-benchmark", "a real office door, one state per minute, 10 training and 9 test weeks (the FreMEn "
        "authors' benchmark; fetched by pinned checksum, or read from $PSG_DATA_SOURCES)", None,
        "psg-eval --dataset door-benchmark (the persistence task; --protocol patrol or published)"),
    "room-presence-benchmark": BuiltinDataset(
        "room-presence-benchmark", "a real smart home (CASAS Aruba): the resident's room per minute, 16 weeks, ten "
        "rooms (fetched by pinned checksum, or read from $PSG_DATA_SOURCES)", None,
        "psg-eval --dataset room-presence-benchmark (the persistence task and locate; --protocol patrol or "
        "published)"),
}
"""The built-in dataset names (name -> :class:`BuiltinDataset`)."""


def resolve(dataset: str | os.PathLike[str], *, command: str = "this command",
            progress: Callable[..., Any] | None = None) -> Path:
    """The dataset directory of a path or a built-in name (:data:`BUILTIN`; a directory of that name wins).

    Args:
        dataset: a dataset directory, or a built-in name such as ``demo`` (built on first use).
        command: the command asking, named in a refusal (``psg-data info``).
        progress: passed to the built-in's ``build`` (called per scan built, only when it is built).

    Returns:
        The directory (not checked further: :func:`psg_data.open_dataset` reads it).

    Raises:
        PsgDataError: a built-in name that is not a dataset directory, naming the commands that take it.
    """
    path = Path(dataset)
    entry = BUILTIN.get(str(dataset))
    if entry is None or path.is_dir():
        return path
    if entry.build is None:
        from psg_data.errors import PsgDataError

        raise PsgDataError(f"{entry.name}: {entry.description}; {command} reads a dataset directory (a path, or "
                           f"{_directory_names()}); {entry.name} is read by {entry.accepted_by}")
    return entry.build(progress=progress)


# -- the public real benchmarks ------------------------------------------------------------------------
_FRAMEWORK2 = "682ac32cf2cb7f53b4e02f0d57e64a88c20a4d08"
_ACTIVITY = "99f110d96633956a0c5cb29d83fe26079e431233"
_DOOR_SHA256 = {
    "training_data.txt": "8be478daea3bfaac7f3b3af3d94dcc80206fb0b996ad0ca53bed8030e04bacca",
    "test_all_1.txt": "a092b847b7ac6b17dadd167a9715fed5110ebc2fe866087a1c2e47f4cdbafc72",
    "test_all_2.txt": "f495bc3f004a584fe6f23782fa69a092c50ab3713cb49854b869cdae7b48b344",
    "test_all_3.txt": "b2b678b4f399bdbdb68ba2138ded419a45c1ba86826cd8073bddb3fa3d9d8d70",
    "test_all_4.txt": "15c045662ad619525d204cbb9ac704616ae426a3f59b73069e8cde89d7af3032",
    "test_all_5.txt": "9c540630865f9389e104363a5ead1c423e82e9585df5d0c1e7fc6cee8f26bb35",
    "test_all_6.txt": "ee9441a99b895b3cd1fb23892a3497dbc41eda4e09aee00d7b0b8970f8b9e8da",
    "test_all_7.txt": "fca510afb8cb7a6a9e94ddf99a624468bf19cc99da1e00175ad816515968f6f4",
    "test_all_8.txt": "ef0ebc84f23231a78237fe3881d843b0f0c1f5013992f7a687e7aa2871031863",
    "test_all_9.txt": "8def67bb2273aa74091e48db129b55f9f0b497a2ba78db3c1965e790ad61250f",
}
_ROOM_SHA256 = {
    "location.min": "aaccf6fa512651e4b20998cee0eff876ae73aa1b32b4624d10442eb65917b3c2",
    "location.names": "4a0cbc239c3312499ca65ec9dff558005104fd1e216456a957c530c768377f85",
}


def _real_sources() -> dict[str, Any]:
    from psg_data._fetch import RemoteFile, RemoteSource

    gh = "https://raw.githubusercontent.com"
    door = RemoteSource(
        "door-benchmark", f"{gh}/chronorobotics/framework2/{_FRAMEWORK2}/",
        tuple(RemoteFile(f"greg_door_2016_min/{n}", f"greg_door_2016_min/{n}", h) for n, h in _DOOR_SHA256.items()),
        f"GitHub chronorobotics/framework2 at commit {_FRAMEWORK2}, folder greg_door_2016_min/")
    room = RemoteSource(
        "room-presence-benchmark", f"{gh}/gestom/fremen_activity_benchmark/{_ACTIVITY}/",
        tuple(RemoteFile(f"aruba_location/{n}", f"data/aruba/{n}", h) for n, h in _ROOM_SHA256.items()),
        f"GitHub gestom/fremen_activity_benchmark at commit {_ACTIVITY}, folder data/aruba/ (saved as aruba_location/)")
    return {"door-benchmark": door, "room-presence-benchmark": room}


REAL_SOURCES = ("door-benchmark", "room-presence-benchmark")
"""The built-in real benchmarks whose files are fetched (pins: ``_real_sources``)."""


def real_benchmark_root(name: str, *, progress: Callable[[int], None] | None = None) -> Path:
    """Folder holding the benchmark's files as published, checked against their pinned SHA-256.

    ``$PSG_DATA_SOURCES`` (a folder laid out as ``greg_door_2016_min/`` and ``aruba_location/``) is
    read in place; otherwise the files are fetched once into ``cache_dir()/sources/NAME``.

    Raises:
        PsgDataError: a file missing or not as pinned, or no network (one line saying where to get them).
    """
    from psg_data._fetch import ensure_source

    return ensure_source(_real_sources()[name], cache_dir() / "sources", progress=progress)


def door_benchmark(*, state_one: str = "open", stamps: str = "wall-clock", progress: Callable[[int], None] | None = None
                   ) -> Any:
    """The door benchmark (:func:`psg_data.loaders.raw.read_door_benchmark`) from its pinned files."""
    from psg_data.loaders.raw import read_door_benchmark

    return read_door_benchmark(real_benchmark_root("door-benchmark", progress=progress), state_one=state_one,
                               stamps=stamps)


def room_presence_benchmark(*, start: str = "2010-11-04", train_weeks: int = 8,
                            progress: Callable[[int], None] | None = None) -> Any:
    """The room-presence benchmark (:func:`psg_data.loaders.raw.read_room_presence_benchmark`) from its pinned files."""
    from psg_data.loaders.raw import read_room_presence_benchmark

    return read_room_presence_benchmark(real_benchmark_root("room-presence-benchmark", progress=progress),
                                        start=start, train_weeks=train_weeks)


STATE_BENCHMARKS: dict[str, Callable[..., Any]] = {"door-benchmark": door_benchmark,
                                                   "room-presence-benchmark": room_presence_benchmark}
"""Real benchmark name -> its reader (settings as keyword arguments, e.g. ``door-benchmark:stamps=utc``)."""


def _directory_names() -> str:
    return " or ".join(n for n, e in BUILTIN.items() if e.build is not None)
