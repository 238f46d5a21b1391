"""Intervals against independent computations: scipy's t quantiles and t.interval, a loop-by-loop
leave-one-out jackknife, a loop-by-loop expanded percentile bootstrap (Hesterberg 2015's level
``Phi(sqrt(n / (n - 1)) t_{n-1, a/2})`` from scipy), and the record / text helpers by their contract."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import stats

from psg_data.errors import EvaluationError
from psg_data.evaluation._intervals import (
    MIN_BOOTSTRAP_UNITS,
    Interval,
    cluster_bootstrap,
    cluster_jackknife,
    describe_interval,
    ratio_interval,
    t_interval,
)

_CONF = st.sampled_from([0.5, 0.8, 0.9, 0.95, 0.99, 0.999])


# --- t_interval ------------------------------------------------------------------------------------------


def _stdev(values: list[float]) -> float:
    """Sample standard deviation (ddof = 1), two-pass with exact sums."""
    m = math.fsum(values) / len(values)
    return math.sqrt(math.fsum((x - m) ** 2 for x in values) / (len(values) - 1))


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.floats(-50.0, 50.0, allow_nan=False), min_size=2, max_size=12), _CONF)
def test_t_interval_is_scipys(values: list[float], conf: float) -> None:
    v = np.array(values)
    iv = t_interval(v, confidence=conf, unit="lab draws")
    mean = math.fsum(values) / len(values)
    sd = _stdev(values)
    lo, hi = stats.t.interval(conf, len(values) - 1, loc=mean, scale=sd / math.sqrt(len(values))) if sd > 0 else (
        mean, mean)
    assert iv.estimate == pytest.approx(mean, abs=1e-9)
    assert (iv.low, iv.high) == pytest.approx((lo, hi), rel=1e-9, abs=1e-9)
    assert (iv.n, iv.method, iv.unit, iv.confidence) == (len(values), "t", "lab draws", conf)


def test_t_interval_drops_non_finite_values_and_flattens() -> None:
    v = np.array([[0.2, np.nan, 0.4], [np.inf, 0.9, -np.inf]])
    iv = t_interval(v)
    ref = stats.t.interval(0.95, 2, loc=0.5, scale=stats.sem([0.2, 0.4, 0.9]))
    assert iv.n == 3 and iv.estimate == pytest.approx(0.5)
    assert (iv.low, iv.high) == pytest.approx(ref)
    assert iv.half_width == pytest.approx((ref[1] - ref[0]) / 2)


def test_t_interval_of_two_values_by_hand() -> None:
    # n = 2: s = |x1 - x2| / sqrt 2, half = t_{1, 0.975} s / sqrt 2 = 12.7062... * 0.1
    iv = t_interval([0.5, 0.7])
    assert iv.high - iv.estimate == pytest.approx(12.706204736174707 * 0.1, rel=1e-12)
    assert iv.estimate == pytest.approx(0.6)


@pytest.mark.parametrize("values", [[], [np.nan], [np.inf, np.nan]])
def test_t_interval_of_nothing(values: list[float]) -> None:
    iv = t_interval(values, unit="seeds", confidence=0.9)
    assert math.isnan(iv.estimate) and math.isnan(iv.low) and math.isnan(iv.high)
    assert (iv.n, iv.method, iv.unit, iv.confidence) == (0, "none", "seeds", 0.9)


def test_t_interval_of_one_value() -> None:
    iv = t_interval([np.nan, 0.25], unit="seeds", confidence=0.8)
    assert iv.estimate == 0.25 and math.isnan(iv.low) and math.isnan(iv.high)
    assert (iv.n, iv.method, iv.unit, iv.confidence) == (1, "none", "seeds", 0.8)
    assert math.isnan(iv.half_width)
    assert t_interval([1.0, 2.0]).unit == "repetitions"


@pytest.mark.parametrize("conf", [0.0, 1.0, -0.5, 1.5])
def test_confidence_outside_the_open_unit_interval_is_rejected(conf: float) -> None:
    for call in (lambda: t_interval([1.0, 2.0], confidence=conf),
                 lambda: cluster_jackknife([1.0, 2.0], [1.0, 1.0], confidence=conf),
                 lambda: cluster_bootstrap(np.arange(12.0), np.ones(12), confidence=conf),
                 lambda: cluster_jackknife([], [], confidence=conf)):
        with pytest.raises(EvaluationError) as e:
            call()
        assert str(e.value) == f"confidence must be in (0, 1), got {conf}"


def test_confidence_just_inside_is_accepted() -> None:
    for conf in (1e-9, 1 - 1e-9):
        assert t_interval([1.0, 2.0, 4.0], confidence=conf).method == "t"


# --- Interval --------------------------------------------------------------------------------------------


def test_interval_half_width_and_round_trip() -> None:
    iv = Interval(0.5, 0.25, 1.0, 7, "bootstrap", "objects", 0.9)
    assert iv.half_width == 0.375
    for lo, hi in ((math.nan, 1.0), (0.0, math.nan), (-math.inf, 1.0), (0.0, math.inf)):
        assert math.isnan(Interval(0.5, lo, hi, 2, "t", "x").half_width)
    d = iv.to_dict()
    assert d == {"estimate": 0.5, "low": 0.25, "high": 1.0, "n": 7, "method": "bootstrap", "unit": "objects",
                 "confidence": 0.9}
    assert Interval.from_dict(json.loads(json.dumps(d))) == iv
    assert Interval(0.5, 0.25, 1.0, 7, "t", "seeds").confidence == 0.95


def test_interval_without_ends_serialises_as_null() -> None:
    iv = Interval(math.inf, math.nan, -math.inf, 1, "none", "seeds", 0.8)
    d = iv.to_dict()
    assert d == {"estimate": None, "low": None, "high": None, "n": 1, "method": "none", "unit": "seeds",
                 "confidence": 0.8}
    json.dumps(d, allow_nan=False)  # strict JSON
    back = Interval.from_dict(d)
    assert math.isnan(back.estimate) and math.isnan(back.low) and math.isnan(back.high)
    assert (back.n, back.method, back.unit, back.confidence) == (1, "none", "seeds", 0.8)


def test_interval_from_a_sparse_dict_takes_the_defaults() -> None:
    back = Interval.from_dict({"estimate": 2, "low": "1.5", "n": None})
    assert back.estimate == 2.0 and type(back.estimate) is float and back.low == 1.5
    assert math.isnan(back.high)
    assert (back.n, back.method, back.unit, back.confidence) == (0, "none", "", 0.95)
    full = Interval.from_dict({"estimate": 1, "low": 0, "high": 3, "n": "4", "method": "t", "unit": "u",
                               "confidence": "0.5"})
    assert full == Interval(1.0, 0.0, 3.0, 4, "t", "u", 0.5)
    assert type(full.n) is int and type(full.confidence) is float


# --- jackknife -------------------------------------------------------------------------------------------


def _jackknife_reference(num: list[float], den: list[float], conf: float) -> tuple[float, float, float]:
    n = len(num)
    est = math.fsum(num) / math.fsum(den)
    loo = [(math.fsum(num) - num[i]) / (math.fsum(den) - den[i]) for i in range(n)]
    m = math.fsum(loo) / n
    se = math.sqrt((n - 1) / n * math.fsum((x - m) ** 2 for x in loo))
    lo, hi = stats.t.interval(conf, n - 1, loc=est, scale=se) if se > 0 else (est, est)
    return est, lo, hi


_UNITS = st.lists(st.tuples(st.floats(0.0, 10.0), st.floats(0.1, 10.0)), min_size=2, max_size=9)


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(_UNITS, _CONF)
def test_jackknife_is_the_loop_by_loop_reference(units: list[tuple[float, float]], conf: float) -> None:
    num, den = [u[0] for u in units], [u[1] for u in units]
    iv = cluster_jackknife(num, den, confidence=conf, unit="queries")
    est, lo, hi = _jackknife_reference(num, den, conf)
    assert iv.estimate == pytest.approx(est, rel=1e-12, abs=1e-12)
    assert (iv.low, iv.high) == pytest.approx((lo, hi), rel=1e-9, abs=1e-9)
    assert (iv.n, iv.method, iv.unit, iv.confidence) == (len(units), "jackknife-t", "queries", conf)


def test_jackknife_defaults_and_trivial_cases() -> None:
    iv = cluster_jackknife([1.0, 3.0, 2.0], [1.0, 2.0, 4.0])
    assert (iv.unit, iv.confidence) == ("objects", 0.95)
    assert (iv.low, iv.high) == pytest.approx(_jackknife_reference([1.0, 3.0, 2.0], [1.0, 2.0, 4.0], 0.95)[1:])
    one = cluster_jackknife([3.0, 5.0], [2.0, 0.0], unit="objects", confidence=0.9)  # the 0-weight unit is dropped
    assert one.estimate == 1.5 and math.isnan(one.low) and math.isnan(one.high)
    assert (one.n, one.method, one.unit, one.confidence) == (1, "none", "objects", 0.9)
    none = cluster_jackknife([np.nan, 1.0], [1.0, -1.0], unit="u", confidence=0.8)
    assert math.isnan(none.estimate) and math.isnan(none.low) and math.isnan(none.high)
    assert (none.n, none.method, none.unit, none.confidence) == (0, "none", "u", 0.8)


def test_ratio_inputs_keep_only_finite_positive_weight_units() -> None:
    num = np.array([[1.0, 2.0, np.nan, 4.0, 5.0, np.inf, 7.0, 8.0]])
    den = np.array([[1.0, 0.0, 1.0, -2.0, np.inf, 1.0, 2.0, 0.5]])
    iv = cluster_jackknife(num, den)
    ref = _jackknife_reference([1.0, 7.0, 8.0], [1.0, 2.0, 0.5], 0.95)
    assert iv.n == 3 and (iv.estimate, iv.low, iv.high) == pytest.approx(ref)
    with pytest.raises(EvaluationError) as e:
        cluster_jackknife([1.0, 2.0, 3.0], [1.0, 1.0])
    assert str(e.value) == "ratio interval: 3 numerators for 2 denominators"
    with pytest.raises(EvaluationError, match="ratio interval: 2 numerators for 3 denominators"):
        ratio_interval([1.0, 2.0], [[1.0, 1.0, 1.0]])


# --- bootstrap -------------------------------------------------------------------------------------------


def _bootstrap_reference(num: np.ndarray, den: np.ndarray, conf: float, n_boot: int, seed: int
                         ) -> tuple[float, float, float]:
    """The documented resampling (numpy.random.default_rng(seed), n_boot multinomial count vectors over the
    n units), the resampled ratios one by one, and numpy's quantiles at Hesterberg's expanded level."""
    n = num.size
    counts = np.random.default_rng(seed).multinomial(n, [1.0 / n] * n, size=n_boot)
    ratios = []
    for c in counts:
        top = math.fsum(float(k) * float(x) for k, x in zip(c, num))
        bottom = math.fsum(float(k) * float(x) for k, x in zip(c, den))
        ratios.append(top / bottom)
    alpha = 1.0 - conf
    level = stats.norm.cdf(math.sqrt(n / (n - 1)) * stats.t.ppf(alpha / 2, df=n - 1))
    lo, hi = np.quantile(np.array(ratios), [level, 1.0 - level])
    return math.fsum(num) / math.fsum(den), float(lo), float(hi)


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(2, 25), _CONF, st.integers(1, 400), st.integers(0, 2**31), st.booleans())
def test_bootstrap_is_the_loop_by_loop_reference(n: int, conf: float, n_boot: int, seed: int, light: bool) -> None:
    rng = np.random.default_rng(seed + n)
    # light: weights below 1, so a resample's total weight can lie below 1 (it is never 0)
    den = rng.uniform(0.01, 0.3, n) if light else rng.uniform(0.5, 5.0, n)
    num = den * rng.uniform(0.0, 1.0, n)
    iv = cluster_bootstrap(num, den, confidence=conf, n_bootstrap=n_boot, seed=seed, unit="queries")
    est, lo, hi = _bootstrap_reference(num, den, conf, n_boot, seed)
    assert iv.estimate == pytest.approx(est, rel=1e-12)
    assert (iv.low, iv.high) == pytest.approx((lo, hi), rel=1e-9, abs=1e-12)
    assert (iv.n, iv.method, iv.unit, iv.confidence) == (n, "bootstrap", "queries", conf)


def test_bootstrap_ends_are_numpys_quantiles_of_the_float_ratios_to_the_sign_of_zero() -> None:
    """Resampled ratios of +-0 (subnormal numerators over a total weight that overflows to inf): the ends
    are numpy's quantiles of the float64 ratios, bit for bit (``nanquantile`` of an object array of the
    same ratios returns +0.0 here for the float array's -0.0)."""
    num, den = np.array([1e-320, -1e-320, 0.0]), np.array([1e308, 1e308, 1e308])
    with np.errstate(over="ignore"):
        iv = cluster_bootstrap(num, den, n_bootstrap=200, seed=0)
    counts = np.random.default_rng(0).multinomial(3, [1.0 / 3] * 3, size=200)
    ratios = [float(sum(int(k) * float(x) for k, x in zip(c, num))) / math.inf for c in counts]
    assert {math.copysign(1.0, r) for r in ratios} == {-1.0, 1.0}  # both zeros occur
    level = stats.norm.cdf(math.sqrt(3 / 2) * stats.t.ppf(0.025, df=2))
    lo, hi = np.quantile(np.array(ratios, dtype=np.float64), [level, 1.0 - level])
    assert (iv.low, iv.high) == (0.0, 0.0)
    assert (np.signbit(iv.low), np.signbit(iv.high)) == (np.signbit(lo), np.signbit(hi))
    assert json.dumps([iv.low, iv.high]) == json.dumps([float(lo), float(hi)])


