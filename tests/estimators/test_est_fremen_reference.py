"""FreMEn against an independent implementation of the public code's rules (strands-project/fremen).

The reference below is written from the description of the public ``CFrelement`` class, not from
our estimator: per exact period T = week / k (float64, times relative to the Monday 00:00 UTC before
the first training observation) the static part is the mean of the observations, re / im are the
sums of (y - mean) cos / sin of 2 pi t / T, the amplitude is |re + i im| / N (0 when 1.5 T exceeds
the span of the data: the duration rule), the phase atan2(im, re); components are sorted by
amplitude; the estimate of order m is mean + sum of the m strongest 2 A cos(2 pi t / T - phase).
``evaluate()`` scores orders 0..M by the error rate of (unclipped estimate > 0.5) and moves to a
higher order only if it beats the best so far by more than 0.001. The order is chosen on the
validation streams when given, else on the last training week with a model fitted on the rest.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import EstimatorError
from psg_data.estimators import EdgeStream, get_estimator
from psg_data.estimators._fremen import FremenModel, choose_order
from psg_data.estimators._fremen_estimator import FremenEstimator
from psg_data.estimators._params import parse_setting

WEEK = 7 * 86400.0
DAY = 86400.0
MONDAY = 1_704_067_200.0  # 2024-01-01 00:00 UTC, a Monday
FIRST_MONDAY_UNIX = 4 * DAY  # 1970-01-05 00:00 UTC


def ref_monday(t0: float) -> float:
    """Monday 00:00 UTC at or before Unix time t0."""
    return FIRST_MONDAY_UNIX + math.floor((t0 - FIRST_MONDAY_UNIX) / WEEK) * WEEK


def ref_fit(t: np.ndarray, y: np.ndarray, n_periods: int, duration_rule: bool = True) -> tuple[float, list]:
    """(static part, [(amplitude, phase, period)] sorted by decreasing amplitude)."""
    gain = float(np.mean(y))
    duration = float(t.max() - t.min())
    elements = []
    for k in range(1, n_periods + 1):
        period = WEEK / k
        angle = 2 * np.pi * t / period
        re = float(np.sum(y * np.cos(angle)) - gain * np.sum(np.cos(angle)))
        im = float(np.sum(y * np.sin(angle)) - gain * np.sum(np.sin(angle)))
        keep = (not duration_rule) or 1.5 * period <= duration
        elements.append((math.hypot(re, im) / t.size if keep else 0.0, math.atan2(im, re), period))
    elements.sort(key=lambda e: -e[0])
    return gain, elements


def ref_estimates(model: tuple[float, list], t: np.ndarray, max_order: int) -> np.ndarray:
    """(max_order + 1, N) unclipped estimates of orders 0..max_order."""
    gain, elements = model
    out = np.empty((max_order + 1, t.size))
    est = np.full(t.size, gain)
    out[0] = est
    for i, (amp, phase, period) in enumerate(elements[:max_order]):
        est = est + 2 * amp * np.cos(t / period * 2 * np.pi - phase)
        out[i + 1] = est
    return out


def ref_evaluate(model: tuple[float, list], t: np.ndarray, y: np.ndarray, max_order: int) -> tuple[int, list]:
    evals = [float(np.mean(np.abs(y - (e > 0.5)))) for e in ref_estimates(model, t, max_order)]
    error, index = 10.0, 0
    for j, v in enumerate(evals):
        if v < error - 0.001:
            index, error = j, v
    return index, evals


def ref_fremen(train: EdgeStream, val: EdgeStream | None, query_s: np.ndarray, n_periods: int,
               max_order: int | None, duration_rule: bool = True) -> tuple[int, list, np.ndarray]:
    """The public rules run with this library's protocol: (order, scores, clipped predictions)."""
    t0 = ref_monday(float(train.t_s.min()))
    t, y = train.t_s - t0, train.y.astype(float)
    mo = n_periods if max_order is None else min(max_order, n_periods)
    model = ref_fit(t, y, n_periods, duration_rule)
    if val is not None:
        order, evals = ref_evaluate(model, val.t_s - t0, val.y.astype(float), mo)
    elif t.max() - t.min() > 1.5 * WEEK:
        held = t >= t.max() - WEEK
        sub = ref_fit(t[~held], y[~held], n_periods, duration_rule)
        order, evals = ref_evaluate(sub, t[held], y[held], mo)
    else:
        order, evals = 0, [0.0]
    pred = np.clip(ref_estimates(model, query_s - t0, order)[order], 0.0, 1.0)
    return order, evals, pred


