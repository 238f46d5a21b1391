"""Tables, files and the figure of a real-benchmark run (:mod:`psg_data.evaluation._state_benchmark`).

What a run writes (``psg-eval --dataset door-benchmark|room-presence-benchmark``):

- ``results.json``: psg-eval's results schema (``psg-eval compare`` and ``load_results`` read its
  main table) with ``kind`` ``psg-data/state-benchmark-results`` version 1 and its own keys: the protocol, the
  benchmark's provenance, every row with its role, its summary per metric (``mean``, ``half_width``
  of the 95 % t-interval over the test weeks, ``std`` across them) and its per-week values, the
  headroom, the paired comparisons, the fits' chosen orders and the problems;
- ``table.txt`` (what was printed), ``summary.csv`` (row, metric, mean, half-width, std),
  ``per_week.csv`` (row, week, metric values), ``comparisons.csv``;
- ``per_week.png``: the mean squared error of every row in every test week.

The printed tables, in order: the headroom (hindsight upper reference against the best baseline,
printed first: a table whose headroom is small cannot separate methods), the main table (mean ±
95 % t half-width over the test weeks), the per-week mean squared errors (as the authors report
them), and the paired comparisons that are significant at 5 %.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from psg_data.evaluation._state_benchmark import LOWER_IS_BETTER, StateRow, StateRun
from psg_data.evaluation._table_formats import Grid, latex_table, markdown_table

__all__ = ["SCHEMA", "state_results", "state_tables", "render", "write_state_outputs"]

SCHEMA = "psg-data/state-benchmark-results"
LABELS = {"mse": "MSE", "mae": "MAE", "balanced_accuracy": "B-Acc", "f1": "F1", "top1": "top-1", "top3": "top-3"}
ROLE_ORDER = {"hindsight": 0, "baseline": 1, "chance": 2, "authors": 3, "method": 4}


_STANDARD_ROLE = {"hindsight": "ceiling", "baseline": "baseline", "chance": "chance", "authors": "baseline",
                  "method": "method"}
_DESCRIPTIONS = {"mse": "mean squared error of the predicted probability over the week's rows (the authors' metric)",
                 "mae": "mean |truth - belief| over the scored time", "balanced_accuracy": "(recall of present + "
                 "recall of absent) / 2 of belief >= 0.5", "f1": "F1 of present, belief >= 0.5",
                 "top1": "share of minutes whose true room is ranked first", "top3": "share of minutes whose true "
                 "room is in the first three"}


def _standard_table(doc: dict[str, Any], title: str) -> dict[str, Any]:
    """The main table in psg-eval's results schema (``psg-eval compare`` and ``load_results`` read it)."""
    n = len(doc["periods"])
    chance = next((r for r in doc["rows"] if r["role"] == "chance"), None)

    def cell(s: dict[str, Any]) -> dict[str, Any]:
        m, hw = s.get("mean"), s.get("half_width")
        lo, hi = (m - hw, m + hw) if m is not None and hw is not None else (None, None)
        return {"mean": m, "std": s.get("std"), "ci_low": lo, "ci_high": hi, "n": n, "method": "t",
                "unit": "test weeks"}
    metrics = [{"key": m, "label": LABELS[m], "better": "lower" if LOWER_IS_BETTER[m] else "higher", "digits": 4,
                "description": _DESCRIPTIONS[m],
                "chance": chance["summary"][m]["mean"] if chance else None} for m in doc["metrics"]]
    rows = [{"method": r["label"], "role": _STANDARD_ROLE[r["role"]], "description": r["description"],
             "values": {m: cell(r["summary"][m]) for m in doc["metrics"]}} for r in doc["rows"]]
    return {"name": "persistence", "title": title, "metrics": metrics, "groups": [], "count_columns": [],
            "primary": "mse", "rows": rows, "notes": [f"±: half-width of the 95 % t-interval over the {n} test weeks"]}


