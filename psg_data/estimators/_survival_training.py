"""Training of Perpetua's and Perpetua*'s survival mixtures from sparse, irregular observations.

1. **States**: each training observation gets a state (present / absent) from the chosen
   segmentation: ``"hmm"`` (default of ``perpetua_star``: posterior of the pooled multi-receptacle
   HMM, :mod:`~psg_data.estimators._hmm`, which also estimates P_M and P_F), ``"observations"``
   (the observations themselves: for noise-free labels), ``"reference"`` (the L2 PELT the public
   Perpetua reference really runs; default of ``perpetua``), ``"bernoulli"`` (Bernoulli PELT with
   ``min_segment`` / ``segment_penalty``); or ground truth (``durations="ground_truth"``).
2. **Runs as intervals on the filter's clock**: a filter's survival time starts at the first
   observation of a run (that is when a restarted filter sets its origin), so a run observed at
   a = t_first, ..., t_last and followed by the opposite state first seen at t_next lasted
   T in (t_last - a, t_next - a]; the last run of a stream is right-censored, T > t_last - a.
   Intervals span whatever gap lies between t_last and t_next (nights, unobserved stretches).
3. **Mixtures**: per edge and state, :func:`~psg_data.estimators._interval_em.fit_interval_mixture`
   (all of a training's fits batched by :func:`~psg_data.estimators._interval_em.fit_interval_mixtures`)
   on the edge's own intervals (weight 1 each) plus a pool with ``pool_weight`` in all: the same
   state's intervals of the object's other edges when they hold at least ``MIN_POOL_ROWS``
   completed runs, else of every edge. An edge with many runs is barely moved by the pool; one
   with two or three borrows its shape (shrinkage). K is chosen by AIC among 1..min(max_components,
   ceil(rows / 3)). A state that was entered but never ended (a feature that never changed) gets
   the reference's fixed prior instead: one log-normal component with median max(4 x the longest
   censored run, 1 day) and sigma 1; a state never entered uses the pool's fit.

Everything a fit decided is returned per edge (runs, censored runs, pool used, K, medians) for the
estimator's ``fit_summary_``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.estimators._hmm import HmmFit, fit_error_hmm
from psg_data.estimators._interval_em import fit_interval_mixtures
from psg_data.estimators._segmentation import segment_labels, segment_reference, segment_stream
from psg_data.estimators._survival import SurvivalMixture

__all__ = ["SEGMENTATIONS", "EdgeRuns", "TrainingRuns", "run_intervals", "training_runs", "fit_edge_survivals",
           "mixture_median_s", "MIN_POOL_ROWS"]

SEGMENTATIONS = ("hmm", "observations", "reference", "bernoulli")
MIN_POOL_ROWS = 5
_DEFAULT_MEDIAN_S = 3600.0


@dataclass
class EdgeRuns:
    """Interval-censored run durations of one edge (s, on the filter's clock)."""

    edge: EdgeKey
    present: tuple[NDArray[np.float64], NDArray[np.float64]]
    absent: tuple[NDArray[np.float64], NDArray[np.float64]]
    n_obs: int
    span_s: float
    frac_present: float


@dataclass
class TrainingRuns:
    """Runs of every training edge and the detector error rates."""

    runs: dict[EdgeKey, EdgeRuns]
    p_m: float
    p_f: float
    segmentation: str
    error_source: str
    hmm: HmmFit | None = None
    info: dict[str, Any] = field(default_factory=dict)


def run_intervals(t_s: ArrayLike, state: ArrayLike) -> tuple[tuple[NDArray[np.float64], NDArray[np.float64]],
                                                              tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """((lo, hi) present, (lo, hi) absent) interval-censored run durations of a state sequence.

    Args:
        t_s: (N,) non-decreasing observation times, s.
        state: (N,) 0/1 states at those times.
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    x = np.asarray(state).astype(np.int8).reshape(-1)
    if t.size == 0:
        z = np.zeros(0)
        return (z, z), (z, z)
    ch = np.flatnonzero(np.diff(x) != 0) + 1
    first = np.concatenate([[0], ch])
    last = np.concatenate([ch - 1, [t.size - 1]])
    nxt = np.concatenate([t[ch], [np.inf]])
    lo = t[last] - t[first]
    hi = nxt - t[first]
    s = x[first]
    return (lo[s == 1], hi[s == 1]), (lo[s == 0], hi[s == 0])


def _merge(streams: Sequence[EdgeStream]) -> dict[EdgeKey, EdgeStream]:
    out: dict[EdgeKey, EdgeStream] = {}
    for s in streams:
        if not isinstance(s, EdgeStream):
            raise EstimatorError(f"fit: expected EdgeStream objects, got {type(s).__name__}")
        if len(s) == 0:
            continue
        if s.edge in out:
            old = out[s.edge]
            t = np.concatenate([old.t_s, s.t_s])
            o = np.argsort(t, kind="stable")
            out[s.edge] = EdgeStream(s.edge, t[o], np.concatenate([old.y, s.y])[o], dict(old.meta))
        else:
            out[s.edge] = s
    return out


def _gt_states(s: EdgeStream) -> tuple[NDArray[np.float64], NDArray[np.int8]] | None:
    if "gt_t_s" in s.meta and "gt_state" in s.meta:
        return np.asarray(s.meta["gt_t_s"], dtype=np.float64), np.asarray(s.meta["gt_state"]).astype(np.int8)
    return None


def _rates_from_labels(y: NDArray[np.int8], lab: NDArray[np.int8]) -> tuple[float, float]:
    pres, absn = y[lab == 1], y[lab == 0]
    pm = (np.sum(pres == 0) + 0.1) / (pres.size + 1.0)
    pf = (np.sum(absn == 1) + 0.1) / (absn.size + 1.0)
    return float(np.clip(pm, 1e-3, 0.45)), float(np.clip(pf, 1e-3, 0.45))


def training_runs(streams: Sequence[EdgeStream], *, segmentation: str = "hmm", durations: str = "segments",
                  p_m: float | None = None, p_f: float | None = None, min_segment: int = 5,
                  segment_penalty: float = 3.0) -> TrainingRuns:
    """States, interval-censored runs and error rates of the training streams (module docstring, steps 1-2).

    Args:
        streams: training streams (ground truth, if used, in ``meta['gt_t_s']`` / ``meta['gt_state']``).
        segmentation: one of :data:`SEGMENTATIONS`.
        durations: "segments" (runs from the segmentation), "ground_truth" (runs from the meta
            ground truth; required) or "auto" (ground truth where present).
        p_m: fixed missed-detection rate (None: estimated).
        p_f: fixed false-positive rate (None: estimated).
        min_segment: minimum segment length (observations) of the "bernoulli" segmentation.
        segment_penalty: change-point penalty of the "bernoulli" segmentation.

    Raises:
        EstimatorError: unknown options, or ground truth requested but missing.
    """
    if segmentation not in SEGMENTATIONS:
        raise EstimatorError(f"segmentation must be one of {', '.join(SEGMENTATIONS)}, got {segmentation!r}")
    if durations not in ("segments", "ground_truth", "auto"):
        raise EstimatorError(f"durations source must be 'segments', 'ground_truth' or 'auto', got {durations!r}")
    if int(min_segment) < 1 or not float(segment_penalty) >= 0:
        raise EstimatorError(f"segmentation: min_segment must be >= 1 and segment_penalty >= 0, got {min_segment}, "
                             f"{segment_penalty}")
    merged = _merge(streams)
    hmm = None
    if segmentation == "hmm" and merged:
        hmm = fit_error_hmm(list(merged.values()), p_m=p_m, p_f=p_f)
    runs: dict[EdgeKey, EdgeRuns] = {}
    ys, labs = [], []
    for e, s in merged.items():
        if segmentation == "hmm":
            assert hmm is not None
            lab = (hmm.posterior[e][1] >= 0.5).astype(np.int8)
        elif segmentation == "observations":
            lab = s.y.copy()
        elif segmentation == "reference":
            lab = segment_labels(s.y, segment_reference(s.y))
        else:
            lab = segment_labels(s.y, segment_stream(s.y, min_size=int(min_segment), penalty=float(segment_penalty)))
        gt = _gt_states(s)
        if durations == "ground_truth" and gt is None:
            raise EstimatorError(f"edge {e}: durations source 'ground_truth' needs meta['gt_t_s'] and meta['gt_state']")
        if gt is not None and durations != "segments":
            pres, absn = run_intervals(*gt)
            j = np.clip(np.searchsorted(gt[0], s.t_s, side="right") - 1, 0, gt[0].size - 1)
            lab = gt[1][j]
        else:
            pres, absn = run_intervals(s.t_s, lab)
        ys.append(s.y)
        labs.append(lab)
        runs[e] = EdgeRuns(e, pres, absn, len(s), float(s.t_s[-1] - s.t_s[0]), float(np.mean(lab)))
    if hmm is not None and durations == "segments":
        pm, pf, source = hmm.p_m, hmm.p_f, "pooled multi-receptacle HMM"
    elif ys:
        pm, pf = _rates_from_labels(np.concatenate(ys), np.concatenate(labs))
        source = f"disagreement with the {'ground truth' if durations != 'segments' else segmentation + ' segments'}"
    else:
        pm, pf, source = 0.1, 0.1, "default (no training data)"
    pm = float(p_m) if p_m is not None else pm
    pf = float(p_f) if p_f is not None else pf
    if p_m is not None or p_f is not None:
        source += " (P_M / P_F set by the user where given)"
    return TrainingRuns(runs, pm, pf, segmentation, source, hmm)


# ------------------------------------------------------------------------------------- mixtures
def mixture_median_s(m: SurvivalMixture) -> float:
    """Median survival time (s) of a mixture (bisection in log time; inf if beyond 1e12 s)."""
    lo, hi = -3.0, 12.0
    if float(np.exp(m.log_sf(np.array([10.0 ** hi])))[0] @ m.weights) > 0.5:
        return math.inf
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if float(np.exp(m.log_sf(np.array([10.0 ** mid])))[0] @ m.weights) > 0.5:
            lo = mid
        else:
            hi = mid
    return float(10.0 ** (0.5 * (lo + hi)))


@dataclass
class _Pool:
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]

    @property
    def n_complete(self) -> int:
        return int(np.sum(np.isfinite(self.hi)))


def _cat_pool(parts: list[tuple[NDArray[np.float64], NDArray[np.float64]]]) -> _Pool:
    if not parts:
        return _Pool(np.zeros(0), np.zeros(0))
    return _Pool(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))


class _Fitter:
    """Collects the mixture fits of a training and runs them as one batched EM (:func:`fit_interval_mixtures`).

    :meth:`fit` and :meth:`pool_fit` return a thunk; after :meth:`run` it gives the fitted mixture.
    """

    def __init__(self, family: str, max_components: int, sigma_min: float, seed: int) -> None:
        self.family, self.max_components, self.sigma_min, self.seed = family, max_components, sigma_min, seed
        self._jobs: list[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], int]] = []
        self._fits: list[SurvivalMixture] = []

    def fit(self, lo: NDArray[np.float64], hi: NDArray[np.float64], w: NDArray[np.float64],
            k_max: int) -> Callable[[], SurvivalMixture]:
        i = len(self._jobs)
        self._jobs.append((lo, hi, w, max(1, k_max)))
        return lambda: self._fits[i]

    def pool_fit(self, pool: _Pool) -> Callable[[], SurvivalMixture] | None:
        if pool.n_complete == 0:
            return None
        k = min(self.max_components, max(1, math.ceil(pool.lo.size / 3)))
        return self.fit(pool.lo, pool.hi, np.ones(pool.lo.size), k)

    def run(self) -> None:
        fits = fit_interval_mixtures(self._jobs, family=self.family, sigma_min=self.sigma_min, random_state=self.seed)
        self._fits = [f.mixture for f in fits]


def _fixed_long(longest_s: float, family: str) -> SurvivalMixture:
    median = max(4.0 * longest_s, 86400.0)
    if family == "exponential":
        return SurvivalMixture.single("exponential", math.log(2.0) / median)
    if family == "weibull":
        return SurvivalMixture.single("weibull", 1.0, median / math.log(2.0) ** 1.0)
    return SurvivalMixture.lognormal_median(median, 1.0)


Thunk = Callable[[], SurvivalMixture]


def _either(first: Thunk | None, second: Thunk) -> SurvivalMixture:
    return first() if first is not None else second()


def _value(m: SurvivalMixture) -> SurvivalMixture:
    return m


class _Plan:
    """The pools and pool fits of a training, and the fit (a thunk) chosen for each edge and state."""

    def __init__(self, data: TrainingRuns, fitter: _Fitter, family: str, max_components: int,
                 pool_weight: float) -> None:
        self.fitter, self.family, self.max_components, self.pool_weight = fitter, family, max_components, pool_weight
        states = ("present", "absent")
        self.glob = {st: _cat_pool([getattr(r, st) for r in data.runs.values()]) for st in states}
        by_obj: dict[str, list[EdgeRuns]] = {}
        for r in data.runs.values():
            by_obj.setdefault(str(r.edge[0]), []).append(r)
        self.obj_pool = {(o, st): _cat_pool([getattr(r, st) for r in rs]) for o, rs in by_obj.items() for st in states}
        default = functools.partial(SurvivalMixture.lognormal_median, _DEFAULT_MEDIAN_S)
        self.fallback = {st: functools.partial(_either, fitter.pool_fit(self.glob[st]), default) for st in states}
        self.obj_fit: dict[tuple[str, str], Thunk | None] = {}

    def state_fit(self, e: EdgeKey, st: str, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> tuple[Thunk, str]:
        """The fit of edge ``e``'s runs in state ``st`` (module docstring, step 3) and where it comes from."""
        op = self.obj_pool[(str(e[0]), st)]
        pool, pool_name = (op, "object") if op.n_complete >= MIN_POOL_ROWS else (self.glob[st], "all edges")
        if lo.size == 0:
            got = None
            if pool_name == "object":
                key = (str(e[0]), st)
                if key not in self.obj_fit:
                    self.obj_fit[key] = self.fitter.pool_fit(op)
                got = self.obj_fit[key]
            return functools.partial(_either, got, self.fallback[st]), f"state never entered: {pool_name} pool"
        if not np.any(np.isfinite(hi)):
            return (functools.partial(_value, _fixed_long(float(np.max(lo)), self.family)),
                    "state never ended: fixed long prior (median 4 x longest run, >= 1 day)")
        w = np.ones(lo.size)
        k_max = min(self.max_components, max(1, math.ceil(lo.size / 3)))
        if pool.lo.size and self.pool_weight > 0:
            lo = np.concatenate([lo, pool.lo])
            hi = np.concatenate([hi, pool.hi])
            w = np.concatenate([w, np.full(pool.lo.size, self.pool_weight / pool.lo.size)])
        return self.fitter.fit(lo, hi, w, k_max), f"own runs + {pool_name} pool (weight {self.pool_weight:g})"


def fit_edge_survivals(data: TrainingRuns, *, family: str = "lognormal", max_components: int = 5,
                       pool_weight: float = 2.0, sigma_min: float = 0.05, seed: int = 0
                       ) -> tuple[dict[EdgeKey, tuple[SurvivalMixture, SurvivalMixture]],
                                  tuple[SurvivalMixture, SurvivalMixture], dict[EdgeKey, dict[str, Any]]]:
    """Per-edge (persistence, emergence) mixtures, defaults for unseen edges and a per-edge report.

    Every mixture of the training is fitted in one batched EM: the edges are walked once to choose
    each fit (a thunk), then the batch runs, then the thunks are read.
    """
    fitter = _Fitter(family, int(max_components), float(sigma_min), int(seed))
    plan = _Plan(data, fitter, family, int(max_components), float(pool_weight))
    pending: dict[EdgeKey, tuple[dict[str, Any], list[dict[str, Any]], list[Thunk]]] = {}
    for e, r in data.runs.items():
        info: dict[str, Any] = {"n_obs": r.n_obs, "span_h": round(r.span_s / 3600.0, 3),
                                "frac_present": round(r.frac_present, 4)}
        parts, pair = [], []
        for st, tag in (("present", "per"), ("absent", "emg")):
            lo, hi = getattr(r, st)
            complete = int(np.sum(np.isfinite(hi)))
            mix, source = plan.state_fit(e, st, lo, hi)
            parts.append({f"{st}_runs": int(lo.size), f"{st}_censored": int(lo.size - complete),
                          f"{tag}_source": source})
            pair.append(mix)
        pending[e] = (info, parts, pair)
    fitter.run()
    out: dict[EdgeKey, tuple[SurvivalMixture, SurvivalMixture]] = {}
    report: dict[EdgeKey, dict[str, Any]] = {}
    for e, (info, parts, pair) in pending.items():
        out[e] = (pair[0](), pair[1]())
        for tag, part, m in zip(("per", "emg"), parts, out[e]):
            info.update(part)
            info[f"{tag}_k"] = m.n_components
            info[f"{tag}_median_h"] = round(mixture_median_s(m) / 3600.0, 3)
        report[e] = info
    return out, (plan.fallback["present"](), plan.fallback["absent"]()), report
