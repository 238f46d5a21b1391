"""Masks, sample grids and their errors: mask_codes, trapezoid_weights and the time-integrated checks (issue 33)."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import EvaluationError
from psg_data.metrics import mask_codes, time_integrated_mae, trapezoid_weights, window_weights


def test_mask_codes_flattens_and_refuses_nan_with_its_own_message() -> None:
    assert mask_codes(np.array([[1, -1], [0, -2]])).tolist() == [True, False, True, False]
    with pytest.raises(EvaluationError, match=r"^y_true contains NaN or inf; expected 0, 1 or a privileged code$"):
        mask_codes([1.0, np.nan])


def test_trapezoid_weights_accept_array_likes() -> None:
    expected = [0.5, 1.5, 1.0]
    assert trapezoid_weights(np.array([[0.0, 1.0, 3.0]])).tolist() == expected
    assert trapezoid_weights(["0", "1", "3"]).tolist() == expected
    # any truthy value is valid: 2 and 1.0 count as True, 0.0 as False
    assert trapezoid_weights([0.0, 1.0, 3.0], valid=[2, 1, 1]).tolist() == expected
    assert trapezoid_weights([0.0, 1.0, 3.0], valid=[1.0, 1.0, 0.0]).tolist() == [0.5, 0.5, 0.0]
    assert trapezoid_weights([0.0, 1.0, 3.0], valid=np.array([[True, True, False]])).tolist() == [0.5, 0.5, 0.0]


@pytest.mark.parametrize(("t", "valid", "message"), [
    ([0.0, 2.0, 2.0, 1.0], None, r"^t_s must be non-decreasing, got 1\.0 after 2\.0 at index 3$"),
    ([1.0, 0.0], None, r"^t_s must be non-decreasing, got 0\.0 after 1\.0 at index 1$"),
    ([0.0, np.nan], None, r"^t_s contains NaN or inf$"),
    ([0.0, 1.0], [True], r"^valid mask has 1 entries, t_s has 2$"),
])
def test_trapezoid_weights_refuse(t: list[float], valid: list[bool] | None, message: str) -> None:
    with pytest.raises(EvaluationError, match=message):
        trapezoid_weights(t, valid)


def test_unsorted_times_with_ties_keep_the_given_order_of_the_tied_samples() -> None:
    # 60 samples on 6 distinct times, shuffled: the metric equals that of the stably sorted input
    rng = np.random.default_rng(3)
    t = rng.integers(0, 6, 60).astype(np.float64) * 3600.0
    y = rng.integers(0, 2, 60)
    b = rng.uniform(0.0, 1.0, 60)
    order = np.argsort(t, kind="stable")
    assert time_integrated_mae(t, y, b) == time_integrated_mae(t[order], y[order], b[order])


def test_custom_codes_and_masked_samples_inside_windows() -> None:
    t, b = [0.0, 1.0, 2.0, 3.0], [0.5, 0.5, 1.0, 0.0]
    # 9 marks a sample as not scorable; -1 then is an error
    assert time_integrated_mae(t, [1, 9, 1, 1], b, codes=(9,)) == pytest.approx(0.5)
    with pytest.raises(EvaluationError, match=r"y_true\[1\] = -1"):
        time_integrated_mae(t, [1, -1, 1, 1], b, codes=(9,))
    # with windows, the interval touching the masked sample is not integrated either
    w = window_weights(t, [[0.0, 3.0]], valid=[True, False, True, True])
    assert w.tolist() == [0.0, 0.0, 0.5, 0.5]
    assert time_integrated_mae(t, [1, -1, 1, 1], b, windows=[[0.0, 3.0]]) == pytest.approx(0.5)


def test_zero_span_messages() -> None:
    with pytest.raises(EvaluationError, match=r"^time-integrated metric needs at least two distinct valid times "
                                              r"\(zero integrated span\)$"):
        time_integrated_mae([5.0], [1], [0.5])
    with pytest.raises(EvaluationError, match=r"\(zero integrated span\) inside the scoring windows$"):
        time_integrated_mae([0.0, 1.0], [1, 1], [0.5, 0.5], windows=[[5.0, 6.0]])
