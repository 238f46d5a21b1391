"""FreMEn: harmonic sums, batch invariance, amplitude/phase recovery, order selection, epochs."""

from __future__ import annotations

import datetime as dt
import json
from zoneinfo import ZoneInfo

import numpy as np
import pytest

from psg_data.errors import EstimatorError
from psg_data.estimators import EdgeStream, FremenComponents, FremenModel, LocalClock, fourier_sums, get_estimator
from psg_data.estimators import _fremen
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


# --- independent checks of the sums, the local clock and the serialised forms (issue 33's mutants) ---

def _plain_sums(tau: np.ndarray, w: np.ndarray, k: int, base: float = WEEK_S) -> np.ndarray:
    ks = np.arange(1, k + 1)
    return np.array([np.sum(w * np.exp(-2j * np.pi * kk * np.asarray(tau, float) / base)) for kk in ks])


def test_fourier_sums_edge_sizes_shapes_and_dispatch() -> None:
    # one observation, K = 1: the closed form w exp(-i 2 pi tau / week)
    got = fourier_sums([3600.0], [0.7], 1)
    assert got.shape == (1,) and abs(got[0] - 0.7 * np.exp(-2j * np.pi * 3600.0 / WEEK_S)) < 1e-15
    # no observation / no period: complex zeros of length K, for every method
    for method in ("auto", "direct", "fft"):
        z = fourier_sums([], [], 5, method=method)
        assert z.dtype == np.complex128 and z.shape == (5,) and not z.any()
        e = fourier_sums([1.0, 2.0], [1.0, 1.0], 0, method=method)
        assert e.dtype == np.complex128 and e.shape == (0,)
    rng = np.random.default_rng(5)
    tau, w = rng.uniform(-WEEK_S, 3 * WEEK_S, 100), rng.random(100)
    direct, fft = fourier_sums(tau, w, 1000, method="direct"), fourier_sums(tau, w, 1000, method="fft")
    # "auto" is the direct sum up to N*K = 100000 (here exactly) and the FFT above
    np.testing.assert_array_equal(fourier_sums(tau, w, 1000), direct)
    np.testing.assert_array_equal(fourier_sums(tau, w, 1001), fourier_sums(tau, w, 1001, method="fft"))
    np.testing.assert_allclose(direct, _plain_sums(tau, w, 1000), rtol=0, atol=1e-10)
    np.testing.assert_allclose(fft, direct, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(direct, _fremen._direct_sums(tau, w, 1000, WEEK_S))
    np.testing.assert_array_equal(fft, _fremen._fft_sums(tau, w, 1000, WEEK_S))
    # columns are flattened; float32 times are read as float64 (no float32 angles)
    np.testing.assert_array_equal(fourier_sums(tau[:, None], w[:, None], 1000), direct)
    np.testing.assert_array_equal(fourier_sums(tau[:, None], w, 1000, method="fft"), fft)
    t32 = tau.astype(np.float32)
    for method in ("direct", "fft"):
        np.testing.assert_allclose(fourier_sums(t32, w, 200, method=method),
                                   _plain_sums(t32.astype(np.float64), w, 200), rtol=0, atol=1e-11)


def test_fft_sums_stay_exact_for_many_periods_and_a_time_just_before_the_epoch() -> None:
    # K = 16384 needs a fine grid (M = 64 K bins): on a coarse one the Taylor series of the
    # within-bin offset would be off by ~1e-6; a time a hair before 0 wraps to theta = one week
    rng = np.random.default_rng(6)
    tau = np.concatenate([[-1e-12, 0.0], rng.uniform(0, 2 * WEEK_S, 60)])
    w = rng.random(tau.size)
    want = fourier_sums(tau, w, 16384, method="direct")
    np.testing.assert_allclose(fourier_sums(tau, w, 16384, method="fft"), want, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fourier_sums(tau[:2], w[:2], 8, method="fft"), _plain_sums(tau[:2], w[:2], 8),
                               rtol=0, atol=1e-13)


def test_model_add_edges_defaults_and_serialised_statistics() -> None:
    with pytest.raises(EstimatorError, match="n_periods must be >= 0, got -1"):
        FremenModel(-1)
    empty = FremenModel(0).add([1.0, 2.0], [1.0, 0.0])  # no periods at all is a valid model
    assert empty.coefficients().shape == (0,) and empty.components(3).order == 0
    m = FremenModel()
    assert m.n_periods == 1000 and m.duration_rule is False and m.base_period_s == WEEK_S
    c0 = m.coefficients()
    assert c0.dtype == np.complex128 and c0.shape == (1000,) and not c0.any()
    np.testing.assert_array_equal(m.ranking(), np.arange(1, 1001))  # ties keep the harmonic order
    with pytest.raises(EstimatorError, match="differ in length"):
        m.add([1.0, 2.0], [1.0])
    m.add([7200.0], [1.0])  # a single observation counts
    assert m.n == 1 and m.sum_y == 1.0 and m.first_tau == m.last_tau == 7200.0
    # a column of times with a flat y (and the reverse) is the same data
    rng = np.random.default_rng(7)
    tau, y = rng.uniform(0, 2 * WEEK_S, 80), (rng.random(80) < 0.4).astype(float)
    flat = FremenModel(40).add(tau, y)
    np.testing.assert_array_equal(FremenModel(40).add(tau[:, None], y).coefficients(), flat.coefficients())
    np.testing.assert_array_equal(FremenModel(40).add(tau, y[:, None]).coefficients(), flat.coefficients())
    # add() passes its method on; the default is the direct sum for small N*K
    by_fft = FremenModel(40).add(tau, y, method="fft")
    np.testing.assert_array_equal(by_fft.s, fourier_sums(tau, y, 40, method="fft"))
    np.testing.assert_array_equal(by_fft.z, fourier_sums(tau, np.ones(80), 40, method="fft"))
    np.testing.assert_array_equal(flat.s, fourier_sums(tau, y, 40, method="direct"))
    np.testing.assert_array_equal(flat.z, fourier_sums(tau, np.ones(80), 40, method="direct"))
    # float32 observations are summed in float64 (a float32 sum of 0.3s is off by ~1e-7 relative here)
    y32 = np.full(200_001, 0.3, dtype=np.float32)
    m32 = FremenModel(0).add(np.arange(y32.size, dtype=float), y32)
    assert m32.mean == pytest.approx(float(np.float32(0.3)), rel=1e-12, abs=0)
    d = json.loads(json.dumps(flat.to_dict()))
    assert set(d) == {"n_periods", "base_period_s", "duration_rule", "n", "sum_y", "first_tau", "last_tau",
                      "s_re", "s_im", "z_re", "z_im"}
    assert (d["n_periods"], d["base_period_s"], d["duration_rule"], d["n"]) == (40, WEEK_S, False, 80)
    assert d["sum_y"] == float(y.sum()) and (d["first_tau"], d["last_tau"]) == (tau.min(), tau.max())
    np.testing.assert_allclose(np.array(d["s_re"]) + 1j * np.array(d["s_im"]), _plain_sums(tau, y, 40), atol=1e-11)
    np.testing.assert_allclose(np.array(d["z_re"]) + 1j * np.array(d["z_im"]), _plain_sums(tau, np.ones(80), 40),
                               atol=1e-11)


def test_duration_rule_boundary_base_period_and_admissible_mask() -> None:
    # span exactly 1.5 days: the daily period (k = 7 of a week) is kept, k = 6 (1.17 days) dropped
    m = FremenModel(10, duration_rule=True).add([0.0, 1.5 * 86400.0], [1.0, 0.0])
    adm = m.admissible()
    assert adm.dtype == np.bool_ and adm.tolist() == [k >= 7 for k in range(1, 11)]
    assert FremenModel(3).admissible().dtype == np.bool_
    assert not m.coefficients()[:6].any() and m.coefficients()[6:].all()
    # ranking: decreasing amplitude, ties (here the dropped periods) in harmonic order
    rng = np.random.default_rng(9)
    t3 = np.sort(rng.uniform(0, 3 * 86400.0, 200))
    m3 = FremenModel(300, duration_rule=True).add(t3, (rng.random(200) < 0.5).astype(float))
    amp = np.abs(m3.coefficients())
    assert (amp == 0).sum() == 3  # 1.5 T > 3 days for T = 7, 3.5 and 2.33 days
    assert m3.ranking().tolist() == sorted(range(1, 301), key=lambda k: -amp[k - 1])
    # a daily base period is kept in the components and used by their prediction
    tau = np.arange(0, 5 * 86400.0, 600.0)
    y = 0.5 + 0.4 * np.cos(2 * np.pi * tau / 43200.0)
    day = FremenModel(4, base_period_s=86400.0).add(tau, y)
    comps = day.components(1)
    assert comps.base_period_s == 86400.0 and comps.k.tolist() == [2]
    np.testing.assert_allclose(comps.predict(tau), y, atol=1e-9)


def test_components_prediction_clips_and_round_trips_through_json() -> None:
    # mean 0.5 plus 2 |c| cos(...) with |c| = 0.5: raw values span [-0.5, 1.5]
    comps = FremenComponents(0.5, np.array([1, 3]), np.array([0.5 * np.exp(0.3j), 0.05j]))
    tau = np.linspace(-WEEK_S, 2 * WEEK_S, 3001)
    theta = 2 * np.pi * tau / WEEK_S
    raw = 0.5 + np.cos(theta + 0.3) + 0.1 * np.cos(3 * theta + np.pi / 2)
    np.testing.assert_allclose(comps.raw(tau), raw, atol=1e-12)
    assert raw.min() < -0.4 and raw.max() > 1.4
    np.testing.assert_allclose(comps.predict(tau), np.clip(raw, 0.0, 1.0), atol=1e-12)
    # float32 times are read as float64; an integer static part is a valid one
    np.testing.assert_allclose(comps.raw(tau.astype(np.float32)), comps.raw(tau.astype(np.float32).astype(float)),
                               rtol=0, atol=1e-12)
    whole = FremenComponents(0, np.array([7]), np.array([0.25 + 0j]))
    np.testing.assert_allclose(whole.raw([0.0, 43200.0]), [0.5, -0.5], atol=1e-12)
    back = FremenComponents.from_dict(json.loads(json.dumps(comps.to_dict())))
    assert back.mean == 0.5 and back.k.dtype == np.int64 and back.k.tolist() == [1, 3]
    assert back.coef.dtype == np.complex128 and back.base_period_s == WEEK_S
    np.testing.assert_array_equal(back.coef, comps.coef)
    np.testing.assert_array_equal(back.predict(tau), comps.predict(tau))
    daily = FremenComponents(0.25, np.array([2]), np.array([0.1 - 0.2j]), 86400.0)
    d = daily.to_dict()
    assert d == {"mean": 0.25, "k": [2], "re": [0.1], "im": [-0.2], "base_period_s": 86400.0}
    back = FremenComponents.from_dict(json.loads(json.dumps(d)))
    assert back.base_period_s == 86400.0
    np.testing.assert_array_equal(back.raw(tau), daily.raw(tau))


def _zone_offset(t: float, zone: str) -> float:
    """UTC offset (s) of ``zone`` at Unix time t, from the standard library's zoneinfo."""
    off = dt.datetime.fromtimestamp(t, ZoneInfo(zone)).utcoffset()
    assert off is not None
    return off.total_seconds()


def _zone_transitions(zone: str, lo: float, hi: float) -> list[float]:
    """Unix times (s) where ``zone``'s offset changes in [lo, hi], by hourly scan and bisection."""
    out = []
    for t in np.arange(lo, hi, 3600.0):
        a, b = float(t), float(t) + 3600.0
        if _zone_offset(a, zone) != _zone_offset(b, zone):
            while b - a > 1.0:
                mid = (a + b) / 2
                a, b = (mid, b) if _zone_offset(mid, zone) == _zone_offset(a, zone) else (a, mid)
            out.append(float(np.ceil(b)))
    return out


@pytest.mark.parametrize("zone", ["America/Toronto", "Australia/Adelaide", "Asia/Kathmandu", "Europe/London"])
def test_wall_seconds_equal_zoneinfo_on_a_fresh_table_around_every_transition(
        zone: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_fremen, "_OFFSET_TABLES", {})  # build the offset table, not a cached one
    lo, hi = 1_704_067_200.0, 1_704_067_200.0 + 400 * 86400.0  # 2024-01-01 UTC and 400 days on
    trans = _zone_transitions(zone, lo, hi)
    assert len(trans) >= (0 if zone == "Asia/Kathmandu" else 2)
    near = [tt + d for tt in trans for d in (-901.0, -900.0, -1.0, -0.5, 0.0, 0.5, 1.0, 450.0, 899.0, 900.0, 901.0)]
    t = np.concatenate([np.arange(lo, hi, 3599.0), near, [lo, hi]])
    want = np.array([x + _zone_offset(x, zone) for x in t])
    np.testing.assert_array_equal(wall_seconds(t, zone), want)


def test_offset_table_is_reused_and_grown_not_rebuilt(monkeypatch: pytest.MonkeyPatch) -> None:
    zone = "America/Toronto"
    monkeypatch.setattr(_fremen, "_OFFSET_TABLES", {})
    calls: list[int] = []
    real = _fremen._offset_steps

    def counted(t: np.ndarray, tz: str) -> tuple[np.ndarray, np.ndarray]:
        calls.append(t.size)
        return real(t, tz)

    monkeypatch.setattr(_fremen, "_offset_steps", counted)
    spring = 1_710_054_000.0  # 2024-03-10 07:00 UTC: Toronto goes from -5 h to -4 h
    assert _zone_offset(spring - 1, zone) == -18000 and _zone_offset(spring, zone) == -14400
    lo = spring - 900.0 + 400 * 86400.0  # the table then starts 900 s before the transition
    assert wall_seconds(np.array([lo]), zone)[0] == lo + _zone_offset(lo, zone)
    assert len(calls) == 1
    a, b = _fremen._OFFSET_TABLES[zone][:2]
    assert a <= lo <= b
    inside = np.array([a, a + 900.0, spring, lo + 300 * 86400.0, b])  # both ends of the table, nearby times
    np.testing.assert_array_equal(wall_seconds(inside, zone), [x + _zone_offset(x, zone) for x in inside])
    assert len(calls) == 1  # no rebuild for times the table covers
    far = np.array([lo + 1500 * 86400.0, lo - 1500 * 86400.0])
    for i, x in enumerate(far):  # each far time grows the table once, keeping what it covered
        assert wall_seconds(np.array([x]), zone)[0] == x + _zone_offset(x, zone)
        assert len(calls) == 2 + i
        both = np.array([a, b, *far[: i + 1]])
        np.testing.assert_array_equal(wall_seconds(both, zone), [x + _zone_offset(x, zone) for x in both])
        assert len(calls) == 2 + i
    a2, b2 = _fremen._OFFSET_TABLES[zone][:2]
    assert a2 <= min(a, far.min()) and b2 >= max(b, far.max())
    # a fresh table that ends exactly at a transition: its last time has the new offset
    monkeypatch.setattr(_fremen, "_OFFSET_TABLES", {})
    fall = 1_730_613_600.0  # 2024-11-03 06:00 UTC: Toronto goes from -4 h to -5 h
    assert _zone_offset(fall - 1, zone) == -14400 and _zone_offset(fall, zone) == -18000
    wall_seconds(np.array([fall - 400 * 86400.0]), zone)  # the table ends at the transition (400-day margin)
    end = _fremen._OFFSET_TABLES[zone][1]
    assert wall_seconds(np.array([end]), zone)[0] == end + _zone_offset(end, zone) and len(calls) == 4


def test_utc_names_and_empty_input_never_need_the_zone_tables(monkeypatch: pytest.MonkeyPatch) -> None:
    def fail(t: np.ndarray, tz: str) -> np.ndarray:
        raise AssertionError("zone offsets were computed")

    monkeypatch.setattr(_fremen, "_offset_steps", fail)
    monkeypatch.setattr(_fremen, "_OFFSET_TABLES", {})
    for zone in ("UTC", "Etc/UTC", "utc", "GMT"):
        out = wall_seconds([0, 86400], zone)
        assert out.dtype == np.float64 and out.tolist() == [0.0, 86400.0]
    out32 = wall_seconds(np.array([T0], dtype=np.float32), "UTC")
    assert out32.dtype == np.float64 and out32[0] == float(np.float32(T0))
    assert wall_seconds(np.zeros(0), "America/Toronto").shape == (0,)


def test_an_unknown_zone_is_one_estimator_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_fremen, "_OFFSET_TABLES", {})
    with pytest.raises(EstimatorError, match="unknown timezone 'Mars/Olympus'"):
        wall_seconds([T0], "Mars/Olympus")


@pytest.mark.parametrize("zone", ["America/Toronto", "Asia/Kathmandu", "Australia/Adelaide"])
def test_reference_monday_and_local_clock_equal_zoneinfo(zone: str) -> None:
    rng = np.random.default_rng(8)
    for t in rng.uniform(1_600_000_000.0, 1_800_000_000.0, 40):
        local = dt.datetime.fromtimestamp(t, ZoneInfo(zone)).replace(tzinfo=None)
        monday = dt.datetime(local.year, local.month, local.day) - dt.timedelta(days=local.weekday())
        want = (monday - dt.datetime(1970, 1, 1)).total_seconds()
        assert reference_monday(float(t), zone) == want
        clock = LocalClock.before(float(t), zone)
        assert clock.timezone == zone and clock.ref_wall_s == want
        later = np.array([t, t + 3 * 86400.0])
        np.testing.assert_array_equal(clock(later), [x + _zone_offset(x, zone) - want for x in later])
        back = LocalClock.from_dict(json.loads(json.dumps(clock.to_dict())))
        assert back == clock and clock.to_dict() == {"timezone": zone, "ref_wall_s": want}