def test_bootstrap_level_by_hand() -> None:
    """n = 2 at 95 %: level Phi(sqrt 2 * t_{1, 0.025}) = Phi(-17.97) ~ 0: the interval spans the resamples."""
    num, den = np.array([0.0, 1.0]), np.array([1.0, 1.0])
    iv = cluster_bootstrap(num, den, n_bootstrap=200, seed=3)
    # resampled ratios are 0 (both units the first), 0.5 or 1: min and max over 200 resamples
    assert (iv.low, iv.high) == (0.0, 1.0)
    assert iv.estimate == 0.5


def test_bootstrap_defaults_trivial_cases_and_checks() -> None:
    num, den = np.linspace(0.1, 1.0, 12), np.linspace(1.0, 2.0, 12)
    iv = cluster_bootstrap(num, den)
    est, lo, hi = _bootstrap_reference(num, den, 0.95, 2000, 0)
    assert (iv.low, iv.high) == pytest.approx((lo, hi), rel=1e-9)
    assert (iv.unit, iv.confidence, iv.n) == ("objects", 0.95, 12)
    one = cluster_bootstrap([2.0, 1.0], [4.0, 0.0], unit="u", confidence=0.8)
    assert one.estimate == 0.5 and math.isnan(one.low) and math.isnan(one.high)
    assert (one.n, one.method, one.unit, one.confidence) == (1, "none", "u", 0.8)
    zero = cluster_bootstrap([], [], unit="u", confidence=0.8)
    assert math.isnan(zero.estimate) and (zero.n, zero.method, zero.unit) == (0, "none", "u")
    assert cluster_bootstrap(num, den, n_bootstrap=1).method == "bootstrap"
    for bad in (0, -3):
        with pytest.raises(EvaluationError) as e:
            cluster_bootstrap(num, den, n_bootstrap=bad)
        assert str(e.value) == f"n_bootstrap must be >= 1, got {bad}"


