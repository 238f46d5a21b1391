"""Perpetua* / Perpetua trained on sparse scans: cadence defaults, forgetting in time, profile
prior, the annealed variant, pooled runs, and the dense room-like stream of the reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import EstimatorError
from psg_data.estimators import EdgeStream, ProfilePrior, check_estimator, get_estimator
from psg_data.estimators._perpetua_star import discounted_cumsum_log
from psg_data.evaluation import evaluate_persistence

T0 = 1_740_960_000.0  # 2025-03-03 00:00 UTC, a Monday
SCANS_H = (9, 11, 13, 15)


def lab_like(days: int = 14, n_obj: int = 6, seed: int = 0) -> list[EdgeStream]:
    """Noise-free scans four times a day of objects hopping between 3 receptacles (or none)."""
    rng = np.random.default_rng(seed)
    t = np.array([T0 + d * 86400 + h * 3600 for d in range(days) for h in SCANS_H], dtype=np.float64)
    out = []
    for o in range(n_obj):
        z = np.empty(t.size, int)
        z[0] = rng.integers(0, 4)
        for i in range(1, t.size):
            z[i] = z[i - 1] if rng.random() < 0.5 else rng.integers(0, 4)
        for r in range(1, 4):
            out.append(EdgeStream((f"o{o}", f"r{r}"), t, (z == r).astype(np.int8)))
    return out


def test_cadence_defaults_and_fit_summary() -> None:
    streams = lab_like()
    est = get_estimator("perpetua_star").fit(streams, timezone="UTC")
    fs = est.fit_summary_
    gap = fs["cadence"]["typical_gap_s"]
    assert gap == pytest.approx(7200.0)
    assert est.half_life_s_ == pytest.approx(gap) and est.gamma_ is None
    assert est.alpha0_per_s_ == pytest.approx(math.log(2) / gap)
    assert est.n_periods_ == 42  # one week / 4 h: the shortest period a 2 h cadence resolves
    assert all(v["source"].startswith("cadence") for v in fs["settings"].values())
    assert fs["error_rates"]["p_m"] < 0.01 and fs["error_rates"]["p_f"] < 0.01  # noise-free labels
    assert fs["error_rates"]["source"] == "pooled multi-receptacle HMM"
    edge = fs["edges"]["o0/r1"]
    assert {"present_runs", "present_censored", "per_source", "per_k", "per_median_h", "emg_median_h"} <= set(edge)
    paper = get_estimator("perpetua_star", gamma=0.99, alpha0=0.01, n_periods=1000).fit(streams)
    assert paper.gamma_ == 0.99 and paper.half_life_s_ is None
    assert paper.alpha0_per_s_ == pytest.approx(0.01 / 60.0)
    assert all(v["source"] == "set" for v in paper.fit_summary_["settings"].values())
    with pytest.raises(EstimatorError, match="not both"):
        get_estimator("perpetua_star", gamma=0.9, half_life_s=60.0).fit(streams)
    fre = get_estimator("fremen").fit(streams)
    assert fre.n_periods_ == 42 and get_estimator("fremen", n_periods=1000).fit(streams).n_periods_ == 1000


def test_forgetting_in_time_halves_per_half_life() -> None:
    inc = np.array([1.0, 0.0, 0.0, 2.0])
    dt = np.array([0.0, 3600.0, 7200.0, 0.0])
    got = discounted_cumsum_log(4.0, inc, -math.log(2) / 3600.0 * dt)
    np.testing.assert_allclose(got, [5.0, 2.5, 0.625, 2.625])
    assert discounted_cumsum_log(3.0, np.ones(3), np.array([0.0, -np.inf, -1e-9]))[1] == 1.0  # factor 0 restarts


@settings(max_examples=40, deadline=None)
@given(inc=st.lists(st.floats(-50, 50), min_size=1, max_size=300), lg=st.floats(-5.0, 0.0), l0=st.floats(-100, 100))
def test_discounted_cumsum_log_matches_loop(inc, lg, l0) -> None:
    inc = np.array(inc)
    log_g = np.full(inc.size, lg) * np.linspace(0.1, 3.0, inc.size)  # varying factors, cumulative << e^-300
    want, acc = [], l0
    for i, g in zip(inc, np.exp(log_g)):
        acc = g * acc + i
        want.append(acc)
    np.testing.assert_allclose(discounted_cumsum_log(l0, inc, log_g), want, rtol=1e-9, atol=1e-9)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(2, 600), cuts=st.lists(st.integers(0, 600), max_size=5))
def test_half_life_batches_equal_one_at_a_time(seed, n, cuts) -> None:
    from psg_data.estimators import SurvivalMixture
    from psg_data.estimators._perpetua_star import PerpetuaStarFilter
    from psg_data.estimators._priors import ConstantPrior

    rng = np.random.default_rng(seed)
    t = T0 + np.cumsum(rng.choice([7200.0, 64800.0], n, p=[0.75, 0.25]) + rng.uniform(-300, 300, n))
    y = (rng.random(n) < 0.3).astype(np.int8)
    per = SurvivalMixture.lognormal_median(3 * 3600.0, 0.8)
    emg = SurvivalMixture.lognormal_median(15 * 3600.0, 0.9)

    def make() -> PerpetuaStarFilter:
        return PerpetuaStarFilter(("o", "r"), per, emg, 0.01, 0.01, ConstantPrior(0.3), gamma=None,
                                  half_life_s=7200.0, alpha0_per_s=1e-4, prior_floor=1e-3)

    a, b = make(), make()
    edges = [0, *sorted(c for c in cuts if 0 < c < n), n]
    for lo, hi in zip(edges[:-1], edges[1:]):
        if hi > lo:
            a.update_many(t[lo:hi], y[lo:hi])
    for ti, yi in zip(t.tolist(), y.tolist()):
        b.update(ti, yi)
    assert a.n_restarts == b.n_restarts
    np.testing.assert_allclose(a.L, b.L, rtol=1e-7, atol=1e-7)
    q = t[-1] + np.linspace(0, 86400, 9)
    np.testing.assert_allclose(a.predict(q), b.predict(q), atol=1e-7)


def test_profile_prior_learns_the_day_profile() -> None:
    t = np.array([T0 + d * 86400 + h * 3600 for d in range(14) for h in SCANS_H])
    local_h = ((t - T0) % 86400) / 3600
    y = (local_h < 12).astype(np.int8)  # present at the 9:00 and 11:00 scans
    p = ProfilePrior.fit(t, y, step_s=7200.0, days="workweek", timezone="UTC", pseudo_count=1.0)
    base = y.mean()
    q = T0 + 21 * 86400 + np.array([9.5, 11.2, 13.0, 15.9, 3.0]) * 3600  # a Monday
    want_in = (10 + base) / 11  # 10 weekday scans in the cell, smoothed toward the mean
    np.testing.assert_allclose(p(q), [want_in, want_in, base / 11, base / 11, base], rtol=1e-12)
    est = get_estimator("perpetua_star", prior="profile")
    assert check_estimator(est)["state_roundtrip"] == "ok"


def test_annealed_variant_tends_to_the_prior() -> None:
    streams = lab_like(seed=3)
    star = get_estimator("perpetua_star", prior="profile").fit(streams)
    ann = get_estimator("perpetua_star_annealed", prior="profile").fit(streams)
    s = streams[0]
    f, g = star.make_filter(s.edge), ann.make_filter(s.edge)
    f.update_many(s.t_s, s.y)
    g.update_many(s.t_s, s.y)
    near, far = s.t_s[-1] + 1.0, s.t_s[-1] + 7 * 86400 + 9 * 3600
    assert float(g.predict([near])[0]) == pytest.approx(float(f.predict([near])[0]), abs=1e-3)
    assert float(g.predict([far])[0]) == pytest.approx(float(star.priors_[s.edge](np.array([far]))[0]), abs=1e-6)


def test_perpetua_starts_present_never_half() -> None:
    est = get_estimator("perpetua").fit(lab_like(days=7))
    f = est.make_filter(("unseen", "edge"))
    assert np.all(f.predict(np.array([T0, T0 + 3600])) == 1.0)  # not 0.5
    g = est.make_filter(("o0", "r1"))
    g.start(T0)
    assert g.per.origin == T0
    p = g.predict(np.array([T0, T0 + 30 * 86400]))
    assert p[0] == pytest.approx(1.0) and p[1] < p[0]
    g.update(T0 + 60.0, 1)
    with pytest.raises(EstimatorError, match="before the first observation"):
        g.start(T0 + 120.0)


def room_like(hours: float, seed: int = 0, dt: float = 0.5, noise: float = 0.1):
    """The reference's room example, generated: 8 features (4 always present, 4 switching every
    5-40 minutes), one observation of each every ``dt`` s with P_M = P_F = ``noise``, ``hours``
    of training then ``hours`` of test."""
    rng = np.random.default_rng(seed)
    t = T0 + np.arange(0.0, 2 * hours * 3600, dt)
    cut = T0 + hours * 3600
    train, test, truth = [], [], {}
    for k in range(8):
        x = np.ones(t.size, np.int8)
        if k >= 4:
            pos, state = 0, int(rng.integers(0, 2))
            while pos < t.size:
                n = int(rng.uniform(300, 2400) / dt)
                x[pos:pos + n] = state
                pos, state = pos + n, 1 - state
        y = np.where(rng.random(t.size) < noise, 1 - x, x).astype(np.int8)
        e = (f"feature{k}", "room")
        m = t < cut
        train.append(EdgeStream(e, t[m], y[m]))
        test.append(EdgeStream(e, t[~m], y[~m]))
        truth[e] = (t[~m][::10], x[~m][::10].astype(np.int64))
    return train, test, truth


def _perpetua(random_state: object = None) -> object:
    """A picklable factory (module level), so the long stream can be scored with ``jobs=2``."""
    return get_estimator("perpetua")


def _room_scores(hours: float, features: int, jobs: int = 1) -> tuple[list[float], dict]:
    train, test, truth = room_like(hours)
    train, test = train[:features], test[:features]
    truth = {s.edge: truth[s.edge] for s in test}
    est = get_estimator("perpetua").fit(train)
    res = evaluate_persistence({"perpetua": _perpetua}, train, test, truth, setting="adaptive", seeds=(0,),
                               jobs=jobs)
    return [r.metrics["mae"] for r in res.edges], est.fit_summary_


def test_room_like_stream_short() -> None:
    mae, fs = _room_scores(hours=0.25, features=5)
    assert fs["segmentation"] == "reference"
    assert fs["error_rates"]["p_f"] == pytest.approx(0.1, abs=0.03) and fs["error_rates"]["p_m"] == pytest.approx(
        0.1, abs=0.03)
    assert max(mae[:4]) <= 0.001  # always-present features
    assert mae[4] < 0.05


@pytest.mark.slow
def test_room_like_stream_three_hours() -> None:
    """3 h + 3 h at 0.5 s (21,600 observations per feature and split), as the reference's example."""
    mae, fs = _room_scores(hours=3.0, features=8, jobs=2)  # the edges' filters in two processes: same scores
    assert max(mae[:4]) <= 0.001
    assert all(fs["edges"][f"feature{k}/room"]["present_runs"] == 1 for k in range(4))  # no over-segmentation
    assert max(mae[4:]) < 0.02


