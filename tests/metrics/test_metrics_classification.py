"""Persistence metrics: agreement with scikit-learn, hand-computed fixtures, edge cases."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.metrics import (
    balanced_accuracy_score,
    confusion_matrix,
    f1_score,
    mean_absolute_error,
)

from psg_data.errors import EvaluationError
from psg_data.metrics import (
    balanced_accuracy,
    binarize,
    confusion_counts,
    f1,
    mae,
    mask_codes,
    span_weighted_mean,
    time_integrated_balanced_accuracy,
    time_integrated_f1,
    time_integrated_mae,
    trapezoid_weights,
)

unit = st.floats(0.0, 1.0, allow_nan=False)


@st.composite
def samples(draw, min_size=1, both_classes=False, weights=False):
    n = draw(st.integers(min_size if not both_classes else max(2, min_size), 40))
    y = draw(st.lists(st.integers(0, 1), min_size=n, max_size=n))
    if both_classes:
        y[0], y[1] = 0, 1
    b = draw(st.lists(unit, min_size=n, max_size=n))
    w = draw(st.lists(st.floats(0.1, 10.0), min_size=n, max_size=n)) if weights else None
    return np.array(y), np.array(b), (None if w is None else np.array(w))


# ---------------------------------------------------------------- scikit-learn agreement


@settings(max_examples=60, deadline=None)
@given(samples(weights=True))
def test_mae_equals_sklearn(data):
    y, b, w = data
    assert mae(y, b, sample_weight=w) == pytest.approx(mean_absolute_error(y, b, sample_weight=w), rel=1e-12, abs=1e-15)
    assert mae(y, b) == pytest.approx(mean_absolute_error(y, b), rel=1e-12, abs=1e-15)


@settings(max_examples=60, deadline=None)
@given(samples(both_classes=True, weights=True), st.booleans())
def test_balanced_accuracy_equals_sklearn_when_both_classes_present(data, weighted):
    y, b, w = data
    w = w if weighted else None
    expected = balanced_accuracy_score(y, (b >= 0.5).astype(int), sample_weight=w)
    assert balanced_accuracy(y, b, sample_weight=w) == pytest.approx(expected, rel=1e-12, abs=1e-15)
    # the reference convention differs only by the 1e-8 guards when both classes are present
    ref = balanced_accuracy(y, b, sample_weight=w, convention="reference")
    assert ref == pytest.approx(expected, abs=1e-6)
    assert ref <= expected + 1e-15


@settings(max_examples=60, deadline=None)
@given(samples(weights=True), st.sampled_from([0.0, 1.0]))
def test_f1_equals_sklearn(data, zero_division):
    y, b, w = data
    expected = f1_score(y, (b >= 0.5).astype(int), sample_weight=w, zero_division=zero_division)
    assert f1(y, b, sample_weight=w, zero_division=zero_division) == pytest.approx(expected, rel=1e-12, abs=1e-15)


@settings(max_examples=60, deadline=None)
@given(samples(weights=True))
def test_reference_convention_matches_formula_on_sklearn_confusion_matrix(data):
    y, b, w = data
    yp = (b >= 0.5).astype(int)
    tn, fp, fn, tp = confusion_matrix(y, yp, labels=[0, 1], sample_weight=w).ravel()
    assert confusion_counts(y, b, sample_weight=w) == pytest.approx((tp, fp, fn, tn), rel=1e-12, abs=1e-12)
    tpr, tnr = tp / (tp + fn + 1e-8), tn / (tn + fp + 1e-8)
    prec = tp / (tp + fp + 1e-8)
    assert balanced_accuracy(y, b, sample_weight=w, convention="reference") == pytest.approx((tpr + tnr) / 2, rel=1e-12, abs=1e-15)
    assert f1(y, b, sample_weight=w, convention="reference") == pytest.approx(2 * prec * tpr / (prec + tpr + 1e-8), rel=1e-12, abs=1e-15)


# ---------------------------------------------------------------- thresholds and single class


def test_belief_exactly_half_is_present():
    assert binarize([0.5, 0.4999999, 0.5000001]).tolist() == [1, 0, 1]
    assert f1([1], [0.5]) == 1.0
    assert balanced_accuracy([1, 0], [0.5, 0.5]) == 0.5  # both predicted present
    assert mae([1, 0], [0.5, 0.5], threshold=0.5) == 0.5  # binarised MAE = error rate
    # a different threshold, same >= rule
    assert f1([1], [0.5], threshold=0.6) == 0.0
    assert f1([1], [0.6], threshold=0.6) == 1.0


def test_single_class_always_present():
    y, b = np.ones(5, int), np.full(5, 0.9)
    assert balanced_accuracy(y, b) == 1.0  # sklearn: recall of the only class
    assert balanced_accuracy(y, b, convention="reference") == pytest.approx(0.5, abs=1e-8)
    assert balanced_accuracy(y, b, convention="reference") < 0.5
    assert f1(y, b) == 1.0
    assert f1(y, b, convention="reference") == pytest.approx(1.0, abs=1e-7)
    # predicted absent everywhere: no true positive
    assert balanced_accuracy(y, 1 - b) == 0.0
    assert balanced_accuracy(y, 1 - b, convention="reference") == 0.0


def test_single_class_always_absent_and_zero_division():
    y, b = np.zeros(4, int), np.full(4, 0.1)
    assert balanced_accuracy(y, b) == 1.0
    assert balanced_accuracy(y, b, convention="reference") == pytest.approx(0.5, abs=1e-8)
    # no positive in truth or prediction: 0/0
    assert f1(y, b) == 0.0
    assert f1(y, b, zero_division=1.0) == 1.0
    assert f1(y, b, convention="reference", zero_division=1.0) == 0.0  # guards, no 0/0
    assert f1(y, b) == f1_score(y, (b >= 0.5).astype(int), zero_division=0.0)


# ---------------------------------------------------------------- masks


def test_mask_codes_and_masked_samples_are_ignored():
    y = np.array([1, -1, 0, -2, 1])
    assert mask_codes(y).tolist() == [True, False, True, False, True]
    b = np.array([0.9, 0.0, 0.2, 1.0, 0.4])
    keep = mask_codes(y)
    assert mae(y, b) == pytest.approx(mae(y[keep], b[keep]))
    assert f1(y, b) == f1(y[keep], b[keep])
    assert mask_codes([3, 0], codes=(3,)).tolist() == [False, True]
    with pytest.raises(EvaluationError, match=r"y_true\[1\] = -1"):
        mask_codes([3, -1], codes=(3,))


def test_invalid_inputs_raise():
    with pytest.raises(EvaluationError, match=r"y_true\[1\] = 2"):
        mask_codes([1, 2])
    with pytest.raises(EvaluationError, match="no samples to score"):
        mae([-1, -2], [0.1, 0.2])
    with pytest.raises(EvaluationError, match="no samples to score"):
        f1([], [])
    with pytest.raises(EvaluationError, match="differ in length"):
        mae([1, 0], [0.5])
    with pytest.raises(EvaluationError, match="must be finite"):
        balanced_accuracy([1, 0], [np.nan, 0.3])
    with pytest.raises(EvaluationError, match="convention must be one of"):
        f1([1], [1.0], convention="weird")  # type: ignore[arg-type]
    with pytest.raises(EvaluationError, match="non-negative"):
        mae([1, 0], [0.5, 0.5], sample_weight=[1.0, -1.0])
    with pytest.raises(EvaluationError, match="zero integrated span"):
        time_integrated_mae([5.0], [1], [0.5])
    with pytest.raises(EvaluationError, match="zero integrated span"):
        time_integrated_mae([0.0, 1.0, 2.0], [1, -1, 0], [0.5, 0.5, 0.5])


# ---------------------------------------------------------------- time-integrated, by hand


def test_time_integrated_three_point_grid_by_hand():
    t = np.array([0.0, 1.0, 3.0])
    y = np.array([1, 0, 1])
    b = np.array([0.8, 0.6, 0.2])
    # |x-b| = 0.2, 0.6, 0.8 ; trapezoids: (0.2+0.6)/2*1 + (0.6+0.8)/2*2 = 0.4 + 1.4 ; span 3
    assert time_integrated_mae(t, y, b) == pytest.approx(1.8 / 3)
    # weights 0.5, 1.5, 1.0 ; predicted 1, 1, 0 -> TP 0.5 (t=0), FP 1.5 (t=1), FN 1.0 (t=3), TN 0
    assert trapezoid_weights(t).tolist() == [0.5, 1.5, 1.0]
    tpr, tnr = 0.5 / 1.5, 0.0
    assert time_integrated_balanced_accuracy(t, y, b) == pytest.approx((tpr + tnr) / 2, abs=1e-7)
    assert time_integrated_balanced_accuracy(t, y, b, convention="sklearn") == pytest.approx(1 / 6)
    p, r = 0.5 / 2.0, 0.5 / 1.5
    assert time_integrated_f1(t, y, b) == pytest.approx(2 * p * r / (p + r), abs=1e-7)
    assert time_integrated_f1(t, y, b, convention="sklearn") == pytest.approx(2 / 7)
    # binarised MAE: |x - [1,1,0]| = 0,1,1 -> 0.5*1 + 1*2 = 2.5 over 3
    assert time_integrated_mae(t, y, b, threshold=0.5) == pytest.approx(2.5 / 3)


def test_time_integrated_always_present_feature_scores_at_most_half():
    t = np.arange(10.0)
    y = np.ones(10, int)
    b = np.full(10, 0.97)
    assert time_integrated_balanced_accuracy(t, y, b) == pytest.approx(0.5, abs=1e-8)
    assert time_integrated_balanced_accuracy(t, y, b, convention="sklearn") == 1.0
    assert time_integrated_mae(t, y, b) == pytest.approx(0.03)


def test_time_integrated_masking_integrates_only_valid_intervals():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.array([1, -1, 0, 0])
    b = np.array([1.0, 0.3, 0.2, 0.6])
    # only [2, 3] has two valid end points: (0.2 + 0.6) / 2 * 1, span 1
    assert time_integrated_mae(t, y, b) == pytest.approx(0.4)
    assert trapezoid_weights(t, mask_codes(y)).tolist() == [0.0, 0.0, 0.5, 0.5]


@st.composite
def grids(draw):
    n = draw(st.integers(2, 30))
    dt = draw(st.lists(st.floats(0.1, 100.0), min_size=n - 1, max_size=n - 1))
    t0 = draw(st.floats(1.6e9, 1.8e9))
    t = t0 + np.concatenate([[0.0], np.cumsum(dt)])
    y = np.array(draw(st.lists(st.integers(0, 1), min_size=n, max_size=n)))
    b = np.array(draw(st.lists(unit, min_size=n, max_size=n)))
    return t, y, b


@settings(max_examples=60, deadline=None)
@given(grids())
def test_time_integrated_mae_equals_numpy_trapezoid(g):
    t, y, b = g
    expected = np.trapezoid(np.abs(y - b), t) / (t[-1] - t[0])
    assert time_integrated_mae(t, y, b) == pytest.approx(expected, rel=1e-9, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(grids())
def test_time_integrated_counts_are_trapezoid_integrals(g):
    t, y, b = g
    x = (b >= 0.5).astype(float)
    tp = np.trapezoid(y * x, t)
    fn = np.trapezoid(y * (1 - x), t)
    fp = np.trapezoid((1 - y) * x, t)
    tn = np.trapezoid((1 - y) * (1 - x), t)
    expected = (tp / (tp + fn + 1e-8) + tn / (tn + fp + 1e-8)) / 2
    assert time_integrated_balanced_accuracy(t, y, b) == pytest.approx(expected, rel=1e-9, abs=1e-12)


def test_span_weighted_mean():
    assert span_weighted_mean([0.2, 0.4], [1.0, 1.0]) == pytest.approx(0.3)
    assert span_weighted_mean([0.2, 0.4, np.nan], [1.0, 3.0, 5.0]) == pytest.approx(0.35)
    assert np.isnan(span_weighted_mean([np.nan], [1.0]))
    with pytest.raises(EvaluationError, match="non-negative"):
        span_weighted_mean([0.1], [-1.0])