def _stream(edge: tuple[str, str], start: float, days: float, per_day: int, seed: int, kind: str) -> EdgeStream:
    rng = np.random.default_rng(seed)
    t = start + np.sort(rng.uniform(0, days * DAY, int(days * per_day)))
    hour = np.mod(t - MONDAY, DAY) / 3600
    weekday = np.floor(np.mod(t - MONDAY, WEEK) / DAY)
    if kind == "office":  # weekdays 9-17
        x = (hour >= 9) & (hour < 17) & (weekday < 5)
    elif kind == "lunch":  # a short daily visit and a weekly one
        x = ((hour >= 12) & (hour < 13.5)) | ((weekday == 2) & (hour >= 15) & (hour < 19))
    else:  # a drifting two-day cycle
        x = np.mod((t - MONDAY) / 3600 + 5, 47) < 20
    y = np.where(rng.random(t.size) < 0.12, ~x, x).astype(np.int8)
    return EdgeStream(edge, t, y)


# (edge, training days, validation week?, kind): 14 days without validation (the lab's case: the
# held-out sub-model spans < 1.5 weeks, so the weekly period is dropped there); 21 days with a
# validation week; 9 days (shorter than 1.5 weeks: the full model drops the weekly period) with one.
CASES = [(("mug", "desk"), 14, False, "office"), (("cup", "sink"), 14, False, "lunch"),
         (("pen", "tray"), 21, True, "office"), (("hat", "hook"), 21, True, "cycle"),
         (("key", "bowl"), 9, True, "lunch"), (("bag", "door"), 9, True, "office")]


def _data(per_day: int, seed: int) -> tuple[list[EdgeStream], list[EdgeStream]]:
    train, val = [], []
    for i, (edge, days, has_val, kind) in enumerate(CASES):
        start = MONDAY + WEEK + 3 * 3600.0 * i  # after the validation week, not on a Monday 00:00
        train.append(_stream(edge, start, days, per_day, seed + i, kind))
        if has_val:
            val.append(_stream(edge, MONDAY, 7, per_day, seed + 100 + i, kind))
    return train, val


@pytest.mark.parametrize(("per_day", "n_periods", "max_order"), [(40, 60, None), (150, 120, None), (60, 200, 5)])
def test_default_fremen_equals_an_independent_implementation_of_the_public_rules(
        per_day: int, n_periods: int, max_order: int | None) -> None:
    train, val = _data(per_day, seed=per_day)
    est = get_estimator("fremen", n_periods=n_periods, max_order=max_order).fit(train, val_streams=val,
                                                                                 timezone="UTC")
    vals = {s.edge: s for s in val}
    orders = []
    for s in train:
        q = np.linspace(s.t_s.max() - 3 * DAY, s.t_s.max() + 8 * DAY, 2000)
        order, evals, want = ref_fremen(s, vals.get(s.edge), q, n_periods, max_order)
        info = est.fit_info_[s.edge]
        assert info["order"] == order, s.edge
        np.testing.assert_allclose(info["scores"], evals, rtol=0, atol=1e-12)
        got = est.make_filter(s.edge).predict(q)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        orders.append(order)
    assert max(orders) > 0  # the streams are periodic: the rule picks components, not only the mean
    summary = est.fit_summary_["order_selection"]
    assert summary["order_rule"] == "reference" and summary["duration_rule"] is True
    assert [summary["edges"][f"{s.edge[0]}/{s.edge[1]}"]["order"] for s in train] == orders


