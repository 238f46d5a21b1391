"""The door task's scores, tables and figure choice.

Door table (one row per method; the queries of every seed pooled, intervals by bootstrap over the
door queries):

- ``blocked %``: first plans through a door closed at the query time (lower is better);
- ``SR %`` / ``SPL %``: over the goals a route reaches at the query time;
- ``SR all %``: over every query, scoring reachability both ways: a reachable goal counts when
  reached, an unreachable one (no route at the query time) when the robot did not set off (a
  correct decline; a walk towards it is a failure and its metres are ``wasted m``);
- ``extra blocked m``: mean extra distance on the queries whose shortest route with every door
  open meets a closed door (the same queries for every method: where door knowledge can pay);
- ``extra m``: walked minus shortest under the true doors, successful episodes (lower is better);
- ``wasted m``: metres walked towards goals no route reaches (ideal 0; lower is better);
- counts: queries, declined (did not set off: the predicted doors leave no route).

Reference rows: ``oracle`` (the true door states: the ceiling), ``all_open`` (every door assumed
open), ``last_seen`` (each door's last observation), ``time_of_week_frequency``.

Objects-behind-doors table: the navigation table (reachable present targets and absent ones), and
a ``Both ways`` column: overall SR over every query, an unreachable present target scored like an
absent one (a correct abort is a success, a walk towards it a failure).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.evaluation._aggregate import Summary
from psg_data.evaluation._intervals import describe_interval, ratio_interval
from psg_data.evaluation._references import describe_method
from psg_data.evaluation._results import EvalResults, MetricInfo, ResultRow, ResultTable, save_results

__all__ = ["door_terms", "summarise_doors", "door_results", "DOOR_METRICS", "pick_blocked_door_query", "walk_summary",
           "DOOR_MODE_LABELS"]

EXPECTED_COST_SUFFIX = " (expected cost)"
"""Label suffix of an estimator's row under the expected-cost door rule (:data:`psg_data.navigation.DOOR_RULES`)."""

DOOR_METRICS: dict[str, MetricInfo] = {
    "blocked_rate": MetricInfo("blocked_rate", "blocked %", "lower", "first plans through a door closed at the query "
                               "time", 100.0, 1),
    "SR": MetricInfo("SR", "SR %", "higher", "reached the goal, over the goals a route reaches at the query time",
                     100.0, 1),
    "SPL": MetricInfo("SPL", "SPL %", "higher", "SR weighted by shortest / walked path (true doors)", 100.0, 1),
    "SR_all": MetricInfo("SR_all", "SR all %", "higher", "every query: a reachable goal reached, or an unreachable "
                         "one declined without walking", 100.0, 1),
    "mean_extra_distance_m": MetricInfo("mean_extra_distance_m", "extra m", "lower", "walked minus shortest under the "
                                        "true doors, successful episodes", 1.0, 2),
    "extra_blocked_m": MetricInfo("extra_blocked_m", "extra blocked m", "lower", "extra m on the queries whose "
                                  "all-doors-open shortest route meets a closed door", 1.0, 2),
    "wasted_m": MetricInfo("wasted_m", "wasted m", "lower", "walked towards goals no route reaches (ideal 0)", 1.0, 2),
}


