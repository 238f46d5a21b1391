"""SurvivalMixture against independent references: mpmath at 50 digits and scipy.stats, per family.

Every log survival function of ``psg_data/estimators/_survival.py`` (the array form, the filters'
(K, n) batch form, the one-duration math-module form, the per-component form) is compared with
``log S(t)`` computed here from the distributions' definitions at 50 significant digits, on
durations from the body far into the tails, and with ``scipy.stats`` (``expon``, ``lognorm``,
``weibull_min``, ``fisk``) under hypothesis. The validation of the constructor is checked per rule.
"""

from __future__ import annotations

import math
import warnings

import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from scipy.special import log_ndtr

from psg_data.errors import EstimatorError
from psg_data.estimators import SURVIVAL_FAMILIES, SurvivalMixture
from psg_data.estimators._survival import log_ndtr_scalar

mpmath.mp.dps = 50

# Three components with different p1 and p2 each, so that a swapped or misplaced parameter shows.
MIXTURES = {
    "exponential": SurvivalMixture("exponential", np.array([0.2, 0.5, 0.3]), np.array([1 / 300.0, 1 / 4000.0, 2e-5]),
                                   np.array([7.0, 0.5, 3.0])),
    "lognormal": SurvivalMixture("lognormal", np.array([0.2, 0.5, 0.3]), np.log([200.0, 3000.0, 40000.0]),
                                 np.array([0.3, 1.1, 2.5])),
    "weibull": SurvivalMixture("weibull", np.array([0.2, 0.5, 0.3]), np.array([0.6, 1.7, 3.2]),
                               np.array([500.0, 4000.0, 30000.0])),
    "loglogistic": SurvivalMixture("loglogistic", np.array([0.2, 0.5, 0.3]), np.array([0.8, 2.5, 4.0]),
                                   np.array([250.0, 3500.0, 20000.0])),
}

# From a second to ~30 years: the body of each component and deep into its tails.
DURATIONS = np.array([1.0, 7.5, 60.0, 333.0, 1800.0, 3600.0, 12_345.0, 86_400.0, 604_800.0, 5e6, 1e9])


def ref_log_sf(family: str, p1: float, p2: float, t: float) -> float:
    """log P(T > t) from the distribution's definition, at 50 digits (t >= 0, seconds)."""
    t_m = mpmath.mpf(max(t, 0.0))
    a, b = mpmath.mpf(p1), mpmath.mpf(p2)
    if t_m == 0:
        return 0.0
    if family == "exponential":  # S = exp(-rate t)
        return float(-a * t_m)
    if family == "lognormal":  # S = Phi(z), z = (mu - ln t) / sigma
        return ref_log_ndtr((a - mpmath.log(t_m)) / b)
    if family == "weibull":  # S = exp(-(t / scale)^k)
        return float(-((t_m / b) ** a))
    return float(-mpmath.log1p((t_m / b) ** a))  # log-logistic: S = 1 / (1 + (t / alpha)^beta)


def ref_log_ndtr(z: mpmath.mpf) -> float:
    """log Phi(z) at 50 digits: log1p(-Phi(-z)) on the upper side, where Phi(z) is within 1e-50 of 1."""
    if z > 0:
        return float(mpmath.log1p(-mpmath.erfc(z / mpmath.sqrt(2)) / 2))
    return float(mpmath.log(mpmath.erfc(-z / mpmath.sqrt(2)) / 2))


def ref_matrix(m: SurvivalMixture, t: np.ndarray) -> np.ndarray:
    """(..., K) reference log S_l(t)."""
    flat = [[ref_log_sf(m.family, float(a), float(b), float(x)) for a, b in zip(m.p1, m.p2)] for x in t.ravel()]
    return np.array(flat).reshape(t.shape + (m.n_components,))


