"""Reading per-scan detections (scene-graph nodes) from Parquet or JSON, with checks.

Layout (one row per detected node; extra columns such as ``frame_index``, ``pixels`` or ``gt_id``
are allowed and ignored):

==============  ===================  ==========================================================
column          type                 meaning
==============  ===================  ==========================================================
scan_id         string               scan of the dataset
label           string               object: its object_id (or object name); receptacle: any text
kind            string               'object' or 'receptacle'
centroid_m      list<double>[3]      centroid of the node's points, world frame, metres
box_center_m    list<double>[3]      oriented box centre, world frame, metres
box_extent_m    list<double>[3]      box side lengths, metres, > 0
box_rotation    list<double>[9]      row-major world-from-box rotation (orthonormal, det +1)
score           double               confidence in [0, 1]
==============  ===================  ==========================================================

JSON: a list of such records, or ``{"detections": [...]}``.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import LabelingError
from psg_data.schemas._records import Box

__all__ = ["Detections", "read_detections", "DETECTION_COLUMNS"]

log = logging.getLogger(__name__)

DETECTION_COLUMNS = ("scan_id", "label", "kind", "centroid_m", "box_center_m", "box_extent_m", "box_rotation", "score")
_ROT_TOL = 1e-3


@dataclass
class Detections:
    """Checked detections (arrays of equal length N).

    Attributes:
        path: file they were read from.
        scan_id, label, kind: (N,) strings.
        centroid_m, box_center_m, box_extent_m: (N, 3) world frame, metres.
        box_rotation: (N, 3, 3) world-from-box rotations.
        score: (N,) confidences.
        row: (N,) row of each detection in the file (0-based).
        stated_on: (N,) for ``relations: stated`` scene graphs, the ``row`` of the receptacle detection a
            stated relation puts each object on (-1: none); None: associate geometrically.
    """

    path: str
    scan_id: NDArray[np.str_]
    label: NDArray[np.str_]
    kind: NDArray[np.str_]
    centroid_m: NDArray[np.float64]
    box_center_m: NDArray[np.float64]
    box_extent_m: NDArray[np.float64]
    box_rotation: NDArray[np.float64]
    score: NDArray[np.float64]
    row: NDArray[np.int64]
    stated_on: NDArray[np.int64] | None = None

    def __len__(self) -> int:
        return int(self.row.size)

    def box(self, i: int) -> Box:
        """Detection ``i``'s box (world frame, metres)."""
        return Box(self.box_center_m[i], self.box_extent_m[i], self.box_rotation[i])

    def subset(self, mask: NDArray[np.bool_]) -> Detections:
        """The detections where ``mask`` is True."""
        return Detections(self.path, self.scan_id[mask], self.label[mask], self.kind[mask], self.centroid_m[mask],
                          self.box_center_m[mask], self.box_extent_m[mask], self.box_rotation[mask], self.score[mask],
                          self.row[mask], None if self.stated_on is None else self.stated_on[mask])


def _load_columns(path: Path) -> dict[str, list[Any]]:
    suffix = path.suffix.lower()
    if suffix == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            t = pq.read_table(path)
        except (OSError, pa.ArrowException) as exc:
            raise LabelingError(f"{path}: not a readable Parquet file ({str(exc).splitlines()[0][:120]})") from exc
        missing = [c for c in DETECTION_COLUMNS if c not in t.column_names]
        if missing:
            raise LabelingError(f"{path}: missing columns {missing}, expected {list(DETECTION_COLUMNS)}")
        return {c: t.column(c).to_pylist() for c in DETECTION_COLUMNS}
    if suffix == ".json":
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise LabelingError(f"{path}: not valid JSON ({exc})") from exc
        if isinstance(data, dict) and "detections" in data:
            data = data["detections"]
        if not isinstance(data, list):
            raise LabelingError(f"{path}: expected a JSON list of detections or {{\"detections\": [...]}}, "
                                f"got {type(data).__name__}")
        cols: dict[str, list[Any]] = {c: [] for c in DETECTION_COLUMNS}
        for i, rec in enumerate(data):
            if not isinstance(rec, dict):
                raise LabelingError(f"{path}:{i}: expected a JSON object per detection, got {type(rec).__name__}")
            for c in DETECTION_COLUMNS:
                if c not in rec:
                    raise LabelingError(f"{path}:{i}: {c}: missing, expected fields {list(DETECTION_COLUMNS)}")
                cols[c].append(rec[c])
        return cols
    raise LabelingError(f"{path}: unknown detections file type {suffix or '(none)'!r}, expected .parquet or .json")


