"""Navigation scores against a per-query brute-force recount of the paper's definitions.

The reference below walks the records one query at a time in plain Python: SR = share of successes,
SPL = mean of ``S_i l_i / max(p_i, l_i)`` (Anderson et al. 2018, the paper's SPL; a success at the
target's own spot, ``p = l = 0``, has efficiency 1), AR = share of correct aborts over absent targets,
DIST = mean metres walked over them, and the overall columns with the module's documented rules for
absent and unreachable targets. It shares no code with ``_navigation_scores``.
"""

from __future__ import annotations

import math
import statistics
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from psg_data.errors import EvaluationError
from psg_data.evaluation._intervals import ratio_interval
from psg_data.evaluation._navigation_scores import (
    ABSENT_RULES,
    COUNTS,
    METRICS,
    UNREACHABLE_RULES,
    query_terms,
    score_records,
    summarise_navigation,
)

_LENGTHS = st.one_of(st.just(0.0), st.floats(0.0, 30.0, allow_nan=False), st.sampled_from([1.0, 2.5, 7.0]))


@st.composite
def _query(draw: Any) -> dict[str, Any]:
    """One episode record obeying the runner's invariants (success only at a reachable target, never
    both success and abort, shortest path NaN exactly when the target is absent or unreachable)."""
    cat = draw(st.sampled_from(["static", "dynamic", "absent"]))
    reachable = cat != "absent" and draw(st.booleans())
    success = reachable and draw(st.booleans())
    aborted = (not success) and draw(st.booleans())
    p = draw(_LENGTHS)
    if reachable:
        l_ = draw(_LENGTHS)
        if success and draw(st.booleans()):
            p = l_ + draw(st.floats(0.0, 5.0))  # a success walks at least the shortest path, usually
    else:
        l_ = float("nan")
    return {"category": cat, "reachable": reachable, "success": success, "aborted": aborted,
            "path_m": float(p), "shortest_path_m": float(l_)}


def _efficiency(success: bool, l_: float, p: float) -> float:
    """S l / max(p, l), with 1 for a success where both are 0 (nothing to walk, nothing walked)."""
    if not success:
        return 0.0
    m = max(p, l_)
    return 1.0 if m == 0 else l_ / m


def _reference_terms(q: dict[str, Any], absent_rule: str, unreach_rule: str) -> dict[str, tuple[float, float]]:
    """Per metric, this query's (numerator, denominator), from the module docstring's rules."""
    out = {m: (0.0, 0.0) for m in METRICS}
    cat, p = q["category"], q["path_m"]
    if cat == "absent":
        out["absent_ar"] = (1.0 if q["aborted"] else 0.0, 1.0)
        out["absent_dist_m"] = (p, 1.0)
    in_columns = cat != "absent" and (q["reachable"] or unreach_rule == "failure")
    like_absent = cat == "absent" or (not q["reachable"] and unreach_rule == "like_absent")
    if in_columns:
        s = bool(q["success"]) and q["reachable"]  # "failure": an unreachable target is a failure
        eff = _efficiency(s, q["shortest_path_m"], p) if q["reachable"] else 0.0
        out[f"{cat}_sr"] = out["overall_sr"] = (1.0 if s else 0.0, 1.0)
        out[f"{cat}_spl"] = out["overall_spl"] = (eff, 1.0)
    elif like_absent and absent_rule != "exclude":
        ok = bool(q["aborted"])  # a correct abort is the success
        if absent_rule == "abort_is_success":
            eff = 1.0 if ok else 0.0
        else:  # "abort_is_success_spl_path": efficiency 1 only for an abort without moving
            eff = 1.0 if ok and p == 0 else 0.0
        out["overall_sr"] = (1.0 if ok else 0.0, 1.0)
        out["overall_spl"] = (eff, 1.0)
    return out