def state_results(run: StateRun, rows: Sequence[StateRow], summary: dict[str, Any], info: dict[str, Any],
                  title: str = "real benchmark") -> dict[str, Any]:
    """The results.json document: psg-eval's results schema (one table) plus the benchmark's own keys."""
    from psg_data.evaluation._persistence_types import clean_json

    o = run.options
    doc = {"kind": SCHEMA, "kind_version": 1, "task": "persistence", "protocol": o.protocol, "setting": o.setting,
           "horizon_s": o.horizon_s if o.setting == "adaptive" else None,
           "patrol": None if o.protocol == "published" else {"label": o.patrol.label, "p_m": o.patrol.p_m,
                                                              "p_f": o.patrol.p_f, "seed": o.patrol.seed},
           "interval": f"95 % t-interval over the {len(run.periods)} test weeks (half_width); std: across weeks",
           "periods": run.periods, "metrics": summary["metrics"], "info": {**run.info, **info},
           "rows": [{"label": r.label, "estimator": r.spec.name, "settings": dict(r.spec.settings), "role": r.role,
                     "description": r.description, "summary": summary["summary"][r.label],
                     "per_period": [{"period": p, **v} for p, v in zip(run.periods, run.values[r.label])]}
                    for r in rows],
           "headroom": summary["headroom"], "comparisons": summary["comparisons"], "fits": run.fits,
           "errors": run.errors}
    doc = clean_json(doc)
    from psg_data.evaluation._results import SCHEMA as RESULTS_SCHEMA
    from psg_data.evaluation._results import SCHEMA_VERSION

    n = len(run.periods)
    doc.update({"schema": RESULTS_SCHEMA, "schema_version": SCHEMA_VERSION, "ok": not run.errors,
                "tables": [_standard_table(doc, title)],
                "interval": {"method": "t", "unit": "test weeks", "n": n, "confidence": 0.95,
                             "text": f"±: half-width of the 95 % t-interval over the {n} test weeks"},
                "config": {"protocol": o.protocol, "setting": o.setting, "horizon_s": doc["horizon_s"]}})
    return doc


def _cell(s: dict[str, float], digits: int = 4) -> str:
    m, hw = s.get("mean"), s.get("half_width")
    if m is None or not math.isfinite(m):
        return "-"
    return f"{m:.{digits}f}" + (f" ± {hw:.{digits}f}" if hw is not None and math.isfinite(hw) else "")


def _ordered(rows: Sequence[StateRow]) -> list[StateRow]:
    return sorted(rows, key=lambda r: ROLE_ORDER.get(r.role, 9))


def _best(doc: dict[str, Any], m: str) -> float | None:
    vals = [r["summary"][m]["mean"] for r in doc["rows"] if r["role"] not in ("hindsight", "chance")
            and r["summary"][m]["mean"] is not None]
    if not vals:
        return None
    return min(vals) if LOWER_IS_BETTER[m] else max(vals)


def state_tables(doc: dict[str, Any], title: str) -> list[Grid]:
    """The headroom, main, per-week and comparison tables as :class:`Grid` (rendered per format)."""
    metrics = doc["metrics"]
    n = len(doc["periods"])
    head = Grid(f"{title}: headroom (printed first)", ["metric", "hindsight", "best baseline", "value", "headroom"],
                [False, True, False, True, True],
                [[(LABELS[m], False), (f"{h['hindsight']:.4f}", False), (h["best_baseline"], False),
                  (f"{h['best_baseline_value']:.4f}", False), (f"{h['headroom']:+.4f}", False)]
                 for m, h in doc["headroom"].items()], [],
                ["headroom = hindsight minus the best baseline, in each metric's better direction (> 0: room for a "
                 "method to beat the baselines); hindsight is time_of_week_frequency fitted on the scored week itself "
                 "(it sees the answers): an upper reference, not an exact ceiling (real data have no generator model)"])
    rows, rules = [], []
    ordered = sorted(doc["rows"], key=lambda r: ROLE_ORDER.get(r["role"], 9))
    best = {m: _best(doc, m) for m in metrics}
    for i, r in enumerate(ordered):
        cells = [(r["label"], False), (r["role"] if r["role"] != "method" else "", False)]
        for m in metrics:
            s = r["summary"][m]
            is_best = r["role"] not in ("hindsight", "chance") and s["mean"] is not None and s["mean"] == best[m]
            cells.append((_cell(s), is_best))
        rows.append(cells)
        if i + 1 < len(ordered) and r["role"] != "method" and ordered[i + 1]["role"] == "method":
            rules.append(i)
    setting = doc["setting"] + (f", horizon {doc['horizon_s'] / 3600:g} h" if doc.get("horizon_s") else "")
    notes = [f"± is the half-width of the 95 % t-interval over the {n} test weeks (paired per-week values in "
             "results.json); every estimator at its defaults, nothing tuned on the test weeks",
             f"protocol {doc['protocol']} ({setting})"
             + (f"; patrol {doc['patrol']['label']}" if doc["patrol"] else ""),
             "MSE: mean squared error of the predicted probability over the week's rows and scored edges (the "
             "authors' metric); MAE, "
             "B-Acc, F1: psg-eval's time-integrated metrics (threshold 0.5); a gap in the rows gets no weight"]
    if "top1" in metrics:
        notes.append("top-1 / top-3: share of minutes whose true room is ranked first / in the first three by "
                     "belief (chance with a random order: 0.1 / 0.3 of ten rooms)")
    main = Grid(title, ["method", "ref", *[LABELS[m] for m in metrics]], [False, False, *[True] * len(metrics)],
                rows, rules, notes, "best non-reference value marked")
    return [head, main, _per_week(doc), _comparison_grid(doc)]


