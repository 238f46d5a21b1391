"""Ready-made datasets, built once and cached: :func:`demo` (the default synthetic lab) and
:func:`navigation_benchmark` (15 procedural houses, the paper's simulation benchmark).

:data:`BUILTIN` maps every built-in name to its builder (one entry per dataset).
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

__all__ = ["demo", "cache_dir", "DEMO_VERSION", "navigation_benchmark", "NAVIGATION_BENCHMARK_VERSION",
           "NAVIGATION_BENCHMARK_SCENES", "BUILTIN"]

log = logging.getLogger(__name__)

DEMO_VERSION = "synth2-steps-seed0-d21-f8-160x120-fmt2"
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

        t = pq.read_table(files).to_pylist()
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
                         scenes: int = NAVIGATION_BENCHMARK_SCENES) -> Path:
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
    """
    root = cache_dir() / f"navigation-benchmark-{NAVIGATION_BENCHMARK_VERSION}"
    with _lock(cache_dir() / f".navigation-benchmark-{NAVIGATION_BENCHMARK_VERSION}.lock"):
        for k in range(scenes):
            scene = root / f"scene_{k:02d}"
            if rebuild or not _is_complete(scene) or not _has_labels(scene):
                from psg_data.labeling import label_dataset
                from psg_data.synth import HouseConfig, build_house

                log.info("building navigation-benchmark scene %d into %s", k, scene)
                build_house(scene, HouseConfig(seed=k), overwrite=True)
                label_dataset(scene, "privileged")
            if progress is not None:
                progress(1)
    return root


def navigation_benchmark_scenes(root: Path | None = None, scenes: int = NAVIGATION_BENCHMARK_SCENES) -> list[Path]:
    """The scene folders of the navigation benchmark (built if needed), in seed order."""
    root = root or navigation_benchmark(scenes=scenes)
    return [root / f"scene_{k:02d}" for k in range(scenes)]


def _has_labels(root: Path) -> bool:
    return (root / "tables" / "labels.parquet").is_file()


BUILTIN: dict[str, Callable[..., Path]] = {"demo": demo, "navigation-benchmark": navigation_benchmark}
"""Built-in dataset name -> builder returning its path (built once into the cache)."""
