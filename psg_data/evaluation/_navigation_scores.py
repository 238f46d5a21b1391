"""Scoring navigation episodes: the paper's table metrics per query, per query set and over all queries.

Metrics (one row per method; the paper's "Predictive Navigation" layout):

- Static presence: SR, SPL over reachable targets that did not move since the last map update.
- Dynamic presence: SR, SPL over reachable targets that moved.
- Absence: AR (correct abort rate) and DIST (metres walked before terminating) over absent targets.
- Overall: SR, SPL over reachable present targets plus absent targets. ``absent_in_overall``
  chooses how absent targets count: ``"abort_is_success"`` (default: a correct abort is a success
  with efficiency 1, whatever was walked), ``"abort_is_success_spl_path"`` (a correct abort is a
  success; its SPL term is 1 only if the agent aborted without moving, else 0) or ``"exclude"``.

Unreachable present targets are counted in ``n_unreachable`` and, by default
(``unreachable="exclude"``), left out of SR and SPL; ``"failure"`` counts them as failures;
``"like_absent"`` scores reachability both ways: they leave the static / dynamic columns and enter
the overall SR / SPL like absent targets (a correct abort is a success, a walk towards them a
failure), see :data:`UNREACHABLE_RULES`.

Every metric is a ratio over queries, ``sum_q num_q / sum_q den_q`` (:func:`query_terms`: e.g.
dynamic SR has ``num = success`` and ``den = 1`` on the reachable dynamic queries), so the estimate
over all query sets pools the queries and its interval is the bootstrap over queries
(:func:`~psg_data.evaluation.ratio_interval`, queries resampled whole within each metric's
queries). Values are fractions in [0, 1] (metres for DIST).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError

__all__ = ["METRICS", "ABSENT_RULES", "UNREACHABLE_RULES", "query_terms", "score_records", "summarise_navigation",
           "COUNTS"]

METRICS = ("static_sr", "static_spl", "dynamic_sr", "dynamic_spl", "absent_ar", "absent_dist_m",
           "overall_sr", "overall_spl")
ABSENT_RULES = ("abort_is_success", "abort_is_success_spl_path", "exclude")
COUNTS = ("n_queries", "n_static", "n_dynamic", "n_absent", "n_unreachable")
UNREACHABLE_RULES = ("exclude", "failure", "like_absent")


def _spl_terms(s: NDArray[np.bool_], l_: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
    den = np.maximum(p, l_)
    ratio = np.divide(l_, den, out=np.ones(s.size, dtype=np.float64), where=den > 0)
    return s.astype(np.float64) * ratio


def query_terms(df: Any, *, absent_in_overall: str = "abort_is_success", unreachable: str = "exclude"
                ) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Per metric, per query: (numerator, denominator) with ``metric = sum(num) / sum(den)`` (module docstring).

    Args:
        df: per-query records (columns of :func:`psg_data.navigation.episode_record`).
        absent_in_overall: how absent queries count in the overall SR/SPL, one of :data:`ABSENT_RULES`.
        unreachable: "exclude" (queries whose target cannot be reached are left out), "failure" or
            "like_absent" (scored in the overall columns like absent targets), :data:`UNREACHABLE_RULES`.
    """
    if absent_in_overall not in ABSENT_RULES:
        raise EvaluationError(f"absent_in_overall: expected one of {ABSENT_RULES}, got {absent_in_overall!r}")
    if unreachable not in UNREACHABLE_RULES:
        raise EvaluationError(f"unreachable: expected one of {UNREACHABLE_RULES}, got {unreachable!r}")
    cat = df["category"].to_numpy()
    reach = df["reachable"].to_numpy(bool)
    succ = df["success"].to_numpy(bool)
    abort = df["aborted"].to_numpy(bool)
    p = df["path_m"].to_numpy(np.float64)
    l_ = df["shortest_path_m"].to_numpy(np.float64)
    present = cat != "absent"
    scored = present & (True if unreachable == "failure" else reach)
    l_safe = np.where(np.isfinite(l_), l_, p)  # unreachable ones only enter as failures (S = 0)
    ab = (cat == "absent") | (present & ~reach if unreachable == "like_absent" else False)
    out: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    spl_all = _spl_terms(succ, l_safe, p)
    for c in ("static", "dynamic"):
        m = (scored & (cat == c)).astype(np.float64)
        out[f"{c}_sr"] = (succ * m, m)
        out[f"{c}_spl"] = (spl_all * m, m)
    abf = (cat == "absent").astype(np.float64)
    out["absent_ar"] = (abort * abf, abf)
    out["absent_dist_m"] = (p * abf, abf)
    sel = (scored | (ab if absent_in_overall != "exclude" else False)).astype(np.float64)
    s_all = np.where(ab, abort, succ)
    l_all = np.where(ab, p if absent_in_overall == "abort_is_success" else 0.0, l_safe)
    out["overall_sr"] = (s_all * sel, sel)
    out["overall_spl"] = (_spl_terms(s_all, l_all, p) * sel, sel)
    return out


