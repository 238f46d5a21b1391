"""The persistence-estimation task: fit estimators, filter each edge, score against ground truth.

Protocol (what :func:`evaluate_persistence` does for every estimator, seed and edge):

1. ``est = factory(random_state=seed).fit(train_streams, val_streams=..., timezone=...)``
   (once per estimator and seed).
2. ``f = est.make_filter(edge)``; ``f.update_many(...)`` with the edge's training observations
   (and its validation observations when ``history="train+val"``).
3. Evaluation times: the ground-truth grid of the edge (``eval_times="grid"``), the edge's test
   observation times inside the grid's span (``"observations"``), or both (default
   ``"observations+grid"``). Ground truth at an observation time is the grid value at the last
   grid time ``<=`` it (the grid is a step function).
4. Predictions:

   - ``setting="predictive"``: no test observation is applied; ``f.predict(all eval times)``.
   - ``setting="adaptive"``: online. Before the test observation at ``t_k`` is applied, every
     evaluation time ``< t_k`` not predicted yet is predicted; then ``f.update(t_k, y_k)``.
     Hence a prediction at time ``t`` uses exactly the observations with time ``<= t`` (the
     filtering posterior; an observation at ``t`` itself is known at ``t``).

5. Checks: predictions must have one value per time, be finite and lie in [0, 1]. A violation,
   or an exception raised by the plugin, is recorded as an :class:`EvaluationIssue` naming the
   estimator, seed, edge and time; that edge is not scored and the run goes on. A fit that fails
   is recorded the same way and its edges get status ``"error"``.
6. Scores per edge: time-integrated MAE / balanced accuracy / F1 on the evaluation times
   (trapezoid rule, ``convention="reference"`` by default, see
   :mod:`psg_data.metrics._classification`) and the per-sample forms (``sample_*`` columns,
   ``sample_convention="sklearn"`` by default). Ground-truth codes -1/-2 are excluded.
7. Aggregation: per (estimator, seed) the time-integrated metrics are averaged over edges with
   weights proportional to each edge's scored span (the reference's feature weighting), the
   per-sample ones with weights proportional to the number of scored points; then mean, std
   (ddof=1), bootstrap CI and count over seeds (:class:`~psg_data.evaluation.Summary`).
   Breakdowns per object, receptacle and local weekday use the same weighting.

Runs ``(estimator, seed)`` fits and edge chunks in a ``ProcessPoolExecutor`` (``spawn``) when
``jobs > 1``, or on any ``concurrent.futures.Executor`` passed as ``executor`` (Dask distributed);
factories and fitted estimators must then be picklable. Results do not depend on ``jobs`` or the
executor.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeKey, EdgeStream, PersistenceEstimator
from psg_data.evaluation._aggregate import Summary, summarize
from psg_data.metrics._classification import (
    PRIVILEGED_CODES,
    _bacc,
    _f1,
    _mae,
    _check_convention,
    mask_codes,
    span_weighted_mean,
    trapezoid_weights,
)

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

__all__ = [
    "TIME_METRICS",
    "SAMPLE_METRICS",
    "WEEKDAY_NAMES",
    "EvaluationIssue",
    "EdgeResult",
    "WeekdayResult",
    "PersistenceResult",
    "PredictionTrace",
    "RegistryFactory",
    "evaluate_persistence",
    "merge_results",
]

logger = logging.getLogger(__name__)

TIME_METRICS: tuple[str, ...] = ("mae", "balanced_accuracy", "f1")
"""Time-integrated metrics (columns of the per-edge table), weighted by span across edges."""
SAMPLE_METRICS: tuple[str, ...] = ("sample_mae", "sample_balanced_accuracy", "sample_f1")
"""Per-sample metrics over the evaluation times, weighted by scored points across edges."""
WEEKDAY_NAMES: tuple[str, ...] = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")

EstimatorFactory = Callable[..., PersistenceEstimator]
Setting = Literal["predictive", "adaptive"]
EvalTimes = Literal["observations+grid", "grid", "observations"]
ProgressCallback = Callable[[int, int], None]


def _clean(x: Any) -> Any:
    """JSON-able copy: NaN/inf -> None, numpy scalars -> Python, tuples -> lists."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, (str, int, float, bool)) or x is None:
        return x
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    return repr(x)


@dataclass(frozen=True)
class EvaluationIssue:
    """A problem met while evaluating one estimator (for one seed and, usually, one edge).

    Attributes:
        estimator: estimator name.
        seed: the seed (``random_state``) of the run.
        object_id: object of the edge, None for a fit failure.
        receptacle_id: receptacle of the edge, None for a fit failure.
        stage: ``"fit"``, ``"history"`` (updating with training data), ``"update"`` (a test
            observation), ``"predict"`` (an exception) or ``"prediction"`` (invalid values).
        t_s: time of the (first) offending prediction or observation, seconds since the Unix
            epoch (UTC); None when not tied to a time.
        n_times: how many evaluation times were affected (invalid values only).
        message: one-line description.
    """

    estimator: str
    seed: int
    object_id: str | None
    receptacle_id: str | None
    stage: str
    t_s: float | None
    message: str
    n_times: int = 1

    def to_dict(self) -> dict[str, Any]:
        return _clean(asdict(self))


