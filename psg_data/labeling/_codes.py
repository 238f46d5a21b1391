"""Dense label grids: ground truth, privileged codes, noise injection and error-rate estimates.

A :class:`LabelGrid` holds one code per (scan, object, receptacle):

* ``1`` present: the object is on the receptacle and was seen (privileged: ground truth present
  and the object visible);
* ``0`` absent: the object is not on the receptacle and the receptacle was seen;
* ``-1`` missing: no observation - the receptacle was not seen, or the object is on it but was not
  seen (ground truth present, object not visible, receptacle visible: the presence cannot be
  confirmed and an absence would be wrong, so nothing is observed), or the schedule has no row for
  the object in that scan;
* ``-2`` invalid: the receptacle is not a valid location of the object (not an edge).

Priority follows the paper's equation (appendix "Relationship Between Groundtruth and Privileged
Data"): -2 first, then 1, then 0, else -1. Valid sets are by default the schedule's support (the
receptacles the object occupies in at least one scan), or a user-given mapping.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import LabelingError
from psg_data.schemas._tables import CODE_ABSENT, CODE_INVALID, CODE_MISSING, CODE_PRESENT

__all__ = ["LabelGrid", "ground_truth", "schedule_support", "valid_mask", "privileged_codes", "inject_noise",
           "ErrorRates", "error_rates", "binomial_interval"]

log = logging.getLogger(__name__)


@dataclass
class LabelGrid:
    """Codes of every (scan, object, receptacle) for one label source.

    Attributes:
        scan_ids: (S,) scans, chronological.
        object_ids: (O,) objects.
        receptacle_ids: (R,) receptacles.
        stamps_ns: (S,) observation time of each scan, int64 UTC nanoseconds.
        codes: (S, O, R) int8 codes (1, 0, -1, -2).
        source: source name stored in the ``source`` column.
        meta: provenance (parameters, seed) of the source.
    """

    scan_ids: list[str]
    object_ids: list[str]
    receptacle_ids: list[str]
    stamps_ns: NDArray[np.int64]
    codes: NDArray[np.int8]
    source: str
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        shape = (len(self.scan_ids), len(self.object_ids), len(self.receptacle_ids))
        self.codes = np.asarray(self.codes, np.int8)
        self.stamps_ns = np.asarray(self.stamps_ns, np.int64)
        if self.codes.shape != shape:
            raise LabelingError(f"label grid {self.source!r}: codes have shape {self.codes.shape}, expected {shape}")
        if self.stamps_ns.shape != (shape[0],):
            raise LabelingError(f"label grid {self.source!r}: {self.stamps_ns.size} stamps for {shape[0]} scans")

    @property
    def valid(self) -> NDArray[np.bool_]:
        """(O, R) pairs that are edges (some scan has a code other than -2)."""
        return np.any(self.codes != CODE_INVALID, axis=0)

    @property
    def observed(self) -> NDArray[np.bool_]:
        """(S, O, R) codes 1 or 0."""
        return (self.codes == CODE_PRESENT) | (self.codes == CODE_ABSENT)

    def code_counts(self) -> dict[int, int]:
        """Cells per code (1, 0, -1, -2), zeros included."""
        vals, n = np.unique(self.codes, return_counts=True)
        out = {c: 0 for c in (CODE_PRESENT, CODE_ABSENT, CODE_MISSING, CODE_INVALID)}
        out.update({int(v): int(k) for v, k in zip(vals, n)})
        return out

    def with_codes(self, codes: NDArray[np.int8], source: str, meta: dict[str, Any] | None = None) -> LabelGrid:
        """The same grid (scans, objects, receptacles, stamps) with other codes."""
        return LabelGrid(list(self.scan_ids), list(self.object_ids), list(self.receptacle_ids), self.stamps_ns.copy(),
                         codes, source, dict(meta or {}))

    def aligned(self, other: LabelGrid) -> NDArray[np.int8]:
        """``other``'s codes on this grid's axes (-1 where ``other`` has no entry)."""
        out = np.full(self.codes.shape, CODE_MISSING, np.int8)
        si = [other.scan_ids.index(s) if s in other.scan_ids else -1 for s in self.scan_ids]
        oi = [other.object_ids.index(o) if o in other.object_ids else -1 for o in self.object_ids]
        ri = [other.receptacle_ids.index(r) if r in other.receptacle_ids else -1 for r in self.receptacle_ids]
        s_ok, o_ok, r_ok = (np.array(x) >= 0 for x in (si, oi, ri))
        if s_ok.any() and o_ok.any() and r_ok.any():
            sub = other.codes[np.ix_(np.array(si)[s_ok], np.array(oi)[o_ok], np.array(ri)[r_ok])]
            out[np.ix_(s_ok, o_ok, r_ok)] = sub
        return out

    def to_table(self) -> Any:
        """Arrow table with the ``labels`` schema (one row per scan, object, receptacle)."""
        import pyarrow as pa

        from psg_data.schemas._tables import TABLES

        S, O, R = self.codes.shape
        s_idx, o_idx, r_idx = (a.ravel() for a in np.meshgrid(np.arange(S), np.arange(O), np.arange(R), indexing="ij"))
        cols = {
            "scan_id": pa.array(np.asarray(self.scan_ids, dtype=object)[s_idx] if S else [], pa.string()),
            "object_id": pa.array(np.asarray(self.object_ids, dtype=object)[o_idx] if O else [], pa.string()),
            "receptacle_id": pa.array(np.asarray(self.receptacle_ids, dtype=object)[r_idx] if R else [], pa.string()),
            "stamp_ns": pa.array(self.stamps_ns[s_idx], pa.int64()),
            "code": pa.array(self.codes.ravel(), pa.int8()),
            "source": pa.array([self.source] * (S * O * R), pa.string()),
        }
        return pa.Table.from_pydict(cols, schema=TABLES["labels"].schema)

    @staticmethod
    def from_table(table: Any, source: str) -> LabelGrid:
        """The grid of ``source`` in a ``labels`` table (axes in first-appearance order)."""
        import pyarrow.compute as pc

        t = table.filter(pc.equal(table.column("source"), source))
        if t.num_rows == 0:
            have = sorted(set(table.column("source").to_pylist()))
            raise LabelingError(f"labels: no rows of source {source!r}; sources present: {have or 'none'}")
        d = t.to_pydict()
        scans = list(dict.fromkeys(d["scan_id"]))
        objs = list(dict.fromkeys(d["object_id"]))
        recs = list(dict.fromkeys(d["receptacle_id"]))
        si = {s: i for i, s in enumerate(scans)}
        oi = {o: i for i, o in enumerate(objs)}
        ri = {r: i for i, r in enumerate(recs)}
        codes = np.full((len(scans), len(objs), len(recs)), CODE_MISSING, np.int8)
        stamps = np.zeros(len(scans), np.int64)
        s_ix = np.fromiter((si[s] for s in d["scan_id"]), np.int64, t.num_rows)
        o_ix = np.fromiter((oi[o] for o in d["object_id"]), np.int64, t.num_rows)
        r_ix = np.fromiter((ri[r] for r in d["receptacle_id"]), np.int64, t.num_rows)
        codes[s_ix, o_ix, r_ix] = np.asarray(d["code"], np.int8)
        stamps[s_ix] = np.asarray(d["stamp_ns"], np.int64)
        order = np.argsort(stamps, kind="stable")
        return LabelGrid([scans[i] for i in order], objs, recs, stamps[order], codes[order], source)


# -- ground truth -------------------------------------------------------------------------------
def _axes(ds: Any) -> tuple[list[str], list[str], list[str], NDArray[np.int64]]:
    scan_ids = list(ds.scan_ids)
    start = {s: ds.scan(s).start_stamp_ns for s in scan_ids}
    return scan_ids, list(ds.objects), list(ds.receptacles), np.array([start[s] for s in scan_ids], np.int64)


def _schedule(ds: Any) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """(S, O, R) presence and (S, O) known (schedule row exists) from the dataset's schedule."""
    scan_ids, obj_ids, rec_ids, _ = _axes(ds)
    present = np.zeros((len(scan_ids), len(obj_ids), len(rec_ids)), bool)
    known = np.zeros((len(scan_ids), len(obj_ids)), bool)
    if not ds.has_table("schedule"):
        raise LabelingError(f"{ds.root}/tables/schedule.parquet: missing; ground-truth sources need the schedule")
    d = ds.table("schedule").to_pydict()
    if not d["scan_id"]:
        raise LabelingError(f"{ds.root}/tables/schedule.parquet: empty; ground-truth sources (gt, privileged, noisy) "
                            "need a schedule row per scan and object")
    si = {s: i for i, s in enumerate(scan_ids)}
    oi = {o: i for i, o in enumerate(obj_ids)}
    ri = {r: i for i, r in enumerate(rec_ids)}
    for s, o, r in zip(d["scan_id"], d["object_id"], d["receptacle_id"]):
        if s not in si or o not in oi:
            continue  # dangling ids are the validator's business
        known[si[s], oi[o]] = True
        if r is not None and r in ri:
            present[si[s], oi[o], ri[r]] = True
    n_unknown = int((~known).sum())
    if n_unknown:
        log.warning("schedule has no row for %d (scan, object) pairs; their codes are -1", n_unknown)
    return present, known