def door_terms(df: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per door metric, per query: (numerator, denominator) of ``metric = sum(num) / sum(den)``."""
    short = df["shortest_m"].to_numpy(float)
    walked = df["walked_m"].to_numpy(float)
    succ = df["success"].to_numpy(bool)
    reach = np.isfinite(short)
    extra = df["extra_m"].to_numpy(float)
    ok_extra = np.isfinite(extra)
    den = np.maximum(walked, np.where(reach, short, 0.0))
    spl = np.divide(np.where(reach, short, 0.0), den, out=np.ones(len(df)), where=den > 0) * succ
    ok_all = np.where(reach, succ, walked == 0.0)
    ob = (df["open_plan_blocked"].to_numpy(bool) if "open_plan_blocked" in df else np.zeros(len(df), bool)) & ok_extra
    return {"blocked_rate": (df["first_plan_blocked"].to_numpy(float), np.ones(len(df))),
            "SR": (succ * reach * 1.0, reach * 1.0), "SPL": (spl * reach, reach * 1.0),
            "SR_all": (ok_all * 1.0, np.ones(len(df))),
            "mean_extra_distance_m": (np.where(ok_extra, extra, 0.0), ok_extra * 1.0),
            "extra_blocked_m": (np.where(ob, extra, 0.0), ob * 1.0),
            "wasted_m": (np.where(reach, 0.0, walked), (~reach) * 1.0)}


def summarise_doors(records: Any, names: list[str], *, seed: int = 0) -> dict[str, dict[str, Summary]]:
    """Method -> metric -> :class:`Summary` (pooled over seeds; bootstrap over door queries; std over seeds).
    ``extra m`` and ``wasted m`` of a method without such episodes are 0 (nothing walked), as in the table.
    """
    out: dict[str, dict[str, Summary]] = {}
    for n in names:
        df = records[records["estimator"] == n]
        per: dict[str, Summary] = {}
        for m, (num, den) in door_terms(df).items():
            iv = ratio_interval(num, den, seed=seed, unit="queries")
            by_seed = [float(np.sum(a) / np.sum(b)) for a, b in
                       (door_terms(g)[m] for _, g in df.groupby("seed")) if np.sum(b) > 0]
            std = float(np.std(by_seed, ddof=1)) if len(by_seed) > 1 else 0.0
            if iv.n == 0 and m in ("mean_extra_distance_m", "wasted_m", "extra_blocked_m"):
                per[m] = Summary(0.0, 0.0, math.nan, math.nan, 0, "none", "queries")
            else:
                per[m] = Summary(iv.estimate, std, iv.low, iv.high, iv.n, iv.method, "queries")
        out[n] = per
    return out


def door_results(res: Any, *, roles: Mapping[str, tuple[str, str]] | None = None,
                 info: Mapping[str, Any] | None = None) -> EvalResults:
    """The door run in the results schema: the door table, and the objects-behind-doors table when it ran."""
    roles = dict(roles or {})
    summ = res.summary.set_index("estimator")
    names = list(summ.index)
    scores = summarise_doors(res.records, names)
    for n in names:  # the expected-cost row of a reference estimator is a reference row too
        base = n.removesuffix(EXPECTED_COST_SUFFIX)
        if n not in roles and base != n and base in roles:
            roles[n] = (roles[base][0], f"{roles[base][1]}, expected-cost door rule")
    rows = [ResultRow(n, roles.get(n, ("method", describe_method(n)))[0], scores[n],
                      roles.get(n, ("method", describe_method(n)))[1],
                      counts={"queries": int(summ.loc[n, "queries"]), "declined": int(summ.loc[n, "declined"])})
            for n in names]
    o = res.options
    refs = [r for r in rows if r.role != "method"]
    s = next((v for r in rows for v in r.values.values() if v.method != "none"), None)
    notes = [f"{m.label} ({m.better} is better): {m.description}" for m in DOOR_METRICS.values()]
    notes.append(f"door queries: a start in one room, a goal receptacle in another, at a time of the test days inside "
                 f"{res.world.hours[0]:g}-{res.world.hours[1]:g} h local; doors with predicted P(open) < "
                 f"{o.threshold} are planned closed (rows NAME; no_path={o.no_path}); rows NAME (expected cost) walk "
                 f"the route of least expected walked distance under independent P(open), doors discovered on arrival "
                 f"(psg_data.maps.expected_cost_route); door streams from {o.labels} "
                 f"({res.world.info.get('doors', {}).get('from', '?')})")
    if refs:
        notes.append("reference rows: " + "; ".join(f"{r.method} = {r.description}" for r in refs))
    notes.append(describe_interval(s.method, "door queries", s.n, extra=f" ({len(o.seeds)} query sets pooled)")
                 if s else "±: -")
    where = (info or {}).get("dataset_label") or res.world.name
    title = (f"Door navigation on {where} (doors from {o.labels}; {o.n_queries} queries x {len(o.seeds)} sets): first "
             "plans through closed doors")
    tables = [t for t in [_headroom_table(rows, res, where)] if t is not None]
    tables.append(ResultTable("doors", title, list(DOOR_METRICS.values()), rows, notes,
                              count_columns=["queries", "declined"]))
    if res.objects is not None:
        tables.append(_objects_table(res.objects))
    return EvalResults("doors", tables, config={**o.to_dict(), "setting_text": f"doors, {o.setting}"},
                       info=dict(info or {}), interval={"method": s.method if s else "none", "unit": "door queries",
                                                        "n": s.n if s else 0, "confidence": 0.95},
                       errors=list(getattr(res, "errors", None) or []))


def _objects_table(objects: Any) -> ResultTable:
    """The objects-behind-doors table: the navigation table (unreachable present targets left out),
    and a ``Both ways`` column: overall SR over every query, an unreachable present target scored
    like an absent one (a correct abort is a success, a walk towards it a failure).
    """
    from psg_data.evaluation._navigation_report import _summary_of, navigation_results
    from psg_data.evaluation._navigation_scores import summarise_navigation

    t = navigation_results(objects, roles={"oracle": ("ceiling", "the true receptacle and doors")}).tables[0]
    t.name, t.title = "objects", ("Objects behind predicted-closed doors: each estimator with all doors open, its "
                                  "predicted doors, the true doors")
    cfg, rec = objects.config, objects.records
    _, both = summarise_navigation(rec[rec["delta"] == float(cfg["delta"])], [r.method for r in t.rows],
                                   absent_in_overall=cfg["absent_in_overall"], unreachable="like_absent")
    by = {str(r["method"]): r for _, r in both.iterrows()}
    for row in t.rows:
        row.values["overall_sr_both"] = _summary_of(by[row.method], "overall_sr")
    t.metrics.append(MetricInfo("overall_sr_both", "SR all %", "higher", "every query: a reachable present target "
                                "found, an absent or unreachable one aborted (a walk towards it fails)", 100.0, 1))
    n = int(both["n_queries"].iloc[0]) if len(both) else 0
    t.groups.append((f"Both ways ({n})", ["overall_sr_both"]))
    return t


def _headroom_table(rows: list[ResultRow], res: Any, where: str) -> ResultTable | None:
    """The gap between ``oracle`` and ``all_open`` (what knowing the doors can buy), shown before the
    estimator rows; None unless both reference rows ran.
    """
    by = {r.method: r for r in rows}
    if not {"oracle", "all_open"} <= set(by):
        return None
    keys = ("SPL", "extra_blocked_m", "blocked_rate")
    o, a = by["oracle"].values, by["all_open"].values
    n_ob = int(res.records.loc[res.records["estimator"] == "all_open", "open_plan_blocked"].sum()) \
        if "open_plan_blocked" in res.records else 0
    notes = [f"headroom: oracle - all_open = {100 * (o['SPL'].mean - a['SPL'].mean):+.1f} SPL points over reachable "
             f"goals; {a['extra_blocked_m'].mean - o['extra_blocked_m'].mean:+.2f} m less extra distance on the "
             f"{n_ob} queries whose all-doors-open shortest route meets a closed door; all_open's first plan is "
             f"blocked on {100 * a['blocked_rate'].mean:.1f} % of the queries",
             "a door estimator can gain at most this much over assuming every door open"]
    return ResultTable("door_headroom", f"Door task headroom on {where}: the true doors against all doors open",
                       [DOOR_METRICS[k] for k in keys], [by["oracle"], by["all_open"]], notes,
                       count_columns=["queries"])


def pick_blocked_door_query(res: Any, label: str) -> int:
    """Index (in the first seed's queries) of a door query whose all-open first plan ran into a closed
    door, preferring the paper's "Predictive Navigation" case: ``label`` predicted that door closed
    (P(open) < 0.5), took the longer route and arrived (the longest such detour first); then one where
    ``label`` planned around it and arrived, then one where ``label`` predicted the door closed and did
    not set off (nothing wasted), then one where ``label``'s own first plan was blocked too; else 0.
    """
    first = res.first
    eps, base = first.episodes[label], first.episodes["all_open"]
    blocked = [i for i, b in enumerate(base) if b.first_plan_blocked]
    around = [i for i in blocked if not eps[i].first_plan_blocked and eps[i].success]
    paper = sorted((i for i in around if any(eps[i].p_open.get(d, 1.0) < 0.5 for d in base[i].doors_discovered)),
                   key=lambda i: -(base[i].walked_m - eps[i].walked_m))
    pools = (paper, around,
             [i for i in blocked if eps[i].declined],
             [i for i in blocked if eps[i].first_plan_blocked], blocked)
    return next((p[0] for p in pools if p), 0)


def write_door_results(res: Any, out: Path, *, roles: Mapping[str, tuple[str, str]] | None, info: Mapping[str, Any]
                       ) -> EvalResults:
    """results.json / summary.csv / table.txt, results.csv (door summary), by_seed.csv, records.csv,
    objects/ (the objects run) and objects/walk.csv.
    """
    results = door_results(res, roles=roles, info=info)
    save_results(results, out)
    res.per_seed.to_csv(out / "by_seed.csv", index=False)
    res.records.to_csv(out / "records.csv", index=False)
    res.summary.to_csv(out / "results.csv", index=False)
    if res.objects is not None:
        res.objects.save(out / "objects", roles={"oracle": ("ceiling", "the true receptacle and doors")})
        walk_summary(res.objects).to_csv(out / "objects" / "walk.csv", index=False)
    return results


DOOR_MODE_LABELS = {"all_open": "doors all open", "predicted": "doors predicted", "truth": "doors known"}


def walk_summary(objects: Any) -> Any:
    """Per method of the objects run: found targets, metres walked (all queries, and towards targets
    no route reaches at the query time, which the SR / SPL table leaves out), and the queries it
    lost / won against the same estimator with all doors open.
    """
    import pandas as pd

    rec = objects.records
    rows = []
    for name, df in rec.groupby("method", sort=False):
        d = df.set_index(["seed", "query_id"])
        row = {"method": name, "queries": len(d), "found": int(d["success"].sum()),
               "walked_m": float(d["path_m"].mean()),
               "walked_unreachable_m": (float(d.loc[~d["reachable"], "path_m"].mean()) if (~d["reachable"]).any()
                                        else 0.0)}
        base = name.rsplit(" [", 1)[0] + f" [{DOOR_MODE_LABELS['all_open']}]"
        if name != base and base in set(rec["method"]):
            b = rec[rec["method"] == base].set_index(["seed", "query_id"])["success"].reindex(d.index)
            row["lost_vs_all_open"] = int((b & ~d["success"]).sum())
            row["won_vs_all_open"] = int((~b & d["success"]).sum())
        rows.append(row)
    return pd.DataFrame(rows)
