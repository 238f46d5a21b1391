"""FreMEn: harmonic sums, batch invariance, amplitude/phase recovery, order selection, epochs."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.estimators import EdgeStream, FremenModel, fourier_sums, get_estimator
from psg_data.estimators._fremen import WEEK_S, reference_monday, wall_seconds

T0 = 1_704_085_200.0  # 2024-01-01 00:00 America/Toronto, a Monday


def test_fft_sums_equal_direct_sums() -> None:
    rng = np.random.default_rng(0)
    tau = rng.uniform(0, 5 * WEEK_S, 3000)
    w = rng.random(3000)
    a = fourier_sums(tau, w, 1000, method="direct")
    b = fourier_sums(tau, w, 1000, method="fft")
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-9 * np.abs(a).max())
    # and a few against a plain loop
    for k in (1, 7, 168, 999):
        want = np.sum(w * np.exp(-2j * np.pi * k * tau / WEEK_S))
        assert abs(a[k - 1] - want) < 1e-8 * abs(np.sum(w))


def test_batches_give_the_one_batch_result() -> None:
    rng = np.random.default_rng(1)
    tau = np.sort(rng.uniform(0, 4 * WEEK_S, 20000))
    y = (rng.random(tau.size) < 0.5).astype(float)
    one = FremenModel(1000).add(tau, y)
    many = FremenModel(1000)
    for part in np.array_split(np.arange(tau.size), 9):
        many.add(tau[part], y[part])
    np.testing.assert_allclose(many.coefficients(), one.coefficients(), rtol=0, atol=1e-13)
    assert many.mean == one.mean
    np.testing.assert_array_equal(many.ranking()[:20], one.ranking()[:20])


def test_recovers_amplitude_and_phase_of_a_daily_cycle() -> None:
    tau = np.arange(0, 3 * WEEK_S, 300.0)
    y = 0.5 + 0.3 * np.cos(2 * np.pi * tau / 86400.0 - 1.0)
    m = FremenModel(200).add(tau, y)
    comps = m.components(1)
    assert comps.k.tolist() == [7]  # one day = one week / 7
    assert 2 * abs(comps.coef[0]) == pytest.approx(0.3, abs=1e-9)
    assert -np.angle(comps.coef[0]) == pytest.approx(1.0, abs=1e-9)
    assert m.mean == pytest.approx(0.5, abs=1e-12)
    np.testing.assert_allclose(comps.predict(tau[:500]), y[:500], atol=1e-9)


def test_unix_epoch_times_keep_phase_when_relative() -> None:
    # Same data at Unix-epoch times; relative epoch in float64 keeps the phases exact.
    tau = np.arange(0, 2 * WEEK_S, 600.0)
    y = (np.mod(tau, 86400) < 43200).astype(float)
    a = FremenModel(500).add(tau, y)
    t_unix = T0 + tau
    ref = reference_monday(t_unix[0], "UTC")
    b = FremenModel(500).add(t_unix - ref, y)
    # T0 is Monday 05:00 UTC, so the UTC Monday reference shifts phases by exactly 5 h
    shift = T0 - ref
    k = np.arange(1, 501)
    np.testing.assert_allclose(b.coefficients(), a.coefficients() * np.exp(-2j * np.pi * k * shift / WEEK_S), atol=1e-12)


def test_wall_clock_and_reference_monday() -> None:
    ws = wall_seconds(np.array([T0]), "America/Toronto")[0]
    assert ws == T0 - 5 * 3600
    assert reference_monday(T0 + 3 * 86400 + 100, "America/Toronto") == ws
    # across DST (2024-03-10) a local 08:00 stays at the same wall-clock phase
    t_before = 1_709_816_400.0 + 8 * 3600  # 2024-03-07 08:00 EST
    t_after = t_before + 7 * 86400 - 3600  # 2024-03-14 08:00 EDT
    w = wall_seconds(np.array([t_before, t_after]), "America/Toronto")
    assert (w[1] - w[0]) == 7 * 86400


def _daily_stream(days: int, start: float, seed: int) -> EdgeStream:
    rng = np.random.default_rng(seed)
    t = start + np.sort(rng.uniform(0, days * 86400, days * 60))
    hour = np.mod(wall_seconds(t, "America/Toronto"), 86400) / 3600
    x = ((hour >= 9) & (hour < 17)).astype(np.int8)
    y = np.where(rng.random(t.size) < 0.1, 1 - x, x).astype(np.int8)
    return EdgeStream(("mug", "desk"), t, y)


def test_fremen_estimator_chooses_small_order_on_validation() -> None:
    train = _daily_stream(21, T0 + 7 * 86400, 0)
    val = _daily_stream(7, T0, 1)
    est = get_estimator("fremen", n_periods=1000).fit([train], val_streams=[val], timezone="America/Toronto")
    info = est.fit_info_[("mug", "desk")]
    assert 1 <= info["order"] <= 60
    f = est.make_filter(("mug", "desk"))
    f.update_many(train.t_s, train.y)
    tq = T0 + 28 * 86400 + np.array([12.0, 3.0]) * 3600  # noon and 3 am
    p = f.predict(tq)
    assert p[0] > 0.75 and p[1] < 0.25
    # unseen edge: the overall mean
    g = est.make_filter(("other", "desk"))
    assert np.allclose(g.predict(tq), np.mean(train.y))
