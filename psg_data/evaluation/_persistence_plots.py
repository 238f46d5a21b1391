"""Figures of the persistence task, as ``matplotlib.figure.Figure`` objects (no pyplot, no backend change).

- :func:`plot_beliefs`: each estimator's belief over the test window against the ground truth, for
  the edges that change most; the time axis keeps only the scored time (nights nobody scored are
  cut out and marked), lines are broken there, wiggly lines are drawn under smooth ones, the
  legend sits under the plots and explains every symbol.
- :func:`plot_metric_bars`: MAE / B-Acc / F1 per row with the stated interval, the value on each
  bar, reference rows hatched, the chance level as a line.
- :func:`plot_horizon`: the three metrics by time since the edge's last observation.

Each writes its figure to ``out_path`` when given (:func:`save_figure`: the file there is replaced
atomically).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from psg_data.evaluation._persistence_types import PredictionTrace

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure


__all__ = ["plot_beliefs", "plot_metric_bars", "plot_horizon", "save_figure", "compressed_axis"]


def save_figure(fig: Figure, out_path: str | Path | None, dpi: int = 110) -> Figure:
    """Write ``fig`` as a PNG at ``out_path`` when one is given (another format by its suffix, as
    ``savefig``); the figure either way.

    Replaces the file atomically: an interrupted call leaves the previous file as it was.
    """
    if out_path is not None:
        from psg_data.writers._safe_output import write_atomically

        out = Path(out_path)
        fmt = os.path.splitext(out.name)[1][1:]
        if not fmt:  # what savefig does with a name without suffix: the default format, its suffix appended
            fmt = fig.canvas.get_default_filetype()
            out = out.with_name(f"{out.name.rstrip('.')}.{fmt}")
        write_atomically(out, lambda tmp: fig.savefig(tmp, format=fmt, dpi=dpi, bbox_inches="tight"))
    return fig


def compressed_axis(t_s: NDArray[np.float64], gap_factor: float = 3.0) -> tuple[NDArray[np.float64], list[int]]:
    """Positions (hours) along the scored time: every gap longer than ``gap_factor`` x the median step
    is shrunk to one median step. Returns (positions, indices where a cut starts a new segment).
    """
    t = np.asarray(t_s, np.float64)
    if t.size < 2:
        return t / 3600.0, []
    d = np.diff(t)
    step = float(np.median(d[d > 0])) if np.any(d > 0) else 1.0
    cut = d > gap_factor * step
    d2 = np.where(cut, step, d)
    return np.concatenate([[0.0], np.cumsum(d2)]) / 3600.0, [int(i) + 1 for i in np.flatnonzero(cut)]


def _broken(x: NDArray[np.float64], y: NDArray[np.float64],
            cuts: Sequence[int]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Insert NaN at the cuts so a line is not drawn across them."""
    if not cuts:
        return x, y
    xs = np.insert(x, cuts, np.nan)
    ys = np.insert(y, cuts, np.nan)
    return xs, ys


def _local_labels(t_s: NDArray[np.float64], starts: Sequence[int], timezone: str) -> list[str]:
    import pandas as pd

    idx = pd.to_datetime(t_s[list(starts)], unit="s", utc=True).tz_convert(timezone)
    return [f"{d.strftime('%a')}\n{d.strftime('%H:%M')}" for d in idx]


def _tick_starts(t_s: NDArray[np.float64], cuts: Sequence[int], timezone: str) -> list[int]:
    """Tick positions: each scored window's start; without windows (one unbroken span), each local midnight."""
    if cuts or t_s.size < 2:
        return [0, *cuts]
    import pandas as pd

    day = pd.to_datetime(t_s, unit="s", utc=True).tz_convert(timezone).normalize()
    change = np.asarray(day[1:] != day[:-1])
    return [0, *(np.flatnonzero(change) + 1).tolist()]


_FIXED_COLOURS = ("perpetua_star", "fremen", "perpetua", "process_oracle", "time_of_week_frequency", "last_seen",
                  "always_present", "always_absent", "persistence_filter", "perpetua_star_oracle",
                  "perpetua_star_schedule", "perpetua_star_annealed", "oracle", "last_seen_map", "random_receptacle")