def _counts(df: Any) -> dict[str, int]:
    cat = df["category"].to_numpy()
    reach = df["reachable"].to_numpy(bool)
    present = cat != "absent"
    return {"n_static": int(np.sum(present & reach & (cat == "static"))),
            "n_dynamic": int(np.sum(present & reach & (cat == "dynamic"))), "n_absent": int(np.sum(cat == "absent")),
            "n_unreachable": int(np.sum(present & ~reach)), "n_queries": int(len(cat))}


def _ratio(num: NDArray[np.float64], den: NDArray[np.float64]) -> float:
    d = float(np.sum(den))
    return float(np.sum(num) / d) if d > 0 else float("nan")


def score_records(df: Any, *, absent_in_overall: str = "abort_is_success", unreachable: str = "exclude"
                  ) -> dict[str, float]:
    """Table metrics of one method on one query set: the :data:`METRICS` (NaN for an empty category)
    and the counts ``n_static``, ``n_dynamic``, ``n_absent``, ``n_unreachable``, ``n_queries``.
    """
    terms = query_terms(df, absent_in_overall=absent_in_overall, unreachable=unreachable)
    out: dict[str, float] = {m: _ratio(*terms[m]) for m in METRICS}
    out.update(_counts(df))
    return out


def summarise_navigation(records: Any, names: Sequence[str], *, absent_in_overall: str = "abort_is_success",
                         unreachable: str = "exclude", confidence: float = 0.95, n_bootstrap: int = 2000,
                         seed: int = 0) -> tuple[Any, Any]:
    """(per_seed, summary) DataFrames from per-query records with columns ``method``, ``seed``, ...

    ``summary`` has per method ``<metric>_mean`` (pooled over all query sets), ``<metric>_std``
    (across query sets, ddof=1; 0 for one), ``<metric>_ci_low`` / ``_ci_high`` (bootstrap over the
    queries), ``<metric>_n`` (queries behind the metric), ``n_seeds`` and the summed counts.
    """
    import pandas as pd

    from psg_data.evaluation._intervals import ratio_interval

    rules = {"absent_in_overall": absent_in_overall, "unreachable": unreachable}
    per_seed = pd.DataFrame([{"method": n, "seed": sd, **score_records(df, **rules)}
                             for (n, sd), df in records.groupby(["method", "seed"], sort=False)])
    rows = []
    for name in names:
        df = records[records["method"] == name]
        ps = per_seed[per_seed["method"] == name]
        terms = query_terms(df, **rules)
        row: dict[str, Any] = {"method": name, "n_seeds": len(ps)}
        for m in METRICS:
            iv = ratio_interval(*terms[m], confidence=confidence, n_bootstrap=n_bootstrap, seed=seed, unit="queries")
            v = ps[m].to_numpy(np.float64)
            v = v[np.isfinite(v)]
            row[f"{m}_mean"], row[f"{m}_std"] = iv.estimate, float(np.std(v, ddof=1)) if v.size > 1 else 0.0
            row[f"{m}_ci_low"], row[f"{m}_ci_high"], row[f"{m}_n"] = iv.low, iv.high, iv.n
            row[f"{m}_method"] = iv.method
        for c in COUNTS:
            row[c] = int(ps[c].sum())
        rows.append(row)
    return per_seed, pd.DataFrame(rows)