def _reference_scores(rows: list[dict[str, Any]], absent_rule: str, unreach_rule: str) -> dict[str, float]:
    out: dict[str, float] = {}
    terms = [_reference_terms(q, absent_rule, unreach_rule) for q in rows]
    for m in METRICS:
        num = sum(t[m][0] for t in terms)
        den = sum(t[m][1] for t in terms)
        out[m] = num / den if den > 0 else math.nan
    out["n_static"] = sum(q["category"] == "static" and q["reachable"] for q in rows)
    out["n_dynamic"] = sum(q["category"] == "dynamic" and q["reachable"] for q in rows)
    out["n_absent"] = sum(q["category"] == "absent" for q in rows)
    out["n_unreachable"] = sum(q["category"] != "absent" and not q["reachable"] for q in rows)
    out["n_queries"] = len(rows)
    return out


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-12, abs=1e-12)


_RULES = st.tuples(st.sampled_from(ABSENT_RULES), st.sampled_from(UNREACHABLE_RULES))


@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_query(), min_size=1, max_size=12), _RULES)
def test_score_records_matches_the_per_query_recount(rows: list[dict[str, Any]], rules: tuple[str, str]) -> None:
    absent_rule, unreach_rule = rules
    got = score_records(pd.DataFrame(rows), absent_in_overall=absent_rule, unreachable=unreach_rule)
    ref = _reference_scores(rows, absent_rule, unreach_rule)
    assert set(got) == set(METRICS) | set(COUNTS)
    for k, v in ref.items():
        assert _same(got[k], v), (k, got[k], v)
    for c in COUNTS:
        assert type(got[c]) is int


@settings(max_examples=200, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_query(), min_size=1, max_size=10), _RULES)
def test_query_terms_are_the_per_query_terms(rows: list[dict[str, Any]], rules: tuple[str, str]) -> None:
    """Each query's own (numerator, denominator): the unit the bootstrap resamples."""
    absent_rule, unreach_rule = rules
    got = query_terms(pd.DataFrame(rows), absent_in_overall=absent_rule, unreachable=unreach_rule)
    assert set(got) == set(METRICS)
    for m in METRICS:
        num, den = got[m]
        assert num.shape == den.shape == (len(rows),)
        assert num.dtype == den.dtype == np.float64
        for i, q in enumerate(rows):
            rn, rd = _reference_terms(q, absent_rule, unreach_rule)[m]
            assert (num[i], den[i]) == pytest.approx((rn, rd), rel=1e-12, abs=1e-12), (m, i, q)


def _cases() -> list[dict[str, Any]]:
    """Hand-made edge cases: walks of 0 m, a walk shorter than the shortest path, every rule's kind."""
    return [
        {"category": "static", "reachable": True, "success": True, "aborted": False, "path_m": 0.0,
         "shortest_path_m": 0.0},  # found where it stood: efficiency 1
        {"category": "static", "reachable": True, "success": True, "aborted": False, "path_m": 6.0,
         "shortest_path_m": 4.0},  # 4 / 6
        {"category": "dynamic", "reachable": True, "success": True, "aborted": False, "path_m": 3.0,
         "shortest_path_m": 5.0},  # walked less than l (a recorded inconsistency): l / max(p, l) = 1
        {"category": "dynamic", "reachable": True, "success": False, "aborted": True, "path_m": 2.0,
         "shortest_path_m": 8.0},
        {"category": "dynamic", "reachable": False, "success": False, "aborted": True, "path_m": 0.0,
         "shortest_path_m": math.nan},  # unreachable, declined at once
        {"category": "static", "reachable": False, "success": False, "aborted": False, "path_m": 9.0,
         "shortest_path_m": math.nan},  # unreachable, walked towards it
        {"category": "absent", "reachable": False, "success": False, "aborted": True, "path_m": 0.0,
         "shortest_path_m": math.nan},  # correct abort without moving
        {"category": "absent", "reachable": False, "success": False, "aborted": True, "path_m": 4.0,
         "shortest_path_m": math.nan},  # correct abort after a walk
        {"category": "absent", "reachable": False, "success": False, "aborted": False, "path_m": 12.0,
         "shortest_path_m": math.nan},
    ]