def test_the_duration_rule_changes_the_short_fits_and_can_be_switched_off() -> None:
    train, val = _data(40, seed=3)
    on = get_estimator("fremen", n_periods=60).fit(train, val_streams=val)
    off = get_estimator("fremen", n_periods=60, duration_rule=False).fit(train, val_streams=val)
    short = ("key", "bowl")  # 9 days: the weekly period (1.5 x 7 days > 9 days) is dropped
    assert on.fit_info_[short]["periods_kept"] == 59 and off.fit_info_[short]["periods_kept"] == 60
    assert 1 not in on.components_[short].k.tolist()
    s = next(x for x in train if x.edge == short)
    q = np.linspace(s.t_s.max(), s.t_s.max() + 7 * DAY, 500)
    order, _, want = ref_fremen(s, next(x for x in val if x.edge == short), q, 60, None, duration_rule=False)
    assert off.fit_info_[short]["order"] == order
    np.testing.assert_allclose(off.make_filter(short).predict(q), want, rtol=0, atol=1e-12)
    # a 21-day fit keeps every period with or without the rule
    assert on.fit_info_[("pen", "tray")]["periods_kept"] == 60


def test_mae_rule_is_the_smallest_order_within_tolerance_of_the_best_clipped_mae() -> None:
    train, val = _data(40, seed=5)
    est = get_estimator("fremen", n_periods=60, order_rule="mae", duration_rule=False).fit(train, val_streams=val)
    for s in val:
        t0 = ref_monday(float(min(x.t_s.min() for x in train if x.edge == s.edge)))
        tr = next(x for x in train if x.edge == s.edge)
        model = ref_fit(tr.t_s - t0, tr.y.astype(float), 60, duration_rule=False)
        est_v = np.clip(ref_estimates(model, s.t_s - t0, 60), 0, 1)
        mae = np.mean(np.abs(est_v - s.y.astype(float)), axis=1)
        want = int(np.flatnonzero(mae <= mae.min() + 1e-3)[0])
        assert est.fit_info_[s.edge]["order"] == want
        np.testing.assert_allclose(est.fit_info_[s.edge]["scores"], mae, rtol=0, atol=1e-12)
    assert est.fit_summary_["order_selection"]["order_rule"] == "mae"


def test_choose_order_rules_on_hand_made_scores() -> None:
    s = [0.30, 0.2995, 0.25, 0.2492, 0.10, 0.0995, 0.1]
    # reference: 0 -> 2 (0.25 < 0.30 - 0.001) -> 4 (0.10); 0.0995 is not better by more than 0.001
    assert choose_order(s, 1e-3, "reference") == 4
    assert choose_order(s, 0.0, "reference") == 5
    # mae: the smallest order within 0.001 of the minimum 0.0995
    assert choose_order(s, 1e-3, "mae") == 4
    # the rules differ: reference compares with the best so far, mae with the overall minimum
    s2 = [0.5, 0.2, 0.1995, 0.199, 0.1985]
    assert choose_order(s2, 1e-3, "reference") == 4  # 0.1985 < 0.2 - 0.001
    assert choose_order(s2, 1e-3, "mae") == 2  # 0.1995 <= 0.1985 + 0.001
    with pytest.raises(EstimatorError, match="order rule"):
        choose_order(s2, 1e-3, "aic")


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=30), st.floats(0.0, 0.05))
def test_choose_order_properties(scores: list[float], tol: float) -> None:
    ref, mae = choose_order(scores, tol, "reference"), choose_order(scores, tol, "mae")
    # brute force of the two definitions
    best, want = math.inf, 0
    for j, v in enumerate(scores):
        if v < best - tol:
            best, want = v, j
    assert ref == want
    assert mae == min(j for j, v in enumerate(scores) if v <= min(scores) + tol)
    # every later order is at most tol better than the reference choice, so mae never picks more
    assert all(v >= scores[ref] - tol for v in scores[ref:])
    assert mae <= ref


def test_order_scores_name_the_rule_and_the_settings_parse_from_the_command_line() -> None:
    m = FremenModel(4).add(np.arange(10.0) * 3600, np.ones(10))
    with pytest.raises(EstimatorError, match="order rule"):
        m.order_scores(np.zeros(1), np.zeros(1), rule="auc")
    decl = FremenEstimator._parameters
    assert parse_setting("fremen", decl, "order_rule", "mae") == "mae"
    assert parse_setting("fremen", decl, "duration_rule", "off") is False
    with pytest.raises(EstimatorError, match="order_rule must be one of reference, mae"):
        parse_setting("fremen", decl, "order_rule", "auc")
    with pytest.raises(EstimatorError, match="order_rule must be one of reference, mae"):
        get_estimator("fremen", order_rule="auc").fit([EdgeStream(("a", "b"), np.arange(3.0), np.ones(3, np.int8))])
    star = get_estimator("perpetua_star")
    assert star.get_params()["order_rule"] == "reference" and star.get_params()["duration_rule"] is True


