"""Time-integrated metrics: unsorted and array-like inputs, windows and defaults of every variant (issue 33)."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import EvaluationError
from psg_data.metrics import (
    balanced_accuracy,
    f1,
    time_integrated_balanced_accuracy,
    time_integrated_f1,
    time_integrated_mae,
    window_weights,
)

T = [0.0, 1.0, 2.0, 4.0, 5.0]
Y = [1, 0, 1, 1, 0]
B = [0.9, 0.6, 0.2, 0.7, 0.4]
WINDOWS = [[0.5, 2.5], [3.5, 5.0]]


def _all(t, y, b, **kw) -> list[float]:
    return [time_integrated_mae(t, y, b, **kw), time_integrated_balanced_accuracy(t, y, b, **kw),
            time_integrated_f1(t, y, b, **kw)]


def test_two_samples_given_in_reverse_order_are_sorted() -> None:
    assert time_integrated_mae([1.0, 0.0], [0, 1], [0.0, 0.5]) == pytest.approx(0.25)


@pytest.mark.parametrize("form", ["row", "strings"])
def test_any_array_like_is_accepted(form: str) -> None:
    expected = _all(T, Y, B)
    if form == "row":
        got = _all(np.asarray(T)[None, :], np.asarray(Y)[None, :], np.asarray(B)[None, :])
    else:  # numbers as text (a CSV column)
        got = _all([str(v) for v in T], Y, [str(v) for v in B])
    assert got == pytest.approx(expected)


def test_windows_weight_every_time_integrated_metric() -> None:
    # each metric with windows equals the weighted per-sample metric with the window weights
    w = window_weights(T, WINDOWS)
    assert time_integrated_balanced_accuracy(T, Y, B, windows=WINDOWS) == pytest.approx(
        balanced_accuracy(Y, B, sample_weight=w, convention="reference"))
    assert time_integrated_f1(T, Y, B, windows=WINDOWS) == pytest.approx(
        f1(Y, B, sample_weight=w, convention="reference"))
    # and differs from the plain trapezoid here
    assert time_integrated_balanced_accuracy(T, Y, B, windows=WINDOWS) != pytest.approx(
        time_integrated_balanced_accuracy(T, Y, B))
    assert time_integrated_f1(T, Y, B, windows=WINDOWS) != pytest.approx(time_integrated_f1(T, Y, B))


def test_time_integrated_f1_defaults_are_the_reference_convention_and_zero_division_0() -> None:
    t, none_present = [0.0, 1.0, 2.0], [0, 0, 0]
    # no positive in truth nor prediction: the reference scores 0 whatever zero_division says
    assert time_integrated_f1(t, none_present, [0.1, 0.1, 0.1], zero_division=1.0) == 0.0
    assert time_integrated_f1(t, none_present, [0.1, 0.1, 0.1], convention="sklearn") == 0.0
    assert time_integrated_f1(t, none_present, [0.1, 0.1, 0.1], convention="sklearn", zero_division=1.0) == 1.0


def test_length_mismatch_names_all_three_lengths() -> None:
    with pytest.raises(EvaluationError, match=r"^t_s, y_true and y_pred differ in length \(3, 2, 2\)$"):
        time_integrated_mae([0.0, 1.0, 2.0], [1, 0], [0.5, 0.5])