# --- ratio_interval --------------------------------------------------------------------------------------


def test_ratio_interval_switches_at_ten_kept_units_and_passes_its_settings() -> None:
    assert MIN_BOOTSTRAP_UNITS == 10
    rng = np.random.default_rng(4)
    num, den = rng.uniform(0, 1, 10), rng.uniform(0.5, 1.5, 10)
    got = ratio_interval(num, den, confidence=0.8, n_bootstrap=150, seed=9, unit="queries")
    est, lo, hi = _bootstrap_reference(num, den, 0.8, 150, 9)
    assert got.method == "bootstrap" and (got.unit, got.confidence, got.n) == ("queries", 0.8, 10)
    assert (got.estimate, got.low, got.high) == pytest.approx((est, lo, hi), rel=1e-9)
    assert ratio_interval(num, den) == cluster_bootstrap(num, den)
    # a unit without weight does not count towards the ten: the jackknife on nine
    den0 = den.copy()
    den0[3] = 0.0
    got9 = ratio_interval(num, den0, confidence=0.8, unit="queries")
    ref = _jackknife_reference(list(np.delete(num, 3)), list(np.delete(den, 3)), 0.8)
    assert got9.method == "jackknife-t" and (got9.unit, got9.confidence, got9.n) == ("queries", 0.8, 9)
    assert (got9.estimate, got9.low, got9.high) == pytest.approx(ref, rel=1e-9)
    assert ratio_interval(num[:9], den[:9]) == cluster_jackknife(num[:9], den[:9])
    assert ratio_interval(num[:9], den[:9]).unit == "objects"