def scipy_log_sf(family: str, p1: float, p2: float, t: np.ndarray) -> np.ndarray:
    """scipy.stats' logsf of the same parametrisation (t >= 0, seconds)."""
    if family == "exponential":
        return stats.expon(scale=1.0 / p1).logsf(t)
    if family == "lognormal":
        return stats.lognorm(s=p2, scale=math.exp(p1)).logsf(t)
    if family == "weibull":
        return stats.weibull_min(c=p1, scale=p2).logsf(t)
    return stats.fisk(c=p1, scale=p2).logsf(t)


def assert_close(got: np.ndarray, want: np.ndarray, rtol: float = 1e-12) -> None:
    got, want = np.asarray(got, dtype=np.float64), np.asarray(want, dtype=np.float64)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=rtol, atol=1e-300)


@pytest.mark.parametrize("family", SURVIVAL_FAMILIES)
def test_log_sf_matches_mpmath_body_and_tails(family: str) -> None:
    m = MIXTURES[family]
    t = DURATIONS.reshape(1, -1).repeat(2, axis=0)  # (2, n): log_sf keeps any leading shape
    t[1] *= 1.5
    got = m.log_sf(t)
    assert got.shape == t.shape + (3,)
    assert_close(got, ref_matrix(m, t))


@pytest.mark.parametrize("family", SURVIVAL_FAMILIES)
def test_log_sf_is_zero_at_and_before_the_origin(family: str) -> None:
    m = MIXTURES[family]
    got = m.log_sf(np.array([-1e6, -3.0, -1e-9, 0.0]))
    assert got.shape == (4, 3)
    assert np.all(got == 0.0)
    assert np.all(m.log_sf_one(np.array([-50.0, 0.0, -1.0]), np.array([0, 1, 2])) == 0.0)


@pytest.mark.parametrize("family", SURVIVAL_FAMILIES)
def test_log_sf_scalar_input_gives_one_row(family: str) -> None:
    m = MIXTURES[family]
    got = m.log_sf(3600.0)
    assert got.shape == (3,)
    assert_close(got, ref_matrix(m, np.array(3600.0)))


@pytest.mark.parametrize("family", SURVIVAL_FAMILIES)
def test_single_precision_durations_are_evaluated_in_double(family: str) -> None:
    """float32 durations (a float32 Parquet column) convert to float64 before any arithmetic."""
    m = MIXTURES[family]
    t32 = np.array([7.3, 3601.7, 86_399.9, 5.1e6], dtype=np.float32)
    want = ref_matrix(m, t32.astype(np.float64))  # the float32 values, exactly, in double
    assert m.log_sf(t32).dtype == np.float64
    assert_close(m.log_sf(t32), want)
    k = np.array([0, 1, 2, 1])
    assert_close(m.log_sf_one(t32, k), want[np.arange(4), k])


@pytest.mark.parametrize("family", SURVIVAL_FAMILIES)
def test_log_sf_rows_matches_mpmath(family: str) -> None:
    m = MIXTURES[family]
    tau = np.concatenate([[0.0], DURATIONS])
    got = m.log_sf_rows(tau)
    assert got.shape == (3, tau.size)
    assert_close(got, ref_matrix(m, tau).T)


@pytest.mark.parametrize("family", SURVIVAL_FAMILIES)
def test_log_sf_scalar_matches_mpmath(family: str) -> None:
    m = MIXTURES[family]
    for tau in np.concatenate([[0.0], DURATIONS]):
        got = m.log_sf_scalar(float(tau))
        assert isinstance(got, list) and len(got) == 3
        assert all(isinstance(v, float) for v in got)
        assert_close(np.array(got), ref_matrix(m, np.array(tau)))