def _short_walks() -> list[dict[str, Any]]:
    """Walks and shortest paths below a metre: SPL's ratio where max(p, l) lies in (0, 1]."""
    return [
        {"category": "static", "reachable": True, "success": True, "aborted": False, "path_m": 0.8,
         "shortest_path_m": 0.2},  # 0.25
        {"category": "dynamic", "reachable": True, "success": True, "aborted": False, "path_m": 0.5,
         "shortest_path_m": 0.4},  # 0.8
        {"category": "absent", "reachable": False, "success": False, "aborted": True, "path_m": 0.5,
         "shortest_path_m": math.nan},  # a correct abort after half a metre
        {"category": "dynamic", "reachable": False, "success": False, "aborted": True, "path_m": 0.25,
         "shortest_path_m": math.nan},  # unreachable, declined after a quarter metre
    ]


@pytest.mark.parametrize("absent_rule", ABSENT_RULES)
@pytest.mark.parametrize("unreach_rule", UNREACHABLE_RULES)
def test_short_walks_hand_counted(absent_rule: str, unreach_rule: str) -> None:
    got = score_records(pd.DataFrame(_short_walks()), absent_in_overall=absent_rule, unreachable=unreach_rule)
    assert got["static_spl"] == pytest.approx(0.25)
    assert got["dynamic_spl"] == pytest.approx(0.8 / (2 if unreach_rule == "failure" else 1))
    spl, n = 0.25 + 0.8, 2
    if unreach_rule == "failure":
        n += 1
    if absent_rule != "exclude":
        eff = 1.0 if absent_rule == "abort_is_success" else 0.0  # both aborts walked
        spl, n = spl + eff, n + 1
        if unreach_rule == "like_absent":
            spl, n = spl + eff, n + 1
    assert got["overall_spl"] == pytest.approx(spl / n)


@pytest.mark.parametrize("absent_rule", ABSENT_RULES)
@pytest.mark.parametrize("unreach_rule", UNREACHABLE_RULES)
def test_edge_cases_hand_counted(absent_rule: str, unreach_rule: str) -> None:
    rows = _cases()
    got = score_records(pd.DataFrame(rows), absent_in_overall=absent_rule, unreachable=unreach_rule)
    # by hand: static column 2 reachable (+1 unreachable failure under "failure")
    n_st, n_dy = (3, 3) if unreach_rule == "failure" else (2, 2)
    assert got["static_sr"] == pytest.approx(2 / n_st)
    assert got["static_spl"] == pytest.approx((1 + 4 / 6) / n_st)
    assert got["dynamic_sr"] == pytest.approx(1 / n_dy)
    assert got["dynamic_spl"] == pytest.approx(1 / n_dy)
    assert got["absent_ar"] == pytest.approx(2 / 3)
    assert got["absent_dist_m"] == pytest.approx(16 / 3)
    # overall: 4 reachable present (3 successes, SPL 1 + 2/3 + 1 + 0) and then the rules
    sr, spl, n = 3.0, 1 + 4 / 6 + 1, 4
    if unreach_rule == "failure":
        n += 2
    if absent_rule != "exclude":
        walked_abort_eff = 1.0 if absent_rule == "abort_is_success" else 0.0
        sr, spl, n = sr + 2, spl + 1 + walked_abort_eff, n + 3
        if unreach_rule == "like_absent":  # the unreachable dynamic one declined at once: a success
            sr, spl, n = sr + 1, spl + 1, n + 2
    assert got["overall_sr"] == pytest.approx(sr / n)
    assert got["overall_spl"] == pytest.approx(spl / n)
    assert (got["n_static"], got["n_dynamic"], got["n_absent"], got["n_unreachable"], got["n_queries"]) == (
        2, 2, 3, 2, 9)


def test_defaults_are_abort_is_success_and_exclude() -> None:
    """The signature's defaults: a correct abort is a success with efficiency 1; unreachable targets left out."""
    rows = _cases() + _short_walks()
    df = pd.DataFrame(rows)
    ref = _reference_scores(rows, "abort_is_success", "exclude")
    got = score_records(df)
    assert all(_same(got[k], ref[k]) for k in ref)
    terms = query_terms(df)
    for m in METRICS:
        want = [_reference_terms(q, "abort_is_success", "exclude")[m] for q in rows]
        assert np.column_stack(terms[m]) == pytest.approx(np.array(want), rel=1e-12, abs=1e-12), m


