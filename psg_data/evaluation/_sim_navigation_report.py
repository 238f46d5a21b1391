"""The simulation navigation tables: ours (± the standard deviation across scenes, and the 95 % interval)
beside the paper's rows.

:func:`sim_summary` scores per-query records (:func:`~psg_data.evaluation._navigation_scores.summarise_navigation`
with the scene as the per-set unit: ``<metric>_std`` is the standard deviation across scenes, the
paper's ``±``; ``<metric>_ci_low`` / ``_ci_high`` the 95 % bootstrap over queries, whole queries
resampled within each column). :func:`sim_table_text` prints the paper's layout (Static presence /
Dynamic presence / Absence / Overall; SR, SPL, AR, Dist) with the paper's rows of the same protocol
(:data:`PAPER_SIM_ROWS`, from the paper's tables "Predictive Navigation" and the detailed "Adaptive
Navigation"). :func:`plot_scene_sr` draws overall SR per scene and method. :func:`readings_text` prints
the grid of the adaptive protocol's readings of the paper's open choices (and its shift-0 control) with
the headroom gaps and Perpetua* minus FreMEn paired over queries (:func:`paired_gap`);
:func:`elapsed_text` overall SR by the time since the last map update.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["PAPER_SIM_ROWS", "PAPER_SIM_COUNTS", "sim_summary", "sim_table_text", "plot_scene_sr", "SIM_COLUMNS",
           "headroom_line", "paired_gap", "readings_text", "elapsed_text", "ELAPSED_BINS_H"]

SIM_COLUMNS = (("Static presence", ("static_sr", "static_spl")), ("Dynamic presence", ("dynamic_sr", "dynamic_spl")),
               ("Absence", ("absent_ar", "absent_dist_m")), ("Overall", ("overall_sr", "overall_spl")))
_KEYS = [k for _, ks in SIM_COLUMNS for k in ks]
_HEAD = {"static_sr": "SR", "static_spl": "SPL", "dynamic_sr": "SR", "dynamic_spl": "SPL", "absent_ar": "AR",
         "absent_dist_m": "Dist m", "overall_sr": "SR", "overall_spl": "SPL"}
_COUNT = {"Static presence": "n_static", "Dynamic presence": "n_dynamic", "Absence": "n_absent"}

_P = tuple[float, float]
PAPER_SIM_ROWS: dict[str, list[tuple[str, str, tuple[_P, ...]]]] = {
    "paper-sim-predictive": [  # Table "Predictive Navigation (Simulation)": static, dynamic, absence, overall
        ("Privileged", "CG", ((51.4, 7.0), (49.3, 6.6), (0.0, 0.0), (0.0, 0.0), (46.4, 16.3), (4.4, 1.6), (35.2, 4.8),
                              (33.2, 4.9))),
        ("Privileged", "CG + LLM", ((88.1, 3.7), (81.1, 3.5), (68.5, 6.3), (44.7, 6.5), (20.2, 10.6), (17.0, 2.4),
                                    (76.4, 3.3), (68.4, 3.3))),
        ("Privileged", "CG + LLM + Hist.", ((94.4, 2.2), (88.5, 2.5), (65.6, 4.8), (41.7, 5.3), (14.3, 9.9),
                                            (17.2, 2.8), (80.0, 3.0), (73.2, 3.7))),
        ("Privileged", "Ours (FreMEn)", ((97.9, 1.1), (93.5, 1.3), (92.8, 3.1), (81.5, 4.1), (90.5, 6.1), (4.2, 1.3),
                                         (95.2, 1.4), (88.9, 2.3))),
        ("Privileged", "Ours (Perpetua*)", ((97.9, 1.1), (93.5, 1.3), (92.8, 3.1), (81.1, 3.9), (90.5, 6.1),
                                            (4.2, 1.3), (95.2, 1.4), (88.9, 2.3))),
        ("CLIP + LLM", "Ours (FreMEn)", ((68.4, 4.0), (65.2, 4.4), (73.8, 7.6), (65.3, 6.5), (90.5, 6.1), (4.5, 1.3),
                                         (71.6, 2.6), (65.0, 3.7))),
        ("CLIP + LLM", "Ours (Perpetua*)", ((68.4, 4.0), (65.2, 4.4), (76.2, 8.3), (67.0, 7.0), (90.5, 6.1),
                                            (4.5, 1.3), (71.6, 2.9), (65.1, 3.1))),
    ],
    "paper-sim-adaptive": [  # Table "Adaptive Navigation" (detailed, appendix)
        ("Privileged", "Ours (FreMEn)", ((79.3, 2.6), (78.1, 3.0), (53.0, 13.4), (48.8, 11.9), (44.4, 29.4),
                                         (9.3, 2.7), (72.0, 3.6), (70.2, 2.8))),
        ("Privileged", "Ours (Perpetua*)", ((89.3, 2.7), (83.4, 1.3), (65.4, 10.4), (56.3, 9.9), (88.9, 11.1),
                                            (7.7, 2.3), (83.2, 4.3), (75.9, 2.9))),
        ("CLIP + LLM", "Ours (FreMEn)", ((57.1, 4.8), (55.9, 4.9), (37.2, 9.4), (36.2, 8.7), (44.4, 29.4),
                                         (10.9, 3.8), (52.0, 5.7), (50.7, 5.2))),
        ("CLIP + LLM", "Ours (Perpetua*)", ((58.5, 3.6), (57.3, 3.8), (38.6, 8.7), (37.2, 8.1), (100.0, 5.1),
                                            (9.8, 4.3), (55.4, 5.1), (51.6, 4.4))),
    ],
}
"""protocol -> (perception, method, the eight columns as (value, ± std across scenes)) of the paper's tables."""

