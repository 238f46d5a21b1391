"""The per-edge work of the persistence task: filter one edge's observations, predict, score.

Runs inline or in worker processes (everything here is picklable plain data). See
:mod:`psg_data.evaluation._persistence_task` for the protocol.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.estimators._base import EdgeKey, PersistenceEstimator
from psg_data.estimators._guard import PluginError, build
from psg_data.evaluation._persistence_types import (
    SAMPLE_METRICS,
    TIME_METRICS,
    BreakdownRow,
    EdgeResult,
    EvaluationIssue,
    PredictionTrace,
)
from psg_data.metrics._classification import _bacc_of, _f1_of

__all__ = ["EdgeJob", "ScoreConfig", "run_edge", "run_edge_rows", "run_chunk", "fit_estimator", "HORIZON_BINS_S",
           "horizon_bin_names"]

HORIZON_BINS_S: tuple[float, ...] = (2 * 3600.0, 12 * 3600.0, 48 * 3600.0)
"""Upper edges of the horizon breakdown bins: < 2 h, 2-12 h, 12-48 h, > 48 h since the last observation."""


def horizon_bin_names(edges_s: Sequence[float] = HORIZON_BINS_S) -> list[str]:
    """``['< 2 h', '2-12 h', '12-48 h', '> 48 h']`` for the default edges."""
    h = [f"{e / 3600:g}" for e in edges_s]
    names = [f"< {h[0]} h"] + [f"{a}-{b} h" for a, b in zip(h, h[1:])] + [f"> {h[-1]} h"]
    return names


@dataclass(frozen=True)
class EdgeJob:
    """One edge's inputs: history, test observations, evaluation times with truth and time weights."""

    edge: EdgeKey
    hist_t: NDArray[np.float64]
    hist_y: NDArray[np.int8]
    test_t: NDArray[np.float64]
    test_y: NDArray[np.int8]
    eval_t: NDArray[np.float64]
    eval_y: NDArray[np.int64]
    eval_w: NDArray[np.float64]
    """time weight of each evaluation time, seconds (0 where masked or outside the windows)"""
    eval_wd: NDArray[np.int64]
    keep: bool = False
    draw: int = 0


@dataclass(frozen=True)
class ScoreConfig:
    setting: str
    horizon_s: float
    threshold: float
    convention: str
    sample_convention: str
    codes: tuple[int, ...]
    horizon_bins_s: tuple[float, ...] = HORIZON_BINS_S


def nan_metrics() -> dict[str, float]:
    return {m: float("nan") for m in (*TIME_METRICS, *SAMPLE_METRICS)}


def _score(y: NDArray[np.int64], b: NDArray[np.float64], w: NDArray[np.float64], cfg: ScoreConfig) -> dict[str, float]:
    """Metrics on valid samples ``y`` (0/1), beliefs ``b`` and time weights ``w``.

    The confusion masks are formed once for the sample and the time-weighted metrics, and balanced
    accuracy and F1 share their counts: the numbers of ``_mae`` / ``_bacc`` / ``_f1`` (the sample forms
    with unit weights, whose sums are counts), with a third of the small numpy calls.
    """
    out = nan_metrics()
    y8 = y.astype(np.int8)
    if not y.size:
        return out
    pos = b >= cfg.threshold
    t = y8 == 1
    masks = (t & pos, ~t & pos, t & ~pos, ~t & ~pos)  # tp, fp, fn, tn
    n_tp, n_fp, n_fn, n_tn = (float(np.count_nonzero(m)) for m in masks)  # = sums of unit weights
    err = np.abs(y8 - b)
    out["sample_mae"] = float(np.sum(err) / float(y.size))
    out["sample_balanced_accuracy"] = _bacc_of(n_tp, n_fp, n_fn, n_tn, cfg.sample_convention)
    out["sample_f1"] = _f1_of(n_tp, n_fp, n_fn, cfg.sample_convention, 0.0)
    total = np.sum(w)
    if total > 0:
        tp, fp, fn, tn = (float(np.sum(w[m])) for m in masks)
        out["mae"] = float(np.sum(w * err) / total)
        out["balanced_accuracy"] = _bacc_of(tp, fp, fn, tn, cfg.convention)
        out["f1"] = _f1_of(tp, fp, fn, cfg.convention, 0.0)
    return out


class _ShapeError(Exception):
    pass


def _predict_checked(f: Any, times: NDArray[np.float64]) -> NDArray[np.float64]:
    p = np.asarray(f.predict(times), dtype=np.float64)
    if p.shape != times.shape:
        p = p.reshape(-1)
        if p.shape != times.shape:
            raise _ShapeError(f"predict returned {p.size} values for {times.size} times")
    return p


@dataclass
class _Progress:
    """Where the online loop is, so that a failure names the stage and the time."""

    stage: str = "predict"
    t: float | None = None