def _coded(df: pd.DataFrame, how: str) -> pd.DataFrame:
    """The same records with the flags as a CSV or a nullable store may hand them over."""
    flags = ["reachable", "success", "aborted"]
    if how == "int":  # 0 / 1
        return df.astype({f: np.int64 for f in flags})
    if how == "float":  # 0.0 / 1.0, as a column read with missing values allowed
        return df.astype({f: np.float64 for f in flags})
    if how == "nullable":  # pandas' nullable boolean
        return df.astype({f: "boolean" for f in flags})
    return df.astype({c: object for c in [*flags, "path_m", "shortest_path_m"]})  # Python objects


@pytest.mark.parametrize("how", ["int", "float", "nullable", "object"])
@pytest.mark.parametrize("absent_rule", ABSENT_RULES)
@pytest.mark.parametrize("unreach_rule", UNREACHABLE_RULES)
def test_coded_flags_give_the_same_float_terms(how: str, absent_rule: str, unreach_rule: str) -> None:
    rows = _cases() + _short_walks()
    df = _coded(pd.DataFrame(rows), how)
    terms = query_terms(df, absent_in_overall=absent_rule, unreachable=unreach_rule)
    for m in METRICS:
        num, den = terms[m]
        assert num.dtype == den.dtype == np.float64, (m, num.dtype, den.dtype)
        want = [_reference_terms(q, absent_rule, unreach_rule)[m] for q in rows]
        assert np.column_stack((num, den)) == pytest.approx(np.array(want), rel=1e-12, abs=1e-12), m
    got = score_records(df, absent_in_overall=absent_rule, unreachable=unreach_rule)
    ref = _reference_scores(rows, absent_rule, unreach_rule)
    assert all(_same(got[k], ref[k]) for k in ref)


@pytest.mark.parametrize("kw, name", [({"absent_in_overall": "maybe"}, "absent_in_overall"),
                                      ({"unreachable": "ignore"}, "unreachable")])
def test_unknown_rule_error_names_the_option_and_the_choices(kw: dict[str, str], name: str) -> None:
    with pytest.raises(EvaluationError) as e:
        query_terms(pd.DataFrame(_cases()), **kw)
    msg = str(e.value)
    choices = ABSENT_RULES if name == "absent_in_overall" else UNREACHABLE_RULES
    assert msg == f"{name}: expected one of {choices}, got {next(iter(kw.values()))!r}"


# --- summarise_navigation: pooled estimate, spread across query sets, interval over queries -----------------


def _records(rng: np.random.Generator, methods: list[str], seeds: list[int], n: int) -> pd.DataFrame:
    rows = []
    for sd in seeds:
        for m in methods:
            for _ in range(n):
                cat = str(rng.choice(["static", "dynamic", "absent"], p=[0.4, 0.4, 0.2]))
                reach = cat != "absent" and bool(rng.random() < 0.85)
                succ = reach and bool(rng.random() < 0.6)
                abort = (not succ) and bool(rng.random() < 0.5)
                l_ = float(rng.uniform(0.5, 10.0)) if reach else math.nan
                p = (l_ + float(rng.exponential(2.0))) if succ else float(rng.choice([0.0, rng.uniform(0, 15)]))
                rows.append({"method": m, "seed": sd, "category": cat, "reachable": reach, "success": succ,
                             "aborted": abort, "path_m": p, "shortest_path_m": l_})
    return pd.DataFrame(rows)


@pytest.mark.parametrize("absent_rule, unreach_rule, n_per_set, seeds",
                         [("abort_is_success", "exclude", 14, [3, 1, 2]),
                          ("abort_is_success_spl_path", "like_absent", 6, [5, 4]),
                          ("exclude", "failure", 3, [7]),
                          ("abort_is_success", "failure", 25, [0, 9])])