def _vectors(path: Path, name: str, values: list[Any], n: int) -> NDArray[np.float64]:
    out = np.full((len(values), n), np.nan)
    for i, v in enumerate(values):
        try:
            a = np.asarray(v if v is not None else [], dtype=float).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise LabelingError(f"{path}:{i}: {name}: {v!r} is not numeric, expected {n} numbers") from exc
        if a.size != n:
            raise LabelingError(f"{path}:{i}: {name}: {a.size} values, expected {n}")
        out[i] = a
    return out


def read_detections(path: str | Path, *, scan_ids: list[str] | None = None, min_score: float = 0.0) -> Detections:
    """Read and check a detections file (layout in the module docstring).

    Args:
        path: ``.parquet`` or ``.json`` file.
        scan_ids: scans of the dataset; a detection of any other scan is an error.
        min_score: detections with a lower score are dropped (after the checks).

    Raises:
        LabelingError: one line ``FILE:ROW: FIELD: problem, expectation`` for the first problem found
            (missing file or column, empty file, unknown scan, unknown kind, non-finite centroid or
            box, box with zero volume, rotation not a proper rotation, score outside [0, 1]).
    """
    p = Path(path)
    if not p.is_file():
        raise LabelingError(f"{p}: detections file not found")
    cols = _load_columns(p)
    n = len(cols["scan_id"])
    if n == 0:
        raise LabelingError(f"{p}: no detections (0 rows), expected at least one detection")
    known = set(scan_ids) if scan_ids is not None else None
    for name in ("scan_id", "label", "kind"):
        for i, v in enumerate(cols[name]):
            if not isinstance(v, str) or not v:
                raise LabelingError(f"{p}:{i}: {name}: {v!r}, expected a non-empty string")
    for i, (s, k) in enumerate(zip(cols["scan_id"], cols["kind"])):
        if known is not None and s not in known:
            raise LabelingError(f"{p}:{i}: scan_id: unknown scan {s!r}, expected a scan_id of tables/scans.parquet")
        if k not in ("object", "receptacle"):
            raise LabelingError(f"{p}:{i}: kind: {k!r}, expected 'object' or 'receptacle'")
    cen = _vectors(p, "centroid_m", cols["centroid_m"], 3)
    bc = _vectors(p, "box_center_m", cols["box_center_m"], 3)
    be = _vectors(p, "box_extent_m", cols["box_extent_m"], 3)
    br = _vectors(p, "box_rotation", cols["box_rotation"], 9).reshape(-1, 3, 3)
    for name, a in (("centroid_m", cen), ("box_center_m", bc)):
        bad = np.flatnonzero(~np.all(np.isfinite(a), axis=1))
        if bad.size:
            i = int(bad[0])
            raise LabelingError(f"{p}:{i}: {name}: {a[i].tolist()}, expected 3 finite coordinates (metres)")
    bad = np.flatnonzero(~np.all(np.isfinite(be) & (be > 0), axis=1))
    if bad.size:
        i = int(bad[0])
        raise LabelingError(f"{p}:{i}: box_extent_m: {be[i].tolist()}, expected 3 positive finite side lengths "
                            "(a box with non-zero volume)")
    fin = np.all(np.isfinite(br), axis=(1, 2))
    err = np.full(n, np.inf)
    det = np.zeros(n)
    if fin.any():
        m = br[fin]
        err[fin] = np.abs(np.einsum("nji,njk->nik", m, m) - np.eye(3)).max(axis=(1, 2))
        det[fin] = np.linalg.det(m)
    bad = np.flatnonzero((err > _ROT_TOL) | (det <= 0))
    if bad.size:
        i = int(bad[0])
        raise LabelingError(f"{p}:{i}: box_rotation: not a proper rotation (max |R^T R - I| = {err[i]:.3g}, "
                            f"det = {det[i]:.3g}), expected an orthonormal 3x3 matrix with det +1, row-major")
    score = np.array([np.nan if v is None else v for v in cols["score"]], dtype=float)
    bad = np.flatnonzero(~(np.isfinite(score) & (score >= 0) & (score <= 1)))
    if bad.size:
        i = int(bad[0])
        raise LabelingError(f"{p}:{i}: score: {score[i]}, expected a number in [0, 1]")
    det_ = Detections(str(p), np.asarray(cols["scan_id"], dtype=object), np.asarray(cols["label"], dtype=object),
                      np.asarray(cols["kind"], dtype=object), cen, bc, be, br, score, np.arange(n))
    if min_score > 0:
        det_ = det_.subset(score >= min_score)
        log.info("%s: kept %d of %d detections with score >= %g", p, len(det_), n, min_score)
    return det_
