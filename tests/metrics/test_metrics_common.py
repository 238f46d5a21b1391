"""Invariance properties checked across every metric (scikit-learn's test_common style)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.metrics import (
    abort_rate,
    balanced_accuracy,
    distance_travelled,
    f1,
    mae,
    spl,
    success_rate,
    time_integrated_balanced_accuracy,
    time_integrated_f1,
    time_integrated_mae,
)


@dataclass(frozen=True)
class M:
    """A metric under a common signature ``fn(t_s, y, b, w)``; ``timed`` ones ignore w."""

    name: str
    fn: Callable[..., float]
    timed: bool


PERSISTENCE_METRICS = [
    M("mae", lambda t, y, b, w: mae(y, b, sample_weight=w), False),
    M("mae_binarised", lambda t, y, b, w: mae(y, b, sample_weight=w, threshold=0.5), False),
    M("bacc_sklearn", lambda t, y, b, w: balanced_accuracy(y, b, sample_weight=w), False),
    M("bacc_reference", lambda t, y, b, w: balanced_accuracy(y, b, sample_weight=w, convention="reference"), False),
    M("f1_sklearn", lambda t, y, b, w: f1(y, b, sample_weight=w), False),
    M("f1_reference", lambda t, y, b, w: f1(y, b, sample_weight=w, convention="reference"), False),
    M("ti_mae", lambda t, y, b, w: time_integrated_mae(t, y, b), True),
    M("ti_bacc_reference", lambda t, y, b, w: time_integrated_balanced_accuracy(t, y, b), True),
    M("ti_bacc_sklearn", lambda t, y, b, w: time_integrated_balanced_accuracy(t, y, b, convention="sklearn"), True),
    M("ti_f1_reference", lambda t, y, b, w: time_integrated_f1(t, y, b), True),
    M("ti_f1_sklearn", lambda t, y, b, w: time_integrated_f1(t, y, b, convention="sklearn"), True),
]
IDS = [m.name for m in PERSISTENCE_METRICS]
TOL = dict(rel=1e-6, abs=1e-9)  # the reference's 1e-8 guards break exact scale invariance


@st.composite
def data(draw):
    n = draw(st.integers(2, 25))
    t = np.concatenate([[0.0], np.cumsum(draw(st.lists(st.floats(0.1, 50.0), min_size=n - 1, max_size=n - 1)))])
    y = np.array(draw(st.lists(st.integers(0, 1), min_size=n, max_size=n)))
    b = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n)))
    w = np.array(draw(st.lists(st.floats(0.1, 10.0), min_size=n, max_size=n)))
    perm = np.array(draw(st.permutations(range(n))))
    c = draw(st.floats(0.5, 100.0))
    return t, y, b, w, perm, c


@pytest.mark.parametrize("m", PERSISTENCE_METRICS, ids=IDS)
@settings(max_examples=25, deadline=None)
@given(d=data())
def test_order_of_samples_does_not_matter(m, d):
    t, y, b, w, perm, _ = d
    assert m.fn(t[perm], y[perm], b[perm], w[perm]) == pytest.approx(m.fn(t, y, b, w), **TOL)


@pytest.mark.parametrize("m", PERSISTENCE_METRICS, ids=IDS)
@settings(max_examples=25, deadline=None)
@given(d=data())
def test_scaling_weights_or_time_does_not_matter(m, d):
    t, y, b, w, _, c = d
    if m.timed:  # an affine change of the time unit/origin leaves time averages unchanged
        other = m.fn(c * t + 12345.0, y, b, w)
    else:
        other = m.fn(t, y, b, c * w)
    assert other == pytest.approx(m.fn(t, y, b, w), **TOL)


@pytest.mark.parametrize("m", PERSISTENCE_METRICS, ids=IDS)
@settings(max_examples=25, deadline=None)
@given(d=data(), code=st.sampled_from([-1, -2]))
def test_masked_samples_do_not_matter_and_range(m, d, code):
    t, y, b, w, _, _ = d
    base = m.fn(t, y, b, w)
    assert 0.0 <= base <= 1.0
    # a masked sample appended after the end (its interval has a masked end point)
    t2 = np.append(t, t[-1] + 7.0)
    y2, b2, w2 = np.append(y, code), np.append(b, 0.3), np.append(w, 2.0)
    assert m.fn(t2, y2, b2, w2) == pytest.approx(base, **TOL)


@pytest.mark.parametrize("m", [m for m in PERSISTENCE_METRICS if not m.timed], ids=lambda m: m.name)
@settings(max_examples=25, deadline=None)
@given(d=data())
def test_integer_weight_equals_repetition(m, d):
    t, y, b, _, _, _ = d
    reps = (np.arange(y.size) % 3) + 1
    got = m.fn(None, y, b, reps.astype(float))
    rep = m.fn(None, np.repeat(y, reps), np.repeat(b, reps), None)
    assert got == pytest.approx(rep, **TOL)


@pytest.mark.parametrize("m", PERSISTENCE_METRICS, ids=IDS)
def test_perfect_prediction_is_best(m):
    t = np.arange(6.0)
    y = np.array([1, 1, 0, 0, 1, 0])
    perfect = m.fn(t, y, y.astype(float), None)
    wrong = m.fn(t, y, 1.0 - y, None)
    if "mae" in m.name:
        assert perfect == 0.0 and wrong == 1.0
    else:
        assert perfect == pytest.approx(1.0, abs=1e-7) and wrong == 0.0


# ---------------------------------------------------------------- navigation metrics


NAV_METRICS = {
    "success_rate": lambda s, l_, p, a, tp, w: success_rate(s, sample_weight=w),
    "spl": lambda s, l_, p, a, tp, w: spl(s, l_, p, sample_weight=w),
    "abort_rate": lambda s, l_, p, a, tp, w: abort_rate(a, sample_weight=w),
    "distance_travelled": lambda s, l_, p, a, tp, w: distance_travelled(p, sample_weight=w),
}


@st.composite
def episodes(draw):
    n = draw(st.integers(1, 20))
    lst = lambda s: np.array(draw(st.lists(s, min_size=n, max_size=n)))  # noqa: E731
    s, a = lst(st.booleans()), lst(st.booleans())
    l_, p = lst(st.floats(0.0, 30.0)), lst(st.floats(0.0, 60.0))
    w = lst(st.floats(0.1, 10.0))
    return s, l_, p, a, None, w, np.array(draw(st.permutations(range(n)))), draw(st.floats(0.5, 100.0))


@pytest.mark.parametrize("name", list(NAV_METRICS))
@settings(max_examples=25, deadline=None)
@given(e=episodes())
def test_navigation_order_and_weight_scaling(name, e):
    s, l_, p, a, tp, w, perm, c = e
    fn = NAV_METRICS[name]
    base = fn(s, l_, p, a, tp, w)
    assert fn(s[perm], l_[perm], p[perm], a[perm], tp, w[perm]) == pytest.approx(base, rel=1e-9, abs=1e-12)
    assert fn(s, l_, p, a, tp, c * w) == pytest.approx(base, rel=1e-9, abs=1e-12)
    if name != "distance_travelled":
        assert 0.0 <= base <= 1.0