def schedule_support(ds: Any) -> NDArray[np.bool_]:
    """(O, R) pairs where the object is on the receptacle in at least one scan of the schedule."""
    present, _ = _schedule(ds)
    return np.asarray(present.any(axis=0), dtype=bool)


def valid_mask(ds: Any, valid: Mapping[str, Sequence[str]] | None = None) -> NDArray[np.bool_]:
    """(O, R) valid (object, receptacle) pairs: ``valid`` (object_id -> receptacle ids) or the schedule support.

    Objects missing from ``valid`` have no valid receptacle.

    Raises:
        LabelingError: ``valid`` names an unknown object or receptacle.
    """
    if valid is None:
        return schedule_support(ds)
    obj_ids, rec_ids = list(ds.objects), list(ds.receptacles)
    out = np.zeros((len(obj_ids), len(rec_ids)), bool)
    for o, recs in valid.items():
        if o not in ds.objects:
            raise LabelingError(f"valid receptacles: unknown object {o!r}, expected an object_id of "
                                f"tables/objects.parquet")
        for r in recs:
            if r not in ds.receptacles:
                raise LabelingError(f"valid receptacles: object {o!r}: unknown receptacle {r!r}, expected a "
                                    "receptacle_id of tables/receptacles.parquet")
            out[obj_ids.index(o), rec_ids.index(r)] = True
    return out


