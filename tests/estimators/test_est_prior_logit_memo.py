"""Perpetua*'s FreMEn prior made cheaper without changing a bit: ``FremenComponents.raw`` with all
components at once equals main's one-at-a-time sum (kept in _fremen_raw_reference.py), and an update at
a time the filter has just predicted reuses that prediction's prior instead of evaluating it again."""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.estimators._fremen import FremenComponents, LocalClock
from psg_data.estimators._perpetua_star import PerpetuaStarFilter
from psg_data.estimators._priors import FremenPrior
from psg_data.estimators._survival import SurvivalMixture
from tests.estimators._fremen_raw_reference import reference_raw

T0 = 1_740_000_000.0


def _components(seed: int, m: int) -> FremenComponents:
    r = np.random.default_rng(seed)
    k = np.sort(r.choice(np.arange(1, 300), m, replace=False)).astype(np.int64)
    return FremenComponents(float(r.uniform(0.1, 0.9)), k, r.normal(0, 0.1, m) + 1j * r.normal(0, 0.1, m))


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.integers(0, 10_000), st.integers(0, 14), st.lists(st.floats(-1e9, 4e9), max_size=40))
def test_raw_equals_the_one_component_at_a_time_sum(seed: int, m: int, taus: list[float]) -> None:
    c = _components(seed, m)
    tau = np.array(taus, dtype=np.float64)
    assert np.array_equal(c.raw(tau), reference_raw(c, tau))
    assert np.array_equal(c.raw(tau.reshape(-1, 1)), reference_raw(c, tau.reshape(-1, 1)))
    one = float(tau[0]) if tau.size else 12345.0
    assert np.array_equal(c.raw(one), reference_raw(c, one)) and c.raw(one).shape == ()


class _Counting:
    """A prior that counts the times it is evaluated at (the FreMEn prior inside)."""

    def __init__(self, prior: Any) -> None:
        self.prior, self.times = prior, 0

    def __call__(self, t: Any) -> Any:
        self.times += np.size(t)
        return self.prior(t)


def _filter(prior: Any) -> PerpetuaStarFilter:
    return PerpetuaStarFilter(("o", "r"), SurvivalMixture.single("lognormal", 9.0, 1.0),
                              SurvivalMixture.single("lognormal", 10.0, 1.5), 0.1, 0.1, prior, gamma=None,
                              half_life_s=86400.0, alpha0_per_s=1e-5, prior_floor=0.05)


def _stream(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r = np.random.default_rng(seed)
    obs_t = T0 + np.cumsum(r.uniform(600.0, 20_000.0, 60))
    obs_y = r.integers(0, 2, obs_t.size).astype(np.int8)
    grid = np.arange(T0, obs_t[-1] + 7200.0, 3600.0)
    return obs_t, obs_y, np.union1d(grid, obs_t)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.integers(0, 10_000), st.integers(1, 10), st.sampled_from([0.0, 1800.0, 7200.0]))
def test_adaptive_loop_equals_updates_without_predictions(seed: int, m: int, horizon: float) -> None:
    """Predict-then-update (the memo used) leaves every state and prediction bit-equal to the same updates
    applied with no prediction between them (every prior evaluated afresh)."""
    prior = FremenPrior(_components(seed, m), LocalClock.before(T0, "America/Toronto"))
    obs_t, obs_y, ev = _stream(seed)
    a, b = _filter(prior), _filter(prior)
    cut = np.searchsorted(ev, obs_t + horizon, side="left")
    pos, got = 0, []
    for k, (t, y) in enumerate(zip(obs_t.tolist(), obs_y.tolist())):
        if cut[k] > pos:
            got.append(a.predict(ev[pos:cut[k]]))
            pos = int(cut[k])
        a.update(t, y)
        b.update(t, y)
        assert (a.L.tolist(), a.E.tolist(), a.phase, a.n_restarts) == (b.L.tolist(), b.E.tolist(), b.phase,
                                                                     b.n_restarts)
    assert np.array_equal(a.predict(ev), b.predict(ev))


def test_update_at_a_predicted_time_does_not_evaluate_the_prior_again() -> None:
    counting = _Counting(FremenPrior(_components(3, 6), LocalClock.before(T0, "America/Toronto")))
    f = _filter(counting)
    obs_t, obs_y, ev = _stream(4)
    f.update(float(obs_t[0]), int(obs_y[0]))
    f.predict(ev[(ev > obs_t[0]) & (ev <= obs_t[3])])
    before = counting.times
    for t, y in zip(obs_t[1:4].tolist(), obs_y[1:4].tolist()):
        f.update(t, y)
    assert counting.times == before  # all three times were in the prediction
    f.update(float(obs_t[4]), int(obs_y[4]))
    assert counting.times == before + 1  # a time not predicted is evaluated


def test_a_changed_time_array_does_not_change_the_remembered_prior() -> None:
    prior = FremenPrior(_components(5, 4), LocalClock.before(T0, "America/Toronto"))
    a, b = _filter(prior), _filter(prior)
    obs_t, obs_y, _ = _stream(6)
    times = obs_t[:5].copy()
    a.predict(times)
    times[:] = obs_t[5:10]  # the caller reuses its buffer: the filter must not see the new values as predicted
    for t, y in zip(obs_t[:5].tolist(), obs_y[:5].tolist()):
        a.update(t, y)
        b.update(t, y)
    assert np.array_equal(a.predict(obs_t[5:]), b.predict(obs_t[5:]))
    assert a.L.tolist() == b.L.tolist()
