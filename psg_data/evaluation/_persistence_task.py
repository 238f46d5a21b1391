"""The persistence-estimation task: fit estimators, filter each edge, score against ground truth.

Protocol (what :func:`run_persistence_task` does for every estimator, seed and edge; settings in
one :class:`~psg_data.evaluation.PersistenceOptions`):

1. ``est = factory(random_state=seed).fit(train_streams, val_streams=..., timezone=...)`` once per
   estimator and seed. An estimator whose fit does not depend on the seed
   (``fit_depends_on_seed`` False) is fitted once, with the first seed.
2. ``f = est.make_filter(edge)``; ``f.update_many(...)`` with the edge's training observations
   (and its validation observations when ``history="train+val"``).
3. Evaluation times: the ground-truth grid of the edge (``eval_times="grid"``), the edge's test
   observation times inside the grid's span (``"observations"``), or both (default
   ``"observations+grid"``). Ground truth at an observation time is the grid value at the last
   grid time ``<=`` it (the grid is a step function).
4. Predictions:

   - ``setting="predictive"``: no test observation is applied; ``f.predict(all eval times)``.
   - ``setting="adaptive"`` with forecast horizon ``h`` (default: the task's, one scan interval
     of a scanned dataset): online; the prediction at ``t`` is made once the filter has exactly
     the test observations with time ``<= t - h`` (``h = 0``: the filtering posterior).

5. Checks: predictions must have one value per time, be finite and lie in [0, 1]. A violation,
   or an exception raised by the plugin, is recorded as an :class:`EvaluationIssue` naming the
   estimator, seed, edge and time; that edge is not scored and the run goes on. A fit that fails
   is recorded the same way and its edges get status ``"error"``.
6. Scores per edge: time-integrated MAE / balanced accuracy / F1 (``convention="reference"``),
   with time weights bounded by the scoring windows (``weighting="windows"``, the default for
   datasets: nights nobody scored get no weight) or the plain trapezoid (``"reference"``, the
   Sec. V-A benchmark), and the per-sample forms (``sample_*`` columns). Codes -1/-2 excluded.
7. Aggregation (:mod:`psg_data.evaluation._persistence_result`): edges are averaged with weights
   proportional to their scored time (the reference's feature weighting); the interval is a
   bootstrap over objects within one dataset and a t-interval over dataset draws.
   Breakdowns per object, receptacle, local weekday and horizon (time since the edge's last
   observation) use the same weighting.

Runs fits and edge chunks on a local spawn pool of ``jobs`` processes or on any
``concurrent.futures.Executor`` passed as ``executor`` (Dask distributed); results do not depend
on either.
"""

from __future__ import annotations

import logging
import pickle
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeKey, EdgeStream, PersistenceEstimator
from psg_data.estimators._guard import build, guarded_call
from psg_data.evaluation._dataset_task import PersistenceTask
from psg_data.evaluation._derived_rows import derived_rows
from psg_data.evaluation._edge_run import (
    Derived,
    EdgeJob,
    EdgeOutcome,
    ScoreConfig,
    fit_estimator,
    nan_metrics,
    run_chunk,
    run_edge_rows,
)
from psg_data.evaluation._options import AUTO_SEEDS, PersistenceOptions
from psg_data.evaluation._persistence_result import PersistenceResult
from psg_data.evaluation._persistence_types import EdgeResult, EvaluationIssue, clean_json
from psg_data.metrics._classification import mask_codes
from psg_data.metrics._time_weights import trapezoid_weights, window_weights

__all__ = ["run_persistence_task", "evaluate_persistence", "RegistryFactory", "resolve_estimators", "seeds_for"]

logger = logging.getLogger(__name__)

EstimatorFactory = Callable[..., PersistenceEstimator]
ProgressCallback = Callable[[int, int], None]


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


def resolve_estimators(estimators: Any) -> dict[str, EstimatorFactory]:
    """Registry names, or a mapping ``name -> registry name | factory(random_state=)`` -> name -> factory."""
    if isinstance(estimators, str):
        estimators = [estimators]
    items = list(estimators.items()) if isinstance(estimators, Mapping) else [(e, e) for e in estimators]
    out: dict[str, EstimatorFactory] = {}
    for name, spec in items:
        if isinstance(spec, str):
            out[str(name)] = RegistryFactory(spec)
        elif callable(spec):
            out[str(name)] = spec
        else:
            raise EvaluationError(f"estimator {name!r}: expected a registry name or a factory taking random_state=, "
                                  f"got {type(spec).__name__}")
    if not out:
        raise EvaluationError("no estimator given; pass names or a mapping name -> factory")
    return out


