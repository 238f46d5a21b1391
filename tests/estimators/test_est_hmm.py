"""Pooled multi-receptacle HMM for error rates; the reference's L2 PELT against ruptures."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from psg_data.estimators import EdgeStream, fit_error_hmm, segment_reference
from psg_data.estimators._hmm import _batch, _forward_backward, _log_emissions, _transitions

T0 = 1.7e9


def simulate(n_obj: int, days: int, p_m: float, p_f: float, seed: int, stay=(0.6, 0.4), miss_rate: float = 0.05):
    """Objects on 2-5 receptacles (or none), 4 scans a day; each step the object stays with
    probability s (same day / overnight) or redraws its state uniformly; observations flipped."""
    rng = np.random.default_rng(seed)
    t = np.array([T0 + d * 86400 + h * 3600 for d in range(days) for h in (9, 11, 13, 15)])
    streams, truth = [], {}
    for o in range(n_obj):
        k = int(rng.integers(2, 6))
        z = np.empty(t.size, int)
        z[0] = rng.integers(0, k + 1)
        for i in range(1, t.size):
            s = stay[1] if t[i] - t[i - 1] > 6 * 3600 else stay[0]
            z[i] = z[i - 1] if rng.random() < s else rng.integers(0, k + 1)
        for r in range(1, k + 1):
            x = (z == r).astype(np.int8)
            flip = np.where(x == 1, rng.random(t.size) < p_m, rng.random(t.size) < p_f)
            seen = rng.random(t.size) > miss_rate  # receptacle hidden at some scans
            y = np.where(flip, 1 - x, x).astype(np.int8)
            streams.append(EdgeStream((f"o{o}", f"r{r}"), t[seen], y[seen]))
            truth[(f"o{o}", f"r{r}")] = x[seen]
    return streams, truth


def test_recovers_error_rates_with_ten_percent_flips() -> None:
    streams, _ = simulate(100, 28, 0.1, 0.1, seed=0)
    fit = fit_error_hmm(streams)
    assert fit.p_m == pytest.approx(0.1, abs=0.02)
    assert fit.p_f == pytest.approx(0.1, abs=0.02)
    assert fit.stay["same_day"] == pytest.approx(0.6, abs=0.05)
    assert fit.stay["long_gap"] == pytest.approx(0.4, abs=0.07)
    tr = np.array(fit.log_likelihood)
    assert np.all(np.diff(tr) >= -1e-6 * np.abs(tr[1:]))  # penalised EM never decreases


def test_asymmetric_and_noise_free_rates() -> None:
    streams, truth = simulate(100, 28, 0.05, 0.15, seed=1)
    fit = fit_error_hmm(streams)
    assert fit.p_m == pytest.approx(0.05, abs=0.02) and fit.p_f == pytest.approx(0.15, abs=0.02)
    clean, truth = simulate(30, 14, 0.0, 0.0, seed=2)
    fit = fit_error_hmm(clean)
    assert fit.p_m < 0.005 and fit.p_f < 0.005
    for e, x in truth.items():  # noise-free: the posterior segmentation is the observations
        np.testing.assert_array_equal(fit.posterior[e][1] >= 0.5, x == 1)


def test_forward_backward_against_enumeration() -> None:
    rng = np.random.default_rng(4)
    t = T0 + np.array([0, 2, 4, 20, 22]) * 3600.0
    ys = {"r1": np.array([1, 0, 0, 1, 1]), "r2": np.array([0, 1, 0, 1, 0])}
    streams = [EdgeStream(("o", r), t, y.astype(np.int8)) for r, y in ys.items()]
    b = _batch(streams, long_gap_s=6 * 3600)
    pm, pf = 0.1, 0.2
    d = np.array([[0.2, 0.5, 0.3]])
    a_s, a_l = _transitions(0.7, d), _transitions(0.3, d)
    le = _log_emissions(b, pm, pf)
    gamma, _, _, ll = _forward_backward(le, a_s, a_l, d, b.long)
    # brute force over all 3^5 paths
    tot, marg = 0.0, np.zeros((5, 3))
    for path in itertools.product(range(3), repeat=5):
        p = d[0, path[0]]
        for i in range(1, 5):
            a = a_l[0] if b.long[0, i] else a_s[0]
            p *= a[path[i - 1], path[i]]
        for i, z in enumerate(path):
            for k, r in enumerate(("r1", "r2")):
                on = z == k + 1
                y = ys[r][i]
                p *= ((1 - pm) if y else pm) if on else (pf if y else (1 - pf))
        tot += p
        for i, z in enumerate(path):
            marg[i, z] += p
    assert float(ll[0]) == pytest.approx(math.log(tot), rel=1e-12)
    np.testing.assert_allclose(gamma[0], marg / tot, rtol=1e-10)
    del rng


def test_reference_segmentation_equals_ruptures() -> None:
    import ruptures as rpt  # a dev dependency: the oracle of this test
    rng = np.random.default_rng(0)
    for _ in range(80):
        n = int(rng.integers(4, 200))
        x = np.repeat(rng.integers(0, 2, 40), rng.integers(1, 50, 40))[:n]
        y = np.where(rng.random(x.size) < rng.choice([0.0, 0.05, 0.2]), 1 - x, x).astype(float)
        want = rpt.Pelt(model="l2", min_size=2, jump=5).fit(y).predict(pen=3)
        assert segment_reference(y)[1:].tolist() == want


def test_time_vectorised_forward_backward_equals_the_loop() -> None:
    from psg_data.estimators._hmm import _forward_backward_scan

    streams, _ = simulate(5, 80, 0.1, 0.1, seed=6)  # 320 steps per object, 3-6 states
    b = _batch(streams, long_gap_s=6 * 3600)
    n_s = b.y.shape[2] + 1
    mask = np.arange(n_s)[None, :] < b.n_states[:, None]
    d = mask / mask.sum(axis=1, keepdims=True)
    le = _log_emissions(b, 0.1, 0.05)
    le = np.where(b.valid_t[:, :, None], le, np.where(mask[:, None, :], 0.0, -np.inf))
    args = (le, _transitions(0.6, d), _transitions(0.3, d), d, b.long & b.valid_t)
    for a, c in zip(_forward_backward(*args), _forward_backward_scan(*args)):
        np.testing.assert_allclose(c, a, rtol=1e-9, atol=1e-9)