@dataclass(frozen=True)
class EdgeResult:
    """Scores of one (estimator, seed, edge).

    Attributes:
        estimator: estimator name.
        seed: seed of the run.
        object_id: first element of the edge key.
        receptacle_id: second element of the edge key.
        status: ``"ok"``, ``"error"`` (see the issues) or ``"unscored"`` (no valid ground truth).
        n_points: scored evaluation times (ground-truth codes excluded).
        span_s: integrated span of the scored times, seconds.
        n_train_obs: observations used as history before the test window.
        n_test_obs: test observations of the edge (applied only in the adaptive setting).
        metrics: metric name -> value (NaN when not scored); keys :data:`TIME_METRICS` and
            :data:`SAMPLE_METRICS`.
    """

    estimator: str
    seed: int
    object_id: str
    receptacle_id: str
    status: str
    n_points: int
    span_s: float
    n_train_obs: int
    n_test_obs: int
    metrics: dict[str, float]

    @property
    def edge(self) -> EdgeKey:
        return (self.object_id, self.receptacle_id)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.update(d.pop("metrics"))
        return _clean(d)


@dataclass(frozen=True)
class WeekdayResult:
    """Scores of one (estimator, seed, edge) restricted to one local weekday (0 = Monday).

    The trapezoid weight of each evaluation time goes to its local weekday; ``span_s`` is the sum
    of those weights (seconds), ``n_points`` the number of scored times that day.
    """

    estimator: str
    seed: int
    object_id: str
    receptacle_id: str
    weekday: int
    span_s: float
    n_points: int
    metrics: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["weekday_name"] = WEEKDAY_NAMES[self.weekday]
        d.update(d.pop("metrics"))
        return _clean(d)


@dataclass(frozen=True)
class PredictionTrace:
    """Beliefs of one (estimator, seed, edge) at its evaluation times (kept for plots).

    Attributes:
        t_s: (N,) evaluation times, float64 seconds since the Unix epoch (UTC).
        belief: (N,) predicted P(present).
        truth: (N,) ground truth (1, 0, or an excluded code -1/-2).
        obs_t_s: the edge's test observation times (applied only in the adaptive setting).
        obs_y: the test observations.
    """

    estimator: str
    seed: int
    edge: EdgeKey
    t_s: NDArray[np.float64]
    belief: NDArray[np.float64]
    truth: NDArray[np.int64]
    obs_t_s: NDArray[np.float64]
    obs_y: NDArray[np.int8]