@pytest.mark.parametrize("family", SURVIVAL_FAMILIES)
def test_log_sf_one_matches_mpmath_with_broadcasting(family: str) -> None:
    m = MIXTURES[family]
    t = DURATIONS[:, None]  # (n, 1) against k (3,): (n, 3)
    k = np.array([2, 0, 1])
    got = m.log_sf_one(t, k)
    assert got.shape == (DURATIONS.size, 3)
    assert_close(got, ref_matrix(m, DURATIONS)[:, k])
    # a float array of indices (computed indices) selects the same components
    assert_close(m.log_sf_one(DURATIONS, np.full(DURATIONS.size, 1.0)), ref_matrix(m, DURATIONS)[:, 1])
    one = m.log_sf_one(1800.0, 2)
    assert np.ndim(one) == 0
    assert_close(one, np.array(ref_log_sf(family, float(m.p1[2]), float(m.p2[2]), 1800.0)))


@settings(max_examples=60, deadline=None)
@given(family=st.sampled_from(SURVIVAL_FAMILIES), p1=st.floats(0.2, 5.0), scale=st.floats(10.0, 1e6),
       t=st.lists(st.floats(0.01, 1e8), min_size=1, max_size=5))
def test_every_form_matches_scipy_stats(family: str, p1: float, scale: float, t: list[float]) -> None:
    # per family: exponential (rate = p1 / scale), lognormal (mu = ln scale, sigma = p1), Weibull and
    # log-logistic (shape p1, scale)
    a, b = {"exponential": (p1 / scale, 2.0), "lognormal": (math.log(scale), p1)}.get(family, (p1, scale))
    m = SurvivalMixture(family, np.array([0.5, 0.5]), np.array([a, 2.0 * a if family != "lognormal" else a + 1]),
                        np.array([b, 2.0 * b]))
    tt = np.array(t)
    with np.errstate(divide="ignore"):
        want = np.stack([scipy_log_sf(family, float(m.p1[j]), float(m.p2[j]), tt) for j in range(2)], axis=-1)
    finite = np.isfinite(want)
    if family == "loglogistic":  # scipy's fisk.logsf is log1p(-(1 + x^-c)^-1): it cancels in the far tail
        finite &= want > -8.0
    for got in (m.log_sf(tt), m.log_sf_rows(tt).T, np.array([m.log_sf_scalar(float(x)) for x in tt]),
                m.log_sf_one(tt[:, None], np.arange(2)[None, :])):
        np.testing.assert_allclose(got[finite], want[finite], rtol=1e-9, atol=1e-300)


def test_weibull_scalar_overflows_to_minus_infinity_like_the_arrays() -> None:
    """(t/scale)^k = e^z near the top of the double range: finite at z = 708.5, -inf once e^z overflows."""
    tau = 1e300
    for z in (700.0, 708.5, 709.9, 800.0):
        scale = math.exp(math.log(tau) - z)  # k = 1: z = ln(tau / scale)
        m = SurvivalMixture.single("weibull", 1.0, scale)
        want = ref_log_sf("weibull", 1.0, scale, tau)
        got = m.log_sf_scalar(tau)[0]
        assert got == want or math.isclose(got, want, rel_tol=1e-12), (z, got, want)
        with np.errstate(over="ignore"):  # numpy's exp warns where it overflows to inf
            assert m.log_sf_rows(np.array([tau]))[0, 0] == got
        assert math.isfinite(got) == (z < 709.0)


def test_loglogistic_scalar_tails_on_both_sides() -> None:
    """z = beta ln(t / alpha) from -700 to 800: log S = -z - e^-z above (no overflow), -e^z below."""
    m = SurvivalMixture.single("loglogistic", 100.0, 1.0)
    for z in (-700.0, -40.0, -1e-3, 1e-3, 0.5, 2.0, 40.0, 800.0):
        tau = math.exp(z / 100.0)
        want = ref_log_sf("loglogistic", 100.0, 1.0, tau)
        assert math.isclose(m.log_sf_scalar(tau)[0], want, rel_tol=1e-12), z
    assert m.log_sf_scalar(1.0)[0] == -math.log(2.0)


