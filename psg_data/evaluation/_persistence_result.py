"""What the persistence task produced, and how its numbers aggregate into a table cell.

Aggregation of one metric over a set of rows (edges, or breakdown rows of one group):

1. per (draw, seed, object): ``N = sum_e w_e m_e`` and ``D = sum_e w_e`` over the object's scored
   edges, with ``w`` the edge's scored time (time-integrated metrics, the reference's feature
   weighting) or its scored points (``sample_*`` metrics);
2. per (draw, object): the mean of N and of D over the estimator's seeds;
3. the point estimate: ``sum_o N / sum_o D`` (the draws' estimates averaged when several);
4. the interval: over >= 2 draws a t-interval of the draws' estimates; within one draw the
   object-level ratio interval (:func:`~psg_data.evaluation.ratio_interval`: bootstrap over the
   objects, jackknife-t under 10); ``std`` is the spread of the draws, or of the seeds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from psg_data.errors import EvaluationError
from psg_data.evaluation._aggregate import Summary
from psg_data.evaluation._intervals import ratio_interval, t_interval
from psg_data.evaluation._persistence_types import (
    SAMPLE_METRICS,
    TIME_METRICS,
    WEEKDAY_NAMES,
    BreakdownRow,
    EdgeResult,
    EvaluationIssue,
    PredictionTrace,
    clean_json,
)

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

__all__ = ["PersistenceResult", "summarize_rows", "merge_results"]

ALL_METRICS = (*TIME_METRICS, *SAMPLE_METRICS)


def _weights(rows: Sequence[Any], metric: str) -> list[float]:
    return [r.span_s if metric in TIME_METRICS else float(r.n_points) for r in rows]


def _object_sums(rows: Sequence[Any], metric: str) -> dict[int, dict[int, dict[str, tuple[float, float]]]]:
    """Draw -> seed -> object -> (N, D) over the rows with a finite value and positive weight."""
    out: dict[int, dict[int, dict[str, tuple[float, float]]]] = {}
    for r, w in zip(rows, _weights(rows, metric)):
        v = r.metrics.get(metric, float("nan"))
        if getattr(r, "status", "ok") != "ok" or not math.isfinite(v) or not w > 0:
            continue
        per = out.setdefault(r.draw, {}).setdefault(r.seed, {})
        n, d = per.get(r.object_id, (0.0, 0.0))
        per[r.object_id] = (n + w * v, d + w)
    return out


def _draw_objects(per_seed: dict[int, dict[str, tuple[float, float]]]) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """Object-level (N, D) averaged over seeds, and each seed's own estimate."""
    objs = sorted({o for per in per_seed.values() for o in per})
    k = len(per_seed)
    num = np.array([sum(per.get(o, (0.0, 0.0))[0] for per in per_seed.values()) / k for o in objs])
    den = np.array([sum(per.get(o, (0.0, 0.0))[1] for per in per_seed.values()) / k for o in objs])
    seed_est = [sum(n for n, _ in per.values()) / sum(d for _, d in per.values()) for per in per_seed.values()]
    return num, den, seed_est


def summarize_rows(rows: Sequence[Any], metric: str, *, confidence: float = 0.95, n_bootstrap: int = 2000,
                   seed: int = 0, draw_unit: str = "lab draws") -> Summary:
    """One table cell from per-edge (or breakdown) rows (module docstring); ``draw_unit`` names the
    draws of a multi-draw interval (``scenes`` for the navigation benchmark).
    """
    sums = _object_sums(rows, metric)
    nan = float("nan")
    if not sums:
        return Summary(nan, nan, nan, nan, 0, "none", "objects")
    per_draw = {d: _draw_objects(s) for d, s in sorted(sums.items())}
    if len(per_draw) >= 2:
        est = [float(n.sum() / dd.sum()) for n, dd, _ in per_draw.values()]
        iv = t_interval(est, confidence=confidence, unit=draw_unit)
        std = float(np.std(est, ddof=1))
        return Summary(iv.estimate, std, iv.low, iv.high, iv.n, iv.method, iv.unit)
    num, den, seed_est = next(iter(per_draw.values()))
    iv = ratio_interval(num, den, confidence=confidence, n_bootstrap=n_bootstrap, seed=seed, unit="objects")
    std = float(np.std(seed_est, ddof=1)) if len(seed_est) > 1 else 0.0
    return Summary(iv.estimate, std, iv.low, iv.high, iv.n, iv.method, iv.unit)