PAPER_SIM_COUNTS: dict[str, tuple[int, int, int]] = {"paper-sim-predictive": (157, 75, 18),
                                                     "paper-sim-adaptive": (80, 38, 7)}
"""The paper's query counts: static presence, dynamic presence, absence."""


def sim_summary(records: Any, names: Sequence[str]) -> tuple[Any, Any]:
    """(per-scene metrics, summary) of per-query records whose ``seed`` column is the scene."""
    from psg_data.evaluation._navigation_scores import summarise_navigation

    return summarise_navigation(records, list(names), absent_in_overall="abort_is_success", unreachable="exclude")


def _cell(row: Any, key: str, kind: str) -> str:
    scale = 1.0 if key == "absent_dist_m" else 100.0
    m = float(row[f"{key}_mean"])
    if not math.isfinite(m):
        return "-"
    if kind == "std":
        return f"{scale * m:.1f} ± {scale * float(row[f'{key}_std']):.1f}"
    lo, hi = max(float(row[f"{key}_ci_low"]), 0.0), float(row[f"{key}_ci_high"])
    hi = hi if key == "absent_dist_m" else min(hi, 1.0)  # the interval within the metric's range
    return f"[{scale * lo:.1f}, {scale * hi:.1f}]" if math.isfinite(lo) and math.isfinite(hi) else "-"