def seeds_for(factory: EstimatorFactory, seeds: tuple[int, ...] | str) -> tuple[int, ...]:
    """The seeds an estimator is fitted with (see :class:`PersistenceOptions` ``seeds``)."""
    wanted: tuple[int, ...] = AUTO_SEEDS if seeds == "auto" else tuple(int(s) for s in seeds)
    try:
        est = build("factory", factory, random_state=wanted[0])
        depends = guarded_call("factory", "fit_depends_on_seed", getattr, est, "fit_depends_on_seed", None)
        if depends is None:
            depends = "random_state" in est.get_params()
    except Exception:  # noqa: BLE001 - a broken factory is reported by the fit (guarded: SystemExit too)
        depends = True
    return wanted if depends else wanted[:1]


# -- inputs ---------------------------------------------------------------------------------------
def _stream_dict(streams: Sequence[EdgeStream] | Mapping[EdgeKey, EdgeStream] | None,
                 what: str) -> dict[EdgeKey, EdgeStream]:
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


def _truth_items(ground_truth: Any) -> list[tuple[Any, Any, Any]]:
    """(edge, t, y) triples of Mapping[edge, (t_s, y) | obj], Sequence[obj with edge/t_s/y] or a DataFrame."""
    if hasattr(ground_truth, "columns") and hasattr(ground_truth, "groupby"):  # pandas DataFrame
        if not {"object_id", "receptacle_id", "t_s", "y"} <= set(ground_truth.columns):
            raise EvaluationError("ground_truth DataFrame needs columns object_id, receptacle_id, t_s, y")
        return [((o, r), g["t_s"].to_numpy(), g["y"].to_numpy())
                for (o, r), g in ground_truth.groupby(["object_id", "receptacle_id"], sort=False)]
    items = []
    if isinstance(ground_truth, Mapping):
        for k, v in ground_truth.items():
            if hasattr(v, "t_s") and hasattr(v, "y"):
                items.append((k, v.t_s, v.y))
                continue
            try:
                t, y = v
            except (TypeError, ValueError):
                raise EvaluationError(f"ground_truth[{k!r}]: expected (t_s, y) or an object with t_s and y") from None
            items.append((k, t, y))
        return items
    for v in ground_truth:
        if not (hasattr(v, "edge") and hasattr(v, "t_s") and hasattr(v, "y")):
            raise EvaluationError(f"ground_truth items need edge, t_s and y attributes, got {type(v).__name__}")
        items.append((v.edge, v.t_s, v.y))
    return items


def ground_truth_dict(ground_truth: Any) -> dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]]:
    """Validated ground truth per edge, sorted by time (see :func:`evaluate_persistence`)."""
    out: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]] = {}
    for k, t, y in _truth_items(ground_truth):
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
        t, y = _merge_repeats(key, t, y)
        if key in out:
            raise EvaluationError(f"ground_truth: edge {key} appears twice")
        out[key] = (t, y)
    return out