def _predictions(f: Any, job: EdgeJob, cfg: ScoreConfig,
                 at: _Progress) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Beliefs at the evaluation times and, per time, the time of the last observation the filter had.

    Adaptive with horizon ``h``: the prediction at ``t`` is made after exactly the test observations
    with time ``<= t - h`` (``h = 0``: the filtering posterior). Predictive: after the history only.
    """
    n = job.eval_t.size
    last_hist = float(job.hist_t[-1]) if job.hist_t.size else float("nan")
    p, last = np.full(n, np.nan), np.full(n, last_hist)
    if cfg.setting == "predictive":
        at.stage, at.t = "predict", (float(job.eval_t[0]) if n else None)
        return _predict_checked(f, job.eval_t), last
    cut = np.searchsorted(job.eval_t, job.test_t + cfg.horizon_s, side="left")
    pos = 0
    for k in range(job.test_t.size):
        c = int(cut[k])
        if c > pos:
            at.stage, at.t = "predict", float(job.eval_t[pos])
            p[pos:c] = _predict_checked(f, job.eval_t[pos:c])
            last[pos:c] = float(job.test_t[k - 1]) if k > 0 else last_hist
            pos = c
        at.stage, at.t = "update", float(job.test_t[k])
        f.update(float(job.test_t[k]), int(job.test_y[k]))
    if pos < n:
        at.stage, at.t = "predict", float(job.eval_t[pos])
        p[pos:] = _predict_checked(f, job.eval_t[pos:])
        last[pos:] = float(job.test_t[-1]) if job.test_t.size else last_hist
    return p, last


def _horizon_bins(age_s: NDArray[np.float64], edges_s: Sequence[float]) -> NDArray[np.int64]:
    """Bin index of each age (time since the last observation); ``len(edges)+1`` = no observation yet."""
    b = np.searchsorted(np.asarray(edges_s, np.float64), age_s, side="right").astype(np.int64)
    b[~np.isfinite(age_s)] = len(edges_s) + 1
    return b


def _breakdowns(name: str, seed: int, job: EdgeJob, y: NDArray[np.int64], p: NDArray[np.float64],
                w: NDArray[np.float64], wd: NDArray[np.int64], hb: NDArray[np.int64], cfg: ScoreConfig
                ) -> list[BreakdownRow]:
    obj, rec = str(job.edge[0]), str(job.edge[1])
    names = [*horizon_bin_names(cfg.horizon_bins_s), "no observation yet"]
    rows = []
    for by, keys, label in (("weekday", wd, None), ("horizon", hb, names)):
        for d in np.unique(keys):
            m = keys == d
            key = int(d) if label is None else label[int(d)]
            rows.append(BreakdownRow(name, seed, obj, rec, by, key, float(np.sum(w[m])), int(m.sum()),
                                     _score(y[m], p[m], w[m], cfg), job.draw))
    return rows


def _failure(what: str, e: Exception) -> str:
    """What a call failed with: a :class:`PluginError`'s own words (the plugin's call named), else
    ``what`` raised the exception.
    """
    return str(e) if isinstance(e, PluginError) else f"{what} raised {type(e).__name__}: {e}"


EdgeOutcome = tuple[EdgeResult, list[BreakdownRow], list[EvaluationIssue], PredictionTrace | None]
Derived = tuple[str, Callable[[NDArray[np.float64]], NDArray[np.float64]]]
"""A row scored from another row's predictions: (its name, the map from those predictions to its own)."""


def _issue(name: str, seed: int, job: EdgeJob, stage: str, t: float | None, msg: str, n: int = 1) -> EvaluationIssue:
    obj, rec = str(job.edge[0]), str(job.edge[1])
    where = f"estimator {name!r} seed {seed} edge ({obj!r}, {rec!r})"
    when = f" at t_s={t!r}" if t is not None else ""
    return EvaluationIssue(name, seed, obj, rec, stage, t, f"{where}: {msg}{when}", n)


def _edge_result(name: str, seed: int, job: EdgeJob, status: str, n_points: int = 0, span: float = 0.0,
                 metrics: dict[str, float] | None = None) -> EdgeResult:
    return EdgeResult(name, seed, str(job.edge[0]), str(job.edge[1]), status, n_points, span, int(job.hist_t.size),
                      int(job.test_t.size), metrics if metrics is not None else nan_metrics(), job.draw)


Failure = tuple[str, "float | None", str]
"""Where an edge's filter failed: (stage, time, message)."""