"""Built-in methods and reference rows with a colour of their own (strong tab20 tones first)."""


def _palette() -> list[Any]:
    import matplotlib

    cmap = matplotlib.colormaps["tab20"]
    return [cmap(i) for i in range(0, 20, 2)] + [cmap(i) for i in range(1, 20, 2)]


def _colours(names: Sequence[Any]) -> list[Any]:
    """The colour of each row (a row or a method name), the same in every figure of a run (beliefs, bars,
    horizons): built-ins and reference rows have fixed ones (:data:`_FIXED_COLOURS`); other labels (a
    plugin, a variant with settings), in name order, the free colours, then any this figure does not use.
    """
    palette = _palette()
    labels = [str(getattr(n, "method", n)) for n in names]
    out: dict[str, Any] = {n: palette[_FIXED_COLOURS.index(n)] for n in labels if n in _FIXED_COLOURS}
    used = {_FIXED_COLOURS.index(n) for n in out}
    free = [k for k in range(len(_FIXED_COLOURS), len(palette))] + [k for k in range(len(_FIXED_COLOURS))
                                                                     if k not in used]
    for k, n in enumerate(sorted({n for n in labels if n not in out})):
        out[n] = palette[free[k % len(free)]]
    return [out[n] for n in labels]


def _draw_order(traces: Sequence[PredictionTrace]) -> list[PredictionTrace]:
    """Wiggly beliefs first (underneath), smooth ones on top, so that no line hides the others."""
    return sorted(traces, key=lambda tr: -float(np.sum(np.abs(np.diff(tr.belief)))))


def _wiggly(belief: NDArray[np.float64]) -> bool:
    """A belief that swings by more than 0.15 per evaluation time on average (drawn thin and light)."""
    return belief.size > 2 and float(np.mean(np.abs(np.diff(belief)))) > 0.15