def test_order_scores_equal_the_reference_evaluation_over_several_chunks() -> None:
    # 1000 orders x 4100 held-out times: the scores are summed over two chunks (4000 rows, then 100)
    rng = np.random.default_rng(11)
    t = np.sort(rng.uniform(0, 2 * WEEK, 300))
    y = (np.mod(t, DAY) < 0.4 * DAY).astype(float)
    tv = rng.uniform(-WEEK, 3 * WEEK, 4100)
    yv = (np.mod(tv, DAY) < 0.4 * DAY).astype(float)
    m = FremenModel(1000).add(t, y)
    model = ref_fit(t, y, 1000, duration_rule=False)
    est = ref_estimates(model, tv, 1000)
    want_ref = np.mean(np.abs(yv - (est > 0.5)), axis=1)
    want_mae = np.mean(np.abs(yv - np.clip(est, 0.0, 1.0)), axis=1)
    np.testing.assert_allclose(m.order_scores(tv, yv), want_ref, rtol=0, atol=1e-12)  # the default rule
    np.testing.assert_array_equal(m.order_scores(tv.reshape(-1, 2), yv), m.order_scores(tv, yv))  # any shape
    np.testing.assert_allclose(m.order_scores(tv, yv, rule="mae"), want_mae, rtol=0, atol=1e-9)
    # columns are flattened; float32 times are read as float64
    np.testing.assert_array_equal(m.order_scores(tv[:50, None], yv[:50, None], 5), m.order_scores(tv[:50], yv[:50], 5))
    t32 = tv[:200].astype(np.float32)
    np.testing.assert_allclose(m.order_scores(t32, yv[:200], 40, rule="mae"),
                               m.order_scores(t32.astype(np.float64), yv[:200], 40, rule="mae"), rtol=0, atol=1e-12)


def test_order_scores_threshold_is_strict_and_sizes_zero_and_one() -> None:
    m = FremenModel(3).add([0.0, 3600.0], [1.0, 0.0])  # mean exactly 0.5: the order-0 estimate is 0.5
    yv = np.array([1.0, 1.0, 1.0, 0.0])
    s = m.order_scores(np.arange(4.0) * 7200, yv, max_order=0)
    assert s.tolist() == [0.75]  # (0.5 > 0.5) is 0: wrong on the three ones
    empty = m.order_scores([], [], max_order=2)
    assert empty.tolist() == [0.0, 0.0, 0.0]
    one = m.order_scores([1800.0], [1.0], max_order=0)
    assert one.tolist() == [1.0]
    with pytest.raises(EstimatorError, match="must be one of reference, mae, train_mse, got 'auc'"):
        m.order_scores([1.0], [1.0], rule="auc")


def test_choose_order_default_rule_shapes_and_no_finite_score() -> None:
    s = [0.30, 0.2995, 0.25, 0.2492, 0.10, 0.0995, 0.1]
    assert choose_order(s, 1e-3) == choose_order(s, 1e-3, "reference") == 4
    assert choose_order(np.array(s)[:, None], 1e-3) == 4
    assert choose_order(np.array(s)[:, None], 1e-3, "mae") == 4
    assert choose_order([math.inf, math.inf], 0.0) == 0  # nothing beats "no score yet": order 0
    assert choose_order([], 0.0) == 0
    # float32 scores are compared in float64: 1 - 2^-24 beats 1.0 by 2^-24 > tol = 3 * 2^-26, although
    # 1.0 - tol would round to 1 - 2^-24 in float32
    s32 = np.array([1.0, 1.0 - 2.0**-24], dtype=np.float32)
    assert choose_order(s32, 3 * 2.0**-26) == 1
    with pytest.raises(EstimatorError, match="must be one of reference, mae, train_mse, got 'aic'"):
        choose_order(s, 1e-3, "aic")
