"""Gap-aware time weights: equal to a brute-force integral of the trapezoid interpolant over the windows."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import EvaluationError
from psg_data.metrics import check_windows, time_integrated_mae, trapezoid_weights, window_weights


def _exact_integral(t: np.ndarray, f: np.ndarray, valid: np.ndarray, windows: np.ndarray) -> float:
    """Integral over the windows of the piecewise-linear interpolant of f (intervals with both ends valid).

    The integrand is linear between the breakpoints {t_i} U {window ends}, so the trapezoid rule on
    the merged breakpoints is exact; computed interval by interval and window by window, with no
    shared code with the library.
    """
    total = 0.0
    for i in range(t.size - 1):
        if not (valid[i] and valid[i + 1]) or t[i + 1] <= t[i]:
            continue
        for a, b in windows:
            u, v = max(a, t[i]), min(b, t[i + 1])
            if v <= u:
                continue
            fu = np.interp(u, [t[i], t[i + 1]], [f[i], f[i + 1]])
            fv = np.interp(v, [t[i], t[i + 1]], [f[i], f[i + 1]])
            total += (fu + fv) / 2.0 * (v - u)
    return total


def _dense_integral(t: np.ndarray, f: np.ndarray, windows: np.ndarray, n: int = 400_001) -> float:
    """The same integral by a fine Riemann sum (all samples valid)."""
    x = np.linspace(t[0], t[-1], n)
    inside = np.zeros(n, bool)
    for a, b in windows:
        inside |= (x >= a) & (x < b)
    y = np.interp(x, t, f) * inside
    return float(np.sum((y[1:] + y[:-1]) / 2 * np.diff(x)))


@st.composite
def _case(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    n = draw(st.integers(2, 25))
    gaps = draw(st.lists(st.floats(0.0, 5.0), min_size=n - 1, max_size=n - 1))
    t = 1.7e9 + np.concatenate([[0.0], np.cumsum(gaps)])  # epoch-sized clock, duplicates allowed
    f = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n)))
    valid = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    k = draw(st.integers(0, 4))
    hi = int((t[-1] - t[0] + 3.0) * 100)
    cuts = np.sort(np.array(draw(st.lists(st.integers(-300, hi), min_size=2 * k, max_size=2 * k, unique=True)))) / 100
    win = 1.7e9 + cuts.reshape(-1, 2) if k else np.zeros((0, 2))
    return t, f, valid, win


@settings(max_examples=300, deadline=None)
@given(_case())
def test_window_weights_equal_the_exact_integral(case: tuple[np.ndarray, ...]) -> None:
    t, f, valid, win = case
    w = window_weights(t, win, valid)
    assert np.all(w >= 0)
    exact = _exact_integral(t, f, valid, win)
    assert float(np.sum(w * f)) == pytest.approx(exact, abs=1e-6)
    # weights sum to the valid time inside the windows (f = 1)
    assert float(np.sum(w)) == pytest.approx(_exact_integral(t, np.ones_like(f), valid, win), abs=1e-6)


def test_window_weights_equal_a_dense_riemann_sum() -> None:
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0, 100, 40))
    f = rng.random(40)
    win = np.array([[5.0, 17.3], [29.0, 41.0], [53.5, 65.0], [90.0, 200.0]])
    assert float(np.sum(window_weights(t, win) * f)) == pytest.approx(_dense_integral(t, f, win), rel=1e-4)


def test_one_window_over_the_span_is_the_plain_trapezoid() -> None:
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.1, 3.0, 50))
    valid = rng.random(50) > 0.2
    np.testing.assert_allclose(window_weights(t, [[t[0] - 1, t[-1] + 1]], valid), trapezoid_weights(t, valid))


def test_nights_get_no_weight() -> None:
    # a day grid every 15 min 9:00-17:00 (hours), two days; windows are the working hours
    day = np.arange(9.0, 17.0001, 0.25)
    t = np.concatenate([day, day + 24.0]) * 3600
    win = np.array([[9, 17], [33, 41]], float) * 3600
    w = window_weights(t, win)
    plain = trapezoid_weights(t)
    assert np.sum(w) == pytest.approx(16 * 3600)
    assert np.sum(plain) == pytest.approx(32 * 3600)  # the plain trapezoid also integrates the 16 h night
    last, first = day.size - 1, day.size
    assert w[last] == pytest.approx(450.0) and w[first] == pytest.approx(450.0)
    assert plain[last] == pytest.approx(450.0 + 8 * 3600)  # half of the night on each side


def test_time_integrated_mae_with_windows() -> None:
    t = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.array([1, 1, 0, 0])
    b = np.array([1.0, 0.0, 0.0, 0.0])
    # error 0 at t=0, 1 at t=1, 0 after: plain = (0.5 + 0.5) / 3; inside [0, 1] only: 0.5 / 1
    assert time_integrated_mae(t, y, b) == pytest.approx(1 / 3)
    assert time_integrated_mae(t, y, b, windows=[[0.0, 1.0]]) == pytest.approx(0.5)
    with pytest.raises(EvaluationError, match="inside the scoring windows"):
        time_integrated_mae(t, y, b, windows=[[10.0, 11.0]])


@pytest.mark.parametrize("bad, match", [([[1, 0]], "end must be after start"), ([[0, 2], [1, 3]], "disjoint"),
                                        ([[0, np.nan]], "finite"), ([1, 2, 3], "shape")])
def test_bad_windows(bad: object, match: str) -> None:
    with pytest.raises(EvaluationError, match=match):
        check_windows(bad)  # type: ignore[arg-type]
