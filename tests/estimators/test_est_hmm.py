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
    gamma, xs, xl, ll = _forward_backward(le, a_s, a_l, d, b.long)
    # brute force over all 3^5 paths: state marginals and the expected transitions per step kind
    tot, marg = 0.0, np.zeros((5, 3))
    xi = {False: np.zeros((3, 3)), True: np.zeros((3, 3))}
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
        for i in range(1, 5):
            xi[bool(b.long[0, i])][path[i - 1], path[i]] += p
    assert float(ll[0]) == pytest.approx(math.log(tot), rel=1e-12)
    np.testing.assert_allclose(gamma[0], marg / tot, rtol=1e-10)
    np.testing.assert_allclose(xs[0], xi[False] / tot, rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(xl[0], xi[True] / tot, rtol=1e-10, atol=1e-15)
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


def _enumerate(ys: dict[str, np.ndarray], long: np.ndarray, pm: float, pf: float, stay: tuple[float, float],
               d: np.ndarray) -> dict[str, object]:
    """Brute force over every path and every step's jump indicator of one object: the E-step's
    expected counts (state marginals, transitions per kind, jumps landing per kind) and log p(y)."""
    labels = sorted(ys)
    n_t, n_s = len(long), len(labels) + 1
    tot = 0.0
    gamma = np.zeros((n_t, n_s))
    trans = {False: 0.0, True: 0.0}
    land = {False: np.zeros(n_s), True: np.zeros(n_s)}
    for path in itertools.product(range(n_s), repeat=n_t):
        p = d[path[0]]
        for i in range(1, n_t):
            s = stay[1] if long[i] else stay[0]
            p *= s * (path[i] == path[i - 1]) + (1 - s) * d[path[i]]
        for i, z in enumerate(path):
            for k, r in enumerate(labels):
                y = ys[r][i]
                if y >= 0:  # -1: not observed
                    p *= ((1 - pm) if y else pm) if z == k + 1 else (pf if y else 1 - pf)
        tot += p
        for i, z in enumerate(path):
            gamma[i, z] += p
        for i in range(1, n_t):
            s = stay[1] if long[i] else stay[0]
            jump = (1 - s) * d[path[i]]  # the jump part of this step's transition probability
            trans[bool(long[i])] += p
            land[bool(long[i])][path[i]] += p * jump / (s * (path[i] == path[i - 1]) + jump)
    return {"loglik": math.log(tot), "gamma": gamma / tot, "trans": {k: v / tot for k, v in trans.items()},
            "land": {k: v / tot for k, v in land.items()}}


def test_one_baum_welch_step_equals_the_closed_form_m_step_on_enumerated_counts() -> None:
    t = T0 + np.array([0, 2, 4, 20, 22]) * 3600.0  # median gap 2 h: the 16 h gap is the long one
    ys = {"r1": np.array([1, 0, 0, 1, 1]), "r2": np.array([0, 1, 0, 1, 1])}
    streams = [EdgeStream(("o", r), t, y.astype(np.int8)) for r, y in ys.items()]
    long = np.array([False, False, False, True, False])
    d0 = np.full(3, 1 / 3)
    for p_m in (None, 0.2):
        fit = fit_error_hmm(streams, p_m=p_m, max_iter=1)
        pm0 = 0.05 if p_m is None else p_m
        en = _enumerate(ys, long, pm0, 0.05, (0.7, 0.5), d0)
        g = en["gamma"]
        # the first trace value: log p(y) plus the Dirichlet penalty 2/3 * sum(log d) at d uniform
        assert fit.log_likelihood[0] == pytest.approx(en["loglik"] + 2.0 * math.log(1 / 3), rel=1e-12)
        y = np.stack([ys["r1"], ys["r2"]], axis=1)
        g_on = g[:, 1:]
        want_pm = np.sum(g_on * (y == 0)) / np.sum(g_on) if p_m is None else p_m
        want_pf = np.sum((1 - g_on) * (y == 1)) / np.sum(1 - g_on)
        assert fit.p_m == pytest.approx(want_pm, rel=1e-10) and fit.p_f == pytest.approx(want_pf, rel=1e-10)
        for kind, lg in (("same_day", False), ("long_gap", True)):
            want = 1 - en["land"][lg].sum() / en["trans"][lg]
            assert fit.stay[kind] == pytest.approx(want, rel=1e-10)
        np.testing.assert_allclose(fit.posterior[("o", "r1")][1], g[:, 1], rtol=1e-10)
        np.testing.assert_allclose(fit.posterior[("o", "r2")][1], g[:, 2], rtol=1e-10)
        assert fit.n_objects == 1 and fit.n_steps == 5 and fit.long_gap_s == 3 * 7200.0
        # the destinations: first states and jumps landing, plus the pseudo-counts; the second trace
        # value is the penalised likelihood under the updated parameters
        d1 = g[0] + en["land"][False] + en["land"][True] + 2.0 / 3
        d1 /= d1.sum()
        nxt = fit_error_hmm(streams, p_m=p_m, max_iter=2, tol=0.0)
        en1 = _enumerate(ys, long, fit.p_m, fit.p_f, (fit.stay["same_day"], fit.stay["long_gap"]), d1)
        pen1 = float(np.sum(2.0 / 3 * np.log(d1)))
        assert nxt.log_likelihood[1] == pytest.approx(en1["loglik"] + pen1, rel=1e-12)


def test_split_streams_of_one_edge_merge_and_typical_gap_and_summary() -> None:
    from psg_data.estimators._hmm import typical_gap_s

    streams, _ = simulate(3, 4, 0.1, 0.1, seed=9)
    one = fit_error_hmm(streams, max_iter=5)
    split = []
    for s in streams:  # every edge as two interleaved streams (odd and even observations)
        split += [EdgeStream(s.edge, s.t_s[::2], s.y[::2]), EdgeStream(s.edge, s.t_s[1::2], s.y[1::2])]
    two = fit_error_hmm(split, max_iter=5)
    assert two.p_m == pytest.approx(one.p_m, rel=1e-12) and two.p_f == pytest.approx(one.p_f, rel=1e-12)
    assert two.log_likelihood == pytest.approx(one.log_likelihood, rel=1e-12)
    for e, (ts, p) in one.posterior.items():
        np.testing.assert_array_equal(two.posterior[e][0], ts)
        np.testing.assert_allclose(two.posterior[e][1], p, rtol=1e-12, atol=1e-15)
    s = one.summary()
    assert s == {"p_m": one.p_m, "p_f": one.p_f, "stay": one.stay, "long_gap_s": one.long_gap_s,
                 "iterations": len(one.log_likelihood), "objects": 3, "object_steps": one.n_steps}
    # the median of the distinct gaps, pooled; repeated times and one-observation streams add nothing
    g = [EdgeStream(("a", "x"), np.array([0.0, 10.0, 10.0, 40.0]), np.ones(4, np.int8)),
         EdgeStream(("a", "y"), np.array([5.0, 7.0]), np.ones(2, np.int8)),
         EdgeStream(("b", "x"), np.array([100.0]), np.ones(1, np.int8))]
    assert typical_gap_s(g) == float(np.median([10.0, 30.0, 2.0]))
    assert typical_gap_s(g[2:]) == 0.0 and typical_gap_s([]) == 0.0


def _loop_and_scan(le: np.ndarray, d: np.ndarray, long: np.ndarray) -> None:
    from psg_data.estimators._hmm import _forward_backward_scan

    args = (le, _transitions(0.6, d), _transitions(0.3, d), d, long)
    for a, c in zip(_forward_backward(*args), _forward_backward_scan(*args)):
        np.testing.assert_allclose(c, a, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("n_s", [2, 3, 4])
def test_time_vectorised_forward_backward_small_state_spaces_short_and_extreme(n_s: int) -> None:
    # 2 and 3 states use the hand-unrolled matrix product; T = 1 and 2 are the edge cases of the
    # backward pass; log emissions of -1000 and below underflow exp() unless each step is shifted by
    # its own maximum, and 3000 steps underflow an unscaled product
    rng = np.random.default_rng(n_s)
    d = rng.dirichlet(np.ones(n_s), size=2)
    for t_max in (1, 2, 3, 40):
        le = np.log(rng.uniform(0.05, 1.0, size=(2, t_max, n_s)))
        _loop_and_scan(le, d, rng.random((2, t_max)) < 0.3)
    _loop_and_scan(rng.uniform(-2000.0, -1000.0, size=(2, 30, n_s)), d, rng.random((2, 30)) < 0.3)
    _loop_and_scan(np.log(rng.uniform(0.05, 1.0, size=(2, 3000, n_s))), d, rng.random((2, 3000)) < 0.3)


def test_pooled_m_step_over_objects_of_different_sizes_and_lengths() -> None:
    # object "o" on two receptacles at five times, object "q" on one receptacle at three: padded
    # states add nothing; q's chain runs on through the two padded times unobserved (same-day
    # steps: they change no likelihood, and their expected transitions enter the stay update, a
    # data augmentation of the EM that keeps its monotonicity and its fixed points); the rates and
    # stays are pooled over both objects
    t = T0 + np.array([0, 2, 4, 20, 22]) * 3600.0
    ys = {"r1": np.array([1, 0, 0, 1, 1]), "r2": np.array([0, 1, 0, 1, 1])}
    tq, yq = T0 + np.array([1, 3, 19]) * 3600.0, {"r1": np.array([1, 1, 0])}
    streams = [EdgeStream(("o", r), t, y.astype(np.int8)) for r, y in ys.items()]
    streams.append(EdgeStream(("q", "r1"), tq, yq["r1"].astype(np.int8)))
    fit = fit_error_hmm(streams, max_iter=1)
    assert fit.long_gap_s == 3 * 7200.0  # the median of 2, 2, 16, 2, 2, 16 h
    eo = _enumerate(ys, np.array([False, False, False, True, False]), 0.05, 0.05, (0.7, 0.5), np.full(3, 1 / 3))
    yq_padded = {"r1": np.array([1, 1, 0, -1, -1])}
    eq = _enumerate(yq_padded, np.array([False, False, True, False, False]), 0.05, 0.05, (0.7, 0.5),
                    np.full(2, 1 / 2))
    pen = 2.0 * math.log(1 / 3) + 2.0 * math.log(1 / 2)
    assert fit.log_likelihood[0] == pytest.approx(eo["loglik"] + eq["loglik"] + pen, rel=1e-12)
    go, gq = eo["gamma"][:, 1:], eq["gamma"][:3, 1:]
    yo, yqq = np.stack([ys["r1"], ys["r2"]], axis=1), yq["r1"][:, None]
    pm = (np.sum(go * (yo == 0)) + np.sum(gq * (yqq == 0))) / (go.sum() + gq.sum())
    pf = (np.sum((1 - go) * (yo == 1)) + np.sum((1 - gq) * (yqq == 1))) / ((1 - go).sum() + (1 - gq).sum())
    assert fit.p_m == pytest.approx(pm, rel=1e-10) and fit.p_f == pytest.approx(pf, rel=1e-10)
    for kind, lg in (("same_day", False), ("long_gap", True)):
        jumps = eo["land"][lg].sum() + eq["land"][lg].sum()
        assert fit.stay[kind] == pytest.approx(1 - jumps / (eo["trans"][lg] + eq["trans"][lg]), rel=1e-10)
    np.testing.assert_allclose(fit.posterior[("q", "r1")][1], eq["gamma"][:3, 1], rtol=1e-10)
    assert fit.n_objects == 2 and fit.n_steps == 8


def test_fixed_rates_are_kept_inside_the_open_interval_and_iteration_limits() -> None:
    t = T0 + np.array([0, 2, 4, 20, 22]) * 3600.0
    ys = {"r1": np.array([1, 0, 0, 1, 1]), "r2": np.array([0, 1, 0, 1, 1])}
    streams = [EdgeStream(("o", r), t, y.astype(np.int8)) for r, y in ys.items()]
    fit = fit_error_hmm(streams, p_m=0.0, p_f=0.7, max_iter=3)
    assert 0.0 < fit.p_m <= 1e-6 and 0.45 < fit.p_f < 0.5  # a zero or > 1/2 rate would be degenerate
    assert np.all(np.isfinite(fit.log_likelihood))
    en = _enumerate(ys, np.array([False, False, False, True, False]), fit.p_m, fit.p_f, (0.7, 0.5), np.full(3, 1 / 3))
    assert fit.log_likelihood[0] == pytest.approx(en["loglik"] + 2.0 * math.log(1 / 3), rel=1e-9)
    swapped = fit_error_hmm(streams, p_m=0.7, p_f=0.0, max_iter=1)
    assert 0.45 < swapped.p_m < 0.5 and 0.0 < swapped.p_f <= 1e-6
    # without a tolerance the default runs its 200 iterations
    assert len(fit_error_hmm(streams, tol=-1.0).log_likelihood) == 200
    # one scan time: no gap, so no step is long; sub-second gaps are gaps as well
    one = [EdgeStream(("o", "r1"), np.array([T0]), np.array([1], np.int8))]
    assert fit_error_hmm(one, max_iter=2).long_gap_s == math.inf
    fast = [EdgeStream(("o", "r1"), T0 + np.array([0.0, 0.5, 1.0, 5.0]), np.array([1, 1, 0, 0], np.int8))]
    assert fit_error_hmm(fast, max_iter=2).long_gap_s == 1.5


def test_stopping_rule_single_observations_and_degenerate_stays() -> None:
    from psg_data.estimators._hmm import _RATE_MAX, _RATE_MIN

    t = T0 + np.array([0, 2, 4, 20, 22]) * 3600.0
    ys = {"r1": np.array([1, 0, 0, 1, 1]), "r2": np.array([0, 1, 0, 1, 1])}
    streams = [EdgeStream(("o", r), t, y.astype(np.int8)) for r, y in ys.items()]
    # Baum-Welch stops at the first iteration whose change is below tol * max(1, |total|)
    for tol in (1e-2, 1e-4, 1e-7):
        tr = fit_error_hmm(streams, tol=tol).log_likelihood
        stop = next(i for i in range(1, len(tr)) if abs(tr[i] - tr[i - 1]) < tol * max(1.0, abs(tr[i])))
        assert len(tr) == stop + 1
    assert len(fit_error_hmm(streams, tol=0.0).log_likelihood) == 200  # never below 0: all iterations
    # one observation, present: the M-step's raw rates are 0 (P_M) and 1 (P_F), kept inside the bounds
    one = [EdgeStream(("o", "r1"), np.array([T0]), np.array([1], np.int8))]
    en = _enumerate({"r1": np.array([1])}, np.array([False]), 0.05, 0.05, (0.7, 0.5), np.full(2, 1 / 2))
    fit = fit_error_hmm(one, max_iter=1)
    g_on = en["gamma"][0, 1]
    assert fit.p_m == float(np.clip(0.0 / g_on, _RATE_MIN, _RATE_MAX))
    assert fit.p_f == float(np.clip((1 - g_on) / (1 - g_on), _RATE_MIN, _RATE_MAX))
    assert fit.stay == {"same_day": 0.7, "long_gap": 0.5}  # no step of either kind: nothing to update
    assert fit_error_hmm(one, max_iter=3).stay == {"same_day": 0.7, "long_gap": 0.5}
    # two scans, one step: its stay is updated from that single transition
    two = [EdgeStream(("o", "r1"), np.array([T0, T0 + 3600.0]), np.array([1, 0], np.int8))]
    en2 = _enumerate({"r1": np.array([1, 0])}, np.array([False, False]), 0.05, 0.05, (0.7, 0.5), np.full(2, 1 / 2))
    assert fit_error_hmm(two, max_iter=1).stay["same_day"] == pytest.approx(
        1 - en2["land"][False].sum() / en2["trans"][False], rel=1e-10)
    # an object that never moves drives the stay toward 1, one that moves at every scan toward 0:
    # both stay strictly inside (0, 1)
    tt = T0 + np.arange(40) * 3600.0
    still = [EdgeStream(("o", "r1"), tt, np.ones(40, np.int8)), EdgeStream(("o", "r2"), tt, np.zeros(40, np.int8))]
    s_still = fit_error_hmm(still, p_m=1e-9, p_f=1e-9, max_iter=80, tol=0.0).stay["same_day"]
    assert 0.999 < s_still < 1.0
    alt = (np.arange(40) % 2).astype(np.int8)
    moving = [EdgeStream(("o", "r1"), tt, alt), EdgeStream(("o", "r2"), tt, (1 - alt).astype(np.int8))]
    s_moving = fit_error_hmm(moving, p_m=1e-9, p_f=1e-9, max_iter=80, tol=0.0).stay["same_day"]
    assert 1e-9 < s_moving < 0.01


def test_no_observations_and_the_strict_long_gap() -> None:
    from psg_data.errors import EstimatorError

    with pytest.raises(EstimatorError, match="^error-rate HMM: no observations$"):
        fit_error_hmm([EdgeStream(("o", "r1"), np.zeros(0), np.zeros(0, np.int8))])
    # gaps 1, 1, 1, 3 h: the typical gap is 1 h, so 3 h is not longer than 3 typical gaps
    t = T0 + np.array([0, 1, 2, 3, 6]) * 3600.0
    b = _batch([EdgeStream(("o", "r1"), t, np.ones(5, np.int8))], long_gap_s=3 * 3600.0)
    assert not b.long.any()
    b = _batch([EdgeStream(("o", "r1"), t, np.ones(5, np.int8))], long_gap_s=3 * 3600.0 - 1)
    assert b.long.tolist() == [[False, False, False, False, True]]