def _pos_of(t: NDArray[np.float64], ref_t: NDArray[np.float64], ref_x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Positions of times ``t`` on the compressed axis of ``ref_t`` (nearest earlier grid time + offset)."""
    i = np.clip(np.searchsorted(ref_t, t, side="right") - 1, 0, ref_t.size - 1)
    return ref_x[i] + (t - ref_t[i]) / 3600.0


def _edge_panel(ax: Any, mine: list[PredictionTrace], colours: dict[str, Any], timezone: str) -> None:
    ref = mine[0]
    x, cuts = compressed_axis(ref.t_s)
    ok = (ref.truth == 0) | (ref.truth == 1)
    xs, ys = _broken(x, np.where(ok, ref.truth, np.nan).astype(float), cuts)
    ax.fill_between(xs, 0, ys, step="post", color="0.86", lw=0, label="ground truth (present)")
    for c in cuts:
        ax.axvline(x[c] - 0.5 * (x[c] - x[c - 1]), color="0.5", lw=0.8, ls=":")
    for tr in _draw_order(mine):
        xb, yb = _broken(x, tr.belief, cuts)
        busy = _wiggly(tr.belief)
        ax.plot(xb, yb, lw=0.7 if busy else 1.4, color=colours[tr.estimator], alpha=0.45 if busy else 0.95,
                label=tr.estimator, zorder=1 if busy else 2)
    if ref.obs_t_s.size:
        inside = (ref.obs_t_s >= ref.t_s[0]) & (ref.obs_t_s <= ref.t_s[-1])
        ox = _pos_of(ref.obs_t_s[inside], ref.t_s, x)
        oy = np.where(ref.obs_y[inside] == 1, 1.06, -0.06)
        ax.plot(ox, oy, "|", color="k", ms=7, mew=1.2, label="test observation (top: seen present, bottom: absent)")
    starts = _tick_starts(ref.t_s, cuts, timezone)
    ax.set_xticks(x[starts], _local_labels(ref.t_s, starts, timezone), fontsize=7)
    ax.set_ylim(-0.12, 1.12)
    ax.set_ylabel("P(present)", fontsize=8)
    ax.set_title(f"{ref.edge[0]} on {ref.edge[1]}", fontsize=9, loc="left")


def plot_beliefs(traces: Sequence[PredictionTrace], out_path: str | Path | None = None, *, timezone: str = "UTC",
                 seed: int | None = None, title: str | None = None, skip: Sequence[str] = ()) -> Figure:
    """The paper's "Persistence Belief" figure (module docstring); ``skip``: rows not drawn (e.g. flat ones).

    Returns a ``matplotlib.figure.Figure``, written as a PNG at ``out_path`` if given.
    """
    from matplotlib.figure import Figure

    traces = [t for t in traces if t.estimator not in set(skip)]
    if seed is None and traces:
        seed = min(t.seed for t in traces)
    traces = [t for t in traces if t.seed == seed and t.draw == min(tr.draw for tr in traces)]
    edges = list(dict.fromkeys(t.edge for t in traces))
    names = list(dict.fromkeys(t.estimator for t in traces))
    colours = dict(zip(names, _colours(names)))
    fig = Figure(figsize=(11, 1.9 * max(1, len(edges)) + 1.4))
    axes = fig.subplots(max(1, len(edges)), 1, squeeze=False)
    for ax, edge in zip(axes[:, 0], edges):
        _edge_panel(ax, [t for t in traces if t.edge == edge], colours, timezone)
    if not edges:
        axes[0, 0].text(0.5, 0.5, "no edge kept for plotting", ha="center", va="center", transform=axes[0, 0].transAxes)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    if handles:
        from matplotlib.lines import Line2D

        if any(compressed_axis(t.t_s)[1] for t in traces):
            handles.append(Line2D([], [], color="0.5", lw=0.8, ls=":"))
            labels.append("cut: time outside the scoring windows (not scored, not drawn)")
        if any(_wiggly(t.belief) for t in traces):
            handles.append(Line2D([], [], color="0.4", lw=0.7, alpha=0.45))
            labels.append("thin, light line: a belief that oscillates between evaluation times")
        fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7, frameon=False, bbox_to_anchor=(0.5, 0.0))
    fig.suptitle(title or f"Belief over the test window, the {len(edges)} edges whose state changes most "
                          f"(seed {seed}, local time {timezone})", fontsize=10)
    fig.tight_layout(rect=(0, 0.04 + 0.015 * math.ceil((len(names) + 3) / 3), 1, 0.97))
    return save_figure(fig, out_path)


_ROLE_HATCH = {"ceiling": "//", "baseline": "..", "chance": "xx"}


def _bar_panel(ax: Any, table: Any, metric: Any, colours: list[Any]) -> None:
    rows = table.rows
    means = np.array([r.values[metric.key].mean for r in rows], float)
    lo = np.array([r.values[metric.key].ci_low for r in rows], float)
    hi = np.array([r.values[metric.key].ci_high for r in rows], float)
    err = np.vstack([np.where(np.isfinite(lo), means - lo, 0), np.where(np.isfinite(hi), hi - means, 0)])
    x = np.arange(len(rows))
    bars = ax.bar(x, np.nan_to_num(means), yerr=np.nan_to_num(err), color=colours, capsize=3, edgecolor="0.25", lw=0.6)
    for b, r in zip(bars, rows):
        b.set_hatch(_ROLE_HATCH.get(r.role, ""))
    for xi, m, h in zip(x, means, hi):
        if math.isfinite(m):
            top = h if math.isfinite(h) else m
            ax.text(xi, min(top, 1.02) + 0.015, f"{m:.2f}", ha="center", va="bottom", fontsize=7)
    if metric.chance is not None and math.isfinite(metric.chance):
        ax.axhline(metric.chance, color="k", ls="--", lw=1.0)
    ax.set_xticks(x, [r.method for r in rows], rotation=35, ha="right", fontsize=7)
    ax.set_title(f"{metric.label} ({metric.better} is better)", fontsize=9)
    ax.set_ylim(0, 1.1)


def plot_metric_bars(results: Any, out_path: str | Path | None = None) -> Figure:
    """Bars of the table's metrics per row (module docstring). ``results``: an
    :class:`~psg_data.evaluation.EvalResults` or a :class:`~psg_data.evaluation.PersistenceResult`.
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if not hasattr(results, "tables"):
        from psg_data.evaluation._report import persistence_results

        results = persistence_results(results)
    table = results.table()
    from psg_data.evaluation._tables import ordered_rows

    table = type(table)(table.name, table.title, table.metrics, ordered_rows(table.rows), table.notes, table.groups,
                        table.count_columns, table.primary, table.spread)
    colours = _colours(table.rows)
    fig = Figure(figsize=(4.2 * len(table.metrics), 3.9))
    axes = fig.subplots(1, len(table.metrics), squeeze=False)[0]
    for ax, m in zip(axes, table.metrics):
        _bar_panel(ax, table, m, colours)
    handles: list[Any] = [Line2D([], [], color="k", ls="--", lw=1.0, label="chance (always_absent)"),
               Line2D([], [], color="k", marker="|", ls="", ms=8, label="95 % interval (see the table's ± line)")]
    handles += [Patch(facecolor="white", edgecolor="0.25", hatch=h, label=f"reference row: {role}")
                for role, h in _ROLE_HATCH.items() if any(r.role == role for r in table.rows)]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=7, frameon=False)
    fig.suptitle(table.title, fontsize=9)
    fig.tight_layout(rect=(0, 0.06, 1, 0.95))
    return save_figure(fig, out_path)