def _per_week(doc: dict[str, Any]) -> Grid:
    rows = []
    for r in sorted(doc["rows"], key=lambda r: ROLE_ORDER.get(r["role"], 9)):
        vals = [p.get("mse") for p in r["per_period"]]
        rows.append([(r["label"], False), *[(f"{v:.4f}" if v is not None else "-", False) for v in vals]])
    return Grid("MSE per test week (as the authors report it)", ["method", *doc["periods"]],
                [False, *[True] * len(doc["periods"])], rows, [], [])


def _comparison_grid(doc: dict[str, Any]) -> Grid:
    sig = [c for c in doc["comparisons"] if c["significant"]]
    rows = [[(c["lower_mse"], False), (c["b"] if c["lower_mse"] == c["a"] else c["a"], False),
             (f"{abs(c['mean_difference']):.4f}", False), (f"{c['p']:.3g}", False)] for c in sig]
    return Grid(f"paired comparisons on MSE over the test weeks: {len(sig)} of {len(doc['comparisons'])} pairs "
                "differ at p < 0.05", ["lower MSE", "than", "by", "p"], [False, False, True, True], rows, [],
                ["two-sided paired t-test over the weeks (scipy.stats.ttest_rel); every pair in comparisons.csv"])


def _text(grid: Grid) -> str:
    body = [[t + (" *" if b else "") for t, b in row] for row in grid.rows]
    cols = [[h, *[row[i] for row in body]] for i, h in enumerate(grid.header)]
    width = [max(len(c) for c in col) for col in cols]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(c.rjust(w) if num else c.ljust(w) for c, w, num in zip(cells, width, grid.numeric)).rstrip()

    out = [grid.title, line(grid.header), "  ".join("-" * w for w in width)]
    for i, row in enumerate(body):
        out.append(line(row))
        if i in grid.rules:
            out.append("  ".join("-" * w for w in width))
    out += [f"  {n}" for n in grid.notes]
    return "\n".join(out)


def render(grids: Sequence[Grid], fmt: str) -> str:
    """The tables in ``fmt``: text, markdown or latex."""
    if fmt == "markdown":
        return "\n\n".join(markdown_table(g) for g in grids if g.rows)
    if fmt == "latex":
        return "\n\n".join(latex_table(g) for g in grids if g.rows)
    return "\n\n".join(_text(g) for g in grids)


def write_state_outputs(doc: dict[str, Any], out: Path, text: str, *, plots: bool = True) -> None:
    """results.json, table.txt, the CSV files and (``plots``) per_week.png into ``out`` (a staging folder)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    (out / "table.txt").write_text(text + "\n", encoding="utf-8")
    with open(out / "summary.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["row", "role", "metric", "mean", "half_width", "std"])
        for r in doc["rows"]:
            for m, s in r["summary"].items():
                w.writerow([r["label"], r["role"], m, s["mean"], s["half_width"], s["std"]])
    with open(out / "per_week.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["row", "role", "period", *doc["metrics"]])
        for r in doc["rows"]:
            for p in r["per_period"]:
                w.writerow([r["label"], r["role"], p["period"], *[p.get(m) for m in doc["metrics"]]])
    with open(out / "comparisons.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["a", "b", "mean_difference_mse", "t", "p", "periods", "lower_mse", "significant"])
        for c in doc["comparisons"]:
            w.writerow([c["a"], c["b"], c["mean_difference"], c["t"], c["p"], c["periods"], c["lower_mse"],
                        c["significant"]])
    if plots:
        _plot_weeks(doc, out / "per_week.png")


def _plot_weeks(doc: dict[str, Any], path: Path) -> None:
    from matplotlib.figure import Figure

    from psg_data.evaluation._persistence_plots import save_figure

    fig = Figure(figsize=(9, 4.5))
    ax = fig.subplots()
    from psg_data.evaluation._persistence_plots import _colours

    x = range(1, len(doc["periods"]) + 1)
    rows = sorted(doc["rows"], key=lambda r: ROLE_ORDER.get(r["role"], 9))
    colours = dict(zip([r["label"] for r in rows], _colours([r["label"] for r in rows])))
    for r in rows:
        y = [p.get("mse") if p.get("mse") is not None else float("nan") for p in r["per_period"]]
        style = {"hindsight": ":", "baseline": "--", "chance": ":", "authors": "-.", "method": "-"}[r["role"]]
        ax.plot(list(x), y, style, marker="o", ms=3, color=colours[r["label"]], label=f"{r['label']} ({r['role']})")
    ax.set_xticks(list(x), doc["periods"], rotation=30)
    ax.set_ylabel("mean squared error of P(state) (lower is better)")
    ax.set_title(f"{doc['info'].get('dataset', '')}, protocol {doc['protocol']}: error per test week")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    save_figure(fig, path)