def ground_truth(ds: Any, valid: Mapping[str, Sequence[str]] | None = None) -> LabelGrid:
    """Ground-truth codes: 1 where the schedule puts the object, 0 elsewhere on valid pairs, -2 on invalid.

    Scans whose schedule row for an object is missing get -1 for that object.
    """
    scan_ids, obj_ids, rec_ids, stamps = _axes(ds)
    present, known = _schedule(ds)
    v = valid_mask(ds, valid)
    codes = np.full(present.shape, CODE_MISSING, np.int8)
    codes[known] = CODE_ABSENT
    codes[present] = CODE_PRESENT
    codes[:, ~v] = CODE_INVALID
    return LabelGrid(scan_ids, obj_ids, rec_ids, stamps, codes, "gt")


def privileged_codes(gt: LabelGrid, receptacle_visible: NDArray[np.bool_],
                     object_visible: NDArray[np.bool_] | None = None) -> LabelGrid:
    """Privileged codes from ground truth and visibility (paper appendix; see the module docstring).

    Args:
        gt: ground-truth grid (codes 1/0/-1/-2).
        receptacle_visible: (S, R) whether each receptacle's top surface was visible in each scan.
        object_visible: (S, O) whether each object was visible; default: its ground-truth
            receptacle was visible.
    """
    S, O, R = gt.codes.shape
    rv = np.asarray(receptacle_visible, bool)
    if rv.shape != (S, R):
        raise LabelingError(f"receptacle_visible: shape {rv.shape}, expected {(S, R)}")
    gt_present = gt.codes == CODE_PRESENT
    gt_absent = gt.codes == CODE_ABSENT
    if object_visible is None:
        ov = np.any(gt_present & rv[:, None, :], axis=2)
    else:
        ov = np.asarray(object_visible, bool)
        if ov.shape != (S, O):
            raise LabelingError(f"object_visible: shape {ov.shape}, expected {(S, O)}")
    codes = np.full(gt.codes.shape, CODE_MISSING, np.int8)
    codes[gt_absent & rv[:, None, :]] = CODE_ABSENT
    codes[gt_present & ov[:, :, None]] = CODE_PRESENT
    codes[gt.codes == CODE_INVALID] = CODE_INVALID
    return gt.with_codes(codes, "privileged")