def _plain_mean(rows: Sequence[Any], metric: str) -> float:
    w = np.array(_weights(rows, metric), dtype=np.float64)
    v = np.array([r.metrics.get(metric, np.nan) for r in rows], dtype=np.float64)
    ok = np.isfinite(v) & (w > 0) & np.array([getattr(r, "status", "ok") == "ok" for r in rows], bool)
    return float(np.sum(w[ok] * v[ok]) / np.sum(w[ok])) if ok.any() else float("nan")


@dataclass
class PersistenceResult:
    """Everything :func:`~psg_data.evaluation.run_persistence_task` produced.

    Attributes:
        config: resolved settings of the run (setting, horizon, weighting, windows, seeds per
            estimator, conventions, counts).
        edges: one :class:`EdgeResult` per (estimator, seed, edge, draw).
        breakdown_rows: weekday and horizon breakdown rows (:class:`BreakdownRow`).
        errors: every :class:`EvaluationIssue`; non-empty means the run is not clean.
        summary: estimator -> metric -> :class:`Summary` (point estimate and stated interval).
        traces: beliefs of the edges requested with ``keep_predictions``.
    """

    config: dict[str, Any]
    edges: list[EdgeResult]
    breakdown_rows: list[BreakdownRow] = field(default_factory=list)
    errors: list[EvaluationIssue] = field(default_factory=list)
    summary: dict[str, dict[str, Summary]] = field(default_factory=dict)
    traces: list[PredictionTrace] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when no issue was recorded (the CLI exits non-zero otherwise)."""
        return not self.errors

    @property
    def estimators(self) -> list[str]:
        """The estimator names of the run, in order."""
        return list(self.config["estimators"])

    @property
    def weekdays(self) -> list[BreakdownRow]:
        """The per-weekday breakdown rows."""
        return [r for r in self.breakdown_rows if r.by == "weekday"]

    def fill_summary(self) -> None:
        """Compute :attr:`summary` from the edges (module docstring)."""
        conf, nb, bs = (float(self.config.get("confidence", 0.95)), int(self.config.get("n_bootstrap", 2000)),
                        int(self.config.get("bootstrap_seed", 0)))
        self.summary = {}
        for name in self.estimators:
            rows = [r for r in self.edges if r.estimator == name]
            unit = str(self.config.get("draw_unit", "lab draws"))
            self.summary[name] = {m: summarize_rows(rows, m, confidence=conf, n_bootstrap=nb, seed=bs, draw_unit=unit)
                                  for m in ALL_METRICS}

    def seed_spread(self, name: str, metric: str = "balanced_accuracy") -> float:
        """Largest standard deviation (ddof=1) over an estimator's seeds of its score on one draw (0 for one seed)."""
        out = 0.0
        for per_seed in _object_sums([r for r in self.edges if r.estimator == name], metric).values():
            _, _, est = _draw_objects(per_seed)
            if len(est) > 1:
                out = max(out, float(np.std(est, ddof=1)))
        return out

    def seed_scores(self) -> dict[str, dict[int, dict[str, float]]]:
        """Per (estimator, seed): metrics averaged over edges (all draws) plus edge counts."""
        out: dict[str, dict[int, dict[str, float]]] = {}
        for name in self.estimators:
            out[name] = {}
            for seed in sorted({r.seed for r in self.edges if r.estimator == name}):
                rows = [r for r in self.edges if r.estimator == name and r.seed == seed]
                d = {m: _plain_mean(rows, m) for m in ALL_METRICS}
                d["n_edges_scored"] = float(sum(r.status == "ok" for r in rows))
                d["n_edges_error"] = float(sum(r.status == "error" for r in rows))
                out[name][seed] = d
        return out

    def to_frame(self) -> pd.DataFrame:
        """Tidy table, one row per (estimator, seed, draw, edge), metrics as columns (results.csv)."""
        import pandas as pd

        cols = ["estimator", "draw", "seed", "object_id", "receptacle_id", "status", "n_points", "span_s",
                "n_train_obs", "n_test_obs", *ALL_METRICS]
        recs = []
        for r in self.edges:
            d = asdict(r)
            d.update(d.pop("metrics"))
            recs.append(d)
        return pd.DataFrame.from_records(recs, columns=cols)

    def weekday_frame(self) -> pd.DataFrame:
        """Tidy table, one row per (estimator, seed, draw, edge, weekday)."""
        import pandas as pd

        cols = ["estimator", "draw", "seed", "object_id", "receptacle_id", "weekday", "weekday_name", "span_s",
                "n_points", *ALL_METRICS]
        recs = []
        for r in self.weekdays:
            d = asdict(r)
            d["weekday"], d["weekday_name"] = int(r.key), WEEKDAY_NAMES[int(r.key)]
            d.update(d.pop("metrics"))
            recs.append(d)
        return pd.DataFrame.from_records(recs, columns=cols)

    def summary_frame(self) -> pd.DataFrame:
        """One row per (estimator, metric): mean, std, ci_low, ci_high, n, method, unit."""
        import pandas as pd

        recs = [{"estimator": name, "metric": m, **asdict(s)} for name, per in self.summary.items()
                for m, s in per.items()]
        return pd.DataFrame.from_records(recs, columns=["estimator", "metric", "mean", "std", "ci_low", "ci_high", "n",
                                                        "method", "unit"])

    def breakdown(self, by: str) -> pd.DataFrame:
        """Metrics per object, receptacle, local weekday or horizon bin, aggregated as the summary is.

        Returns:
            Columns ``estimator, <by>, metric, mean, std, ci_low, ci_high, n, method, unit``.
        """
        import pandas as pd

        rows, key = self._breakdown_rows(by)
        groups: dict[tuple[str, Any], list[Any]] = {}
        for r in rows:
            groups.setdefault((r.estimator, key(r)), []).append(r)
        conf, nb = float(self.config.get("confidence", 0.95)), int(self.config.get("n_bootstrap", 2000))
        recs = []
        for (name, k), rs in groups.items():
            for m in ALL_METRICS:
                s = summarize_rows(rs, m, confidence=conf, n_bootstrap=nb)
                recs.append({"estimator": name, by: k, "metric": m, **asdict(s)})
        return pd.DataFrame.from_records(recs, columns=["estimator", by, "metric", "mean", "std", "ci_low", "ci_high",
                                                        "n", "method", "unit"])

    def _breakdown_rows(self, by: str) -> tuple[list[Any], Callable[[Any], Any]]:
        if by == "object":
            return list(self.edges), lambda r: r.object_id
        if by == "receptacle":
            return list(self.edges), lambda r: r.receptacle_id
        if by == "weekday":
            return self.weekdays, lambda r: WEEKDAY_NAMES[int(r.key)]
        if by == "horizon":
            return [r for r in self.breakdown_rows if r.by == "horizon"], lambda r: r.key
        raise EvaluationError(f"breakdown: by must be 'object', 'receptacle', 'weekday' or 'horizon', got {by!r}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dict: config, summary, per-seed scores, errors (edges and breakdowns go to CSV files)."""
        return clean_json({
            "config": self.config, "ok": self.ok,
            "summary": {n: {m: s.to_dict() for m, s in per.items()} for n, per in self.summary.items()},
            "seeds": {n: {str(s): v for s, v in per.items()} for n, per in self.seed_scores().items()},
            "errors": [e.to_dict() for e in self.errors],
        })


def merge_results(results: Sequence[PersistenceResult], *, draw_unit: str = "lab draws") -> PersistenceResult:
    """Merge runs on different draws of a synthetic dataset (``--lab-seeds``, benchmark draws) into one result.

    The configuration of the first run is kept, with ``draws`` the union of all draws; the summary
    becomes the t-interval over draws.

    Raises:
        EvaluationError: no results, different estimators or settings, or a draw used twice.
    """
    if not results:
        raise EvaluationError("merge_results: nothing to merge")
    first = results[0]
    draws: list[int] = []
    for r in results:
        if r.estimators != first.estimators or r.config.get("setting") != first.config.get("setting"):
            raise EvaluationError("merge_results: runs differ in estimators or setting; merge only runs of one "
                                  "configuration")
        for d in r.config.get("draws", [0]):
            if d in draws:
                raise EvaluationError(f"merge_results: draw {d} appears in two runs")
            draws.append(d)
    config = dict(first.config)
    config["draws"] = draws
    config["draw_unit"] = draw_unit
    for k in ("n_edges", "n_objects"):
        v = sum(r.config.get(k, 0) for r in results) / len(results)
        config[k] = int(v) if float(v).is_integer() else round(v, 1)
    config["per_draw"] = [{k: r.config.get(k) for k in ("draws", "n_edges", "n_objects", "n_test_observations")}
                          for r in results]
    merged = PersistenceResult(config=config, edges=[e for r in results for e in r.edges],
                               breakdown_rows=[w for r in results for w in r.breakdown_rows],
                               errors=[e for r in results for e in r.errors],
                               traces=[t for r in results for t in r.traces])
    merged.fill_summary()
    return merged