# --- describe_interval -----------------------------------------------------------------------------------


def test_describe_interval_texts() -> None:
    assert describe_interval("t", "lab draws", 5) == (
        "±: half-width of the 95 % t-interval over 5 lab draws (mean ± t * s / sqrt(n))")
    assert describe_interval("bootstrap", "objects", 21, 0.9, extra=" (pooled)") == (
        "±: half-width of the 90 % expanded percentile bootstrap over the 21 objects (objects resampled whole)"
        " (pooled)")
    assert describe_interval("jackknife-t", "queries", 7, 0.975) == (
        "±: half-width of the 97.5 % t-interval over the 7 queries with a jackknife standard error"
        " (too few queries for a bootstrap)")
    assert describe_interval("none", "seeds", 1) == "±: no interval (a single seed, nothing varies)"
    assert describe_interval("none", "", 1, extra="; x") == "±: no interval (a single value, nothing varies); x"
    assert describe_interval("something else", "s", 0) == "±: no interval (a single value, nothing varies)"
    # only the trailing s of a plural goes: a unit named in capitals keeps its letters
    assert describe_interval("none", "ROI BOX", 1) == "±: no interval (a single ROI BOX, nothing varies)"
    # -ies plurals (the navigation and door tables' queries) take -y, one trailing s only goes
    assert describe_interval("none", "door queries", 1) == "±: no interval (a single door query, nothing varies)"
    assert describe_interval("none", "passes", 1) == "±: no interval (a single passe, nothing varies)"


def test_exact_rationals_are_read_as_floats() -> None:
    """Values numpy holds as objects (``fractions.Fraction``) are converted, not rejected."""
    from fractions import Fraction

    vals = [Fraction(1, 2), Fraction(7, 10), Fraction(3, 5)]
    ref = t_interval([0.5, 0.7, 0.6])
    assert t_interval(vals) == ref
    num, den = [Fraction(1, 3), Fraction(2, 3), Fraction(1, 1)], [Fraction(1, 1), Fraction(2, 1), Fraction(3, 2)]
    assert cluster_jackknife(num, den) == cluster_jackknife([1 / 3, 2 / 3, 1.0], [1.0, 2.0, 1.5])
    assert ratio_interval(num, den).n == 3
