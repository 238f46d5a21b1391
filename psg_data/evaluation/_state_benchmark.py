"""Scoring estimators on a real long-term benchmark (door, room presence) under one of its protocols.

:func:`state_rows` lists the rows of a run (the user's estimators, the paper's comparison methods
and the reference rows that bound a real-data table: the hindsight upper reference, the baselines,
the authors' simple methods, chance); :func:`run_state_benchmark` fits each row once per seed and
scores every test period (:mod:`psg_data.evaluation._state_protocols`); :func:`summarize_state_run` turns the
per-period values into the mean over periods with a 95 % t-interval, the headroom and the paired
comparisons over periods. Every per-edge step is psg-eval's own (:func:`run_edge`: the same filter
loop, horizon rule, checks of plugin predictions and metric conventions).

Reference rows on real data (there is no generator model, so no exact ceiling):

- ``hindsight``: ``time_of_week_frequency`` fitted on the scored test period itself (it sees the
  answers: an upper reference, not a method);
- baselines ``last_seen``, ``time_of_week_frequency``, and the authors' ``mean`` (the training base
  rate, ``training_mean``) and ``hist`` (time-of-day bins, ``time_of_day_histogram``);
- ``fremen:n_periods=84,max_order=5,order_rule=train_mse``: FreMEn as the authors run it
  (84 periods of one week / k, orders 1-5 chosen on the training error), beside our default;
- chance ``always_absent`` (B-Acc 0.5 as any constant; its MSE is the share of present time).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.evaluation._edge_run import EdgeJob, EdgeOutcome, ScoreConfig, fit_estimator, run_edge
from psg_data.evaluation._hints import EstimatorSpec
from psg_data.evaluation._persistence_task import RegistryFactory, seeds_for
from psg_data.evaluation._state_protocols import PatrolPlan, edge_jobs, patrol_streams, score_config

__all__ = ["StateRow", "StateRunOptions", "StateRun", "state_rows", "run_state_benchmark", "summarize_state_run",
           "evaluate_state_benchmark",
           "METRICS", "LOWER_IS_BETTER", "AUTHORS_FREMEN", "HINDSIGHT"]

METRICS = ("mse", "mae", "balanced_accuracy", "f1", "top1", "top3")
"""Per-period metrics: mse (the authors'), psg-eval's time-integrated MAE / B-Acc / F1, and for a
one-hot benchmark the share of rows whose true room is ranked first (top1) or in the first three (top3)."""
LOWER_IS_BETTER = {"mse": True, "mae": True, "balanced_accuracy": False, "f1": False, "top1": False, "top3": False}
AUTHORS_FREMEN = "fremen:n_periods=84,max_order=5,order_rule=train_mse"
HINDSIGHT = "hindsight"


@dataclass(frozen=True)
class StateRow:
    """One row of a real-benchmark table: its label, the registry spec and its role."""

    label: str
    spec: EstimatorSpec
    role: str
    description: str


def _spec(label: str, name: str, **settings: Any) -> EstimatorSpec:
    return EstimatorSpec(label, name, tuple(settings.items()))


def state_rows(specs: Sequence[EstimatorSpec], *, references: bool = True) -> list[StateRow]:
    """The rows of a run: the user's specs, then (``references``) perpetua / fremen and the reference rows."""
    from psg_data.evaluation._references import PAPER_METHODS, describe_method

    rows = [StateRow(s.label, s, "method", describe_method(s.label)) for s in specs]
    if not references:
        return rows
    have = {r.label for r in rows}
    extra = [StateRow(m, EstimatorSpec.of(m), "method", describe_method(m)) for m in PAPER_METHODS]
    extra += [
        StateRow(AUTHORS_FREMEN, _spec(AUTHORS_FREMEN, "fremen", n_periods=84, max_order=5, order_rule="train_mse"),
                 "authors", "FreMEn as the authors run it: 84 periods (one week / k), orders 1-5 by training MSE"),
        StateRow(HINDSIGHT, EstimatorSpec.of("time_of_week_frequency"), "hindsight",
                 "time-of-week frequency fitted on the scored test week itself (sees the answers): upper reference"),
        StateRow("last_seen", EstimatorSpec.of("last_seen"), "baseline", describe_method("last_seen")),
        StateRow("time_of_week_frequency", EstimatorSpec.of("time_of_week_frequency"), "baseline",
                 describe_method("time_of_week_frequency")),
        StateRow("mean", EstimatorSpec.of("training_mean"), "baseline", "the training base rate (the authors' Mean)"),
        StateRow("hist", EstimatorSpec.of("time_of_day_histogram"), "baseline",
                 "training mean of the time-of-day bin, 3/4/6/12/24 bins a day by training MSE (the authors' Hist)"),
        StateRow("always_absent", EstimatorSpec.of("always_absent"), "chance", describe_method("always_absent")),
    ]
    return rows + [r for r in extra if r.label not in have]


@dataclass(frozen=True)
class StateRunOptions:
    """Settings of a run.

    Attributes:
        protocol: ``published`` or ``patrol``.
        setting: ``adaptive`` or ``predictive`` (``published`` is predictive).
        horizon_s: forecast horizon of the adaptive setting, seconds.
        patrol: the patrol (``patrol`` protocol).
        seeds: estimator seeds (``auto``: 0, 1, 2 for seed-dependent estimators, else 0).
        windows: the scored hours of each day (a :class:`~psg_data.evaluation.DailyWindows` on the
            benchmark's clock); None: every row (rows outside get code -1, excluded from every metric).
    """

    protocol: str = "patrol"
    setting: str = "adaptive"
    horizon_s: float = 7200.0
    patrol: PatrolPlan = field(default_factory=PatrolPlan)
    seeds: tuple[int, ...] | str = "auto"
    windows: Any = None

    def __post_init__(self) -> None:
        if self.protocol not in ("published", "patrol"):
            raise EvaluationError(f"protocol {self.protocol!r}; expected published or patrol")
        if self.protocol == "published" and self.setting != "predictive":
            object.__setattr__(self, "setting", "predictive")
        if not (math.isfinite(self.horizon_s) and self.horizon_s >= 0):
            raise EvaluationError(f"horizon {self.horizon_s!r} s; expected a finite duration >= 0")


@dataclass
class StateRun:
    """Per-period values of every row, and the problems met.

    Attributes:
        values: row label -> period index -> metric -> value (mean over seeds).
        periods: period labels, in order.
        errors: one line per problem (a fit or an edge that failed; the row's values are then NaN).
        fits: row label -> fit summaries (FreMEn orders, chosen bins), first seed.
        options: the run's options; info: the benchmark's provenance.
    """

    values: dict[str, list[dict[str, float]]]
    periods: list[str]
    errors: list[str]
    fits: dict[str, Any]
    options: StateRunOptions
    info: dict[str, Any]


def _streams(bench: Any, opts: StateRunOptions) -> tuple[list[EdgeStream], list[dict[EdgeKey, EdgeStream]]]:
    """Training streams and each period's test streams under the protocol."""
    if opts.protocol == "published":
        return bench.train_streams(), [{} for _ in bench.periods]
    comp = not bench.one_hot
    train = patrol_streams(bench.train, opts.patrol, bench.timezone, complement=comp, salt=0)
    tests = [{s.edge: s for s in patrol_streams(p.truth, opts.patrol, bench.timezone, complement=comp, salt=k + 1)}
             for k, p in enumerate(bench.periods)]
    return train, tests


def _scored(truth: dict[EdgeKey, Any], windows: Any) -> dict[EdgeKey, Any]:
    """The truth with rows outside the scored windows set to -1 (excluded); as is without windows."""
    if windows is None:
        return truth
    out = {}
    for e, (t, y) in truth.items():
        y2 = np.array(y, dtype=np.int64, copy=True)
        y2[~windows.contains(t) & (y2 >= 0)] = -1
        out[e] = (t, y2)
    return out


def _period_values(outcomes: list[Any], one_hot: bool) -> dict[str, float]:
    """The period's metrics from its edges' outcomes (time metrics weighted by scored time, as psg-eval)."""
    res = [o[0] for o in outcomes]
    if any(r.status == "error" for r in res):
        return {m: math.nan for m in METRICS}
    span = np.array([r.span_s for r in res])
    out = {m: float(np.sum(span * [r.metrics[m] for r in res]) / span.sum()) if span.sum() > 0 else math.nan
           for m in ("mae", "balanced_accuracy", "f1")}
    sq = [((tr.belief - tr.truth) ** 2)[tr.truth >= 0] for tr in (o[3] for o in outcomes)]
    out["mse"] = float(np.mean(np.concatenate(sq)))
    out["top1"] = out["top3"] = math.nan
    if one_hot:
        out["top1"], out["top3"] = _locate([o[3] for o in outcomes])
    return out


def _locate(traces: list[Any]) -> tuple[float, float]:
    """Share of rows whose true receptacle is ranked first / in the first three by belief (ties: listed order)."""
    b = np.stack([tr.belief for tr in traces], axis=1)
    y = np.stack([tr.truth for tr in traces], axis=1)
    ok = (y >= 0).all(axis=1) & (y == 1).any(axis=1)
    rank = np.argsort(-b[ok], axis=1, kind="stable")
    true = np.argmax(y[ok] == 1, axis=1)
    pos = np.argmax(rank == true[:, None], axis=1)
    return float(np.mean(pos < 1)), float(np.mean(pos < 3))


class _WithHistory:
    """An estimator whose filters start with their edge's training history, applied once and copied per period.

    Every test period starts from the same history (the training rows or patrol observations), so
    applying it once per edge instead of once per period gives the same filters (a deep copy each).
    """

    def __init__(self, est: Any, history: dict[EdgeKey, EdgeStream]) -> None:
        self.est, self.history = est, history
        self._ready: dict[EdgeKey, Any] = {}

    def make_filter(self, edge: EdgeKey) -> Any:
        if edge not in self._ready:
            f = self.est.make_filter(edge)
            h = self.history.get(edge)
            if h is not None and len(h):
                f.update_many(h.t_s, h.y)
            self._ready[edge] = f
        return copy.deepcopy(self._ready[edge])


@dataclass(frozen=True)
class _Setup:
    """What every job of a run shares: the training streams and each period's edge jobs (one per scored edge)."""

    train: list[EdgeStream]
    hist: dict[EdgeKey, EdgeStream]
    jobs: list[list[EdgeJob]]
    truths: list[dict[EdgeKey, Any]]
    cfg: ScoreConfig
    timezone: str

    @classmethod
    def of(cls, bench: Any, opts: StateRunOptions) -> _Setup:
        train, tests = _streams(bench, opts)
        truths = [_scored(p.truth, opts.windows) for p in bench.periods]
        jobs = [edge_jobs(truths[k], bench.scored, {}, tests[k], k, bench.timezone) for k in range(len(truths))]
        return cls(train, {s.edge: s for s in train}, jobs, truths, score_config(opts.setting, opts.horizon_s),
                   bench.timezone)


def _edge_task(label: str, seed: int, est: Any, history: EdgeStream | None, jobs: list[EdgeJob],
               cfg: ScoreConfig) -> list[EdgeOutcome]:
    """One edge of a fitted row: its filter fed the edge's training history once, then every period scored."""
    prepared: Any = _WithHistory(est, {} if history is None else {history.edge: history})
    return [run_edge(label, seed, prepared, j, cfg) for j in jobs]


def _hindsight_task(label: str, factory: Any, seed: int, truth: dict[EdgeKey, Any], jobs: list[EdgeJob],
                    cfg: ScoreConfig, timezone: str) -> tuple[list[EdgeOutcome] | None, str | None]:
    """The hindsight row on one period: fitted on the period's own scored rows, then asked with nothing else."""
    own = [EdgeStream(x, t[y >= 0], y[y >= 0]) for x, (t, y) in truth.items()]
    est, msg = fit_estimator(label, factory, seed, own, None, timezone)
    if est is None:
        return None, msg
    return [run_edge(label, seed, est, j, cfg) for j in jobs], None


_Key = tuple[Any, ...]
"""A task: ("fit", row, seed), ("edge", row, seed, edge index) or ("hindsight", row, seed, period)."""


class _Tasks:
    """The tasks of a run and their results: a fit per row and seed, then one task per edge of the fitted row
    (the hindsight row: one per period); :meth:`assemble` reads the results in the rows' order whatever order
    they completed in.
    """

    def __init__(self, bench: Any, rows: Sequence[StateRow], opts: StateRunOptions) -> None:
        self.bench, self.rows, self.setup = bench, list(rows), _Setup.of(bench, opts)
        self.factories = [RegistryFactory(r.spec.name, r.spec.settings) for r in self.rows]
        self.seeds = [seeds_for(f, opts.seeds) for f in self.factories]
        self.results: dict[_Key, Any] = {}
        self.left = [0] * len(self.rows)

    def first(self) -> list[_Key]:
        """The tasks runnable at once: every fit (and every hindsight period); the rows fitted once first.

        A row with one seed has one fit that cannot be split (on the room-presence benchmark the
        persistence filter's, 229 of about 1,000 CPU-s), while a row's seeds run side by side: started
        first, the long single fit overlaps the others instead of running alone at the end.
        """
        out: list[_Key] = []
        for i in sorted(range(len(self.rows)), key=lambda i: len(self.seeds[i]) > 1):
            r = self.rows[i]
            for s in self.seeds[i]:
                out += [("hindsight", i, s, k) for k in range(len(self.setup.jobs))] if r.role == "hindsight" \
                    else [("fit", i, s)]
        for key in out:
            self.left[key[1]] += 1
        return out

    def call(self, key: _Key) -> tuple[Callable[..., Any], tuple[Any, ...]]:
        """The function and arguments of a task."""
        kind, i, seed, j = (*key, None)[:4]
        r, su = self.rows[i], self.setup
        if kind == "fit":
            return fit_estimator, (r.label, self.factories[i], seed, su.train, None, su.timezone)
        if kind == "hindsight":
            return _hindsight_task, (r.label, self.factories[i], seed, su.truths[j], su.jobs[j], su.cfg, su.timezone)
        edge = self.bench.scored[j]
        return _edge_task, (r.label, seed, self.results[("fit", i, seed)][0], su.hist.get(edge),
                            [jobs[j] for jobs in su.jobs], su.cfg)

    def done(self, key: _Key, value: Any) -> tuple[list[_Key], bool]:
        """Record a result: the tasks it makes runnable (a fit's edges) and whether its row is complete."""
        self.results[key] = value
        i = key[1]
        new: list[_Key] = []
        if key[0] == "fit" and value[0] is not None:
            new = [("edge", i, key[2], j) for j in range(len(self.bench.scored))]
        self.left[i] += len(new) - 1
        return new, self.left[i] == 0

    def assemble(self) -> tuple[dict[str, list[dict[str, float]]], list[str], dict[str, Any]]:
        """Per-period values (mean over seeds), problems and fit digests of every row, in the rows' order."""
        values, errors, fits = {}, [], {}
        for i, r in enumerate(self.rows):
            values[r.label], errs, fits[r.label] = self._row(i)
            errors += errs
        return values, errors, fits

    def _row(self, i: int) -> tuple[list[dict[str, float]], list[str], Any]:
        r, periods = self.rows[i], self.bench.periods
        nan = {m: math.nan for m in METRICS}
        per_seed, errors, summary = [], [], None
        for seed in self.seeds[i]:
            vals: list[dict[str, float]] = []
            if r.role != "hindsight":
                est, err = self.results[("fit", i, seed)]
                if est is None:
                    errors.append(f"estimator {r.label!r} seed {seed}: fit raised {err}")
                    per_seed.append([dict(nan) for _ in periods])
                    continue
                summary = summary or getattr(est, "fit_summary_", None)
                edges = [self.results[("edge", i, seed, j)] for j in range(len(self.bench.scored))]
            for k, p in enumerate(periods):
                outs = [e[k] for e in edges] if r.role != "hindsight" else self.results[("hindsight", i, seed, k)][0]
                if outs is None:
                    errors.append(f"{r.label} {p.label}: fit raised {self.results[('hindsight', i, seed, k)][1]}")
                    vals.append(dict(nan))
                    continue
                errors += [x.message for o in outs for x in o[2]]
                vals.append(_period_values(outs, self.bench.one_hot))
            per_seed.append(vals)
        mean = [{m: float(np.mean([s[k][m] for s in per_seed])) for m in METRICS} for k in range(len(periods))]
        return mean, errors, _fit_digest(summary)


def _fit_digest(summary: Any) -> Any:
    """The part of a fit summary worth keeping: FreMEn's chosen orders (else nothing)."""
    if not isinstance(summary, dict):
        return None
    osel = summary.get("order_selection")
    if isinstance(osel, dict):
        return {"order_rule": osel.get("order_rule"),
                "orders": {k: v.get("order") for k, v in (osel.get("edges") or {}).items()}}
    return None


def run_state_benchmark(bench: Any, rows: Sequence[StateRow], opts: StateRunOptions, *,
                        executor: Any = None, progress: Callable[[int, int], None] | None = None) -> StateRun:
    """Score every row on every period of ``bench`` (a :class:`~psg_data.loaders.raw.StateBenchmark`).

    Args:
        bench: the benchmark.
        rows: from :func:`state_rows`.
        opts: protocol, setting, horizon, patrol and seeds.
        executor: a ``concurrent.futures.Executor``, or None (inline): a fit per row and seed, then one job
            per scored edge of the fitted row (the hindsight row: one per period); the results are
            assembled in the rows' order, the same as inline.
        progress: called as ``progress(done_rows, total_rows)`` when a row's last job is done.
    """
    tasks = _Tasks(bench, rows, opts)
    done_rows = 0

    def finished(key: _Key, value: Any) -> list[_Key]:
        nonlocal done_rows
        new, complete = tasks.done(key, value)
        done_rows += complete
        if complete and progress is not None:
            progress(done_rows, len(rows))
        return new

    if executor is None:
        todo = tasks.first()
        while todo:
            key = todo.pop(0)
            fn, args = tasks.call(key)
            todo[:0] = finished(key, fn(*args))
    else:
        _run_pool(tasks, executor, finished)
    values, errors, fits = tasks.assemble()
    return StateRun(values, [p.label for p in bench.periods], errors, fits, opts, dict(bench.info))


def _run_pool(tasks: _Tasks, executor: Any, finished: Callable[[_Key, Any], list[_Key]]) -> None:
    """Submit the tasks, a fit's edge tasks as soon as it is done (so both workers stay busy to the end)."""
    from concurrent.futures import FIRST_COMPLETED, wait

    def submit(key: _Key) -> Any:
        fn, args = tasks.call(key)
        return executor.submit(fn, *args)

    pending = {submit(k): k for k in tasks.first()}
    while pending:
        ready, _ = wait(list(pending), return_when=FIRST_COMPLETED)
        for fut in ready:
            key = pending.pop(fut)
            for new in finished(key, fut.result()):
                pending[submit(new)] = new


def _interval(x: NDArray[np.float64]) -> tuple[float, float, float]:
    """Mean, 95 % t half-width (:func:`~psg_data.evaluation.t_interval`) and standard deviation over periods."""
    from psg_data.evaluation._intervals import t_interval

    iv = t_interval(x, unit="test weeks")
    x = x[np.isfinite(x)]
    sd = float(np.std(x, ddof=1)) if x.size > 1 else math.nan
    return iv.estimate, iv.high - iv.estimate, sd


def summarize_state_run(run: StateRun, rows: Sequence[StateRow], *, one_hot: bool) -> dict[str, Any]:
    """Mean over periods with a 95 % t-interval per row and metric, the headroom, and paired comparisons on MSE."""
    metrics = [m for m in METRICS if one_hot or m not in ("top1", "top3")]
    summary: dict[str, dict[str, Any]] = {}
    for r in rows:
        per = run.values[r.label]
        summary[r.label] = {m: dict(zip(("mean", "half_width", "std"),
                                        _interval(np.array([p[m] for p in per], dtype=np.float64))))
                            for m in metrics}
    return {"metrics": metrics, "summary": summary, "headroom": _headroom(summary, rows, metrics),
            "comparisons": _comparisons(run, rows)}


def _headroom(summary: dict[str, Any], rows: Sequence[StateRow], metrics: Sequence[str]) -> dict[str, Any]:
    """Per metric: the hindsight value, the best baseline (and which), and hindsight minus it (signed: > 0 = room)."""
    base = [r.label for r in rows if r.role == "baseline"]
    if HINDSIGHT not in summary or not base:
        return {}
    out = {}
    for m in metrics:
        vals = {b: summary[b][m]["mean"] for b in base if math.isfinite(summary[b][m]["mean"])}
        if not vals:
            continue
        low = LOWER_IS_BETTER[m]
        best = min(vals, key=lambda b: vals[b]) if low else max(vals, key=lambda b: vals[b])
        hind = summary[HINDSIGHT][m]["mean"]
        room = (vals[best] - hind) if low else (hind - vals[best])
        out[m] = {"hindsight": hind, "best_baseline": best, "best_baseline_value": vals[best], "headroom": room}
    return out


def _comparisons(run: StateRun, rows: Sequence[StateRow]) -> list[dict[str, Any]]:
    """Paired two-sided t-tests over periods on MSE for every pair of methods and baselines (the authors' test)."""
    from scipy import stats

    labels = [r.label for r in rows if r.role in ("method", "authors", "baseline")]
    out = []
    for i, a in enumerate(labels):
        for b in labels[i + 1:]:
            xa = np.array([p["mse"] for p in run.values[a]])
            xb = np.array([p["mse"] for p in run.values[b]])
            ok = np.isfinite(xa) & np.isfinite(xb)
            d = xa[ok] - xb[ok]
            if d.size < 2 or np.all(d == d[0]):
                continue
            t, p = stats.ttest_rel(xa[ok], xb[ok])
            out.append({"a": a, "b": b, "mean_difference": float(d.mean()), "t": float(t), "p": float(p),
                        "periods": int(d.size), "lower_mse": a if d.mean() < 0 else b, "significant": bool(p < 0.05)})
    return out


def evaluate_state_benchmark(bench: Any, estimators: Sequence[str | EstimatorSpec], *, protocol: str = "published",
                             references: bool = True, jobs: int = 1, **options: Any) -> dict[str, Any]:
    """Score estimators on a :class:`~psg_data.loaders.raw.StateBenchmark` (a real benchmark, or your own streams).

    Args:
        bench: the benchmark: training rows and test periods per edge.
        estimators: registry names, or :class:`EstimatorSpec` with settings.
        protocol: ``published`` (fit on the training rows, forecast each period) or ``patrol``.
        references: also score the paper's methods and the reference rows (hindsight, baselines, chance).
        jobs: worker processes (a fit per row and seed, then one job per scored edge); 1 runs inline.
        **options: fields of :class:`StateRunOptions` (``setting``, ``horizon_s``, ``patrol``, ``seeds``,
            ``windows``).

    Returns:
        The results document (what ``results.json`` holds): per row its summary per metric (mean over
        periods, 95 % t half-width, std) and its per-period values, the headroom and the paired comparisons.
    """
    from psg_data.evaluation._state_report import state_results

    specs = [e if isinstance(e, EstimatorSpec) else EstimatorSpec.of(e) for e in estimators]
    rows = state_rows(specs, references=references)
    opts = StateRunOptions(protocol=protocol, **options)
    if jobs == 1:
        run = run_state_benchmark(bench, rows, opts)
    else:
        from psg_data._pool import process_pool

        with process_pool(jobs) as pool:
            run = run_state_benchmark(bench, rows, opts, executor=pool)
    return state_results(run, rows, summarize_state_run(run, rows, one_hot=bench.one_hot), {}, bench.name)