@pytest.mark.slow
def test_million_observations_stay_finite() -> None:
    from psg_data.estimators import SurvivalMixture, fit_error_hmm
    from psg_data.estimators._perpetua_star import PerpetuaStarFilter
    from psg_data.estimators._priors import ConstantPrior

    n = 1_000_000
    rng = np.random.default_rng(7)
    t = T0 + np.cumsum(rng.uniform(0.3, 0.7, n))
    x = (np.mod(t, 3600.0) < 1800.0).astype(np.int8)
    y = np.where(rng.random(n) < 0.1, 1 - x, x).astype(np.int8)
    f = PerpetuaStarFilter(("o", "r"), SurvivalMixture.lognormal_median(1800.0, 0.05),
                           SurvivalMixture.lognormal_median(1800.0, 0.05), 0.1, 0.1, ConstantPrior(0.5), gamma=None,
                           half_life_s=30.0, alpha0_per_s=0.01, prior_floor=1e-3)
    f.update_many(t, y)
    assert np.all(np.isfinite(f.L)) and np.all(np.isfinite(f.E))
    p = f.predict(t[-1] + np.array([0.0, 10.0, 1e5]))
    assert np.all(np.isfinite(p)) and np.all((p >= 0) & (p <= 1))
    fit = fit_error_hmm([EdgeStream(("o", "r"), t, y)], max_iter=3)
    assert np.all(np.isfinite(fit.log_likelihood)) and 0 < fit.p_f < 0.5 and 0 < fit.p_m < 0.5