@dataclass
class PersistenceResult:
    """Everything :func:`evaluate_persistence` produced.

    Attributes:
        config: settings of the run (setting, eval_times, timezone, seeds, conventions, ...).
        edges: one :class:`EdgeResult` per (estimator, seed, edge), in input order.
        weekdays: per-weekday breakdown rows.
        errors: every :class:`EvaluationIssue`; non-empty means the run is not clean.
        summary: estimator -> metric -> :class:`Summary` over seeds.
    """

    config: dict[str, Any]
    edges: list[EdgeResult]
    weekdays: list[WeekdayResult]
    errors: list[EvaluationIssue]
    summary: dict[str, dict[str, Summary]] = field(default_factory=dict)
    traces: list[PredictionTrace] = field(default_factory=list)
    """Predictions of the edges requested with ``keep_predictions`` (every seed)."""

    @property
    def ok(self) -> bool:
        """True when no issue was recorded (the CLI exits non-zero otherwise)."""
        return not self.errors

    @property
    def estimators(self) -> list[str]:
        return list(self.config["estimators"])

    def seed_scores(self) -> dict[str, dict[int, dict[str, float]]]:
        """Per (estimator, seed): metrics averaged over edges plus edge counts."""
        out: dict[str, dict[int, dict[str, float]]] = {}
        for name in self.estimators:
            out[name] = {}
            for seed in self.config["seeds"]:
                rows = [r for r in self.edges if r.estimator == name and r.seed == seed]
                out[name][seed] = _aggregate_rows(rows)
        return out

    def to_frame(self) -> pd.DataFrame:
        """Tidy table, one row per (estimator, seed, edge), metrics as columns (results.csv)."""
        import pandas as pd

        cols = [
            "estimator", "seed", "object_id", "receptacle_id", "status", "n_points", "span_s",
            "n_train_obs", "n_test_obs", *TIME_METRICS, *SAMPLE_METRICS,
        ]
        recs = []
        for r in self.edges:
            d = asdict(r)
            d.update(d.pop("metrics"))
            recs.append(d)
        return pd.DataFrame.from_records(recs, columns=cols)

    def weekday_frame(self) -> pd.DataFrame:
        """Tidy table, one row per (estimator, seed, edge, weekday)."""
        import pandas as pd

        cols = [
            "estimator", "seed", "object_id", "receptacle_id", "weekday", "weekday_name",
            "span_s", "n_points", *TIME_METRICS, *SAMPLE_METRICS,
        ]
        recs = []
        for r in self.weekdays:
            d = asdict(r)
            d["weekday_name"] = WEEKDAY_NAMES[r.weekday]
            d.update(d.pop("metrics"))
            recs.append(d)
        return pd.DataFrame.from_records(recs, columns=cols)

    def summary_frame(self) -> pd.DataFrame:
        """One row per (estimator, metric): mean, std, ci_low, ci_high, n (over seeds)."""
        import pandas as pd

        recs = [
            {"estimator": name, "metric": m, **asdict(s)}
            for name, per in self.summary.items()
            for m, s in per.items()
        ]
        return pd.DataFrame.from_records(recs, columns=["estimator", "metric", "mean", "std", "ci_low", "ci_high", "n"])

    def breakdown(self, by: Literal["object", "receptacle", "weekday"]) -> pd.DataFrame:
        """Metrics per object, receptacle or local weekday: mean and std (ddof=1) over seeds.

        Within a seed, edges are averaged with the same weights as the overall score (span for
        time-integrated metrics, points for per-sample ones).

        Returns:
            Columns ``estimator, <key>, metric, mean, std, n`` (n = seeds with a value).
        """
        import pandas as pd

        if by == "object":
            rows: list[Any] = self.edges
            key: Callable[[Any], Any] = lambda r: r.object_id  # noqa: E731
        elif by == "receptacle":
            rows, key = self.edges, lambda r: r.receptacle_id
        elif by == "weekday":
            rows, key = self.weekdays, lambda r: WEEKDAY_NAMES[r.weekday]
        else:
            raise EvaluationError(f"breakdown: by must be 'object', 'receptacle' or 'weekday', got {by!r}")
        groups: dict[tuple[str, Any], dict[int, list[Any]]] = {}
        for r in rows:
            groups.setdefault((r.estimator, key(r)), {}).setdefault(r.seed, []).append(r)
        recs = []
        for (name, k), per_seed in groups.items():
            per_seed_scores = [_aggregate_rows(rs) for rs in per_seed.values()]
            for m in (*TIME_METRICS, *SAMPLE_METRICS):
                v = np.array([s[m] for s in per_seed_scores], dtype=np.float64)
                v = v[np.isfinite(v)]
                std = float(np.std(v, ddof=1)) if v.size > 1 else (0.0 if v.size == 1 else float("nan"))
                recs.append({"estimator": name, by: k, "metric": m,
                             "mean": float(np.mean(v)) if v.size else float("nan"), "std": std, "n": int(v.size)})
        return pd.DataFrame.from_records(recs, columns=["estimator", by, "metric", "mean", "std", "n"])

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict (results.json): config, summary, per-seed scores, edges, weekdays, errors."""
        return _clean({
            "config": self.config,
            "ok": self.ok,
            "summary": {n: {m: s.to_dict() for m, s in per.items()} for n, per in self.summary.items()},
            "seeds": {n: {str(s): v for s, v in per.items()} for n, per in self.seed_scores().items()},
            "edges": [r.to_dict() for r in self.edges],
            "weekdays": [r.to_dict() for r in self.weekdays],
            "errors": [e.to_dict() for e in self.errors],
        })


def _aggregate_rows(rows: Sequence[EdgeResult | WeekdayResult]) -> dict[str, float]:
    ok = [r for r in rows if getattr(r, "status", "ok") == "ok"]
    spans = np.array([r.span_s for r in ok], dtype=np.float64)
    pts = np.array([r.n_points for r in ok], dtype=np.float64)
    out: dict[str, float] = {}
    for m in TIME_METRICS:
        out[m] = span_weighted_mean([r.metrics[m] for r in ok], spans) if ok else float("nan")
    for m in SAMPLE_METRICS:
        out[m] = span_weighted_mean([r.metrics[m] for r in ok], pts) if ok else float("nan")
    out["n_edges_scored"] = float(len(ok))
    out["n_edges_error"] = float(sum(1 for r in rows if getattr(r, "status", "ok") == "error"))
    return out


# --------------------------------------------------------------------------------------------
# per-edge work (runs inline or in worker processes)


@dataclass(frozen=True)
class _EdgeJob:
    edge: EdgeKey
    hist_t: NDArray[np.float64]
    hist_y: NDArray[np.int8]
    test_t: NDArray[np.float64]
    test_y: NDArray[np.int8]
    eval_t: NDArray[np.float64]
    eval_y: NDArray[np.int64]
    eval_wd: NDArray[np.int64]
    keep: bool = False


@dataclass(frozen=True)
class _Config:
    setting: str
    threshold: float
    convention: str
    sample_convention: str
    codes: tuple[int, ...]


def _nan_metrics() -> dict[str, float]:
    return {m: float("nan") for m in (*TIME_METRICS, *SAMPLE_METRICS)}


def _score(y: NDArray[np.int64], b: NDArray[np.float64], w: NDArray[np.float64], cfg: _Config) -> dict[str, float]:
    """Metrics on valid samples ``y`` (0/1), beliefs ``b`` and trapezoid weights ``w``."""
    out = _nan_metrics()
    y8 = y.astype(np.int8)
    if y.size:
        ones = np.ones_like(b)
        out["sample_mae"] = _mae(y8, b, ones, None)
        out["sample_balanced_accuracy"] = _bacc(y8, b, ones, cfg.threshold, cfg.sample_convention)
        out["sample_f1"] = _f1(y8, b, ones, cfg.threshold, cfg.sample_convention, 0.0)
    if np.sum(w) > 0:
        out["mae"] = _mae(y8, b, w, None)
        out["balanced_accuracy"] = _bacc(y8, b, w, cfg.threshold, cfg.convention)
        out["f1"] = _f1(y8, b, w, cfg.threshold, cfg.convention, 0.0)
    return out


def _predict_checked(f: Any, times: NDArray[np.float64]) -> NDArray[np.float64]:
    p = np.asarray(f.predict(times), dtype=np.float64)
    if p.shape != times.shape:
        p = p.reshape(-1)
        if p.shape != times.shape:
            raise _ShapeError(f"predict returned {p.size} values for {times.size} times")
    return p


class _ShapeError(Exception):
    pass


def _run_edge(name: str, seed: int, est: PersistenceEstimator, job: _EdgeJob, cfg: _Config
              ) -> tuple[EdgeResult, list[WeekdayResult], list[EvaluationIssue], PredictionTrace | None]:
    er, wr, iss, p = _run_edge_scores(name, seed, est, job, cfg)
    trace = None
    if job.keep and p is not None:
        trace = PredictionTrace(name, seed, job.edge, job.eval_t, p, job.eval_y, job.test_t, job.test_y)
    return er, wr, iss, trace


def _run_edge_scores(name: str, seed: int, est: PersistenceEstimator, job: _EdgeJob, cfg: _Config
                     ) -> tuple[EdgeResult, list[WeekdayResult], list[EvaluationIssue], NDArray[np.float64] | None]:
    obj, rec = str(job.edge[0]), str(job.edge[1])

    def issue(stage: str, t: float | None, msg: str, n: int = 1) -> EvaluationIssue:
        where = f"estimator {name!r} seed {seed} edge ({obj!r}, {rec!r})"
        at = f" at t_s={t!r}" if t is not None else ""
        return EvaluationIssue(name, seed, obj, rec, stage, t, f"{where}: {msg}{at}", n)

    def result(status: str, n_points: int = 0, span: float = 0.0, metrics: dict[str, float] | None = None) -> EdgeResult:
        return EdgeResult(name, seed, obj, rec, status, n_points, span, int(job.hist_t.size), int(job.test_t.size),
                          metrics if metrics is not None else _nan_metrics())

    n = job.eval_t.size
    try:
        f = est.make_filter(job.edge)
        if job.hist_t.size:
            f.update_many(job.hist_t, job.hist_y)
    except Exception as e:  # noqa: BLE001 - plugin failures are reported, not raised
        t0 = float(job.hist_t[0]) if job.hist_t.size else None
        return result("error"), [], [issue("history", t0, f"filter creation/update with the training history raised {type(e).__name__}: {e}")], None

    p = np.full(n, np.nan)
    stage, t_fail = "predict", None
    try:
        if cfg.setting == "predictive":
            t_fail = float(job.eval_t[0]) if n else None
            p = _predict_checked(f, job.eval_t)
        else:
            cut = np.searchsorted(job.eval_t, job.test_t, side="left")
            pos = 0
            for k in range(job.test_t.size):
                c = int(cut[k])
                if c > pos:
                    stage, t_fail = "predict", float(job.eval_t[pos])
                    p[pos:c] = _predict_checked(f, job.eval_t[pos:c])
                    pos = c
                stage, t_fail = "update", float(job.test_t[k])
                f.update(float(job.test_t[k]), int(job.test_y[k]))
            if pos < n:
                stage, t_fail = "predict", float(job.eval_t[pos])
                p[pos:] = _predict_checked(f, job.eval_t[pos:])
    except Exception as e:  # noqa: BLE001
        what = "update with a test observation" if stage == "update" else "predict"
        return result("error"), [], [issue(stage, t_fail, f"{what} raised {type(e).__name__}: {e}")], None

    bad = ~np.isfinite(p) | (p < 0.0) | (p > 1.0)
    if np.any(bad):
        i = int(np.argmax(bad))
        kind = "NaN" if np.isnan(p[i]) else f"{float(p[i])!r} outside [0, 1]"
        more = f" ({int(bad.sum())} of {n} evaluation times invalid)"
        return result("error"), [], [issue("prediction", float(job.eval_t[i]), f"prediction is {kind}{more}", int(bad.sum()))], None

    valid = mask_codes(job.eval_y, cfg.codes)
    w = trapezoid_weights(job.eval_t, valid)
    yv, pv, wv, wdv = job.eval_y[valid], p[valid], w[valid], job.eval_wd[valid]
    if yv.size == 0:
        return result("unscored"), [], [], p
    metrics = _score(yv, pv, wv, cfg)
    span = float(np.sum(wv))
    weekday_rows = []
    for d in np.unique(wdv):
        m = wdv == d
        weekday_rows.append(WeekdayResult(name, seed, obj, rec, int(d), float(np.sum(wv[m])), int(m.sum()),
                                          _score(yv[m], pv[m], wv[m], cfg)))
    status = "ok" if span > 0 else "unscored"
    return result(status, int(yv.size), span, metrics), weekday_rows, [], p


def _fit(name: str, factory: EstimatorFactory, seed: int, train: Sequence[EdgeStream],
         val: Sequence[EdgeStream] | None, timezone: str) -> tuple[PersistenceEstimator | None, str | None]:
    try:
        est = factory(random_state=seed)
        est.fit(train, val_streams=val, timezone=timezone)
        return est, None
    except Exception as e:  # noqa: BLE001
        return None, f"{type(e).__name__}: {e}"


def _run_chunk(name: str, seed: int, est: PersistenceEstimator, jobs: Sequence[_EdgeJob], cfg: _Config
               ) -> list[tuple[EdgeResult, list[WeekdayResult], list[EvaluationIssue], PredictionTrace | None]]:
    return [_run_edge(name, seed, est, j, cfg) for j in jobs]


# --------------------------------------------------------------------------------------------
# input normalisation


def _stream_dict(streams: Sequence[EdgeStream] | Mapping[EdgeKey, EdgeStream] | None, what: str) -> dict[EdgeKey, EdgeStream]:
    if streams is None:
        return {}
    items = list(streams.values()) if isinstance(streams, Mapping) else list(streams)
    out: dict[EdgeKey, EdgeStream] = {}
    for s in items:
        if not isinstance(s, EdgeStream):
            raise EvaluationError(f"{what}: expected EdgeStream items, got {type(s).__name__}")
        key = (str(s.edge[0]), str(s.edge[1]))
        if key in out:
            raise EvaluationError(f"{what}: edge {key} appears twice; merge its observations into one EdgeStream")
        out[key] = s
    return out


def _ground_truth_dict(ground_truth: Any) -> dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]]:
    """Accept Mapping[edge, (t_s, y) | obj with .t_s/.y], Sequence[obj with .edge/.t_s/.y] or a DataFrame."""
    items: list[tuple[Any, Any, Any]] = []
    if hasattr(ground_truth, "columns") and hasattr(ground_truth, "groupby"):  # pandas DataFrame
        cols = set(ground_truth.columns)
        if not {"object_id", "receptacle_id", "t_s", "y"} <= cols:
            raise EvaluationError("ground_truth DataFrame needs columns object_id, receptacle_id, t_s, y")
        for (o, r), g in ground_truth.groupby(["object_id", "receptacle_id"], sort=False):
            items.append(((o, r), g["t_s"].to_numpy(), g["y"].to_numpy()))
    elif isinstance(ground_truth, Mapping):
        for k, v in ground_truth.items():
            if hasattr(v, "t_s") and hasattr(v, "y"):
                items.append((k, v.t_s, v.y))
            else:
                try:
                    t, y = v
                except (TypeError, ValueError):
                    raise EvaluationError(f"ground_truth[{k!r}]: expected (t_s, y) or an object with t_s and y") from None
                items.append((k, t, y))
    else:
        for v in ground_truth:
            if not (hasattr(v, "edge") and hasattr(v, "t_s") and hasattr(v, "y")):
                raise EvaluationError(f"ground_truth items need edge, t_s and y attributes, got {type(v).__name__}")
            items.append((v.edge, v.t_s, v.y))
    out: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]] = {}
    for k, t, y in items:
        if not (isinstance(k, tuple) and len(k) == 2):
            raise EvaluationError(f"ground_truth: edge key must be (object_id, receptacle_id), got {k!r}")
        key = (str(k[0]), str(k[1]))
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        y = np.asarray(y).reshape(-1)
        if t.shape != y.shape:
            raise EvaluationError(f"ground_truth {key}: t_s and y differ in length ({t.size} vs {y.size})")
        if not np.all(np.isfinite(t)):
            raise EvaluationError(f"ground_truth {key}: t_s contains NaN or inf")
        try:
            mask_codes(y)
        except EvaluationError as e:
            raise EvaluationError(f"ground_truth {key}: {e}") from None
        order = np.argsort(t, kind="stable")
        t, y = t[order], y[order].astype(np.int64)
        if t.size > 1 and np.any(np.diff(t) == 0):
            i = int(np.argmax(np.diff(t) == 0))
            raise EvaluationError(f"ground_truth {key}: duplicate grid time t_s={t[i]!r}")
        if key in out:
            raise EvaluationError(f"ground_truth: edge {key} appears twice")
        out[key] = (t, y)
    return out


def _weekdays(t_s: NDArray[np.float64], timezone: str) -> NDArray[np.int64]:
    import pandas as pd

    if t_s.size == 0:
        return np.zeros(0, dtype=np.int64)
    idx = pd.to_datetime(t_s, unit="s", utc=True).tz_convert(timezone)
    return np.asarray(idx.day_of_week, dtype=np.int64)


@dataclass(frozen=True)
class RegistryFactory:
    """Picklable factory of a registry estimator with fixed settings.

    ``factory(random_state=seed)`` passes the seed only if the estimator has a ``random_state``
    setting (deterministic estimators then repeat the same run for every seed).
    """

    name: str
    settings: tuple[tuple[str, Any], ...] = ()

    def __call__(self, *, random_state: int) -> PersistenceEstimator:
        from psg_data.estimators import get_estimator  # type: ignore[attr-defined]

        settings = dict(self.settings)
        est = get_estimator(self.name, **settings)
        if "random_state" in est.get_params() and "random_state" not in settings:
            est = get_estimator(self.name, **settings, random_state=random_state)
        return est


def _resolve_estimators(estimators: Any) -> dict[str, EstimatorFactory]:
    if isinstance(estimators, str):
        estimators = [estimators]
    if isinstance(estimators, Mapping):
        items = list(estimators.items())
    else:
        items = [(e, e) for e in estimators]
    out: dict[str, EstimatorFactory] = {}
    for name, spec in items:
        if isinstance(spec, str):
            out[str(name)] = RegistryFactory(spec)
        elif callable(spec):
            out[str(name)] = spec
        else:
            raise EvaluationError(f"estimator {name!r}: expected a registry name or a factory taking random_state=, got {type(spec).__name__}")
    if not out:
        raise EvaluationError("no estimator given; pass names or a mapping name -> factory")
    return out


# --------------------------------------------------------------------------------------------


def evaluate_persistence(
    estimators: str | Sequence[str] | Mapping[str, EstimatorFactory | str],
    train_streams: Sequence[EdgeStream],
    test_streams: Sequence[EdgeStream],
    ground_truth: Any,
    *,
    val_streams: Sequence[EdgeStream] | None = None,
    setting: Setting = "predictive",
    eval_times: EvalTimes = "observations+grid",
    timezone: str = "UTC",
    seeds: Sequence[int] = (0,),
    history: Literal["train", "train+val"] = "train",
    threshold: float = 0.5,
    convention: Literal["reference", "sklearn"] = "reference",
    sample_convention: Literal["reference", "sklearn"] = "sklearn",
    codes: Sequence[int] = PRIVILEGED_CODES,
    jobs: int = 1,
    progress: ProgressCallback | None = None,
    keep_predictions: Sequence[EdgeKey] = (),
    executor: Executor | None = None,
) -> PersistenceResult:
    """Evaluate persistence estimators on a test window against dense ground truth.

    See the module docstring for the exact protocol.

    Args:
        estimators: registry names (resolved with ``psg_data.estimators.get_estimator(name,
            random_state=seed)``; estimators without a ``random_state`` setting are built
            without it, so their seeds repeat the same run) or a mapping ``name -> factory`` where ``factory(random_state=
            seed)`` returns an unfitted :class:`~psg_data.estimators.PersistenceEstimator`.
        train_streams: training observations, one :class:`EdgeStream` per edge.
        test_streams: test-window observations (applied online in the adaptive setting).
        ground_truth: per edge a grid of times (seconds, UTC epoch) and states (1 present,
            0 absent, -1/-2 excluded): ``Mapping[edge, (t_s, y)]``, a mapping or sequence of
            objects with ``edge``/``t_s``/``y`` attributes, or a DataFrame with columns
            ``object_id, receptacle_id, t_s, y``. Every ground-truth edge is evaluated.
        val_streams: validation observations passed to ``fit``.
        setting: ``"predictive"`` (no test updates) or ``"adaptive"`` (online updates).
        eval_times: ``"observations+grid"``, ``"grid"`` or ``"observations"``.
        timezone: IANA site timezone (passed to ``fit``; weekday breakdown uses local time).
        seeds: seeds; each estimator is built and fitted once per seed.
        history: ``"train"`` (default) or ``"train+val"``: observations applied before the test
            window.
        threshold: belief threshold, present iff ``b >= threshold``.
        convention: convention of the time-integrated metrics (default ``"reference"``).
        sample_convention: convention of the per-sample metrics (default ``"sklearn"``).
        codes: ground-truth codes excluded from scoring.
        jobs: worker processes; 1 runs inline, -1 uses every CPU.
        progress: called as ``progress(done, total)`` with counts of (estimator, seed, edge)
            units after each finishes.
        keep_predictions: edges whose beliefs at every evaluation time are kept in
            ``result.traces`` (for plots).
        executor: run fits and edge chunks on this ``concurrent.futures.Executor`` (e.g. from
            :func:`psg_data._executors.open_executor`: Dask distributed) instead of a local pool
            of ``jobs`` processes; the result is the same.

    Returns:
        A :class:`PersistenceResult`; check ``result.ok`` / ``result.errors``.

    Raises:
        EvaluationError: empty test split or ground truth, bad settings, unknown timezone, or an
            estimator that cannot be sent to worker processes.
    """
    if setting not in ("predictive", "adaptive"):
        raise EvaluationError(f"setting must be 'predictive' or 'adaptive', got {setting!r}")
    if eval_times not in ("observations+grid", "grid", "observations"):
        raise EvaluationError(f"eval_times must be 'observations+grid', 'grid' or 'observations', got {eval_times!r}")
    if history not in ("train", "train+val"):
        raise EvaluationError(f"history must be 'train' or 'train+val', got {history!r}")
    _check_convention(convention)
    _check_convention(sample_convention)
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise EvaluationError("seeds is empty; pass at least one seed, e.g. seeds=(0,)")
    if len(set(seeds)) != len(seeds):
        raise EvaluationError(f"seeds must be distinct, got {seeds}")
    try:
        from zoneinfo import ZoneInfo

        ZoneInfo(timezone)
    except Exception:  # noqa: BLE001
        raise EvaluationError(f"unknown timezone {timezone!r}; expected an IANA name such as 'Europe/Zurich'") from None
    if jobs == -1:
        from psg_data._cpus import available_cpus

        jobs = available_cpus()
    if jobs < 1:
        raise EvaluationError(f"jobs must be >= 1 or -1, got {jobs}")

    factories = _resolve_estimators(estimators)
    train = _stream_dict(train_streams, "train_streams")
    test = _stream_dict(test_streams, "test_streams")
    val = _stream_dict(val_streams, "val_streams")
    n_test_obs = sum(len(s) for s in test.values())
    if n_test_obs == 0:
        raise EvaluationError(
            f"test split is empty: {len(test)} test streams with 0 observations; check the split times "
            "(nothing to adapt to and no test window to score)"
        )
    gt = _ground_truth_dict(ground_truth)
    if not gt or all(t.size == 0 for t, _ in gt.values()):
        raise EvaluationError("ground truth is empty: no edge has ground-truth times in the test window")
    unscored = sorted(set(test) - set(gt))
    if unscored:
        logger.warning("%d test edges have no ground truth and are not scored, e.g. %s", len(unscored), unscored[0])

    cfg = _Config(setting, float(threshold), convention, sample_convention, tuple(int(c) for c in codes))
    keep = {(str(k[0]), str(k[1])) for k in keep_predictions}
    edge_jobs: list[_EdgeJob] = []
    empty_t, empty_y = np.zeros(0, dtype=np.float64), np.zeros(0, dtype=np.int8)
    for key, (gt_t, gt_y) in gt.items():
        tr = train.get(key)
        hist_t, hist_y = (tr.t_s, tr.y) if tr is not None else (empty_t, empty_y)
        if history == "train+val" and key in val:
            hist_t = np.concatenate([hist_t, val[key].t_s])
            hist_y = np.concatenate([hist_y, val[key].y])
            order = np.argsort(hist_t, kind="stable")
            hist_t, hist_y = hist_t[order], hist_y[order]
        te = test.get(key)
        test_t, test_y = (te.t_s, te.y) if te is not None else (empty_t, empty_y)
        if gt_t.size:
            inside = test_t[(test_t >= gt_t[0]) & (test_t <= gt_t[-1])]
        else:
            inside = empty_t
        if eval_times == "grid":
            et = gt_t
        elif eval_times == "observations":
            et = np.unique(inside)
        else:
            et = np.union1d(gt_t, inside)
        if et.size:
            ey = gt_y[np.searchsorted(gt_t, et, side="right") - 1]
        else:
            ey = np.zeros(0, dtype=np.int64)
        edge_jobs.append(_EdgeJob(key, hist_t, hist_y, test_t, test_y, et, ey, _weekdays(et, timezone), key in keep))

    names = list(factories)
    total = len(names) * len(seeds) * len(edge_jobs)
    done = 0
    fitted: dict[tuple[str, int], PersistenceEstimator | None] = {}
    outcomes: dict[tuple[str, int, int], tuple[EdgeResult, list[WeekdayResult], list[EvaluationIssue], PredictionTrace | None]] = {}
    fit_issues: dict[tuple[str, int], EvaluationIssue] = {}
    train_list, val_list = list(train.values()), (list(val.values()) if val_streams is not None else None)

    def fit_failed(name: str, seed: int, msg: str) -> None:
        nonlocal done
        fit_issues[(name, seed)] = EvaluationIssue(name, seed, None, None, "fit", None,
                                                   f"estimator {name!r} seed {seed}: fit raised {msg}")
        for i, j in enumerate(edge_jobs):
            outcomes[(name, seed, i)] = (
                EdgeResult(name, seed, j.edge[0], j.edge[1], "error", 0, 0.0, int(j.hist_t.size), int(j.test_t.size), _nan_metrics()),
                [], [], None,
            )
        done += len(edge_jobs)
        if progress is not None:
            progress(done, total)

    if jobs == 1 and executor is None:
        for name in names:
            for seed in seeds:
                est, err = _fit(name, factories[name], seed, train_list, val_list, timezone)
                fitted[(name, seed)] = est
                if est is None:
                    fit_failed(name, seed, str(err))
                    continue
                for i, j in enumerate(edge_jobs):
                    outcomes[(name, seed, i)] = _run_edge(name, seed, est, j, cfg)
                    done += 1
                    if progress is not None:
                        progress(done, total)
    else:
        n_chunks = max(1, min(len(edge_jobs), 4 * jobs))
        chunks = [list(range(k, len(edge_jobs), n_chunks)) for k in range(n_chunks)]
        with _executor(jobs, executor) as pool:
            pending: dict[Future[Any], tuple[str, str, int, list[int]]] = {}
            for name in names:
                for seed in seeds:
                    try:
                        fut = pool.submit(_fit, name, factories[name], seed, train_list, val_list, timezone)
                    except Exception as e:  # noqa: BLE001
                        raise EvaluationError(f"estimator {name!r}: factory cannot be sent to worker processes (jobs={jobs}): {e}; use jobs=1 or a picklable factory") from None
                    pending[fut] = ("fit", name, seed, [])
            while pending:
                finished, _ = wait(list(pending), return_when=FIRST_COMPLETED)
                for fut in finished:
                    kind, name, seed, idx = pending.pop(fut)
                    try:
                        value = fut.result()
                    except BrokenProcessPool as e:
                        raise EvaluationError(
                            f"estimator {name!r} seed {seed}: a worker process died (jobs={jobs}): {e}; "
                            "scripts using jobs > 1 need an `if __name__ == '__main__':` guard; or use jobs=1"
                        ) from None
                    except Exception as e:  # noqa: BLE001 - pickling/transport failures are configuration errors
                        raise EvaluationError(
                            f"estimator {name!r} seed {seed}: could not run in a worker process (jobs={jobs}): "
                            f"{type(e).__name__}: {e}; use jobs=1 or make the factory and fitted estimator picklable"
                        ) from None
                    if kind == "fit":
                        est, err = value
                        fitted[(name, seed)] = est
                        if est is None:
                            fit_failed(name, seed, str(err))
                            continue
                        for ch in chunks:
                            jobs_ch = [edge_jobs[i] for i in ch]
                            pending[pool.submit(_run_chunk, name, seed, est, jobs_ch, cfg)] = ("edges", name, seed, ch)
                    else:
                        for i, out in zip(idx, value):
                            outcomes[(name, seed, i)] = out
                        done += len(idx)
                        if progress is not None:
                            progress(done, total)

    edges: list[EdgeResult] = []
    weekdays: list[WeekdayResult] = []
    errors: list[EvaluationIssue] = []
    traces: list[PredictionTrace] = []
    for name in names:
        for seed in seeds:
            if (name, seed) in fit_issues:
                errors.append(fit_issues[(name, seed)])
            for i in range(len(edge_jobs)):
                er, wr, iss, tr = outcomes[(name, seed, i)]
                edges.append(er)
                weekdays.extend(wr)
                errors.extend(iss)
                if tr is not None:
                    traces.append(tr)
    for e in errors:
        logger.error("%s", e.message)

    params: dict[str, Any] = {}
    for name in names:
        est = next((fitted[(name, s)] for s in seeds if fitted.get((name, s)) is not None), None)
        try:
            params[name] = est.get_params() if est is not None else None
        except Exception:  # noqa: BLE001
            params[name] = None
    config = _clean({
        "task": "persistence",
        "setting": setting,
        "eval_times": eval_times,
        "history": history,
        "timezone": timezone,
        "seeds": seeds,
        "estimators": names,
        "estimator_params": params,
        "threshold": threshold,
        "threshold_rule": "present iff belief >= threshold",
        "convention": convention,
        "sample_convention": sample_convention,
        "excluded_codes": list(cfg.codes),
        "n_edges": len(edge_jobs),
        "n_test_observations": n_test_obs,
        "n_test_edges_without_ground_truth": len(unscored),
        "edge_weighting": "time-integrated metrics: scored span; sample metrics: scored points",
        "std_ddof": 1,
    })
    result = PersistenceResult(config=config, edges=edges, weekdays=weekdays, errors=errors, traces=traces)
    _fill_summary(result)
    return result


def _executor(jobs: int, executor: Executor | None) -> contextlib.AbstractContextManager[Executor]:
    """The executor given (left open: its owner closes it), else a local spawn pool of ``jobs``."""
    if executor is not None:
        return contextlib.nullcontext(executor)
    from psg_data._executors import open_executor

    return open_executor(jobs)


def _fill_summary(result: PersistenceResult) -> None:
    seed_scores = result.seed_scores()
    for name in result.estimators:
        result.summary[name] = {
            m: summarize([seed_scores[name][s][m] for s in result.config["seeds"]])
            for m in (*TIME_METRICS, *SAMPLE_METRICS)
        }


def merge_results(results: Sequence[PersistenceResult]) -> PersistenceResult:
    """Merge runs that differ only in their seeds (e.g. one dataset draw per seed) into one result.

    The configuration of the first run is kept, with ``seeds`` the union of all seeds and per-run
    settings that differ (such as edge counts) recorded under ``per_run``.

    Raises:
        EvaluationError: no results, different estimators or settings, or a seed used twice.
    """
    if not results:
        raise EvaluationError("merge_results: nothing to merge")
    first = results[0]
    seeds: list[int] = []
    for r in results:
        if r.estimators != first.estimators or r.config.get("setting") != first.config.get("setting"):
            raise EvaluationError("merge_results: runs differ in estimators or setting; merge only runs of one configuration")
        for s in r.config["seeds"]:
            if s in seeds:
                raise EvaluationError(f"merge_results: seed {s} appears in two runs")
            seeds.append(s)
    config = dict(first.config)
    config["seeds"] = seeds
    config["per_run"] = [{k: r.config.get(k) for k in ("seeds", "n_edges", "n_test_observations")} for r in results]
    merged = PersistenceResult(
        config=config,
        edges=[e for r in results for e in r.edges],
        weekdays=[w for r in results for w in r.weekdays],
        errors=[e for r in results for e in r.errors],
        traces=[t for r in results for t in r.traces],
    )
    _fill_summary(merged)
    return merged