def _grid(header: list[str], rows: list[list[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    fmt = lambda r: "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))  # noqa: E731
    return [fmt(header), "-" * len(fmt(header)), *[fmt(r) for r in rows]]


def sim_table_text(summary: Any, *, protocol: str, labels: str, roles: Mapping[str, tuple[str, str]],
                   n_scenes: int, title: str | None = None, table: str | None = None) -> str:
    """The paper-shaped text table: ours (mean ± std across scenes), the 95 % intervals, the paper's rows.

    ``table``: ours as the one table renderer printed it (``format_table`` of the run's results, the
    same cells and ± as its Markdown / LaTeX forms), shown instead of this module's own grid.
    """
    r0 = summary.iloc[0]
    counts = {g: int(r0[c]) for g, c in _COUNT.items()}
    counts["Overall"] = int(r0["n_queries"]) - int(r0["n_unreachable"])
    head = ["method"] + [f"{g.split()[0]} {_HEAD[k]}" for g, ks in SIM_COLUMNS for k in ks]
    ours = []
    for _, r in summary.iterrows():
        role = roles.get(str(r["method"]), ("method", ""))[0]
        name = f"{r['method']}" + (f" [{role}]" if role != "method" else "")
        ours.append([name] + [_cell(r, k, "std") for k in _KEYS])
    if table is not None:
        lines = table.splitlines()
    else:
        lines = [title or f"{protocol}: {int(r0['n_queries'])} queries over {n_scenes} scenes, labels {labels}", ""]
        lines += _grid(head, ours)
    lines += ["", "95 % intervals over queries (whole queries resampled within each column; expanded percentile "
                  "bootstrap, jackknife-t under 10 queries; clipped to the metric's range):", ""]
    lines += _grid(head, [[row[0]] + [_cell(r, k, "ci") for k in _KEYS]
                          for row, (_, r) in zip(ours, summary.iterrows())])
    paper = PAPER_SIM_ROWS.get(protocol.split("+")[0], [])
    if paper:
        pc = PAPER_SIM_COUNTS[protocol.split("+")[0]]
        lines += ["", f"The paper's rows (ProcTHOR; {pc[0]} static, {pc[1]} dynamic present, {pc[2]} absent queries; "
                      "± std across scenes):", ""]
        lines += _grid(head, [[f"paper: {meth} [{perc}]"] + [f"{v:.1f} ± {s:.1f}" for v, s in vals]
                              for perc, meth, vals in paper])
    lines += ["", f"counts: static presence {counts['Static presence']}, dynamic presence "
              f"{counts['Dynamic presence']}, absence {counts['Absence']}, unreachable present targets (left out) "
              f"{int(r0['n_unreachable'])}",
              "± : standard deviation across scenes (ddof 1; the paper's ±); SR / SPL / AR in %, Dist in metres "
              "walked on absent targets; Overall counts a correct abort as a success (SPL 1)"]
    head_line = headroom_line(summary, roles)
    if head_line:
        lines.append(head_line)
    refs = [f"{m} = {d}" for m, (role, d) in roles.items() if role != "method"]
    if refs and table is None:  # the renderer's notes name them already
        lines.append("reference rows: " + "; ".join(refs))
    return "\n".join(lines) + "\n"


def headroom_line(summary: Any, roles: Mapping[str, tuple[str, str]]) -> str:
    """What the table can detect, in overall SR: the ceiling against the best baseline and chance, and the
    adaptation gap (``process_oracle`` minus ``process_oracle:model=train``); "" without those rows.
    """
    sr = {str(r["method"]): 100 * float(r["overall_sr_mean"]) for _, r in summary.iterrows()}
    base = {m: v for m, v in sr.items() if roles.get(m, ("", ""))[0] == "baseline"}
    chance = [v for m, v in sr.items() if roles.get(m, ("", ""))[0] == "chance"]
    if "process_oracle" not in sr or not base:
        return ""
    best = max(base, key=lambda m: base[m])
    out = (f"headroom (overall SR): process_oracle {sr['process_oracle']:.1f} against the best baseline {best} "
           f"{base[best]:.1f}" + (f" and chance {chance[0]:.1f}" if chance else ""))
    if "process_oracle:model=train" in sr:
        out += (f"; adaptation gap process_oracle - process_oracle:model=train "
                f"{sr['process_oracle'] - sr['process_oracle:model=train']:+.1f} points")
        if "fremen" in sr:
            out += (f"; process_oracle:model=train - fremen {sr['process_oracle:model=train'] - sr['fremen']:+.1f} "
                    "points (what a predictor that does not adapt could still gain)")
    return out


ELAPSED_BINS_H = (0.0, 1.0, 6.0, 24.0, 72.0, math.inf)
"""Edges of the time since the last map update, hours (:func:`elapsed_text`)."""


def _overall(records: Any, method: str) -> Any:
    """Per scored query of ``method`` ((seed, query_id) index): 1 for a success or a correct abort, else 0
    (the overall SR's terms: unreachable present targets left out).
    """
    import pandas as pd

    from psg_data.evaluation._navigation_scores import query_terms

    d = records[records["method"] == method]
    num, den = query_terms(d, absent_in_overall="abort_is_success", unreachable="exclude")["overall_sr"]
    idx = pd.MultiIndex.from_arrays([d["seed"].to_numpy(), d["query_id"].to_numpy()])
    return pd.Series(num, index=idx)[den > 0]


def paired_gap(records: Any, a: str, b: str, *, seed: int = 0) -> tuple[float, float, float, int]:
    """Overall SR of ``a`` minus ``b`` on the queries both scored, in points, with its paired 95 % interval
    (expanded percentile bootstrap over queries, or jackknife-t under 10): (gap, low, high, n queries).
    """
    from psg_data.evaluation._intervals import ratio_interval

    sa, sb = _overall(records, a), _overall(records, b)
    both = sa.index.intersection(sb.index)
    if not len(both):
        return math.nan, math.nan, math.nan, 0
    diff = sa.loc[both].to_numpy(float) - sb.loc[both].to_numpy(float)
    iv = ratio_interval(diff, [1.0] * diff.size, seed=seed, unit="queries")
    return 100 * iv.estimate, 100 * iv.low, 100 * iv.high, int(diff.size)


def _gap_cell(records: Any, a: str, b: str, names: Sequence[str], interval: bool = False) -> str:
    if a not in names or b not in names:
        return "-"
    g, lo, hi, n = paired_gap(records, a, b)
    if not n:
        return "-"
    return f"{g:+.1f}" + (f" [{lo:+.1f}, {hi:+.1f}]" if interval and math.isfinite(lo) else "")


def readings_text(records: Any, names: Sequence[str], roles: Mapping[str, tuple[str, str]],
                  readings: Sequence[tuple[str, str, str]], main: tuple[str, str, str], shifts: Sequence[str]
                  ) -> str:
    """The readings grid: per house shift and reading of the open choices, overall SR of the ceilings and the
    methods, absent AR of the methods, the two headroom gaps and Perpetua* - FreMEn with its paired 95 %
    interval. ``records`` carry ``shift``, ``last_map``, ``agent_memory``, ``absence``.
    """
    ceil = [n for n in ("process_oracle", "process_oracle:model=train") if n in names]
    meth = [n for n in names if roles.get(n, ("method", ""))[0] == "method" and n not in ceil]
    head = ["houses", "last map", "memory", "absence"] + [f"{n} SR" for n in ceil + meth] + \
        [f"{n} AR" for n in meth] + ["oracle - train", "train - fremen", "perpetua_star - fremen [95 %]"]
    rows = []
    for sh in shifts:
        for r in readings:
            d = records[(records["shift"] == sh) & (records["last_map"] == r[0]) & (records["agent_memory"] == r[1])
                        & (records["absence"] == r[2])]
            if d.empty:
                continue
            sr = {n: 100 * float(_overall(d, n).mean()) for n in ceil + meth}
            ar = [d[(d["method"] == n) & (d["category"] == "absent")]["aborted"] for n in meth]
            rows.append([sh + (" *" if r == main and sh == shifts[0] else ""), *r]
                        + [f"{sr[n]:.1f}" for n in ceil + meth]
                        + [f"{100 * a.mean():.0f} ({len(a)})" if len(a) else "-" for a in ar]
                        + [_gap_cell(d, "process_oracle", "process_oracle:model=train", names),
                           _gap_cell(d, "process_oracle:model=train", "fremen", names),
                           _gap_cell(d, "perpetua_star", "fremen", names, interval=True)])
    lines = ["Every reading of the open choices on the same draws (overall SR %, absent AR % (n); gaps in points, "
             "paired over queries; * = the table above):", ""]
    return "\n".join(lines + _grid(head, rows)) + "\n"


def elapsed_text(records: Any, names: Sequence[str], roles: Mapping[str, tuple[str, str]]) -> str:
    """Overall SR by the time from the last map update to the query (:data:`ELAPSED_BINS_H`)."""
    import numpy as np

    h = (records["t_s"] - records["t_map_s"]).to_numpy(float) / 3600.0
    b = np.digitize(h, ELAPSED_BINS_H[1:-1])
    ceil = [n for n in ("process_oracle", "process_oracle:model=train") if n in names]
    have = set(records["method"])
    show = [n for n in ceil + [n for n in names if roles.get(n, ("method", ""))[0] == "method" and n not in ceil]
            if n in have]
    labels = [f"{lo:g}-{hi:g} h" if math.isfinite(hi) else f"> {lo:g} h"
              for lo, hi in zip(ELAPSED_BINS_H[:-1], ELAPSED_BINS_H[1:])]
    rows, ns = [], []
    for k in range(len(labels)):
        d = records[b == k]
        ns.append(len(_overall(d, show[0])) if show and not d.empty else 0)
    for n in show:
        rows.append([n] + [f"{100 * float(_overall(records[b == k], n).mean()):.1f}" if ns[k] else "-"
                           for k in range(len(labels))])
    if {"perpetua_star", "fremen"} <= set(names):
        rows.append(["perpetua_star - fremen"] + [_gap_cell(records[b == k], "perpetua_star", "fremen", names)
                                                  if ns[k] else "-" for k in range(len(labels))])
    head = ["overall SR % by time since the last map update"] + [f"{lab} ({n})" for lab, n in zip(labels, ns)]
    return "\n".join(_grid(head, rows)) + "\n"


def plot_scene_sr(per_scene: Any, out_path: str | Path, *, title: str, roles: Mapping[str, tuple[str, str]]) -> Path:
    """Overall SR per scene (x) and method (markers), PNG (a ``Figure``, no pyplot: the user's backend stays)."""
    import numpy as np
    from matplotlib.figure import Figure

    from psg_data.evaluation._persistence_plots import _colours, save_figure

    methods = list(dict.fromkeys(per_scene["method"]))
    colours = _colours(methods)
    scenes = sorted(set(int(s) for s in per_scene["seed"]))
    fig = Figure(figsize=(max(8.0, 0.7 * len(scenes) + 4), 4.4))
    ax = fig.add_subplot(1, 1, 1)
    markers = "os^vD<>PX*hp"
    for k, m in enumerate(methods):
        d = per_scene[per_scene["method"] == m].set_index("seed")
        y = [100 * float(d.loc[s, "overall_sr"]) if s in d.index else np.nan for s in scenes]
        role = roles.get(m, ("method", ""))[0]
        ax.plot(range(len(scenes)), y, marker=markers[k % len(markers)], ls="-" if role == "method" else ":",
                color=colours[k],
                lw=1.5 if role == "method" else 1.0, label=m + ("" if role == "method" else f" ({role})"))
    ax.set_xticks(range(len(scenes)), [f"house {s}" for s in scenes], rotation=45, ha="right")
    ax.set_ylabel("overall SR per scene (%)")
    ax.set_ylim(-2, 102)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    out = Path(out_path)
    save_figure(fig, out)
    return out
