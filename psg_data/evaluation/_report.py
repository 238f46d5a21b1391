"""Presenting persistence results: the results schema's table with its reference rows and notes, and the files.

:func:`persistence_results` turns a :class:`~psg_data.evaluation.PersistenceResult` into the
versioned :class:`~psg_data.evaluation.EvalResults` (one table shaped like the paper's Table I,
reference rows first, a ``% of ceiling`` column, one line under the table per metric and for the
setting, the ceiling and the interval); :func:`write_persistence_results` writes it with the
per-edge CSV files and the breakdowns. Plots are in :mod:`psg_data.evaluation._persistence_plots`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from psg_data.evaluation._intervals import describe_interval
from psg_data.evaluation._persistence_result import PersistenceResult
from psg_data.evaluation._persistence_types import TIME_METRICS
from psg_data.evaluation._references import describe_method
from psg_data.evaluation._results import EvalResults, MetricInfo, ResultRow, ResultTable, save_results

__all__ = ["persistence_results", "format_persistence_table", "write_persistence_results", "choose_plot_edges",
           "PERSISTENCE_METRICS", "pct_of_ceiling"]

PERSISTENCE_METRICS: dict[str, MetricInfo] = {
    "mae": MetricInfo("mae", "MAE", "lower", "mean |truth - belief| over the scored time, 0 best"),
    "balanced_accuracy": MetricInfo("balanced_accuracy", "B-Acc", "higher",
                                    "(recall of present + recall of absent) / 2 of belief >= 0.5 per edge (reference "
                                    "convention: an edge that is always present scores at most 0.5)"),
    "f1": MetricInfo("f1", "F1", "higher", "F1 of 'present' for belief >= 0.5 per edge (0 without a true positive)"),
}


def _chance(result: PersistenceResult) -> dict[str, float]:
    """Chance level per metric: the always_absent row when it ran, else the values known without it (its
    B-Acc depends on how many edges have one state only, so it is left unknown).
    """
    if "always_absent" in result.summary:
        return {m: result.summary["always_absent"][m].mean for m in TIME_METRICS}
    return {"mae": float(result.config.get("present_share") or math.nan), "balanced_accuracy": math.nan, "f1": 0.0}


def _ceiling(rows: list[ResultRow]) -> dict[str, float]:
    out: dict[str, float] = {}
    for m, info in PERSISTENCE_METRICS.items():
        vals = [r.values[m].mean for r in rows if r.role == "ceiling" and math.isfinite(r.values[m].mean)]
        if vals:
            out[m] = min(vals) if info.better == "lower" else max(vals)
    return out


def pct_of_ceiling(value: float, ceiling: float | None, chance: float | None) -> float | None:
    """``100 (value - chance) / (ceiling - chance)``: 0 at chance, 100 at the ceiling (None if undefined)."""
    if ceiling is None or chance is None or not all(math.isfinite(x) for x in (value, ceiling, chance)):
        return None
    if abs(ceiling - chance) < 1e-12:
        return None
    return 100.0 * (value - chance) / (ceiling - chance)


def _rows(result: PersistenceResult, roles: Mapping[str, tuple[str, str]]) -> list[ResultRow]:
    seeds = result.config.get("estimator_seeds", {})
    rows = []
    for name in result.estimators:
        role, desc = roles.get(name, ("method", describe_method(name)))
        ok = {(r.draw, r.object_id, r.receptacle_id) for r in result.edges if r.estimator == name and r.status == "ok"}
        n_draws = max(1, len({r.draw for r in result.edges if r.estimator == name}))
        n_ok = len(ok) // n_draws if len(ok) % n_draws == 0 else round(len(ok) / n_draws, 1)
        rows.append(ResultRow(name, role, {m: result.summary[name][m] for m in TIME_METRICS}, desc,
                              counts={"edges": n_ok, "fits": len(seeds.get(name, [0]))}))
    return rows


def _metric_notes(metrics: list[MetricInfo], chance: dict[str, float], result: PersistenceResult) -> list[str]:
    share = result.config.get("present_share")
    out = []
    for m in metrics:
        c = chance.get(m.key)
        if m.key == "mae":
            extra = (f"; chance: always_absent {c:.3f} (objects are on their edges {100 * share:.0f} % of the scored "
                     "time), a constant 0.5 scores 0.500") if c is not None and share is not None else ""
        elif m.key == "balanced_accuracy":
            extra = (f"; chance: always_absent {c:.3f} (a constant belief scores 0.5 on an edge with both states in "
                     "the scored time, 0 or 0.5 on an edge with one)") if c is not None and math.isfinite(c) else ""
        else:
            extra = f"; chance: always_absent {c:.3f}" if c is not None and math.isfinite(c) else ""
        out.append(f"{m.label} ({m.better} is better): {m.description}{extra}")
    return out


def _setting_note(cfg: dict[str, Any]) -> str:
    text = str(cfg.get("setting_text", cfg.get("setting")))
    if cfg.get("setting") == "adaptive" and cfg.get("horizon"):
        from psg_data.evaluation._windows import format_duration

        h = format_duration(float(cfg["horizon"]))
        text += f" (a prediction at t uses the observations up to t - {h}; horizon: {cfg.get('horizon_reason')})"
    elif cfg.get("setting") == "adaptive":
        text += f" (a prediction at t uses the observations up to t; horizon: {cfg.get('horizon_reason')})"
    else:
        text += " (the test week forecast from the training data; no test observation is applied)"
    w = cfg.get("windows")
    if cfg.get("weighting") == "windows" and isinstance(w, dict):
        weight = f"time integrals inside the scoring windows {w.get('text')} ({w.get('source')}); gaps get no weight"
    else:
        weight = "plain trapezoid over the whole span (the reference's weighting)"
    labels = f"; labels {cfg['labels']} (what the estimators are fitted and updated with)" if cfg.get("labels") else ""
    return f"setting: {text}; {weight}{labels}"


def _interval_note(rows: list[ResultRow], result: PersistenceResult) -> str:
    s = next(iter(rows[0].values.values())) if rows else None
    if s is None:
        return "±: -"
    seeds = result.config.get("estimator_seeds", {})
    multi = sorted(n for n, ss in seeds.items() if len(ss) > 1)
    extra = ""
    if multi:
        spread = max(result.seed_spread(n) for n in multi)
        extra = (f"; {', '.join(multi)}: fit depends on the seed, averaged over {len(seeds[multi[0]])} fits "
                 f"(seed-to-seed std of B-Acc <= {spread:.4f}); the other rows are fitted once")
    return describe_interval(s.method, s.unit, s.n, float(result.config.get("confidence", 0.95)), extra=extra)


def _ceiling_note(rows: list[ResultRow], ceiling: dict[str, float], chance: dict[str, float]) -> str | None:
    if not ceiling:
        return None
    refs = [r for r in rows if r.role == "ceiling"]
    best = [r for r in rows if r.role != "ceiling" and r.pct_of_ceiling is not None]
    text = "ceiling: " + "; ".join(f"{r.method} = {r.description}" for r in refs)
    text += (f"; B-Acc {ceiling.get('balanced_accuracy', math.nan):.3f}, F1 {ceiling.get('f1', math.nan):.3f}, "
             f"MAE {ceiling.get('mae', math.nan):.3f} (best of the ceiling rows)")
    if best:
        top = max(best, key=lambda r: r.pct_of_ceiling or -math.inf)
        text += f"; the best other row ({top.method}) closes {top.pct_of_ceiling:.0f} % of the B-Acc gap from chance"
    c = chance.get("balanced_accuracy", math.nan)
    return text + f"; % of ceiling = 100 (B-Acc - chance) / (ceiling B-Acc - chance), chance = {c:.3f}"


def _scene_std_note(rows: list[ResultRow], n: int) -> str:
    """The standard deviation across scenes of every row (the paper's ±)."""
    parts = [f"{r.method} " + " / ".join(f"{m} {r.values[k].std:.3f}" for k, m in
                                         (("mae", "MAE"), ("balanced_accuracy", "B-Acc"), ("f1", "F1")))
             for r in rows]
    return f"std across the {n} scenes (ddof 1; the paper's ±): " + "; ".join(parts)


def persistence_results(result: PersistenceResult, *, roles: Mapping[str, tuple[str, str]] | None = None,
                        info: dict[str, Any] | None = None, title: str | None = None) -> EvalResults:
    """The results-schema form of a persistence run (module docstring).

    Args:
        result: the run.
        roles: row label -> (role, description) for reference rows (``ceiling``, ``baseline``,
            ``chance``); other rows are methods.
        info: provenance stored as ``info``.
        title: the table's title.
    """
    cfg = result.config
    rows = _rows(result, roles or {})
    chance = _chance(result)
    ceiling = _ceiling(rows)
    primary = "balanced_accuracy" if ceiling else None
    for r in rows:
        r.pct_of_ceiling = pct_of_ceiling(r.values["balanced_accuracy"].mean, ceiling.get("balanced_accuracy"),
                                          chance.get("balanced_accuracy")) if primary else None
    metrics = [PERSISTENCE_METRICS[m] for m in TIME_METRICS]
    metrics = [MetricInfo(m.key, m.label, m.better, m.description, m.scale, m.digits, chance.get(m.key))
               for m in metrics]
    notes = [*_metric_notes(metrics, chance, result), _setting_note(cfg)]
    cn = _ceiling_note(rows, ceiling, chance)
    if cn:
        notes.append(cn)
    notes.append(_interval_note(rows, result))
    draws = cfg.get("draws") or [0]
    where = (f"{len(draws)} draws of {cfg.get('dataset_kind', 'the dataset')} (seeds {min(draws)}-{max(draws)})"
             if len(draws) > 1 else str(cfg.get("dataset")))
    if len(draws) > 1 and cfg.get("draw_unit") == "scenes":
        where = f"the {len(draws)} scenes of {cfg.get('dataset_kind') or 'the benchmark'}"
        notes.insert(len(notes) - 1, _scene_std_note(rows, len(draws)))
    name = title or (f"Persistence estimation on {where} ({cfg.get('n_edges')} edges of {cfg.get('n_objects')} objects"
                     f"{' per draw' if len(draws) > 1 else ''}; {cfg.get('setting_text')})")
    first = rows[0].values["mae"] if rows else None
    interval = ({"method": first.method, "unit": first.unit, "n": first.n, "confidence": cfg.get("confidence", 0.95),
                 "text": notes[-1]} if first is not None else {})
    horizon = result.breakdown("horizon")
    horizon = horizon[horizon["metric"].isin(TIME_METRICS)]
    table = ResultTable("persistence", name, metrics, rows, notes, count_columns=["edges", "fits"], primary=primary)
    return EvalResults("persistence", [table], config=cfg, info=dict(info or {}), interval=interval,
                       breakdowns={"horizon": horizon.to_dict("records")},
                       errors=[e.to_dict() for e in result.errors])


def format_persistence_table(result: PersistenceResult, *, roles: Mapping[str, tuple[str, str]] | None = None) -> str:
    """The table and its notes as plain text (:func:`persistence_results` rendered)."""
    from psg_data.evaluation._tables import format_results

    return format_results(persistence_results(result, roles=roles))


def choose_plot_edges(result_or_truth: Any, k: int = 4) -> list[tuple[str, str]]:
    """The ``k`` edges whose ground truth changes most often in the test window (ties: name order)."""
    import numpy as np

    truth = result_or_truth
    scored = []
    for edge, (_, y) in truth.items():
        y = np.asarray(y)
        y = y[(y == 0) | (y == 1)]
        scored.append((-int(np.count_nonzero(np.diff(y))), edge))
    scored.sort()
    return [e for _, e in scored[:k]]


def write_persistence_results(result: PersistenceResult, out_dir: str | Path, *, info: dict[str, Any],
                              roles: Mapping[str, tuple[str, str]] | None = None, title: str | None = None,
                              results: EvalResults | None = None) -> dict[str, Path]:
    """Write ``results.json`` (the results schema), ``summary.csv``, ``table.txt``, ``results.csv`` (one row
    per estimator, seed, draw and edge), ``seeds.json`` and the breakdowns per object / receptacle /
    weekday / horizon (``by_*.csv``). ``results``: :func:`persistence_results` of the same arguments when
    the caller has it already (it is not computed twice).

    Replaces each of these files in ``out_dir`` atomically (an interrupted call leaves the previous
    file as it was; other files are left alone).
    """
    import json
    from functools import partial

    from psg_data.writers._safe_output import write_atomically

    out = Path(out_dir)
    if results is None:
        results = persistence_results(result, roles=roles, info=info, title=title)
    paths = save_results(results, out)
    extra = {"csv": out / "results.csv", "by_object": out / "by_object.csv", "by_receptacle": out / "by_receptacle.csv",
             "by_weekday": out / "by_weekday.csv", "by_horizon": out / "by_horizon.csv", "seeds": out / "seeds.json"}
    write_atomically(extra["csv"], lambda tmp: result.to_frame().to_csv(tmp, index=False))
    for by in ("object", "receptacle", "weekday", "horizon"):
        write_atomically(extra[f"by_{by}"], partial(result.breakdown(by).to_csv, index=False))
    seeds = json.dumps(result.to_dict()["seeds"], indent=1) + "\n"
    write_atomically(extra["seeds"], lambda tmp: tmp.write_text(seeds, encoding="utf-8"))
    return {**paths, **extra}
