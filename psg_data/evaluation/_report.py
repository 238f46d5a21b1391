"""Presenting persistence results: the paper-style table, result files and PNG plots."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from psg_data.evaluation._persistence_task import PersistenceResult, PredictionTrace

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["format_persistence_table", "write_persistence_results", "plot_beliefs", "plot_metric_bars",
           "choose_plot_edges"]

_TABLE_METRICS = (("mae", "MAE", "lower"), ("balanced_accuracy", "B-Acc", "higher"), ("f1", "F1", "higher"))


def format_persistence_table(result: PersistenceResult, *, digits: int = 3) -> str:
    """A text table shaped like the paper's Table I: method, MAE, B-Acc, F1 as mean +- std over seeds.

    The best mean of each column is marked with ``*``; ``n`` is the number of seeds with a score.
    """
    names = result.estimators
    best: dict[str, float] = {}
    for key, _, better in _TABLE_METRICS:
        vals = [result.summary[n][key].mean for n in names if np.isfinite(result.summary[n][key].mean)]
        if vals:
            best[key] = min(vals) if better == "lower" else max(vals)
    header = ["Method", *(f"{label} {'(lower better)' if b == 'lower' else '(higher better)'}"
                          for _, label, b in _TABLE_METRICS), "seeds", "edges"]
    rows = []
    for n in names:
        cells = [n]
        for key, _, _ in _TABLE_METRICS:
            s = result.summary[n][key]
            if not np.isfinite(s.mean):
                cells.append("-")
                continue
            mark = "*" if key in best and abs(s.mean - best[key]) < 0.5 * 10**-digits else " "
            cells.append(f"{s.mean:.{digits}f} +- {s.std:.{digits}f}{mark}")
        cells.append(str(result.summary[n]["mae"].n))
        n_ok = len({(r.object_id, r.receptacle_id) for r in result.edges if r.estimator == n and r.status == "ok"})
        cells.append(str(n_ok))
        rows.append(cells)
    w = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    fmt = lambda cells: "  ".join(c.ljust(w[i]) if i == 0 else c.rjust(w[i]) for i, c in enumerate(cells))  # noqa: E731
    lines = [fmt(header), "  ".join("-" * x for x in w), *(fmt(r) for r in rows)]
    cfg = result.config
    lines.append(f"setting: {cfg.get('setting')}; metrics: time-integrated, {cfg.get('convention')} convention, "
                 f"present iff belief >= {cfg.get('threshold')}; std over seeds (ddof=1); * best")
    return "\n".join(lines)


def choose_plot_edges(result_or_truth: Any, k: int = 4) -> list[tuple[str, str]]:
    """The ``k`` edges whose ground truth changes most often in the test window (ties: name order)."""
    truth = result_or_truth
    scored = []
    for edge, (t, y) in truth.items():
        y = np.asarray(y)
        y = y[(y == 0) | (y == 1)]
        scored.append((-int(np.count_nonzero(np.diff(y))), edge))
    scored.sort()
    return [e for _, e in scored[:k]]


def write_persistence_results(result: PersistenceResult, out_dir: str | Path, *, info: dict[str, Any]) -> dict[str, Path]:
    """Write ``results.json`` (config, provenance, every metric), ``results.csv`` (one row per
    estimator, seed and edge), ``summary.csv`` and the per-object / receptacle / weekday breakdowns.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = result.to_dict()
    data["info"] = info
    paths = {"json": out / "results.json", "csv": out / "results.csv", "summary": out / "summary.csv",
             "by_object": out / "by_object.csv", "by_receptacle": out / "by_receptacle.csv",
             "by_weekday": out / "by_weekday.csv", "table": out / "table.txt"}
    paths["json"].write_text(json.dumps(data, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    result.to_frame().to_csv(paths["csv"], index=False)
    result.summary_frame().to_csv(paths["summary"], index=False)
    result.breakdown("object").to_csv(paths["by_object"], index=False)
    result.breakdown("receptacle").to_csv(paths["by_receptacle"], index=False)
    result.breakdown("weekday").to_csv(paths["by_weekday"], index=False)
    paths["table"].write_text(format_persistence_table(result) + "\n", encoding="utf-8")
    return paths


def _save(fig: Figure, out_path: str | Path | None, dpi: int = 110) -> Figure:
    """Write ``fig`` as a PNG at ``out_path`` when one is given; the figure either way."""
    if out_path is not None:
        out = Path(out_path)
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=dpi)
    return fig


def plot_beliefs(traces: Sequence[PredictionTrace], out_path: str | Path | None = None, *, timezone: str = "UTC",
                 seed: int | None = None, title: str | None = None) -> Figure:
    """The paper's "Persistence Belief" figure: per edge, each estimator's belief over the test
    window against the ground truth (shaded) and the test observations (ticks), local time axis.

    Returns a ``matplotlib.figure.Figure`` (no pyplot, no backend change), written as a PNG at
    ``out_path`` if given.
    """
    import matplotlib
    import pandas as pd
    from matplotlib.figure import Figure

    if seed is None and traces:
        seed = min(t.seed for t in traces)
    traces = [t for t in traces if t.seed == seed]
    edges = list(dict.fromkeys(t.edge for t in traces))
    names = list(dict.fromkeys(t.estimator for t in traces))
    fig = Figure(figsize=(11, 2.1 * max(1, len(edges)) + 0.6))
    axes = fig.subplots(max(1, len(edges)), 1, sharex=True, squeeze=False)
    colours = matplotlib.colormaps["tab10"]

    def local(t: np.ndarray) -> Any:
        return pd.to_datetime(t, unit="s", utc=True).tz_convert(timezone).tz_localize(None)

    for ax, edge in zip(axes[:, 0], edges):
        mine = [t for t in traces if t.edge == edge]
        ref = mine[0]
        ok = (ref.truth == 0) | (ref.truth == 1)
        ax.fill_between(local(ref.t_s[ok]), 0, ref.truth[ok], step="post", color="0.85", label="ground truth")
        for tr in mine:
            ax.plot(local(tr.t_s), tr.belief, lw=1.2, color=colours(names.index(tr.estimator) % 10), label=tr.estimator)
        if ref.obs_t_s.size:
            ax.plot(local(ref.obs_t_s), np.where(ref.obs_y == 1, 1.04, -0.04), "|", color="k", ms=6,
                    label="observations")
        ax.set_ylim(-0.1, 1.1)
        ax.set_ylabel("P(present)")
        ax.set_title(f"{edge[0]} on {edge[1]}", fontsize=9, loc="left")
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=min(6, len(names) + 2))
    fig.suptitle(title or f"Persistence belief over the test window (seed {seed}, local time {timezone})", fontsize=10)
    fig.tight_layout()
    return _save(fig, out_path)


def plot_metric_bars(result: PersistenceResult, out_path: str | Path | None = None) -> Figure:
    """Per-estimator bars of MAE, B-Acc and F1 (mean over seeds, error bars = std); a
    ``matplotlib.figure.Figure``, written as a PNG at ``out_path`` if given."""
    import matplotlib
    from matplotlib.figure import Figure

    names = result.estimators
    fig = Figure(figsize=(4 * len(_TABLE_METRICS), 3.4))
    axes = fig.subplots(1, len(_TABLE_METRICS))
    for ax, (key, label, better) in zip(axes, _TABLE_METRICS):
        means = [result.summary[n][key].mean for n in names]
        stds = [result.summary[n][key].std for n in names]
        ax.bar(range(len(names)), np.nan_to_num(means), yerr=np.nan_to_num(stds), color=matplotlib.colormaps["tab10"](
            np.arange(len(names)) % 10), capsize=3)
        ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
        ax.set_title(f"{label} ({better} is better)", fontsize=9)
        ax.set_ylim(0, 1)
    fig.tight_layout()
    return _save(fig, out_path)
