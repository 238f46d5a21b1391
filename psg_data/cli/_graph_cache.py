"""The fitted graphs of ``psg-data graph DATASET``, cached: a second call with the same inputs loads the fit.

A fit is saved (the saved-graph format of :mod:`psg_data.graph._store`) under
``<cache_dir>/graph-fits/<key>.json``, the key a SHA-256 of everything that changes it: the dataset's
manifest and table files (contents), the label source (and the contents of a ``detections:FILE``),
the label seed, the estimator with its settings, and the psg-data version. A cached file that no
longer loads is refitted and replaced; a graph that cannot be saved (e.g. ``process_oracle``) is
fitted every time.
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path
from typing import Any

__all__ = ["fit_cache_key", "cached_fit"]

log = logging.getLogger(__name__)


def _hash_file(h: Any, path: Path) -> None:
    h.update(path.name.encode() + b"\0")
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)


def fit_cache_key(root: Path, estimator: str, labels: str, *, label_seed: int = 0) -> str:
    """Hex SHA-256 of the inputs of a graph fit (module docstring)."""
    from psg_data import __version__

    h = hashlib.sha256()
    for part in (f"psg-data {__version__}", f"estimator {estimator}", f"labels {labels}", f"label seed {label_seed}"):
        h.update(part.encode() + b"\0")
    _hash_file(h, root / "dataset.json")
    for p in sorted((root / "tables").glob("*")):
        if p.is_file():
            _hash_file(h, p)
    if labels.startswith("detections:"):
        det = Path(labels.split(":", 1)[1])
        if det.is_file():
            _hash_file(h, det)
    return h.hexdigest()


def cached_fit(root: Path, estimator: str, labels: str) -> Any:
    """``PredictiveGraph.from_dataset(root, estimator, labels=labels)``, loaded from the cache when fitted before."""
    from psg_data.datasets import cache_dir
    from psg_data.errors import PsgDataError
    from psg_data.graph import PredictiveGraph

    path = cache_dir() / "graph-fits" / f"{fit_cache_key(root, estimator, labels)}.json"
    if path.is_file():
        try:
            return PredictiveGraph.load(path)
        except PsgDataError as e:  # damaged or from a build that cannot read it: refit
            log.info("graph cache %s not used (%s); refitting", path, e)
    g = PredictiveGraph.from_dataset(root, estimator, labels=labels)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        g.save(path)
    except (PsgDataError, OSError) as e:  # not saveable (process_oracle) or a read-only cache: no cache
        log.info("graph fit not cached (%s)", e)
    return g
