"""Ready-made datasets: :func:`demo` builds the default synthetic lab once and caches it."""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

__all__ = ["demo", "cache_dir", "DEMO_VERSION"]

log = logging.getLogger(__name__)

DEMO_VERSION = "synth2-steps-seed0-d21-f8-160x120-fmt2"
"""Cache key of the demo dataset; bumped whenever the generator's output (or its format) changes."""


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