def inject_noise(grid: LabelGrid, p_m: float, p_f: float, seed: int = 0, source: str | None = None) -> LabelGrid:
    """Flip observed codes: present -> absent with probability ``p_m``, absent -> present with ``p_f``.

    Codes -1 and -2 are kept. Deterministic for a seed (one uniform draw per grid cell, in
    (scan, object, receptacle) order).
    """
    for name, p in (("P_M", p_m), ("P_F", p_f)):
        if not (np.isfinite(p) and 0 <= p <= 1):
            raise LabelingError(f"noise {name}: {p}, expected a probability in [0, 1]")
    u = np.random.default_rng([int(seed), 7919]).random(grid.codes.shape)
    codes = grid.codes.copy()
    codes[(grid.codes == CODE_PRESENT) & (u < p_m)] = CODE_ABSENT
    codes[(grid.codes == CODE_ABSENT) & (u < p_f)] = CODE_PRESENT
    return grid.with_codes(codes, source or f"noisy:{p_m:g},{p_f:g}", {"p_m": p_m, "p_f": p_f, "seed": int(seed),
                                                                        "base": grid.source})


# -- error rates ----------------------------------------------------------------------------------
def binomial_interval(k: int, n: int, confidence: float = 0.95, method: str = "wilson") -> tuple[float, float]:
    """Confidence interval of a binomial proportion ``k / n``.

    Args:
        k: successes.
        n: trials.
        confidence: coverage of the interval, in (0, 1).
        method: ``wilson`` (score interval) or ``clopper-pearson`` (exact, conservative).

    Returns:
        (low, high); (0, 1) when ``n == 0``.
    """
    if n <= 0:
        return 0.0, 1.0
    if not 0 < confidence < 1:
        raise LabelingError(f"confidence: {confidence}, expected in (0, 1)")
    alpha = 1 - confidence
    if method == "wilson":
        z = NormalDist().inv_cdf(1 - alpha / 2)
        p = k / n
        den = 1 + z * z / n
        mid = (p + z * z / (2 * n)) / den
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
        return max(0.0, mid - half), min(1.0, mid + half)
    if method == "clopper-pearson":
        from scipy.stats import beta

        lo = 0.0 if k == 0 else float(beta.ppf(alpha / 2, k, n - k + 1))
        hi = 1.0 if k == n else float(beta.ppf(1 - alpha / 2, k + 1, n - k))
        return lo, hi
    raise LabelingError(f"interval method {method!r}: expected 'wilson' or 'clopper-pearson'")


@dataclass(frozen=True)
class ErrorRates:
    """Miss and false-positive rates of a label source against ground truth.

    Attributes:
        p_m: P(observed absent | truly present) among observed pairs.
        p_m_ci: confidence interval of ``p_m``.
        n_present: observations of truly present pairs.
        p_f: P(observed present | truly absent).
        p_f_ci: confidence interval of ``p_f``.
        n_absent: observations of truly absent pairs.
        confidence: confidence level of the intervals.
    """

    p_m: float
    p_m_ci: tuple[float, float]
    n_present: int
    p_f: float
    p_f_ci: tuple[float, float]
    n_absent: int
    confidence: float = 0.95

    def __str__(self) -> str:
        pct = round(100 * self.confidence)
        return (f"P_M = {self.p_m:.4f} [{self.p_m_ci[0]:.4f}, {self.p_m_ci[1]:.4f}] (n={self.n_present}), "
                f"P_F = {self.p_f:.4f} [{self.p_f_ci[0]:.4f}, {self.p_f_ci[1]:.4f}] (n={self.n_absent}), {pct}% CI")


def error_rates(labels: LabelGrid, gt: LabelGrid, *, confidence: float = 0.95, method: str = "wilson") -> ErrorRates:
    """Estimate P_M and P_F of ``labels`` against ``gt`` over the cells ``labels`` observed (1/0).

    Truth: ``gt`` 1 is present; 0 and -2 (a receptacle the object never occupies) are absent, so a
    false detection on a receptacle outside the valid set counts as a false positive; cells where
    ``gt`` is -1 (unknown) are ignored. ``gt`` is aligned to ``labels``' axes by id.
    """
    g = labels.aligned(gt)
    obs = labels.observed
    pres = obs & (g == CODE_PRESENT)
    absn = obs & ((g == CODE_ABSENT) | (g == CODE_INVALID))
    n_p, n_a = int(pres.sum()), int(absn.sum())
    k_m = int((pres & (labels.codes == CODE_ABSENT)).sum())
    k_f = int((absn & (labels.codes == CODE_PRESENT)).sum())
    return ErrorRates(k_m / n_p if n_p else float("nan"), binomial_interval(k_m, n_p, confidence, method), n_p,
                      k_f / n_a if n_a else float("nan"), binomial_interval(k_f, n_a, confidence, method), n_a,
                      confidence)