def _bin_shares(result: Any, order: list[str]) -> dict[str, float]:
    """Share of the scored time in each horizon bin (first estimator, first seed and draw)."""
    rows = [r for r in result.breakdown_rows if r.by == "horizon"]
    if not rows:
        return {}
    r0 = rows[0]
    mine = [r for r in rows if (r.estimator, r.seed, r.draw) == (r0.estimator, r0.seed, r0.draw)]
    total = sum(r.span_s for r in mine) or 1.0
    return {b: sum(r.span_s for r in mine if r.key == b) / total for b in order}


def plot_horizon(result: Any, out_path: str | Path | None = None, *, skip: Sequence[str] = ()) -> Figure:
    """The metrics by time since the edge's last observation the filter had (``by_horizon.csv``), with
    intervals; one line per row; the chance row (``always_absent``) dashed black.
    """
    from matplotlib.figure import Figure

    from psg_data.evaluation._edge_run import horizon_bin_names
    from psg_data.evaluation._report import PERSISTENCE_METRICS

    df = result.breakdown("horizon")
    order = [b for b in [*horizon_bin_names(), "no observation yet"] if b in set(df["horizon"])]
    shares = _bin_shares(result, order)
    names = [n for n in result.estimators if n not in set(skip)]
    colours = _colours(names)
    fig = Figure(figsize=(13, 4.2))
    axes = fig.subplots(1, 3)
    x = np.arange(len(order))
    for ax, key in zip(axes, ("mae", "balanced_accuracy", "f1")):
        info = PERSISTENCE_METRICS[key]
        for i, n in enumerate(names):
            d = df[(df.estimator == n) & (df.metric == key)].set_index("horizon").reindex(order)
            m = d["mean"].to_numpy(float)
            err = np.vstack([np.nan_to_num(m - d["ci_low"].to_numpy(float)),
                             np.nan_to_num(d["ci_high"].to_numpy(float) - m)])
            ax.errorbar(x + (i - (len(names) - 1) / 2) * 0.05, m, yerr=err, marker="o", ms=4, lw=1.2, capsize=2,
                        color=colours[i], label=n)
        if "always_absent" in set(df.estimator):
            c = df[(df.estimator == "always_absent") & (df.metric == key)].set_index("horizon").reindex(order)
            ax.plot(x, c["mean"].to_numpy(float), "k--", lw=1.0, label="chance (always_absent)")
        ax.set_xticks(x, [f"{b}\n{100 * shares.get(b, 0):.0f} % of the time" for b in order], fontsize=8)
        ax.set_xlim(-0.5, len(order) - 0.5)
        ax.set_xlabel("time since the edge's last observation the filter had", fontsize=8)
        ax.set_title(f"{info.label} ({info.better} is better)", fontsize=9)
    h, lab = axes[1].get_legend_handles_labels()
    fig.legend(h, lab, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=7, frameon=False)
    setting = str(result.config.get("setting_text", ""))
    fig.suptitle(f"Scores by forecast horizon ({setting}; points: estimate, bars: 95 % interval as in the table; "
                 "under each bin its share of the scored time)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, out_path)