def test_log_ndtr_scalar_matches_mpmath_in_all_three_ranges() -> None:
    edges = [-1.0, np.nextafter(-1.0, 0.0), np.nextafter(-1.0, -2.0), -37.0, np.nextafter(-37.0, 0.0)]
    # erfc(-x / sqrt 2) / 2 leaves the normal range near x = -37.5: only the series is accurate below
    below = [-37.2, -37.5, -37.9, -37.99, -38.5, -39.0, -45.0, -300.0, -1e4]
    x = np.concatenate([np.linspace(-60.0, 8.0, 341), edges, below, [0.0, 30.0]])
    for v in x:
        want = ref_log_ndtr(mpmath.mpf(float(v)))
        got = log_ndtr_scalar(float(v))
        assert math.isclose(got, want, rel_tol=1e-13, abs_tol=1e-300), (v, got, want)
    np.testing.assert_allclose([log_ndtr_scalar(float(v)) for v in x], log_ndtr(x), rtol=1e-13, atol=1e-300)


def test_log_ndtr_scalar_series_is_accurate_to_a_few_ulps() -> None:
    """Below x = -37 (where erfc would leave the normal range) the erfcx series to 1/u^10 keeps
    log Phi within ~3 ulps: its first omitted term is ~1e-15 relative to s at x = -37."""
    for v in np.concatenate([np.linspace(-45.0, -37.0, 400, endpoint=False), [-50.0, -1e3, -1e6]]):
        want = ref_log_ndtr(mpmath.mpf(float(v)))
        assert math.isclose(log_ndtr_scalar(float(v)), want, rel_tol=2e-15), v


def test_lognormal_scalar_uses_the_math_module_log_ndtr() -> None:
    m = MIXTURES["lognormal"]
    for tau in (1e-3, 50.0, 4000.0, 1e7, 1e12):
        assert_close(np.array(m.log_sf_scalar(tau)), ref_matrix(m, np.array(tau)))


