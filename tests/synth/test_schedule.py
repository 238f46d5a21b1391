"""Hierarchical schedules: determinism, periodic structure, roles, distribution shift, DST."""

from __future__ import annotations

import datetime as dt
import zoneinfo

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.synth import LabConfig, LabModel, LabSchedule, make_layout

START = dt.date(2025, 3, 3)  # Monday; DST starts on Sunday 2025-03-09 in America/Toronto
TZ = "America/Toronto"


def _sched(seed: int, days: int = 21, shifted: frozenset[int] = frozenset()) -> LabSchedule:
    return LabSchedule(make_layout(seed), seed, START, days, TZ, shifted)


def test_same_seed_identical_different_seed_differs() -> None:
    a, b, c = _sched(4), _sched(4), _sched(5)
    for o in a.object_ids:
        np.testing.assert_array_equal(a.objects[o].change_ns, b.objects[o].change_ns)
        np.testing.assert_array_equal(a.objects[o].states, b.objects[o].states)
    assert not np.array_equal(a.dense().objects, c.dense().objects)


def _autocorr(x: np.ndarray, lag: int) -> float:
    """Mean lag-autocorrelation of the columns of x (non-constant columns only)."""
    x = x - x.mean(axis=0)
    num = (x[:-lag] * x[lag:]).sum(axis=0)
    den = (x * x).sum(axis=0)
    keep = den > 0
    return float(np.mean(num[keep] / den[keep]))


@pytest.mark.parametrize("seed", [0, 11])
def test_daily_and_weekly_periodicity(seed: int) -> None:
    d = _sched(seed).dense(step_s=3600)
    occ = d.presence().reshape(len(d.stamps_ns), -1).astype(float)
    absent = (d.objects < 0).astype(float)
    x = np.concatenate([occ, absent, d.doors_open.astype(float)], axis=1)
    a24, a168 = _autocorr(x, 24), _autocorr(x, 168)
    for lag in (7, 12, 31, 55, 90):
        assert a24 > _autocorr(x, lag) + 0.05, lag
        assert a168 > _autocorr(x, lag) + 0.05, lag


def test_roles_static_dynamic_absent() -> None:
    s = _sched(0)
    d = s.dense(step_s=600)
    for j, o in enumerate(s.object_ids):
        col = d.objects[:, j]
        if s.roles[o] == "static":
            assert np.all(col == col[0]) and col[0] >= 0
        elif s.roles[o] == "dynamic":
            assert col.min() >= 0 and len(np.unique(col)) >= 2
        else:
            assert (col < 0).any() and (col >= 0).any()


def test_doors_closed_at_night_and_sometimes_by_day() -> None:
    s = _sched(0)
    d = s.dense(step_s=900)
    zone = zoneinfo.ZoneInfo(TZ)
    hours = np.array([dt.datetime.fromtimestamp(t / 1e9, zone).hour for t in d.stamps_ns])
    night = (hours < 6) | (hours >= 21)
    assert not d.doors_open[night].any()
    day = (hours >= 10) & (hours < 16)
    for k in range(d.doors_open.shape[1]):
        assert 0.2 < d.doors_open[day, k].mean() < 1.0


def test_long_weekend_shift_changes_exactly_the_chosen_days() -> None:
    cfg = LabConfig(seed=2, shift="long-weekend")
    shifted = cfg.shifted_days()
    zone = zoneinfo.ZoneInfo(TZ)
    names = {(START + dt.timedelta(days=d)).strftime("%a") for d in shifted}
    assert names == {"Mon", "Fri"} and all(d >= cfg.n_train_days for d in shifted) and len(shifted) == 2
    base, shift = _sched(2), _sched(2, shifted=shifted)
    db, ds = base.dense(step_s=600), shift.dense(step_s=600)
    day_of = np.array([(dt.datetime.fromtimestamp(t / 1e9, zone).date() - START).days for t in db.stamps_ns])
    diff = (db.objects != ds.objects).any(axis=1) | (db.doors_open != ds.doors_open).any(axis=1)
    assert set(np.unique(day_of[diff]).tolist()) == set(shifted)
    for o in shift.object_ids:
        for d in shifted:
            sat = d + (5 - (START + dt.timedelta(days=d)).weekday()) % 7
            sat_allowed = {base.objects[o].day_patterns[x] for x in range(sat, 21, 7)} | {
                p.name for p in shift.object_models[o].day_patterns if p.name.startswith("weekend")}
            assert shift.objects[o].day_patterns[d] in sat_allowed | {"static"}


def test_scans_at_local_slots_across_dst() -> None:
    lab = LabModel(LabConfig(seed=0, days=9, frames_per_scan=1, width=32, height=24))
    zone = zoneinfo.ZoneInfo(TZ)
    assert len(lab.scans) == 36
    for p in lab.scans:
        local = dt.datetime.fromtimestamp(p.start_ns / 1e9, zone)
        assert local.hour in (9, 11, 13, 15) and local.minute < 10
        assert (local.date() - START).days == p.day
    utc_hours = {dt.datetime.fromtimestamp(p.start_ns / 1e9, dt.timezone.utc).hour for p in lab.scans if p.day in (0, 8)
                 and dt.datetime.fromtimestamp(p.start_ns / 1e9, zone).hour == 9}
    assert utc_hours == {14, 13}  # EST (UTC-5) before, EDT (UTC-4) after the switch


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 9))
def test_timelines_well_formed(seed: int, days: int) -> None:
    s = LabSchedule(make_layout(seed % 7), seed, START, days, TZ)
    R = len(s.receptacle_ids)
    for tl in [*s.objects.values(), *s.doors.values()]:
        assert np.all(np.diff(tl.change_ns) > 0)
        assert np.all(tl.states[1:] != tl.states[:-1])
        assert tl.change_ns[0] == s.start_ns and tl.change_ns[-1] < s.end_ns
        assert tl.states.min() >= -1 and tl.states.max() < R
        # brute-force lookup agrees with the vectorised one
        probe = np.sort(np.random.default_rng(seed).integers(s.start_ns, s.end_ns, 20))
        brute = [tl.states[max(i for i in range(len(tl.change_ns)) if tl.change_ns[i] <= t)] for t in probe]
        np.testing.assert_array_equal(tl.at(probe), brute)
