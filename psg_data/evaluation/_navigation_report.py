"""Presenting navigation results: the paper-shaped table in the results schema, the files, the figures.

:func:`navigation_results` turns a :class:`~psg_data.navigation.NavigationResult` into
:class:`~psg_data.evaluation.EvalResults` (the ``sim`` layout of the paper's "Predictive
Navigation" table or the ``real`` layout of its "Real-World Navigation" table, reference rows
first, a delta-sweep table when there is one); :func:`write_navigation_results` writes it with the
per-query records; :func:`choose_map_query` picks the query the maps show (a dynamic target on
which the methods disagree); :func:`plot_delta_sweep` draws SR / AR against delta.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from psg_data.evaluation._aggregate import Summary
from psg_data.evaluation._intervals import MIN_BOOTSTRAP_UNITS
from psg_data.evaluation._references import describe_method
from psg_data.evaluation._report import pct_of_ceiling
from psg_data.evaluation._results import EvalResults, MetricInfo, ResultRow, ResultTable, save_results

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["navigation_results", "write_navigation_results", "choose_map_query", "plot_delta_sweep", "NAV_METRICS"]

NAV_METRICS: dict[str, MetricInfo] = {
    "static_sr": MetricInfo("static_sr", "SR %", "higher", "success rate on present targets that did not move since "
                            "the last map update", 100.0, 1),
    "static_spl": MetricInfo("static_spl", "SPL %", "higher", "success weighted by shortest / walked path length "
                             "(Anderson et al. 2018)", 100.0, 1),
    "dynamic_sr": MetricInfo("dynamic_sr", "SR %", "higher", "success rate on present targets that moved", 100.0, 1),
    "dynamic_spl": MetricInfo("dynamic_spl", "SPL %", "higher", "SPL on moved targets", 100.0, 1),
    "absent_ar": MetricInfo("absent_ar", "AR %", "higher", "correct abort rate on targets absent from the scene",
                            100.0, 1),
    "absent_dist_m": MetricInfo("absent_dist_m", "Dist m", "lower", "metres walked before giving up on an absent "
                                "target", 1.0, 1),
    "overall_sr": MetricInfo("overall_sr", "SR %", "higher", "success over reachable present and absent targets "
                             "(a correct abort counts as success)", 100.0, 1),
    "overall_spl": MetricInfo("overall_spl", "SPL %", "higher", "SPL over the same queries", 100.0, 1),
}

_LAYOUTS = {
    "sim": [("Static presence", ["static_sr", "static_spl"]), ("Dynamic presence", ["dynamic_sr", "dynamic_spl"]),
            ("Absence", ["absent_ar", "absent_dist_m"]), ("Overall", ["overall_sr", "overall_spl"])],
    "real": [("Static", ["static_sr"]), ("Dynamic", ["dynamic_sr"]), ("Absent", ["absent_ar"]),
             ("Overall", ["overall_sr"])],
}
_COUNT = {"Static presence": "n_static", "Dynamic presence": "n_dynamic", "Absence": "n_absent", "Static": "n_static",
          "Dynamic": "n_dynamic", "Absent": "n_absent"}


def _summary_of(row: Any, m: str) -> Summary:
    g = lambda k: float(row.get(f"{m}_{k}", math.nan))  # noqa: E731
    return Summary(g("mean"), g("std"), g("ci_low"), g("ci_high"), int(row.get(f"{m}_n", 0) or 0),
                   str(row.get(f"{m}_method", "none")), "queries")


def _rows(summary: Any, metrics: list[str], roles: Mapping[str, tuple[str, str]]) -> list[ResultRow]:
    out = []
    for _, r in summary.iterrows():
        name = str(r["method"])
        role, desc = roles.get(name, ("method", describe_method(name)))
        out.append(ResultRow(name, role, {m: _summary_of(r, m) for m in metrics}, desc,
                             counts={"queries": int(r["n_queries"]), "query sets": int(r["n_seeds"])}))
    return out


def _groups(layout: str, summary: Any, cfg: dict[str, Any]) -> list[tuple[str, list[str]]]:
    r0 = summary.iloc[0] if len(summary) else None
    out = []
    for g, ks in _LAYOUTS[layout]:
        if g == "Overall":
            n = (int(r0["n_queries"]) - (int(r0["n_unreachable"]) if cfg.get("unreachable") == "exclude" else 0)
                 if r0 is not None else 0)
        else:
            n = int(r0[_COUNT[g]]) if r0 is not None else 0
        out.append((f"{g} ({n})", ks))
    return out


_KINDS = {
    "SR": ("higher", "success rate; static = present targets that did not move since the last map update, dynamic = "
                     "moved, overall = reachable present and absent targets (a correct abort is a success)"),
    "SPL": ("higher", "success weighted by shortest / walked path length (Anderson et al. 2018)"),
    "AR": ("higher", "correct abort rate on targets absent from the scene"),
    "Dist": ("lower", "metres walked before giving up on an absent target"),
}


def _per_set_unit(cfg: Mapping[str, Any]) -> str:
    return "scenes" if cfg.get("env") == "navigation-benchmark" else "query sets"


def _notes(rows: list[ResultRow], metrics: list[str], res: Any, spread: str = "interval") -> list[str]:
    cfg = res.config
    chance = next((r for r in rows if r.role == "chance"), None)
    out = []
    for kind, (better, text) in _KINDS.items():
        keys = [m for m in metrics if NAV_METRICS[m].label.split()[0] == kind]
        if not keys:
            continue
        line = f"{kind} ({better} is better): {text}"
        if chance is not None:
            vals = ", ".join(f"{m.split('_')[0]} {NAV_METRICS[m].scale * chance.values[m].mean:.1f}" for m in keys
                             if math.isfinite(chance.values[m].mean))
            line += f"; chance ({chance.method}): {vals}" if vals else ""
        out.append(line)
    w = cfg.get("windows") or {}
    where = ("inside the scoring windows " + str(w.get("text")) if cfg.get("query_windows") != "none" and w
             else "at any time after the map")
    doors = "as in each row's brackets" if cfg.get("door_modes") else cfg.get("door_belief")
    out.append(f"protocol {cfg.get('protocol')}: {cfg.get('setting')} agent, delta {cfg.get('delta')}, "
               f"{cfg.get('max_attempts')} attempts, doors {doors}, labels {cfg.get('labels', 'gt')}; "
               f"query times {where}; scored against the {cfg.get('truth', 'schedule')} at the query time; "
               f"unreachable present targets: {int(res.summary['n_unreachable'].iloc[0]) if len(res.summary) else 0} "
               f"(rule: {cfg.get('unreachable')})")
    refs = [r for r in rows if r.role != "method"]
    if refs:
        out.append("reference rows: " + "; ".join(f"{r.method} = {r.description}" for r in refs))
    s = next((v for r in rows for v in r.values.values() if v.method != "none"), None)
    n_sets = len(cfg.get("seeds") or [])
    if s is None:
        out.append("±: -")
        return out
    if spread == "std":
        out.append(f"±: standard deviation across the {n_sets} {_per_set_unit(cfg)} (ddof 1; the paper's ±), not an "
                   "interval; the 95 % intervals over queries are ci_low / ci_high in results.json and summary.csv")
        return out
    groups = {"static": "static_sr", "dynamic": "dynamic_sr", "absent": "absent_ar", "overall": "overall_sr"}
    counts = {g: v.n for g, key in groups.items() if (v := rows[0].values.get(key)) is not None}
    what = ", ".join(f"{k} {n}" for k, n in counts.items())
    out.append(f"±: half-width of the 95 % interval over each column's queries, resampled whole ({what}; {n_sets} "
               f"query sets pooled): expanded percentile bootstrap, or a jackknife t-interval under "
               f"{MIN_BOOTSTRAP_UNITS} queries")
    return out


def _main_table(res: Any, roles: Mapping[str, tuple[str, str]], layout: str, spread: str) -> ResultTable:
    if layout == "auto":
        layout = "real" if str(res.config.get("protocol", "")).startswith("paper-real") else "sim"
    groups = _groups(layout, res.summary, res.config)
    metrics = [k for _, ks in groups for k in ks]
    rows = _rows(res.summary, metrics, roles)
    ceiling = next((r for r in rows if r.role == "ceiling"), None)
    chance = next((r for r in rows if r.role == "chance"), None)
    primary = "overall_sr" if ceiling is not None else None
    if primary and ceiling is not None:
        for r in rows:
            r.pct_of_ceiling = pct_of_ceiling(r.values[primary].mean, ceiling.values[primary].mean,
                                              chance.values[primary].mean if chance else 0.0)
    infos = [NAV_METRICS[m] for m in metrics]
    if chance is not None:
        infos = [MetricInfo(i.key, i.label, i.better, i.description, i.scale, i.digits, chance.values[i.key].mean)
                 for i in infos]
    n = int(res.summary["n_queries"].iloc[0]) // max(1, len(res.config.get("seeds") or [1])) if len(res.summary) else 0
    title = (f"Object navigation on {res.config.get('env')} ({n} queries x {len(res.config.get('seeds') or [])} query "
             f"sets, protocol {res.config.get('protocol')}, {res.config.get('setting')}, delta "
             f"{res.config.get('delta')})")
    return ResultTable("navigation", title, infos, rows, _notes(rows, metrics, res, spread), groups,
                       ["queries", "query sets"], primary, spread)


def _sweep_table(res: Any, roles: Mapping[str, tuple[str, str]]) -> ResultTable | None:
    if res.sweep is None:
        return None
    keys = ["overall_sr", "dynamic_sr", "absent_ar"]
    rows = []
    order = {m: i for i, m in enumerate(res.config.get("methods", []))}
    sweep = res.sweep.assign(_o=res.sweep["method"].map(order)).sort_values(["_o", "delta"], kind="stable")
    for _, r in sweep.iterrows():
        role = roles.get(str(r["method"]), ("method", ""))[0]
        rows.append(ResultRow(f"{r['method']} @ {r['delta']:g}", role, {m: _summary_of(r, m) for m in keys},
                              counts={"delta": f"{r['delta']:g}"}))
    infos = [MetricInfo(k, f"{'overall' if k == 'overall_sr' else k.split('_')[0]} {NAV_METRICS[k].label}",
                        NAV_METRICS[k].better, NAV_METRICS[k].description, 100.0, 1) for k in keys]
    notes = ["delta: the agent declares the target absent when no untried receptacle has a belief >= delta; a low "
             "delta finds more moved objects and aborts less on absent ones (delta_sweep.png)"]
    return ResultTable("delta_sweep", "Delta sweep (same queries and filters for every delta)", infos, rows, notes,
                       count_columns=["delta"])


def navigation_results(res: Any, *, roles: Mapping[str, tuple[str, str]] | None = None, layout: str = "auto",
                       info: Mapping[str, Any] | None = None, spread: str = "interval") -> EvalResults:
    """The results-schema form of a navigation run (module docstring); ``spread``: what the main table's
    ± is (``interval``: the 95 % interval's half-width; ``std``: the standard deviation across the
    query sets, the paper's ± of its simulation tables).
    """
    roles = dict(roles or {})
    tables = [_main_table(res, roles, layout, spread)]
    label = (info or {}).get("dataset_label")
    if label:
        tables[0].title = tables[0].title.replace(f"on {res.config.get('env')} ", f"on {label} ", 1)
    sweep = _sweep_table(res, roles)
    if sweep is not None:
        tables.append(sweep)
    main = tables[0]
    s = next((v for r in main.rows for v in r.values.values() if v.method != "none"), None)
    interval = ({"method": s.method, "unit": "queries", "n": s.n, "confidence": 0.95, "text": main.notes[-1]}
                if s else {})
    return EvalResults("navigation", tables, config=dict(res.config), info=dict(info or {}), interval=interval,
                       errors=list(getattr(res, "errors", None) or []))


def write_navigation_results(res: Any, out_dir: str | Path, *, roles: Mapping[str, tuple[str, str]] | None = None,
                             info: Mapping[str, Any] | None = None, spread: str = "interval") -> dict[str, Path]:
    """Write the results schema (results.json, summary.csv, table.txt), records.parquet, per_seed.csv,
    results.csv (one row per method, every column of the summary) and sweep.csv (with a sweep);
    ``spread`` as for :func:`navigation_results`.

    Replaces each of these files in ``out_dir`` atomically (an interrupted call leaves the previous
    file as it was; other files are left alone); never inside the input dataset (``res.env``'s).

    Raises:
        UnsafeOutputError: ``out_dir`` is or lies inside the input dataset; nothing is written.
    """
    from functools import partial

    from psg_data.writers._safe_output import write_atomically

    out, inputs = Path(out_dir), [input_dataset(getattr(res, "env", None))]
    paths = save_results(navigation_results(res, roles=roles, info=info, spread=spread), out, inputs=inputs)
    extra = {"records": out / "records.parquet", "per_seed": out / "per_seed.csv", "csv": out / "results.csv"}
    write_atomically(extra["records"], partial(res.records.to_parquet, index=False), inputs=inputs)
    write_atomically(extra["per_seed"], partial(res.per_seed.to_csv, index=False), inputs=inputs)
    write_atomically(extra["csv"], partial(res.summary.to_csv, index=False), inputs=inputs)
    if res.sweep is not None:
        extra["sweep"] = out / "sweep.csv"
        write_atomically(extra["sweep"], partial(res.sweep.to_csv, index=False), inputs=inputs)
    return {**paths, **extra}


def input_dataset(env: Any) -> str | None:
    """The folder of the dataset a navigation environment was built from (None: a synthetic lab or no env)."""
    return None if env is None else env.extra.get("root")


def choose_map_query(res: Any, methods: list[str] | None = None) -> tuple[int, int]:
    """(seed, query_id) of the first query set's most informative query for the maps: a dynamic target
    on which the methods' outcomes and first receptacles disagree most (then: any dynamic one,
    then query 0).
    """
    rec = res.records
    rec = rec[rec["delta"] == float(res.config.get("delta", 0.2))] if "delta" in rec else rec
    sd = sorted(res.queries)[0]
    rec = rec[rec["seed"] == sd]
    if methods:
        rec = rec[rec["method"].isin(methods)]
    dyn = rec[rec["category"] == "dynamic"]
    if dyn.empty:
        return sd, int(res.queries[sd][0].query_id)
    sig = dyn.assign(sig=dyn["outcome"].astype(str) + "|" + dyn["predicted_receptacle"].astype(str),
                     far=dyn["shortest_path_m"].fillna(0.0) >= 3.0)
    score = sig.groupby("query_id").agg(far=("far", "all"), kinds=("sig", "nunique"), found=("success", "sum"))
    best = score.sort_values(["far", "kinds", "found"], ascending=[False, False, False]).index[0]
    return sd, int(best)


def plot_delta_sweep(res: Any, out_path: str | Path | None = None, *,
                     roles: Mapping[str, tuple[str, str]] | None = None) -> Figure:
    """Overall SR, dynamic SR and AR against delta, one line per method (reference rows dashed), 95 % intervals."""
    import numpy as np
    from matplotlib.figure import Figure

    from psg_data.evaluation._persistence_plots import _colours, save_figure

    sw = res.sweep
    fig = Figure(figsize=(13, 3.8))
    axes = fig.subplots(1, 3)
    names = list(dict.fromkeys(sw["method"]))
    colours = _colours(names)  # the same colour per method as in every other figure
    for ax, key, title in zip(axes, ("overall_sr", "dynamic_sr", "absent_ar"),
                              ("overall SR (%)", "dynamic SR (%)", "AR: correct aborts on absent targets (%)")):
        for i, n in enumerate(names):
            d = sw[sw["method"] == n].sort_values("delta")
            m = 100 * d[f"{key}_mean"].to_numpy(float)
            err = 100 * np.vstack([np.nan_to_num(d[f"{key}_mean"] - d[f"{key}_ci_low"]),
                                   np.nan_to_num(d[f"{key}_ci_high"] - d[f"{key}_mean"])])
            ax.errorbar(d["delta"], m, yerr=err, marker="o", ms=4, capsize=2, lw=1.3, color=colours[i], label=n,
                        ls="--" if n in (roles or {}) else "-")
        ax.set_xlabel("delta (abort when no receptacle has a belief >= delta)", fontsize=8)
        ax.set_title(title, fontsize=9)
        ax.set_ylim(-3, 103)
    h, lab = axes[0].get_legend_handles_labels()
    fig.legend(h, lab, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=7, frameon=False,
               title="dashed: reference rows", title_fontsize=7)
    fig.suptitle("Navigation against delta (same queries; bars: 95 % bootstrap interval over queries)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, out_path)
