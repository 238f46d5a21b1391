"""Interval-censored EM: recovery from sparse sampling, AIC, monotone likelihood, closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from psg_data.errors import EstimatorError
from psg_data.estimators import SurvivalMixture, fit_interval_mixture
from psg_data.estimators._interval_em import (
    _estep_exponential,
    _estep_lognormal,
    _weibull_logp,
    _weibull_nll_grad,
    em_intervals,
    interval_log_likelihood,
)
from psg_data.estimators._survival_training import mixture_median_s, run_intervals

H = 3600.0


def sparse_sample(true_t: np.ndarray, rng: np.random.Generator, gap_s: float = 2 * H) -> tuple[np.ndarray, np.ndarray]:
    """Each run is watched by irregular scans from its start (the first scan) until the data end.

    Returns the interval the switch falls in on the scan clock: (last scan before T, first scan
    at or after T], or (last scan before the data end, inf) when the data end first.
    """
    n = true_t.size
    scans = np.concatenate([np.zeros((n, 1)), np.cumsum(rng.uniform(0.7, 1.3, (n, 400)) * gap_s, axis=1)], axis=1)
    end = rng.uniform(20 * H, 300 * H, n)  # independent censoring
    j = np.array([np.searchsorted(r, t) for r, t in zip(scans, true_t)])
    lo, hi = scans[np.arange(n), j - 1], scans[np.arange(n), j]
    last = np.array([r[r <= e][-1] for r, e in zip(scans, end)])
    cens = hi > end
    return np.where(cens, last, lo), np.where(cens, np.inf, hi)


def _two_lognormals(n: int, rng: np.random.Generator) -> np.ndarray:
    c = rng.random(n) < 0.6
    return np.where(c, rng.lognormal(math.log(3 * H), 0.4, n), rng.lognormal(math.log(20 * H), 0.3, n))


@pytest.mark.parametrize("family,k", [("lognormal", 5), ("exponential", 3), ("weibull", 1)])
def test_medians_recovered_from_sparse_scans(family: str, k: int) -> None:
    rng = np.random.default_rng(11)
    t = {"lognormal": lambda: _two_lognormals(500, rng), "exponential": lambda: rng.exponential(5 * H, 500),
         "weibull": lambda: 4 * H * rng.weibull(2.0, 500)}[family]()
    lo, hi = sparse_sample(t, rng)
    assert np.mean(hi - lo < np.inf) > 0.9 and np.median(hi - lo) > 1.5 * H  # sparse: the switch is hidden
    fit = fit_interval_mixture(lo, hi, family=family, max_components=k, random_state=0)
    assert mixture_median_s(fit.mixture) == pytest.approx(float(np.median(t)), rel=0.15)
    naive = np.median(np.where(np.isinf(hi), lo, 0.5 * (lo + hi)))  # midpoints are biased, the fit is not
    assert abs(mixture_median_s(fit.mixture) - np.median(t)) <= abs(naive - np.median(t)) + 0.05 * np.median(t)


@pytest.mark.slow
def test_aic_picks_the_true_number_of_components() -> None:
    hits = 0
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        lo, hi = sparse_sample(_two_lognormals(500, rng), rng)
        fit = fit_interval_mixture(lo, hi, max_components=5, random_state=seed)
        hits += min(fit.aic_by_k, key=fit.aic_by_k.get) == 2
    assert hits >= 8


def test_single_component_recovered_quickly() -> None:
    rng = np.random.default_rng(5)
    lo, hi = sparse_sample(rng.lognormal(math.log(6 * H), 0.5, 400), rng)
    fit = fit_interval_mixture(lo, hi, max_components=3, random_state=1)
    assert fit.mixture.n_components == 1
    assert fit.mixture.p1[0] == pytest.approx(math.log(6 * H), abs=0.1)
    assert fit.mixture.p2[0] == pytest.approx(0.5, abs=0.08)


rows = st.lists(st.tuples(st.floats(0.0, 50.0), st.floats(0.0, 30.0), st.booleans(), st.booleans()), min_size=3,
                max_size=40)


@settings(max_examples=30, deadline=None)
@given(rows=rows, family=st.sampled_from(["lognormal", "exponential", "weibull"]), k=st.integers(1, 3),
       seed=st.integers(0, 1000))
# a Weibull component collapsing on a 0.2 ms exact duration made S(lo) = 0 for the other row (inf - inf = NaN)
@example(rows=[(0.0, 0.0, False, False), (1.0, 1.0, False, False), (5.960464477539063e-08, 0.0, False, False)],
         family="weibull", k=2, seed=0)
# an interval 1e-10 h wide at 1 h: Phi(b) - Phi(a) and the truncated moments cancelled to ~eps / width
@example(rows=[(0.0, 0.0, False, False), (0.0, 0.0, True, False), (1.0, 1e-10, False, False)],
         family="lognormal", k=1, seed=0)
# an 8e-306 s wide interval: lam d subnormal made 1/(lam d) overflow, E[T] = -inf and lam jump to 2e300
@example(rows=[(0.0, 0.0, False, False), (0.0, 2.225073858507203e-309, False, False), (1.0, 0.0, False, False)],
         family="exponential", k=1, seed=0)
# lo = 1.8e-320 s (subnormal): d / lo overflows, (lo/s)^k underflows to 0 and 0 * expm1(inf) was NaN
@example(rows=[(0.0, 0.0, False, False), (0.0, 0.0, False, False), (5e-324, 4.0, False, False)],
         family="weibull", k=1, seed=0)
@example(rows=[(0.0, 0.0, False, False), (0.0, 0.0, False, False), (5e-324, 1.0, False, False)],
         family="lognormal", k=1, seed=0)
def test_log_likelihood_never_decreases(rows, family, k, seed) -> None:
    lo = np.array([r[0] for r in rows]) * H
    width = np.array([r[1] for r in rows]) * H
    hi = np.where([r[2] for r in rows], np.inf, lo + width)  # censored rows; width 0: exact
    hi = np.where([r[3] for r in rows] & np.isfinite(hi), lo + np.maximum(width, 60.0), hi)
    keep = hi > 0
    if keep.sum() < 1:
        return
    lo, hi = lo[keep], hi[keep]
    rng = np.random.default_rng(seed)
    g = np.log(np.maximum(np.where(np.isinf(hi), lo + H, 0.5 * (lo + hi)), 60.0))
    mu = np.quantile(g, (np.arange(k) + 0.5) / k) + rng.normal(0, 0.3, k)
    pi = np.full(k, 1.0 / k)
    p1, p2 = {"lognormal": (mu, np.ones(k)), "exponential": (np.exp(-mu), np.ones(k)),
              "weibull": (np.ones(k), np.exp(mu))}[family]
    _, _, _, trace = em_intervals(family, lo, hi, np.ones(lo.size), pi, p1, p2, max_iter=40 if family != "weibull" else 8)
    tr = np.array(trace)
    assert np.all(np.isfinite(tr))
    assert np.all(np.diff(tr) >= -1e-7 * np.maximum(1.0, np.abs(tr[1:])))


def test_closed_forms_against_quadrature() -> None:
    from scipy import integrate, stats

    mu, sd = math.log(5 * H), 0.7
    for lo, hi in [(2 * H, 4 * H), (0.0, 1 * H), (30 * H, np.inf), (400 * H, 402 * H)]:  # incl. a far tail
        logp, ex, ex2 = _estep_lognormal(np.array([lo]), np.array([hi]), np.array([mu]), np.array([sd]))
        a = -np.inf if lo == 0 else math.log(lo)
        b = math.log(hi)
        dist = stats.norm(mu, sd)
        p = dist.cdf(b) - dist.cdf(a)
        if p > 1e-250:
            assert math.exp(float(logp[0, 0])) == pytest.approx(p, rel=1e-9)
        # truncated normal moments (scipy's truncnorm is an independent implementation)
        tn = stats.truncnorm((a - mu) / sd, (b - mu) / sd, loc=mu, scale=sd)
        assert float(ex[0, 0]) == pytest.approx(tn.mean(), rel=1e-7, abs=1e-7)
        assert float(ex2[0, 0]) == pytest.approx(tn.var() + (tn.mean() - mu) ** 2, rel=1e-6)
    lam = 1 / (3 * H)
    for lo, hi in [(H, 2 * H), (0.0, 10 * H), (5 * H, np.inf)]:
        logp, et = _estep_exponential(np.array([lo]), np.array([hi]), np.array([lam]))
        dist = stats.expon(scale=1 / lam)
        p = dist.cdf(hi) - dist.cdf(lo)
        assert math.exp(float(logp[0, 0])) == pytest.approx(p, rel=1e-10)
        top = hi if np.isfinite(hi) else lo + 60 / lam
        m = integrate.quad(lambda t: t * dist.pdf(t), lo, top, epsabs=1e-12)[0] / p
        assert float(et[0, 0]) == pytest.approx(m, rel=1e-6)


# widths near the underflow limit (lo = 0) and narrow against lo (relative width 1e-13 .. 1e-6)
TINY = [(0.0, 8e-306), (0.0, 1e-300), (0.0, 1e-320), (0.0, 1e-12), (H, H * (1 + 1e-12)), (H, H * (1 + 1e-6)),
        (10 * H, 10 * H * (1 + 1e-9)), (5.0, 5.0 * (1 + 1e-13))]


@pytest.mark.parametrize("lo,hi", TINY)
def test_tiny_widths_against_mpmath(lo: float, hi: float) -> None:
    """log P and the E-step moments of every family for tiny widths, against 80-digit arithmetic."""
    import mpmath

    mpmath.mp.dps = 80
    lo_, hi_ = np.array([lo]), np.array([hi])
    L, U = mpmath.mpf(lo), mpmath.mpf(hi)  # the doubles themselves, exactly
    for lam in (1 / (3 * H), 1 / 60.0, 1e-7):
        logp, et = _estep_exponential(lo_, hi_, np.array([lam]))
        lm = mpmath.mpf(lam)
        p = mpmath.exp(-lm * L) * -mpmath.expm1(-lm * (U - L))
        m = L + 1 / lm - (U - L) / mpmath.expm1(lm * (U - L))
        assert float(logp[0, 0]) == pytest.approx(float(mpmath.log(p)), rel=1e-12)
        assert float(et[0, 0]) == pytest.approx(float(m), rel=1e-12)
    for mu, sd in ((math.log(3 * H), 0.8), (math.log(60.0), 0.5)):  # widths < 1e-5 in z = (ln t - mu) / sd
        logp, ex, ex2 = _estep_lognormal(lo_, hi_, np.array([mu]), np.array([sd]))
        a = -mpmath.inf if lo == 0 else (mpmath.log(L) - mu) / sd
        b = (mpmath.log(U) - mu) / sd
        # Phi(b) - Phi(a) without cancellation: the integral of phi over [a, b]
        p = mpmath.quad(mpmath.npdf, [a, b]) if lo > 0 else mpmath.ncdf(b)
        pa = 0 if lo == 0 else mpmath.npdf(a)
        ez = (pa - mpmath.npdf(b)) / p
        ez2 = 1 + ((0 if lo == 0 else a * pa) - b * mpmath.npdf(b)) / p
        assert float(logp[0, 0]) == pytest.approx(float(mpmath.log(p)), rel=1e-10)
        # lo = 0: phi(b) / Phi(b) is exp(log phi(b) - log Phi(b)), two numbers ~b^2 / 2 (b down to
        # -1.4e4 here), so its relative error is ~eps b^2 (not a width effect: log hi does not underflow)
        assert float(ex[0, 0]) == pytest.approx(float(mu + sd * ez), rel=1e-10 + 4e-16 * float(b * b))
        assert float(ex2[0, 0]) == pytest.approx(float(sd * sd * ez2), rel=1e-7, abs=1e-12)
    for k, s in ((0.5, 3 * H), (1.0, 3 * H), (2.0, 3 * H), (5.0, 3 * H), (1.5, 60.0)):
        ua, ub = (L / s) ** k, (U / s) ** k
        want = float(-ua + mpmath.log(-mpmath.expm1(-(ub - ua))))
        got = float(_weibull_logp(lo_, hi_, np.array([k]), np.array([s]))[0, 0])
        assert got == pytest.approx(want, rel=1e-11)
        # the M-step objective is the same log P (it decides whether a step is taken)
        f, g = _weibull_nll_grad(np.array([math.log(k), math.log(s)]), lo_, hi_, np.array([1.0]))
        assert -f == pytest.approx(want, rel=1e-11)
        assert np.all(np.isfinite(g))


def test_likelihood_matches_direct_cdf_sum() -> None:
    from scipy import stats

    mix = SurvivalMixture("weibull", np.array([0.4, 0.6]), np.array([1.5, 0.8]), np.array([2 * H, 9 * H]))
    lo = np.array([0.0, H, 3 * H, 10 * H, 5 * H])
    hi = np.array([2 * H, 1.5 * H, np.inf, 12 * H, 5 * H])  # last row exact
    want = 0.0
    for a, b in zip(lo, hi):
        comps = [stats.weibull_min(c, scale=s) for c, s in zip(mix.p1, mix.p2)]
        if a == b:
            want += math.log(sum(w * d.pdf(a) for w, d in zip(mix.weights, comps)))
        else:
            want += math.log(sum(w * (d.cdf(b) - d.cdf(a)) for w, d in zip(mix.weights, comps)))
    assert interval_log_likelihood(mix, lo, hi) == pytest.approx(want, rel=1e-10)


def test_run_intervals_on_the_filters_clock() -> None:
    t = np.array([0.0, 2, 4, 20, 22, 24, 40]) * H
    x = np.array([1, 1, 0, 0, 1, 1, 1])
    (plo, phi), (alo, ahi) = run_intervals(t, x)
    np.testing.assert_allclose(plo, [2 * H, 18 * H])  # first run: last present 2 h after its start
    np.testing.assert_allclose(phi, [4 * H, np.inf])  # ... the opposite first seen 4 h after; last censored
    np.testing.assert_allclose(alo, [16 * H])
    np.testing.assert_allclose(ahi, [18 * H])


def test_million_rows_stay_finite_and_errors_are_clear() -> None:
    rng = np.random.default_rng(2)
    t = rng.lognormal(math.log(3 * H), 0.8, 1_000_000)
    lo = np.floor(t / 60.0) * 60.0
    fit = fit_interval_mixture(lo, lo + 60.0, max_components=1, n_restarts=0, max_iter=30)
    assert np.all(np.isfinite(fit.trace))
    assert fit.mixture.p1[0] == pytest.approx(math.log(3 * H), abs=0.01)
    with pytest.raises(EstimatorError, match="unknown family"):
        fit_interval_mixture([1.0], [2.0], family="gamma")
    with pytest.raises(EstimatorError, match="no usable intervals"):
        fit_interval_mixture([5.0], [1.0])