def test_summarise_navigation_against_the_recount(absent_rule: str, unreach_rule: str, n_per_set: int,
                                                   seeds: list[int]) -> None:
    rng = np.random.default_rng(n_per_set)
    methods = ["zeta", "alpha"]
    rec = _records(rng, methods, seeds, n_per_set)
    conf, nb, bseed = 0.8, 300, 11
    per_seed, summary = summarise_navigation(rec, ["alpha", "zeta"], absent_in_overall=absent_rule,
                                             unreachable=unreach_rule, confidence=conf, n_bootstrap=nb, seed=bseed)
    # per query set, in the records' order (seed-major here), by the recount
    groups = list(dict.fromkeys(zip(rec["method"], rec["seed"])))
    assert list(zip(per_seed["method"], per_seed["seed"])) == groups
    for (m, sd), row in zip(groups, per_seed.to_dict("records")):
        sub = rec[(rec["method"] == m) & (rec["seed"] == sd)].to_dict("records")
        ref = _reference_scores(sub, absent_rule, unreach_rule)
        for k, v in ref.items():
            assert _same(float(row[k]), float(v)), (m, sd, k)
    assert list(summary["method"]) == ["alpha", "zeta"]
    for row in summary.to_dict("records"):
        sub = rec[rec["method"] == row["method"]].to_dict("records")
        pooled = _reference_scores(sub, absent_rule, unreach_rule)
        sets = [_reference_scores([q for q in sub if q["seed"] == sd], absent_rule, unreach_rule) for sd in seeds]
        assert row["n_seeds"] == len(seeds)
        for c in COUNTS:
            assert row[c] == sum(s[c] for s in sets) == pooled[c]
        for m in METRICS:
            assert _same(row[f"{m}_mean"], pooled[m]), m
            finite = [s[m] for s in sets if not math.isnan(s[m])]
            std = statistics.stdev(finite) if len(finite) > 1 else 0.0
            assert row[f"{m}_std"] == pytest.approx(std, rel=1e-9, abs=1e-12), m
            terms = [_reference_terms(q, absent_rule, unreach_rule)[m] for q in sub]
            n_units = sum(d > 0 for _, d in terms)
            assert row[f"{m}_n"] == n_units
            want = "none" if n_units < 2 else ("bootstrap" if n_units >= 10 else "jackknife-t")
            assert row[f"{m}_method"] == want
            iv = ratio_interval([t[0] for t in terms], [t[1] for t in terms], confidence=conf, n_bootstrap=nb,
                                seed=bseed, unit="queries")
            assert iv.confidence == conf
            for end in ("low", "high"):
                a, b = row[f"{m}_ci_{end}"], getattr(iv, end)
                assert _same(a, b), (m, end, a, b)


def test_summarise_navigation_defaults() -> None:
    """Defaults: abort_is_success, exclude, 95 %, 2000 resamples with seed 0 (the signature)."""
    rec = _records(np.random.default_rng(21), ["a"], [0, 1], 12)
    per_seed, summary = summarise_navigation(rec, ["a"])
    rows = rec.to_dict("records")
    row = summary.to_dict("records")[0]
    for (_, sd), ps in zip(dict.fromkeys(zip(rec["method"], rec["seed"])), per_seed.to_dict("records")):
        ref = _reference_scores([q for q in rows if q["seed"] == sd], "abort_is_success", "exclude")
        assert all(_same(float(ps[k]), float(v)) for k, v in ref.items())
    for m in METRICS:
        terms = [_reference_terms(q, "abort_is_success", "exclude")[m] for q in rows]
        iv = ratio_interval([t[0] for t in terms], [t[1] for t in terms], confidence=0.95, n_bootstrap=2000,
                            seed=0, unit="queries")
        assert _same(row[f"{m}_mean"], iv.estimate) and row[f"{m}_method"] == iv.method
        assert _same(row[f"{m}_ci_low"], iv.low) and _same(row[f"{m}_ci_high"], iv.high), m