def test_exponential_ignores_its_unused_second_parameter_without_warnings() -> None:
    """p2 is unused by the exponential family: any value, even <= 0, is accepted and never read."""
    m = SurvivalMixture("exponential", np.array([1.0, 3.0]), np.array([1e-3, 1e-4]), np.array([-2.0, 0.0]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert m.log_sf_scalar(100.0) == pytest.approx([-0.1, -0.01], rel=1e-15)
        assert_close(m.log_sf_rows(np.array([100.0])), np.array([[-0.1], [-0.01]]))
        assert_close(m.log_sf(100.0), np.array([-0.1, -0.01]))
        assert_close(m.log_sf_one(100.0, 1), np.array(-0.01))


def test_scalar_path_after_a_change_of_family_cache_free_objects() -> None:
    """Two mixtures with the same arrays but different families do not share scalar parameters."""
    p1, p2 = np.array([2.0]), np.array([1000.0])
    w = SurvivalMixture("weibull", np.ones(1), p1, p2)
    ll = SurvivalMixture("loglogistic", np.ones(1), p1, p2)
    ln = SurvivalMixture("lognormal", np.ones(1), np.log(p2), np.array([0.5]))
    for tau in (10.0, 1000.0, 5e4):
        for m in (w, ll, ln, w):  # the second call on w reads its cached parameters
            assert_close(np.array(m.log_sf_scalar(tau)), ref_matrix(m, np.array(tau)))


def test_scalar_path_reads_its_parameters_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """The documented fast path (math module, no numpy): ln(scale) is taken with numpy once, on the first
    call, and every later call runs without touching numpy."""
    import psg_data.estimators._survival as survival

    m = SurvivalMixture("weibull", np.ones(2), np.array([1.5, 0.7]), np.array([100.0, 5000.0]))
    first = m.log_sf_scalar(250.0)

    class NoNumpy:
        def __getattr__(self, name: str) -> None:
            raise AssertionError(f"the scalar path called numpy.{name} after its first call")

    monkeypatch.setattr(survival, "np", NoNumpy())
    assert m.log_sf_scalar(250.0) == first
    assert_close(np.array(m.log_sf_scalar(9000.0)), ref_matrix(m, np.array(9000.0)))


# --- the constructor's validation and normalisation ---------------------------------------------------------


def test_weights_are_normalised_and_arrays_stored_as_float64() -> None:
    m = SurvivalMixture("weibull", [1, 3], [2, 1], [10, 20])  # type: ignore[arg-type]  # lists of ints
    for arr in (m.weights, m.p1, m.p2):
        assert isinstance(arr, np.ndarray) and arr.dtype == np.float64 and arr.shape == (2,)
    np.testing.assert_array_equal(m.weights, [0.25, 0.75])
    np.testing.assert_array_equal(m.p1, [2.0, 1.0])
    np.testing.assert_array_equal(m.p2, [10.0, 20.0])
    assert m.n_components == 2
    np.testing.assert_allclose(m.log_weights, np.log([0.25, 0.75]), rtol=1e-15)
    # float32 weights (a float32 Parquet column) are normalised in double precision
    w32 = np.array([0.1, 0.3, 0.7], dtype=np.float32)
    m32 = SurvivalMixture("weibull", w32, np.ones(3, dtype=np.float32), np.ones(3, dtype=np.float32))
    for arr in (m32.weights, m32.p1, m32.p2):
        assert arr.dtype == np.float64
    w64 = [float(v) for v in w32]  # the float32 values, exactly
    np.testing.assert_allclose(m32.weights, [v / math.fsum(w64) for v in w64], rtol=1e-15)
    assert abs(math.fsum(m32.weights.tolist()) - 1.0) <= 2e-16


def test_scalars_become_one_component() -> None:
    m = SurvivalMixture("loglogistic", 5.0, 2.0, 100.0)  # type: ignore[arg-type]
    assert m.weights.shape == m.p1.shape == m.p2.shape == (1,)
    assert m.weights[0] == 1.0 and m.n_components == 1
    assert_close(m.log_sf(100.0), np.array([-math.log(2.0)]))


def test_a_zero_weight_component_is_allowed() -> None:
    m = SurvivalMixture("lognormal", np.array([0.0, 2.0]), np.array([1.0, 2.0]), np.array([1.0, 1.0]))
    np.testing.assert_array_equal(m.weights, [0.0, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert m.log_weights[0] == -math.inf and m.log_weights[1] == 0.0


def test_negative_mu_is_a_valid_lognormal_and_unused_p2_a_valid_exponential() -> None:
    ln = SurvivalMixture("lognormal", np.ones(2), np.array([-3.0, 0.0]), np.array([0.5, 2.0]))
    assert_close(ln.log_sf(np.array([0.01])), ref_matrix(ln, np.array([0.01])))
    ex = SurvivalMixture("exponential", np.ones(1), np.array([0.5]), np.array([0.0]))
    assert ex.p2[0] == 0.0


@pytest.mark.parametrize("family", ["exponential", "weibull", "loglogistic"])
@pytest.mark.parametrize("bad", [0.0, -1.0])
def test_p1_must_be_positive_except_lognormal(family: str, bad: float) -> None:
    with pytest.raises(EstimatorError, match=rf"^survival mixture \({family}\): p1 must be > 0$"):
        SurvivalMixture(family, np.ones(2), np.array([1.0, bad]), np.array([1.0, 1.0]))


@pytest.mark.parametrize("family", ["lognormal", "weibull", "loglogistic"])
@pytest.mark.parametrize("bad", [0.0, -1.0])
def test_p2_must_be_positive_except_exponential(family: str, bad: float) -> None:
    with pytest.raises(EstimatorError, match=rf"^survival mixture \({family}\): p2 must be > 0$"):
        SurvivalMixture(family, np.ones(2), np.array([1.0, 1.0]), np.array([bad, 1.0]))


def test_unknown_family_names_the_valid_ones() -> None:
    with pytest.raises(EstimatorError) as e:
        SurvivalMixture("gamma", np.ones(1), np.ones(1), np.ones(1))
    assert str(e.value) == "unknown survival family 'gamma'; valid: exponential, lognormal, weibull, loglogistic"


WEIGHTS_MSG = r"^survival mixture: weights must be non-negative and sum to a positive value$"


@pytest.mark.parametrize("w", [[-0.1, 1.1], [0.0, 0.0], [np.inf, 1.0], [np.nan, 1.0], [-1.0, -2.0]])
def test_bad_weights_are_refused(w: list[float]) -> None:
    with pytest.raises(EstimatorError, match=WEIGHTS_MSG):
        SurvivalMixture("weibull", np.array(w), np.ones(2), np.ones(2))


@pytest.mark.parametrize("shapes", [((2,), (3,), (2,)), ((2,), (2,), (3,)), ((3,), (2,), (2,)),
                                    ((2, 2), (2, 2), (2, 2)), ((0,), (0,), (0,))])
def test_mismatched_empty_or_2d_arrays_are_refused(shapes: tuple[tuple[int, ...], ...]) -> None:
    w, p1, p2 = (np.ones(s) for s in shapes)
    shown = ", ".join(str(s) for s in shapes)
    with pytest.raises(EstimatorError) as e:
        SurvivalMixture("weibull", w, p1, p2)
    assert str(e.value) == f"survival mixture: weights/p1/p2 must be equal-length 1-D arrays, got {shown}"


def test_validation_checks_the_converted_arrays() -> None:
    """Nested lists are converted first, then checked: a (1, 2) list is 2-D and refused."""
    with pytest.raises(EstimatorError, match="equal-length 1-D"):
        SurvivalMixture("weibull", [[1.0, 1.0]], [[1.0, 1.0]], [[1.0, 1.0]])  # type: ignore[arg-type]
    with pytest.raises(EstimatorError, match="p1 must be > 0"):
        SurvivalMixture("weibull", [1.0], [0], [1.0])  # type: ignore[arg-type]
    with pytest.raises(EstimatorError, match="p2 must be > 0"):
        SurvivalMixture("weibull", [1.0], [1.0], [0])  # type: ignore[arg-type]


@pytest.mark.parametrize("family", SURVIVAL_FAMILIES)
def test_round_trip_and_constructors(family: str) -> None:
    m = MIXTURES[family]
    d = m.to_dict()
    assert d == {"family": family, "weights": m.weights.tolist(), "p1": m.p1.tolist(), "p2": m.p2.tolist()}
    back = SurvivalMixture.from_dict(d)
    assert back.family == family
    for a, b in ((back.weights, m.weights), (back.p1, m.p1), (back.p2, m.p2)):
        np.testing.assert_array_equal(a, b)
    one = SurvivalMixture.single(family, 1.5, 2.5)
    assert one.family == family and one.p1.tolist() == [1.5] and one.p2.tolist() == [2.5]
    assert SurvivalMixture.single("exponential", 0.25).p2.tolist() == [1.0]


@pytest.mark.parametrize("which", ["p1", "p2"])
def test_single_refuses_a_complex_parameter_rather_than_dropping_its_imaginary_part(which: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a ComplexWarning would mean the imaginary part was dropped
        with pytest.raises(TypeError):
            SurvivalMixture.single("weibull", **{"p1": 1.5, "p2": 10.0, which: 2.0 + 1.0j})  # type: ignore[arg-type]


def test_lognormal_median_is_the_median() -> None:
    m = SurvivalMixture.lognormal_median(3600.0, 0.7)
    assert m.family == "lognormal" and m.p2.tolist() == [0.7]
    assert m.log_sf(3600.0)[0] == pytest.approx(-math.log(2.0), rel=1e-14)
    assert SurvivalMixture.lognormal_median(3600.0).p2.tolist() == [1.0]
