"""Scoring windows and window weights at their edges: empty, touching, zero-length, rounding (issue 33)."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import EvaluationError
from psg_data.metrics import check_windows, window_weights


def test_no_windows_is_an_empty_k_by_2_array_and_gives_zero_weights() -> None:
    empty = check_windows([])
    assert empty.shape == (0, 2) and empty.dtype == np.float64
    assert window_weights([0.0, 1.0], []).tolist() == [0.0, 0.0]


@pytest.mark.parametrize(("bad", "message"), [
    ([5.0], r"^windows: expected a \(K, 2\) array of \[start, end\] seconds, got shape \(1,\)$"),
    ([[0.0, np.inf]], r"^windows: start and end must be finite seconds$"),
    ([[0.0, 1.0], [3.0, 2.0]], r"^windows\[1\] = \[3\.0, 2\.0\]: end must be after start$"),
    ([[0.0, 1.0], [3.0, 3.0]], r"^windows\[1\] = \[3\.0, 3\.0\]: end must be after start$"),
    ([[0.0, 2.0], [3.0, 4.0], [3.5, 10.0]],
     r"^windows\[2\] starts at 3\.5 before windows\[1\] ends \(4\.0\); expected sorted, disjoint windows$"),
    ([[0.0, 1.0], [1.0, 2.0], [1.5, 3.0]],
     r"^windows\[2\] starts at 1\.5 before windows\[1\] ends \(2\.0\)"),
])
def test_bad_windows_name_the_window(bad: object, message: str) -> None:
    with pytest.raises(EvaluationError, match=message):
        check_windows(bad)


def test_touching_windows_are_disjoint() -> None:
    # [start, end) windows: one may start where the previous ends
    assert check_windows([[0.0, 1.0], [1.0, 2.0], [2.0, 3.0]]).shape == (3, 2)
    assert window_weights([0.0, 3.0], [[0.0, 1.0], [1.0, 3.0]]) == pytest.approx([1.5, 1.5])


def test_a_window_near_the_first_sample_of_a_long_interval_is_integrated_exactly() -> None:
    # integral over [1, 3] of (1e9 - t) / 1e9 and of t / 1e9: the clock is shifted to the first sample,
    # so no square of a large time enters the weights
    assert window_weights([0.0, 1e9], [[1.0, 3.0]]) == pytest.approx([2.0 - 4e-9, 4e-9], rel=1e-9, abs=1e-15)


@pytest.mark.parametrize(("t", "window"), [
    # a short window that ends at a sample: the left end's weight rounds to -5.5e-12 before clipping
    ([2884971.58099136, 5059341.403311961, 6683021.969954264, 7513695.582090377],
     [5059341.402688472, 5059341.403311961]),
    # one that starts at a sample: the right end's weight rounds to -1.0e-11 before clipping
    ([784836.4027479492, 1680309.8329903192, 4122987.0547731603], [1680309.8329903192, 1680309.8335904197]),
])
def test_weights_are_never_negative(t: list[float], window: list[float]) -> None:
    w = window_weights(t, [window])
    assert np.all(w >= 0.0)
    assert w.sum() == pytest.approx(window[1] - window[0], rel=1e-6)