def _merge_repeats(key: EdgeKey, t: NDArray[np.float64], y: NDArray[np.int64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Sorted grid with each repeated time kept once when its states agree (test periods that overlap,
    as a recording's weeks that repeat a day); refused when they do not.
    """
    same = np.diff(t) == 0 if t.size > 1 else np.zeros(0, bool)
    if not same.any():
        return t, y
    clash = same & (y[1:] != y[:-1])
    if clash.any():
        i = int(np.argmax(clash))
        raise EvaluationError(f"ground_truth {key}: time t_s={t[i]!r} appears twice with states {int(y[i])} and "
                              f"{int(y[i + 1])}; expected one state per time")
    keep = np.r_[True, ~same]
    return t[keep], y[keep]


def _weekdays(t_s: NDArray[np.float64], timezone: str) -> NDArray[np.int64]:
    import pandas as pd

    if t_s.size == 0:
        return np.zeros(0, dtype=np.int64)
    idx = pd.to_datetime(t_s, unit="s", utc=True).tz_convert(timezone)
    return np.asarray(idx.day_of_week, dtype=np.int64)


def _check_task(task: PersistenceTask, setting: str = "adaptive") -> None:
    try:
        from zoneinfo import ZoneInfo

        ZoneInfo(task.timezone)
    except Exception:  # noqa: BLE001
        raise EvaluationError(f"unknown timezone {task.timezone!r}; expected an IANA name such as "
                              "'Europe/Zurich'") from None
    n_obs = sum(len(s) for s in task.test_streams)
    if n_obs == 0 and setting != "predictive":  # the predictive setting applies none: a forecast needs no test data
        raise EvaluationError(f"test split is empty: {len(task.test_streams)} test streams with 0 observations; check "
                              "the split times (nothing to adapt to and no test window to score)")
    if not task.ground_truth or all(np.size(t) == 0 for t, _ in task.ground_truth.values()):
        raise EvaluationError("ground truth is empty: no edge has ground-truth times in the test window")


def _eval_times(gt_t: NDArray[np.float64], test_t: NDArray[np.float64], eval_times: str) -> NDArray[np.float64]:
    inside = test_t[(test_t >= gt_t[0]) & (test_t <= gt_t[-1])] if gt_t.size else np.zeros(0)
    if eval_times == "grid":
        return gt_t
    if eval_times == "observations":
        return np.unique(inside)
    return np.union1d(gt_t, inside)


def _edge_jobs(task: PersistenceTask, opts: PersistenceOptions, keep: set[EdgeKey]) -> list[EdgeJob]:
    """One :class:`EdgeJob` per ground-truth edge: history, test observations, evaluation times and weights."""
    train, test = _stream_dict(task.train_streams, "train_streams"), _stream_dict(task.test_streams, "test_streams")
    val = _stream_dict(task.val_streams, "val_streams")
    gt = ground_truth_dict(task.ground_truth)
    unscored = sorted(set(test) - set(gt))
    if unscored:
        logger.warning("%d test edges have no ground truth and are not scored, e.g. %s", len(unscored), unscored[0])
    empty_t, empty_y = np.zeros(0, dtype=np.float64), np.zeros(0, dtype=np.int8)
    windows = opts.windows_or_none
    jobs = []
    for key, (gt_t, gt_y) in gt.items():
        tr = train.get(key)
        hist_t, hist_y = (tr.t_s, tr.y) if tr is not None else (empty_t, empty_y)
        if opts.history == "train+val" and key in val:
            hist_t, hist_y = np.concatenate([hist_t, val[key].t_s]), np.concatenate([hist_y, val[key].y])
            order = np.argsort(hist_t, kind="stable")
            hist_t, hist_y = hist_t[order], hist_y[order]
        te = test.get(key)
        test_t, test_y = (np.asarray(te.t_s, np.float64), te.y) if te is not None else (empty_t, empty_y)
        et = _eval_times(gt_t, test_t, opts.eval_times)
        ey = gt_y[np.searchsorted(gt_t, et, side="right") - 1] if et.size else np.zeros(0, dtype=np.int64)
        valid = mask_codes(ey, opts.codes)
        w = (trapezoid_weights(et, valid) if windows is None or et.size < 2
             else window_weights(et, windows.intervals(float(et[0]), float(et[-1])), valid))
        jobs.append(EdgeJob(key, hist_t, hist_y, test_t, test_y, et, ey, w, _weekdays(et, task.timezone),
                            key in keep, task.draw))
    return jobs


# -- execution --------------------------------------------------------------------------------------
@dataclass
class _Run:
    """The state of one evaluation while its fits and edge chunks complete."""

    factories: dict[str, EstimatorFactory]
    seeds: dict[str, tuple[int, ...]]
    jobs: list[EdgeJob]
    cfg: ScoreConfig
    task: PersistenceTask
    progress: ProgressCallback | None
    done: int = 0

    def __post_init__(self) -> None:
        self.outcomes: dict[tuple[str, int, int], EdgeOutcome] = {}
        self.fitted: dict[tuple[str, int], PersistenceEstimator | None] = {}
        self.fit_issues: dict[tuple[str, int], EvaluationIssue] = {}
        self.total = sum(len(s) for s in self.seeds.values()) * len(self.jobs)
        self.derived = derived_rows({n: (f.name, dict(f.settings)) for n, f in self.factories.items()
                                     if isinstance(f, RegistryFactory)}, self.seeds)
        self.children: dict[str, list[Derived]] = {}
        for d, row in self.derived.items():
            self.children.setdefault(row.base, []).append((d, row.fn))

    def pairs(self) -> list[tuple[str, int]]:
        return [(n, s) for n in self.factories for s in self.seeds[n]]

    def fit_pairs(self) -> list[tuple[str, int]]:
        """The pairs that are fitted and filtered: all but the rows scored from another row's predictions."""
        return [(n, s) for n, s in self.pairs() if n not in self.derived]

    def store(self, name: str, seed: int, i: int, outs: list[EdgeOutcome]) -> None:
        """Job ``i``'s outcomes of ``name`` and of its derived rows (:func:`run_edge_rows`' order)."""
        for n, out in zip([name, *(d for d, _ in self.children.get(name, ()))], outs):
            self.outcomes[(n, seed, i)] = out
        self.advance(len(outs))

    def advance(self, k: int) -> None:
        self.done += k
        if self.progress is not None:
            self.progress(self.done, self.total)

    def fit_failed(self, name: str, seed: int, msg: str) -> None:
        """Every edge of ``name`` (and of its derived rows, whose fit is this one) an error."""
        for n in [name, *(d for d, _ in self.children.get(name, ()))]:
            self.fit_issues[(n, seed)] = EvaluationIssue(n, seed, None, None, "fit", None,
                                                         f"estimator {n!r} seed {seed}: {msg}")
            for i, j in enumerate(self.jobs):
                self.outcomes[(n, seed, i)] = (EdgeResult(n, seed, j.edge[0], j.edge[1], "error", 0, 0.0,
                                                          int(j.hist_t.size), int(j.test_t.size), nan_metrics(),
                                                          j.draw), [], [], None)
            self.advance(len(self.jobs))

    def fit_args(self, name: str, seed: int) -> tuple[Any, ...]:
        t = self.task
        val = list(t.val_streams) if t.val_streams is not None else None
        return name, self.factories[name], seed, list(t.train_streams), val, t.timezone


def _execute_inline(run: _Run) -> None:
    for name, seed in run.fit_pairs():
        est, err = fit_estimator(*run.fit_args(name, seed))
        run.fitted[(name, seed)] = est
        if est is None:
            run.fit_failed(name, seed, str(err))
            continue
        for i, j in enumerate(run.jobs):
            run.store(name, seed, i, run_edge_rows(name, seed, est, j, run.cfg, run.children.get(name, ())))


def _worker_error(name: str, seed: int, jobs: int, e: BaseException) -> EvaluationError:
    if isinstance(e, BrokenProcessPool):
        return EvaluationError(f"estimator {name!r} seed {seed}: a worker process died (jobs={jobs}): {e}; "
                               "scripts using jobs > 1 need an `if __name__ == '__main__':` guard; or use jobs=1")
    return EvaluationError(f"estimator {name!r} seed {seed}: could not run in a worker process (jobs={jobs}): "
                           f"{type(e).__name__}: {e}; use jobs=1 or make the factory and fitted estimator picklable")


def _execute_pool(run: _Run, pool: Executor, jobs: int) -> None:
    n_chunks = max(1, min(len(run.jobs), 4 * jobs))
    chunks = [list(range(k, len(run.jobs), n_chunks)) for k in range(n_chunks)]
    pending: dict[Future[Any], tuple[str, str, int, list[int]]] = {}
    for name in run.factories if isinstance(pool, ProcessPoolExecutor) else ():
        try:  # checked here: a pickling failure inside the pool races with stopping it (CPython 3.11)
            pickle.dumps(run.factories[name])
        except Exception as e:  # noqa: BLE001
            raise EvaluationError(f"estimator {name!r}: factory cannot be sent to worker processes (jobs={jobs}): "
                                  f"{type(e).__name__}: {e}; use jobs=1 or a picklable factory") from None
    for name, seed in run.fit_pairs():
        pending[pool.submit(fit_estimator, *run.fit_args(name, seed))] = ("fit", name, seed, [])
    while pending:
        finished, _ = wait(list(pending), return_when=FIRST_COMPLETED)
        for fut in finished:
            kind, name, seed, idx = pending.pop(fut)
            try:
                value = fut.result()
            except Exception as e:  # noqa: BLE001 - transport failures are configuration errors
                raise _worker_error(name, seed, jobs, e) from None
            if kind == "edges":
                for i, outs in zip(idx, value):
                    run.store(name, seed, i, outs)
                continue
            est, err = value
            run.fitted[(name, seed)] = est
            if est is None:
                run.fit_failed(name, seed, str(err))
                continue
            for ch in chunks:
                fut2 = pool.submit(run_chunk, name, seed, est, [run.jobs[i] for i in ch], run.cfg,
                                   run.children.get(name, []))
                pending[fut2] = ("edges", name, seed, ch)


def _open_pool(jobs: int, executor: Executor | None) -> Any:
    """The executor given (left open: its owner closes it), else a local spawn pool of ``jobs``."""
    import contextlib

    if executor is not None:
        return contextlib.nullcontext(executor)
    from psg_data._executors import open_executor

    return open_executor(jobs)


def _resolve_jobs(jobs: int) -> int:
    if jobs == -1:
        from psg_data._cpus import available_cpus

        return available_cpus()
    if jobs < 1:
        raise EvaluationError(f"jobs must be >= 1 or -1, got {jobs}")
    return jobs


# -- assembly ---------------------------------------------------------------------------------------
def _estimator_params(run: _Run) -> dict[str, Any]:
    params: dict[str, Any] = {}
    for name in run.factories:
        if name in run.derived:
            params[name] = run.derived[name].params
            continue
        est = next((run.fitted[(name, s)] for s in run.seeds[name] if run.fitted.get((name, s)) is not None), None)
        try:
            params[name] = est.get_params() if est is not None else None
        except Exception:  # noqa: BLE001
            params[name] = None
    return params


def _config(run: _Run, opts: PersistenceOptions) -> dict[str, Any]:
    task = run.task
    return clean_json({
        "task": "persistence", "dataset": task.name, "dataset_kind": task.protocol.get("kind", task.info.get("kind")),
        **opts.to_dict(),
        "setting_text": opts.describe_setting(), "horizon_reason": task.horizon_reason,
        "seeds": sorted({s for ss in run.seeds.values() for s in ss}),
        "estimator_seeds": {n: list(s) for n, s in run.seeds.items()},
        "estimators": list(run.factories), "estimator_params": _estimator_params(run),
        "threshold_rule": "present iff belief >= threshold", "excluded_codes": list(opts.codes),
        **({"derived_rows": {d: row.base for d, row in run.derived.items()}} if run.derived else {}),
        "n_edges": len(run.jobs), "n_objects": len({j.edge[0] for j in run.jobs}),
        "n_test_observations": int(sum(j.test_t.size for j in run.jobs)),
        "edge_weighting": "time-integrated metrics: scored time; sample metrics: scored points",
        "cadence_s": task.cadence_s, "draws": [task.draw], "present_share": _present_share(run.jobs, opts),
        "labels": task.info.get("labels_spec"), "label_seed": task.info.get("label_seed"),
    })


def _present_share(jobs: Sequence[EdgeJob], opts: PersistenceOptions) -> float:
    """Share of the scored time the objects are present on their edges (always_absent's MAE)."""
    num = den = 0.0
    for j in jobs:
        valid = mask_codes(j.eval_y, opts.codes)
        num += float(np.sum(j.eval_w[valid] * (j.eval_y[valid] == 1)))
        den += float(np.sum(j.eval_w[valid]))
    return num / den if den > 0 else float("nan")


def _assemble(run: _Run, opts: PersistenceOptions) -> PersistenceResult:
    edges, rows, errors, traces = [], [], [], []
    for name, seed in run.pairs():
        if (name, seed) in run.fit_issues:
            errors.append(run.fit_issues[(name, seed)])
        for i in range(len(run.jobs)):
            er, br, iss, tr = run.outcomes[(name, seed, i)]
            edges.append(er)
            rows.extend(br)
            errors.extend(iss)
            if tr is not None:
                traces.append(tr)
    for e in errors:
        logger.error("%s", e.message)
    result = PersistenceResult(config=_config(run, opts), edges=edges, breakdown_rows=rows, errors=errors,
                               traces=traces)
    result.fill_summary()
    return result


def run_persistence_task(estimators: Any, task: PersistenceTask, options: PersistenceOptions | None = None, *,
                         jobs: int = 1, executor: Executor | None = None, progress: ProgressCallback | None = None,
                         keep_predictions: Sequence[EdgeKey] = ()) -> PersistenceResult:
    """Evaluate persistence estimators on a task (see the module docstring for the protocol).

    Args:
        estimators: registry names (built with ``get_estimator(name, random_state=seed)``) or a
            mapping ``name -> registry name | factory(random_state=seed)``.
        task: the inputs (:func:`~psg_data.evaluation.persistence_task_from_dataset` and friends).
        options: the settings (default :class:`PersistenceOptions`, ``auto`` fields decided by the task).
        jobs: worker processes; 1 runs inline, -1 uses every CPU.
        executor: run fits and edge chunks on this executor instead of a local pool of ``jobs``.
        progress: called as ``progress(done, total)`` with counts of (estimator, seed, edge) units.
        keep_predictions: edges whose beliefs at every evaluation time are kept in ``result.traces``.

    Returns:
        A :class:`~psg_data.evaluation.PersistenceResult`; check ``result.ok`` / ``result.errors``.

    Raises:
        EvaluationError: empty test split (adaptive setting) or ground truth, bad settings, unknown
            timezone, or an estimator that cannot be sent to worker processes.
    """
    given = options or PersistenceOptions()
    opts = given.resolve(task)
    _check_task(task, str(opts.setting))
    jobs = _resolve_jobs(jobs)
    factories = resolve_estimators(estimators)
    cfg = ScoreConfig(opts.setting, float(opts.horizon), float(opts.threshold), opts.convention,  # type: ignore[arg-type]
                      opts.sample_convention, tuple(opts.codes))
    keep = {(str(k[0]), str(k[1])) for k in keep_predictions}
    run = _Run(factories, {n: seeds_for(f, opts.seeds) for n, f in factories.items()}, _edge_jobs(task, opts, keep),
               cfg, task, progress)
    if jobs == 1 and executor is None:
        _execute_inline(run)
    else:
        with _open_pool(jobs, executor) as pool:
            _execute_pool(run, pool, jobs)
    result = _assemble(run, opts)
    if given.horizon != "auto":
        result.config["horizon_reason"] = "set by the caller (--horizon)"
    return result


def evaluate_persistence(estimators: Any, train_streams: Sequence[EdgeStream], test_streams: Sequence[EdgeStream],
                         ground_truth: Any, *, val_streams: Sequence[EdgeStream] | None = None, timezone: str = "UTC",
                         options: PersistenceOptions | None = None, jobs: int = 1,
                         progress: ProgressCallback | None = None, keep_predictions: Sequence[EdgeKey] = (),
                         executor: Executor | None = None, **settings: Any) -> PersistenceResult:
    """:func:`run_persistence_task` on bare streams (no dataset: no scoring windows, no cadence).

    Args:
        estimators: as in :func:`run_persistence_task`.
        train_streams: training observations, one :class:`EdgeStream` per edge.
        test_streams: test-window observations (applied online in the adaptive setting).
        ground_truth: per edge a grid of times (seconds, UTC epoch) and states (1 present,
            0 absent, -1/-2 excluded): ``Mapping[edge, (t_s, y)]``, a mapping or sequence of
            objects with ``edge``/``t_s``/``y`` attributes, or a DataFrame with columns
            ``object_id, receptacle_id, t_s, y``. Every ground-truth edge is evaluated.
        val_streams: validation observations passed to ``fit``.
        timezone: IANA site timezone (passed to ``fit``; the weekday breakdown uses local time).
        options: the settings; or give them as keywords (``setting="predictive"``, ``seeds=(0, 1)``,
            ``horizon="2h"``, ``windows="9-17"``, ...: fields of :class:`PersistenceOptions`).
            Without windows the plain trapezoid is used and the horizon ``auto`` is 0.
        jobs: as in :func:`run_persistence_task`.
        progress: as in :func:`run_persistence_task`.
        keep_predictions: as in :func:`run_persistence_task`.
        executor: as in :func:`run_persistence_task`.
        **settings: fields of :class:`PersistenceOptions` (when ``options`` is not given).
    """
    if options is not None and settings:
        raise EvaluationError("evaluate_persistence: pass options= or keyword settings, not both")
    opts = options if options is not None else PersistenceOptions().replace(**settings)
    task = PersistenceTask("streams", list(_stream_dict(train_streams, "train_streams").values()),
                           list(_stream_dict(test_streams, "test_streams").values()), ground_truth_dict(ground_truth),
                           timezone, list(_stream_dict(val_streams, "val_streams").values()) if val_streams is not None
                           else None, info={"dataset": "streams"})
    return run_persistence_task(estimators, task, opts, jobs=jobs, executor=executor, progress=progress,
                                keep_predictions=keep_predictions)