def _filter_edge(est: PersistenceEstimator, job: EdgeJob, cfg: ScoreConfig
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | Failure:
    """(beliefs, time of the last observation per evaluation time), or the failure; plugin failures
    are caught here, never raised.
    """
    try:
        f = est.make_filter(job.edge)
        if job.hist_t.size:
            f.update_many(job.hist_t, job.hist_y)
    except Exception as e:  # noqa: BLE001 - plugin failures are reported, not raised
        t0 = float(job.hist_t[0]) if job.hist_t.size else None
        return "history", t0, _failure("filter creation/update with the training history", e)
    at = _Progress()
    try:
        return _predictions(f, job, cfg, at)
    except PluginError as e:
        if e.invalid and e.t_s is not None:  # NaN or out of range: stage "prediction", at the first bad time
            return "prediction", e.t_s, "prediction is " + e.detail.removeprefix("returned ")
        return at.stage, at.t, str(e)
    except Exception as e:  # noqa: BLE001
        what = "update with a test observation" if at.stage == "update" else "predict"
        return at.stage, at.t, _failure(what, e)


def _score_edge(name: str, seed: int, job: EdgeJob, p: NDArray[np.float64], last: NDArray[np.float64],
                cfg: ScoreConfig) -> EdgeOutcome:
    """Check and score one row's beliefs ``p`` on one edge."""
    bad = ~np.isfinite(p) | (p < 0.0) | (p > 1.0)
    if np.any(bad):
        i = int(np.argmax(bad))
        kind = "NaN" if np.isnan(p[i]) else f"{float(p[i])!r} outside [0, 1]"
        msg = f"prediction is {kind} ({int(bad.sum())} of {p.size} evaluation times invalid)"
        iss = _issue(name, seed, job, "prediction", float(job.eval_t[i]), msg, int(bad.sum()))
        return _edge_result(name, seed, job, "error"), [], [iss], None
    trace = (PredictionTrace(name, seed, job.edge, job.eval_t, p, job.eval_y, job.test_t, job.test_y, job.eval_w,
                             job.draw) if job.keep else None)
    from psg_data.metrics import mask_codes

    valid = mask_codes(job.eval_y, cfg.codes)
    if not valid.any():
        return _edge_result(name, seed, job, "unscored"), [], [], trace
    yv, pv, wv = job.eval_y[valid], p[valid], job.eval_w[valid]
    hb = _horizon_bins(job.eval_t[valid] - last[valid], cfg.horizon_bins_s)
    rows = _breakdowns(name, seed, job, yv, pv, wv, job.eval_wd[valid], hb, cfg)
    span = float(np.sum(wv))
    status = "ok" if span > 0 and math.isfinite(span) else "unscored"
    return _edge_result(name, seed, job, status, int(yv.size), span, _score(yv, pv, wv, cfg)), rows, [], trace


def run_edge(name: str, seed: int, est: PersistenceEstimator, job: EdgeJob, cfg: ScoreConfig) -> EdgeOutcome:
    """Filter, predict and score one edge for one fitted estimator; plugin failures become issues."""
    return run_edge_rows(name, seed, est, job, cfg)[0]


def run_edge_rows(name: str, seed: int, est: PersistenceEstimator, job: EdgeJob, cfg: ScoreConfig,
                  derived: Sequence[Derived] = ()) -> list[EdgeOutcome]:
    """:func:`run_edge`, and each ``derived`` row scored from the same predictions (one filter run);
    a filter failure is an issue of every row.

    Returns:
        The outcome of ``name``, then one per derived row, in their order.
    """
    out = _filter_edge(est, job, cfg)
    names = [name, *(d[0] for d in derived)]
    if isinstance(out[0], str):
        stage, t, msg = out  # type: ignore[misc]
        return [(_edge_result(n, seed, job, "error"), [], [_issue(n, seed, job, stage, t, msg)], None) for n in names]
    p, last = out
    outcomes = [_score_edge(name, seed, job, p, last, cfg)]
    for dname, fn in derived:
        outcomes.append(_score_edge(dname, seed, job, np.asarray(fn(p), dtype=np.float64), last, cfg))
    return outcomes


def run_chunk(name: str, seed: int, est: PersistenceEstimator, jobs: Sequence[EdgeJob], cfg: ScoreConfig,
              derived: Sequence[Derived] = ()) -> list[list[EdgeOutcome]]:
    """:func:`run_edge` of each job: per job, the outcomes of ``name`` and of each derived row."""
    return [run_edge_rows(name, seed, est, j, cfg, derived) for j in jobs]


def fit_estimator(name: str, factory: Any, seed: int, train: Sequence[Any], val: Sequence[Any] | None,
                  timezone: str) -> tuple[PersistenceEstimator | None, str | None]:
    """Build with ``random_state=seed`` and fit; (estimator, None) or (None, the error).

    A plugin is isolated (:func:`psg_data.estimators._guard.isolate`): its calls are guarded, its
    arrays read-only, its predictions checked.
    """
    try:
        est = build(name, factory, random_state=seed)
        est.fit(train, val_streams=val, timezone=timezone)
        return est, None
    except PluginError as e:
        return None, str(e)
    except Exception as e:  # noqa: BLE001
        return None, f"fit raised {type(e).__name__}: {e}"
