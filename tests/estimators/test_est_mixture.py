"""Persistence / emergence mixtures: brute-force marginalisation, log-space numerics, invariants."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import EstimatorError
from psg_data.estimators import MixtureFilter, SurvivalMixture

FAMILIES = {
    "exponential": SurvivalMixture.single("exponential", 1 / 3000.0),
    "lognormal": SurvivalMixture("lognormal", np.array([0.3, 0.7]), np.log([1500.0, 6000.0]), np.array([0.5, 0.8])),
    "weibull": SurvivalMixture.single("weibull", 1.7, 4000.0),
    "loglogistic": SurvivalMixture.single("loglogistic", 2.5, 3500.0),
}


def brute_force_posterior(surv: SurvivalMixture, k: int, t_obs, y, p_m, p_f, t_query):
    """P(T > t_query | Y, c_k) by discretising T finely (likelihood at cell midpoints)."""
    grid = np.concatenate([np.linspace(0, t_obs[-1] * 1.5 + 1, 400_001)])
    sf = np.exp(surv.log_sf(grid)[:, k])
    mass = -np.diff(sf)
    mid = 0.5 * (grid[1:] + grid[:-1])
    tail = sf[-1]  # T beyond the grid: present at all observations
    present = t_obs[None, :] <= mid[:, None]
    lik_p = np.where(y == 1, 1 - p_m, p_m)
    lik_a = np.where(y == 1, p_f, 1 - p_f)
    loglik = np.where(present, np.log(lik_p), np.log(lik_a)).sum(axis=1)
    l_all = np.log(lik_p).sum()
    ref = max(loglik.max(), l_all)
    w = mass * np.exp(loglik - ref)
    w_tail = tail * np.exp(l_all - ref)
    num = w[mid > t_query].sum() + w_tail
    return num / (w.sum() + w_tail)


@pytest.mark.parametrize("family", list(FAMILIES))
def test_persistence_posterior_matches_brute_force(family: str) -> None:
    rng = np.random.default_rng(1)
    surv = FAMILIES[family]
    t_obs = np.sort(rng.uniform(0, 8000, 12))
    y = (t_obs < 4000).astype(np.int8)
    y[3] = 1 - y[3]
    for k in range(surv.n_components):
        one = SurvivalMixture(surv.family, np.ones(1), surv.p1[k:k + 1], surv.p2[k:k + 1])
        f = MixtureFilter(one, 0.1, 0.15, escape=0.0, escape_first=0.0)  # the exact recursion
        f.reset(0.0)
        f.update_many(t_obs, y)
        for tq in (t_obs[-1], t_obs[-1] + 500, t_obs[-1] + 3000):
            got = float(f.predict(np.array([tq]))[0])
            want = brute_force_posterior(one, 0, t_obs, y, 0.1, 0.15, tq)
            assert got == pytest.approx(want, abs=2e-3)


def test_evidence_matches_brute_force_sum() -> None:
    surv = FAMILIES["lognormal"]
    t_obs = np.array([100.0, 900.0, 2000.0, 2600.0, 5000.0])
    y = np.array([1, 1, 0, 1, 0], dtype=np.int8)
    f = MixtureFilter(surv, 0.2, 0.05, escape=0.0, escape_first=0.0)  # the exact recursion
    f.reset(0.0)
    f.update_many(t_obs, y)
    # exact: T falls in one of the N+1 intervals between observation times
    edges = np.concatenate([[0.0], t_obs, [np.inf]])
    sf = np.exp(surv.log_sf(np.where(np.isinf(edges), 1e300, edges)))
    lik_p = np.where(y == 1, 0.8, 0.2)
    lik_a = np.where(y == 1, 0.05, 0.95)
    ev = np.zeros(surv.n_components)
    for i in range(len(t_obs) + 1):  # present for the first i observations
        ev += (sf[i] - sf[i + 1]) * np.prod(lik_p[:i]) * np.prod(lik_a[i:])
    np.testing.assert_allclose(np.exp(f.component_log_evidence()), ev, rtol=1e-10)
    w = f.posterior_weights()
    np.testing.assert_allclose(w, surv.weights * ev / np.sum(surv.weights * ev), rtol=1e-10)


def test_batch_equals_sequential_and_chunks() -> None:
    rng = np.random.default_rng(2)
    t = np.cumsum(rng.uniform(10, 600, 3000))
    y = (rng.random(3000) < 0.6).astype(np.int8)
    a = MixtureFilter(FAMILIES["lognormal"], 0.1, 0.1)
    a.update_many(t, y)
    b = MixtureFilter(FAMILIES["lognormal"], 0.1, 0.1)
    for ti, yi in zip(t[:200], y[:200]):
        b.update(ti, yi)
    b.update_many(t[200:], y[200:], chunk=77)
    np.testing.assert_allclose(a.component_log_evidence(), b.component_log_evidence(), rtol=1e-9)
    q = t[-1] + np.linspace(0, 5000, 11)
    np.testing.assert_allclose(a.predict(q), b.predict(q), atol=1e-9)


def test_million_observations_do_not_underflow() -> None:
    n = 1_000_000
    t = np.arange(n, dtype=np.float64) * 60.0
    rng = np.random.default_rng(3)
    y = np.where(rng.random(n) < 0.1, 0, 1).astype(np.int8)
    for surv in (SurvivalMixture.single("exponential", 1e-3), FAMILIES["lognormal"]):  # rate * t ~ 6e4
        f = MixtureFilter(surv, 0.1, 0.1)
        f.update_many(t, y)
        assert np.all(np.isfinite(f.component_log_evidence()))
        p = f.predict(t[-1] + np.array([0.0, 60.0, 1e5]))
        assert np.all(np.isfinite(p)) and np.all((p >= 0) & (p <= 1))
        assert f.l < -1e4  # the likelihood itself is far below float64's range


def test_emergence_is_persistence_of_absence_with_swapped_errors() -> None:
    surv = FAMILIES["weibull"]
    t = np.array([50.0, 400.0, 900.0, 1500.0])
    y = np.array([0, 0, 1, 1], dtype=np.int8)
    e = MixtureFilter(surv, 0.1, 0.2, emergence=True)
    e.update_many(t, y)
    # an emergence filter's "present" is absence: compare with a persistence filter on 1 - y and swapped roles
    q = MixtureFilter(surv, 0.2, 0.1)
    q.update_many(t, 1 - y)
    np.testing.assert_allclose(e.predict(t[-1] + np.array([0.0, 700.0])), 1 - q.predict(t[-1] + np.array([0.0, 700.0])))
    assert float(MixtureFilter(surv, 0.1, 0.1, emergence=True).predict(np.array([5.0]))[0]) == 0.0


@settings(max_examples=40, deadline=None)
@given(
    ys=st.lists(st.integers(0, 1), min_size=1, max_size=40),
    gaps=st.lists(st.floats(0.0, 5000.0), min_size=40, max_size=40),
    pm=st.floats(0.0, 0.45), pf=st.floats(0.0, 0.45),
    w=st.lists(st.floats(0.01, 1.0), min_size=3, max_size=3),
)
def test_weights_sum_to_one_and_predictions_in_range(ys, gaps, pm, pf, w) -> None:
    surv = SurvivalMixture("lognormal", np.array(w), np.log([300.0, 3000.0, 30000.0]), np.array([0.4, 1.0, 2.0]))
    t = 1.7e9 + np.cumsum(gaps[: len(ys)])
    for emergence in (False, True):
        f = MixtureFilter(surv, pm, pf, emergence=emergence)
        f.update_many(t, np.array(ys, dtype=np.int8))
        assert f.posterior_weights().sum() == pytest.approx(1.0, abs=1e-12)
        p = f.predict(t[-1] + np.array([0.0, 1.0, 1e3, 1e6, 1e9]))
        assert np.all(np.isfinite(p)) and np.all((p >= 0) & (p <= 1))
        if not emergence:
            assert np.all(np.diff(p) <= 1e-12)  # persistence beliefs only decay without observations


def test_survival_validation() -> None:
    with pytest.raises(EstimatorError, match="unknown survival family"):
        SurvivalMixture.single("gamma", 1.0)
    with pytest.raises(EstimatorError, match="p_m must be in"):
        MixtureFilter(FAMILIES["exponential"], 0.7, 0.1)


@pytest.mark.parametrize("family", list(FAMILIES))
@pytest.mark.parametrize("emergence", [False, True])
def test_scalar_step_equals_vectorised_scan(family: str, emergence: bool) -> None:
    rng = np.random.default_rng(3)
    t = 1.7e9 + np.cumsum(rng.uniform(10, 900, 400))
    y = (rng.random(400) < 0.6).astype(np.int8)
    a = MixtureFilter(FAMILIES[family], 0.1, 0.2, emergence=emergence)
    b = MixtureFilter(FAMILIES[family], 0.1, 0.2, emergence=emergence)
    a.update_many(t, y)
    ev = [b.step(float(ti), int(yi))[0] for ti, yi in zip(t, y)]
    assert ev[-1] == pytest.approx(a.log_evidence(), rel=1e-9, abs=1e-9)
    np.testing.assert_allclose(b.component_log_evidence(), a.component_log_evidence(), rtol=1e-9, atol=1e-9)
    q = t[-1] + np.linspace(0, 20000, 30)
    np.testing.assert_allclose(b.predict(q), a.predict(q), atol=1e-10)


def test_scalar_log_ndtr_matches_scipy() -> None:
    from scipy.special import log_ndtr

    from psg_data.estimators._survival import log_ndtr_scalar

    x = np.concatenate([np.linspace(-200, 40, 2001), [-37.0, -36.999, -1.0, -0.999]])
    got = np.array([log_ndtr_scalar(float(v)) for v in x])
    np.testing.assert_allclose(got, log_ndtr(x), rtol=1e-12, atol=1e-300)


def test_escape_floor_lets_a_narrow_prior_see_an_early_change() -> None:
    """A restarted filter with a narrow log-normal (median 1 h, sigma 0.01) believes contrary
    observations long before the prior's lower tail only with the escape floor."""
    narrow = SurvivalMixture.lognormal_median(3600.0, 0.01)
    t = np.arange(0.0, 120.0, 0.5)  # two minutes at 0.5 s
    y = np.zeros(t.size, dtype=np.int8)
    y[0] = 1  # present at the restart, then seen absent every 0.5 s
    exact = MixtureFilter(narrow, 0.1, 0.1, escape=0.0, escape_first=0.0)
    exact.update_many(t, y)
    floored = MixtureFilter(narrow, 0.1, 0.1)
    floored.update_many(t, y)
    assert float(exact.predict(t[-1:])[0]) > 0.999  # zero prior mass on an early change: ignores the data
    assert float(floored.predict(t[-1:])[0]) < 1e-6
    # about log(1e10) / log(0.9 / 0.1) ~ 11 contrary observations overcome the floor
    g = MixtureFilter(narrow, 0.1, 0.1)
    g.update_many(t[:13], y[:13])
    assert float(g.predict(t[12:13])[0]) < 0.5
    h = MixtureFilter(narrow, 0.1, 0.1)
    for ti, yi in zip(t, y):  # the scalar path applies the same floors
        h.update(float(ti), int(yi))
    np.testing.assert_allclose(h.component_log_evidence(), floored.component_log_evidence(), rtol=1e-9)
