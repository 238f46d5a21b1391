"""Scoring windows and cadence against independent references (issue 33).

Local time is recomputed here with ``datetime.fromtimestamp(t, ZoneInfo(zone))`` instant by instant
(the module converts with pandas for ``contains`` and maps local wall-clock hours to UTC for
``intervals``): membership on minute grids across DST changes, half-hour and 45-minute offsets and
the days around them; cadences and dataset windows from per-scan ``datetime`` arithmetic and
``statistics.median``; text forms evaluated by hand.

Not compared: window bounds strictly inside a repeated or skipped local hour (e.g. 1:30 in
America/Toronto on a DST day), where ``intervals`` takes the wall time's first occurrence and
``contains`` every instant whose wall time is inside.
"""

from __future__ import annotations

import datetime as dt
import math
import statistics
from pathlib import Path
from types import SimpleNamespace
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.errors import EvaluationError
from psg_data.evaluation import (
    DailyWindows,
    dataset_cadence_s,
    dataset_windows,
    format_duration,
    parse_duration,
    parse_windows,
)
from psg_data.evaluation._windows import cadence_from_stamps

MIN = 60.0


def _utc(zone: str, *args: int) -> float:
    """UTC seconds of an unambiguous local wall-clock time."""
    return dt.datetime(*args, tzinfo=ZoneInfo(zone)).timestamp()  # type: ignore[misc]


def _inside_reference(t: float, hours: list[tuple[float, float]], zone: str) -> bool:
    local = dt.datetime.fromtimestamp(t, ZoneInfo(zone))
    sod = local.hour * 3600 + local.minute * 60 + local.second + local.microsecond / 1e6
    return any(lo * 3600.0 <= sod < hi * 3600.0 for lo, hi in hours)


def _runs(grid: np.ndarray, inside: np.ndarray, end: float) -> list[list[float]]:
    """Maximal runs of ``inside`` on a grid of step 60 s as [start, end) seconds."""
    out: list[list[float]] = []
    for t, keep in zip(grid, inside):
        if not keep:
            continue
        if out and out[-1][1] == t:
            out[-1][1] = t + MIN
        else:
            out.append([float(t), float(t + MIN)])
    return [[a, min(b, end)] for a, b in out]


def _merged(iv: np.ndarray) -> list[list[float]]:
    out: list[list[float]] = []
    for a, b in iv.tolist():
        if out and out[-1][1] == a:
            out[-1][1] = b
        else:
            out.append([a, b])
    return out


# (zone, windows, first local day of a 3-day grid): DST changes, odd offsets, midnight changes
CASES = [
    ("America/Toronto", [(9.0, 17.0)], (2023, 3, 11)),                 # spring forward at 2:00
    ("America/Toronto", [(0.5, 3.5), (12.0, 12.25), (23.0, 24.0)], (2023, 11, 4)),  # fall back, 1:00-2:00 twice
    ("America/Toronto", [(0.0, 24.0)], (2023, 11, 4)),                 # whole days, the 25-hour one
    ("Europe/Berlin", [(0.0, 2.0), (3.0, 6.5), (6.5, 8.0), (20.75, 24.0)], (2024, 3, 30)),
    ("Australia/Lord_Howe", [(0.25, 1.0), (1.0, 1.5), (2.5, 10.0)], (2024, 4, 6)),  # back to 1:30 at 2:00
    ("Asia/Kolkata", [(9.0, 17.5)], (2024, 1, 31)),                    # +5:30, local days end mid-UTC-hour
    ("Pacific/Chatham", [(2.75, 4.0), (8.25, 12.0), (13.0, 18.75)], (2024, 9, 28)),  # +12:45 -> +13:45 at 2:45
    ("America/Santiago", [(0.0, 1.0), (8.0, 20.0), (22.0, 24.0)], (2023, 9, 2)),  # midnight skipped
    ("America/Santiago", [(0.0, 1.0), (23.0, 24.0)], (2024, 4, 6)),     # 23:00-24:00 twice
    ("UTC", [(0.0, 0.5), (23.5, 24.0)], (2024, 2, 28)),               # leap day in the middle
]


@pytest.mark.parametrize(("zone", "hours", "day"), CASES)
def test_intervals_and_contains_match_a_minute_by_minute_local_clock(
        zone: str, hours: list[tuple[float, float]], day: tuple[int, int, int]) -> None:
    w = DailyWindows(tuple(hours), zone)
    t0 = _utc(zone, *day, 0, 0) - 7 * 3600.0  # starts on the day before, a UTC-minute boundary
    t1 = t0 + 3 * 86400.0
    grid = np.arange(t0, t1, MIN)
    ref = np.array([_inside_reference(t, hours, zone) for t in grid])
    assert ref.any() and not ref.all() or hours == [(0.0, 24.0)]
    got = w.contains(grid)
    assert got.dtype == np.bool_ and got.shape == grid.shape
    np.testing.assert_array_equal(got, ref)

    iv = w.intervals(t0, t1)
    assert iv.dtype == np.float64 and iv.ndim == 2 and iv.shape[1] == 2
    assert np.all(iv[:, 1] > iv[:, 0]) and np.all(iv[1:, 0] >= iv[:-1, 1])
    assert iv.min() >= t0 and iv.max() <= t1
    assert _merged(iv) == _runs(grid, ref, t1)


@pytest.mark.parametrize(("zone", "hours", "day"), CASES)
def test_intervals_clip_at_arbitrary_instants(zone: str, hours: list[tuple[float, float]],
                                              day: tuple[int, int, int]) -> None:
    w = DailyWindows(tuple(hours), zone)
    base = _utc(zone, *day, 0, 0)
    full = w.intervals(base - 2 * 86400.0, base + 5 * 86400.0)
    rng = np.random.default_rng(7)
    edges = full.reshape(-1)
    # random instants, window edges themselves and instants just beside them
    picks = np.concatenate([base + rng.uniform(-86400.0, 3 * 86400.0, 12), edges[2:8], edges[2:8] + 0.25,
                            edges[2:8] - 0.25])
    for t0 in picks:
        for t1 in picks:
            if t1 < t0:
                continue
            ref = [[max(a, t0), min(b, t1)] for a, b in full.tolist() if min(b, t1) > max(a, t0)]
            got = w.intervals(float(t0), float(t1))
            assert got.shape == (len(ref), 2)
            assert got.tolist() == ref


def test_intervals_of_a_zero_span_or_no_window_are_an_empty_k_by_2_array() -> None:
    w = DailyWindows(((9.0, 17.0),), "America/Toronto")
    start = _utc("America/Toronto", 2024, 5, 1, 9, 0)
    for t0, t1 in [(start, start), (start - 3600.0, start), (start + 8 * 3600.0, start + 9 * 3600.0),
                   (start + 3600.0, start + 3600.0)]:
        got = w.intervals(t0, t1)
        assert got.shape == (0, 2) and got.dtype == np.float64
    # a window ending exactly at t0 and the next one starting exactly at t1: nothing in between
    end = start + 8 * 3600.0
    assert w.intervals(end, start + 86400.0).shape == (0, 2)
    assert w.intervals(end, start + 86400.0 + 1.0).tolist() == [[start + 86400.0, start + 86400.0 + 1.0]]


def test_intervals_reach_the_next_midnight_and_fractional_hours() -> None:
    zone = "Asia/Kolkata"
    w = DailyWindows(((9.5, 12.0 + 7.0 / 60.0), (18.0 + 1.0 / 3.0, 24.0)), zone)
    t0 = _utc(zone, 2024, 6, 3, 0, 0)
    got = w.intervals(t0, t0 + 2 * 86400.0)
    ref = []
    for d in (3, 4):
        ref += [[_utc(zone, 2024, 6, d, 9, 30), _utc(zone, 2024, 6, d, 12, 7)],
                [_utc(zone, 2024, 6, d, 18, 20), _utc(zone, 2024, 6, d + 1, 0, 0)]]
    assert got.tolist() == ref


def test_intervals_find_the_window_of_the_first_and_last_local_day() -> None:
    # the window of t0's own local day (its last hour) and of t1's own local day (its first hours), in zones
    # 14 h ahead of and 11 h behind UTC
    zone = "Pacific/Kiritimati"  # UTC+14
    w = DailyWindows(((20.0, 24.0),), zone)
    t0 = _utc(zone, 2024, 6, 3, 23, 0)
    assert w.intervals(t0, t0 + 1800.0).tolist() == [[t0, t0 + 1800.0]]
    zone = "Pacific/Pago_Pago"  # UTC-11
    w = DailyWindows(((0.0, 4.0),), zone)
    t1 = _utc(zone, 2024, 6, 3, 1, 0)
    assert w.intervals(t1 - 1800.0, t1).tolist() == [[t1 - 1800.0, t1]]


def test_intervals_do_not_depend_on_the_machines_zone(monkeypatch: pytest.MonkeyPatch) -> None:
    # local days of the windows' zone read in the machine's zone would be up to two days off here
    # (UTC-12 vs UTC+14: 26 h); the result must not change with the TZ of the process
    import time

    west = DailyWindows(((22.0, 24.0),), "Etc/GMT+12")  # UTC-12
    t0 = _utc("Etc/GMT+12", 2024, 6, 3, 23, 0)  # 2024-06-05 01:00 at UTC+14
    east = DailyWindows(((0.0, 2.0),), "Pacific/Kiritimati")  # UTC+14
    t1 = _utc("Pacific/Kiritimati", 2024, 6, 5, 1, 0)  # 2024-06-03 23:00 at UTC-12
    try:
        for machine in ("XXX-14", "YYY+12", "UTC0"):  # POSIX TZ strings: UTC+14, UTC-12, UTC
            monkeypatch.setenv("TZ", machine)
            time.tzset()
            assert west.intervals(t0, t0 + 1800.0).tolist() == [[t0, t0 + 1800.0]]
            assert east.intervals(t1 - 1800.0, t1).tolist() == [[t1 - 1800.0, t1]]
    finally:
        monkeypatch.undo()
        time.tzset()


def test_intervals_of_integer_instants_are_float_seconds() -> None:
    zone = "Europe/Berlin"
    w = DailyWindows(((9.0, 17.0),), zone)
    t0 = int(_utc(zone, 2024, 7, 1, 10, 0))
    got = w.intervals(t0, t0 + 3600)
    assert got.dtype == np.float64 and got.tolist() == [[float(t0), float(t0 + 3600)]]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 96), min_size=2, max_size=6, unique=True),
       st.sampled_from(["America/Toronto", "Europe/London", "Asia/Kathmandu", "Pacific/Chatham", "UTC"]),
       st.floats(1.5e9, 1.9e9), st.lists(st.floats(0.0, 3 * 86400.0), min_size=1, max_size=40))
def test_contains_is_the_local_hour_inside_a_window(quarters: list[int], zone: str, t0: float,
                                                    offsets: list[float]) -> None:
    q = sorted(quarters)
    hours = [(q[i] / 4.0, q[i + 1] / 4.0) for i in range(0, len(q) - 1, 2)]
    w = DailyWindows(tuple(hours), zone)
    t = np.round(t0 + np.asarray(offsets), 3)
    ref = [_inside_reference(x, hours, zone) for x in t]
    assert w.contains(t).tolist() == ref
    assert w.contains(list(t)).tolist() == ref


def test_contains_of_scalars_nested_and_empty_inputs() -> None:
    zone = "Europe/Berlin"
    w = DailyWindows(((9.0, 17.0),), zone)
    nine = _utc(zone, 2024, 7, 1, 9, 0)
    assert w.contains(nine).tolist() == [True]
    assert w.contains(nine - 0.5).tolist() == [False]
    assert w.contains([[nine - 1.0, nine], [nine + 8 * 3600.0 - 1.0, nine + 8 * 3600.0]]).tolist() == [
        False, True, True, False]
    # the second counts: 16:59:59 is inside, 08:59:59 outside (a minute-only clock says 8.98 and 16.98)
    one = DailyWindows(((8.0 + 59.0 / 60.0 + 59.5 / 3600.0, 16.0 + 59.0 / 60.0 + 30.0 / 3600.0),), zone)
    assert one.contains([nine - 1.0, nine - 31.0, nine + 8 * 3600.0 - 31.0, nine + 8 * 3600.0 - 30.0]).tolist() == [
        False, False, True, False]
    # array-likes are read as float seconds, as the metrics read them: numeric text, integers
    sec = [nine - 1.0, nine, nine + 8 * 3600.0]
    assert w.contains([repr(x) for x in sec]).tolist() == [False, True, False]
    assert w.contains(np.asarray(sec, dtype=np.int64)).tolist() == [False, True, False]
    empty = w.contains([])
    assert empty.shape == (0,) and empty.dtype == np.bool_
    assert w.contains(np.zeros((0, 3))).shape == (0,)


def test_windows_check_their_hours() -> None:
    w = DailyWindows(((9, 12), (12, 17)), "UTC")
    assert w.hours == ((9.0, 12.0), (12.0, 17.0)) and all(type(x) is float for h in w.hours for x in h)
    assert w.source == "configured"
    assert DailyWindows(((0, 24),), "UTC").hours == ((0.0, 24.0),)
    for bad, message in [
        ((), r"^scoring windows: none given$"),
        (((-0.5, 3.0),), r"^scoring window -0\.5-3 h: expected 0 <= start < end <= 24 \(local hours\)$"),
        (((3.0, 24.5),), r"^scoring window 3-24\.5 h: expected 0 <= start < end <= 24 \(local hours\)$"),
        (((5.0, 5.0),), r"^scoring window 5-5 h: expected 0 <= start < end <= 24 \(local hours\)$"),
        (((6.0, 5.0),), r"^scoring window 6-5 h"),
        (((9.0, 12.0), (11.5, 17.0)), r"^scoring windows 09:00-12:00,11:30-17:00: expected sorted, disjoint ranges$"),
        (((1.0, 2.0), (3.0, 4.0), (3.5, 5.0)), r"^scoring windows 01:00-02:00,03:00-04:00,03:30-05:00: expected"),
        (((13.0, 17.0), (9.0, 12.0)), r"^scoring windows 13:00-17:00,09:00-12:00: expected sorted"),
    ]:
        with pytest.raises(EvaluationError, match=message):
            DailyWindows(bad, "UTC")


def test_text_forms() -> None:
    w = DailyWindows(((0.0, 9.5), (13.0 + 1.0 / 3.0, 17.0 + 59.0 / 60.0), (23.75, 24.0)), "America/Toronto",
                     source="the lab's scan steps")
    assert DailyWindows.describe_hours(w.hours) == "00:00-09:30,13:20-17:59,23:45-24:00"
    assert w.describe() == "00:00-09:30,13:20-17:59,23:45-24:00 America/Toronto"
    assert DailyWindows.describe_hours([(8.9999999, 10.00001)]) == "09:00-10:00"
    assert w.to_dict() == {"hours": [[0.0, 9.5], [13.0 + 1.0 / 3.0, 17.0 + 59.0 / 60.0], [23.75, 24.0]],
                           "timezone": "America/Toronto", "source": "the lab's scan steps",
                           "text": "00:00-09:30,13:20-17:59,23:45-24:00 America/Toronto"}


@pytest.mark.parametrize(("text", "hours"), [
    ("9-17", ((9.0, 17.0),)),
    (" 9 - 17 ", ((9.0, 17.0),)),
    ("09:00-12:00,13:00-17:30", ((9.0, 12.0), (13.0, 17.5))),
    ("13:15-17,0-9:45", ((0.0, 9.75), (13.25, 17.0))),  # sorted
    ("0-24", ((0.0, 24.0),)),
    ("23:59-24:00", ((23.0 + 59.0 / 60.0, 24.0),)),
    ("7:05-8", ((7.0 + 5.0 / 60.0, 8.0),)),
])
def test_parse_windows(text: str, hours: tuple[tuple[float, float], ...]) -> None:
    w = parse_windows(text, "Europe/Berlin")
    assert w.hours == hours and w.timezone == "Europe/Berlin" and w.source == "configured"


@pytest.mark.parametrize(("text", "part"), [
    ("9", "9"), ("9-", "9-"), ("-17", "-17"), ("9-17,", ""), ("9:60-17", "9:60-17"), ("25-26", "25-26"),
    ("9-24:30", "9-24:30"), ("9-24:01", "9-24:01"), ("9:5-17", "9:5-17"), ("9am-5pm", "9am-5pm"),
    ("123-130", "123-130"), ("9-17 ,x-3", "x-3"), ("9-25", "9-25"), ("25-26", "25-26"), ("9-12-17", "9-12-17"),
])
def test_parse_windows_refuses_malformed_ranges(text: str, part: str) -> None:
    expected = (f"--windows {text!r}: expected local hour ranges like 9-17 or 09:00-12:00,13:00-17:00, "
                f"got {part!r}")
    with pytest.raises(EvaluationError) as err:
        parse_windows(text, "UTC")
    assert str(err.value) == expected


def test_parse_windows_passes_impossible_ranges_to_the_checks() -> None:
    with pytest.raises(EvaluationError, match=r"^scoring window 17-9 h"):
        parse_windows("17-9", "UTC")
    with pytest.raises(EvaluationError, match=r"^scoring windows 09:00-12:00,11:00-13:00: expected sorted"):
        parse_windows("11-13,9-12", "UTC")


# --- datasets: the lab's scan steps, or the hours the scans cover ------------------------------------------------


def _dataset(zone: str | None, scans: list[tuple[float, float]], extra: dict[str, Any] | None = None) -> Any:
    """A dataset as the functions read it: ``info`` (timezone, extra) and the scans table."""
    table = pd.DataFrame({"scan_id": [f"s{i}" for i in range(len(scans))],
                          "start_stamp_ns": [int(round(a * 1e9)) for a, _ in scans],
                          "end_stamp_ns": [int(round(b * 1e9)) for _, b in scans]})
    return SimpleNamespace(info=SimpleNamespace(timezone=zone, extra=extra or {"generator": "tests"}),
                           df=lambda name: {"scans": table}[name])


def _windows_reference(zone: str, scans: list[tuple[float, float]]) -> tuple[float, float]:
    tz = ZoneInfo(zone)
    starts = [dt.datetime.fromtimestamp(a, tz) for a, _ in scans]
    ends = [dt.datetime.fromtimestamp(b, tz) for _, b in scans]
    lo = min(math.floor(s.hour + s.minute / 60) for s in starts)
    hi = max(e.hour * 3600 + e.minute * 60 + e.second for e in ends) / 3600
    return float(lo), float(math.ceil(hi)) if hi > lo else lo + 1.0


@pytest.mark.parametrize(("zone", "scans"), [
    # local 8:40-9:05 and 16:10-16:59:30 on another day: 8-17
    ("America/Toronto", [((2024, 3, 9, 8, 40, 0), (2024, 3, 9, 9, 5, 0)),
                         ((2024, 3, 11, 16, 10, 0), (2024, 3, 11, 16, 59, 30))]),
    # an end at 17:00:00 exactly stays 17, one at 17:00:30 becomes 18
    ("Europe/Berlin", [((2024, 5, 2, 9, 0, 0), (2024, 5, 2, 17, 0, 0))]),
    ("Europe/Berlin", [((2024, 5, 2, 9, 59, 59), (2024, 5, 2, 17, 0, 30)),
                       ((2024, 5, 3, 10, 0, 0), (2024, 5, 3, 11, 0, 0))]),
    # late scans: the end rounds up to midnight
    ("Asia/Kolkata", [((2024, 1, 5, 21, 15, 0), (2024, 1, 5, 23, 59, 10))]),
    # one scan that is only an instant at 9:00: one hour
    ("UTC", [((2024, 1, 5, 9, 0, 0), (2024, 1, 5, 9, 0, 0))]),
    # a scan across local midnight: the end's hour of day is before the start's, one hour
    ("America/Toronto", [((2024, 1, 5, 23, 30, 0), (2024, 1, 6, 0, 10, 0))]),
])
def test_dataset_windows_are_the_hours_the_scans_cover(zone: str, scans: list[tuple[tuple[int, ...], ...]]) -> None:
    stamps = [(_utc(zone, *a), _utc(zone, *b)) for a, b in scans]
    w = dataset_windows(_dataset(zone, stamps))
    assert w.hours == (_windows_reference(zone, stamps),)
    assert w.timezone == zone and w.source == "the hours the scans cover"


def test_dataset_windows_without_a_zone_are_utc_hours() -> None:
    a = _utc("UTC", 2024, 1, 5, 13, 20)
    for zone in (None, ""):
        w = dataset_windows(_dataset(zone, [(a, a + 3600.0)]))
        assert w.hours == ((13.0, 15.0),) and w.timezone == "UTC"


def test_dataset_windows_of_a_written_dataset(make_dataset: Any) -> None:
    from psg_data.loaders import open_dataset

    root: Path = make_dataset()
    with open_dataset(root) as ds:
        scans = ds.df("scans")
        stamps = [(a / 1e9, b / 1e9) for a, b in zip(scans["start_stamp_ns"], scans["end_stamp_ns"])]
        w = dataset_windows(ds)
        cadence = dataset_cadence_s(ds)
    # three scans 2 h apart from 17:13 local: 17-22 America/Toronto, one cadence of 2 h
    assert w.hours == (_windows_reference("America/Toronto", stamps),) == ((17.0, 22.0),)
    assert cadence == 7200.0


@pytest.mark.parametrize(("scan_hours", "window", "cadence"), [
    (None, (9.0, 17.0), 7200.0),                       # the default lab: 9, 11, 13, 15
    ([], (9.0, 17.0), 7200.0),
    ([15, 9, 13, 11], (9.0, 17.0), 7200.0),
    ([8, 10, 14], (8.0, 17.0), 3 * 3600.0),            # gaps 2 and 4: median 3
    ([9, 10, 13, 15, 23], (9.0, 24.0), 2.5 * 3600.0),  # gaps 1, 3, 2, 8: median 2.5, capped at 24
    ([7.5, 9.0, 9.5, 14.0], (7.5, 15.5), 1.5 * 3600.0),  # gaps 1.5, 0.5, 4.5: median 1.5 (mean 2.17)
    ([10], (10.0, 12.0), 86400.0),                     # one scan a day: a 2 h step, a day's cadence
    (["6", "22"], (6.0, 24.0), 16 * 3600.0),
    ([9, 12], (9.0, 15.0), 3 * 3600.0),
])
def test_the_labs_windows_and_cadence_are_its_scan_steps(scan_hours: list[Any] | None,
                                                         window: tuple[float, float], cadence: float) -> None:
    extra: dict[str, Any] = {"generator": "psg_data.synth"}
    if scan_hours is not None:
        extra["scan_hours"] = scan_hours
        hours = sorted(float(h) for h in scan_hours)
        if len(hours) > 1:  # the expected values from the definition
            step = statistics.median(b - a for a, b in zip(hours, hours[1:]))
            assert window == (hours[0], min(24.0, hours[-1] + step)) and cadence == step * 3600.0
    ds = _dataset("Europe/Berlin", [(0.0, 1.0)], extra)  # the scans are not read
    w = dataset_windows(ds)
    assert w.hours == (window,) and w.timezone == "Europe/Berlin" and w.source == "the lab's scan steps"
    assert dataset_cadence_s(ds) == cadence
    assert dataset_windows(_dataset(None, [(0.0, 1.0)], extra)).timezone == "UTC"


def _cadence_reference(stamps: list[float], zone: str) -> float | None:
    ts = sorted(stamps)
    if len(ts) < 2:
        return None
    days = [dt.datetime.fromtimestamp(t, ZoneInfo(zone)).date() for t in ts]
    gaps = [b - a for a, b, da, db in zip(ts, ts[1:], days, days[1:]) if da == db] or \
        [b - a for a, b in zip(ts, ts[1:])]
    return round(statistics.median(gaps) / 60.0) * 60.0


@pytest.mark.parametrize(("zone", "local"), [
    # Toronto evenings are the next UTC day: local days 20:00, 22:00 | 9:00, 10:00 -> gaps 2 h, 1 h
    ("America/Toronto", [(2024, 1, 5, 20, 0), (2024, 1, 5, 22, 0), (2024, 1, 6, 9, 0), (2024, 1, 6, 10, 0)]),
    # unsorted, an odd number of same-day gaps, a gap rounded to the minute (61.4 min -> 61)
    ("Asia/Kolkata", [(2024, 1, 6, 13, 1), (2024, 1, 6, 9, 0), (2024, 1, 6, 11, 0), (2024, 1, 7, 9, 0)]),
    # one scan a day: no same-day gap, the median of all gaps (days)
    ("Europe/Berlin", [(2024, 1, 5, 9, 0), (2024, 1, 6, 9, 0), (2024, 1, 8, 9, 0)]),
    # one same-day gap (30 min) beside a gap of a day
    ("Europe/Berlin", [(2024, 1, 5, 9, 0), (2024, 1, 5, 9, 30), (2024, 1, 6, 9, 0)]),
    # gaps of 3.5 min: the median rounds to 4 min (to the nearest minute, ties to even as round())
    ("UTC", [(2024, 1, 5, 9, 0), (2024, 1, 5, 9, 3), (2024, 1, 5, 9, 7)]),
    # two scans
    ("UTC", [(2024, 1, 5, 9, 0), (2024, 1, 5, 9, 45)]),
])
def test_cadence_is_the_median_same_day_gap(zone: str, local: list[tuple[int, ...]]) -> None:
    stamps = [_utc(zone, *x) for x in local]
    if zone == "Asia/Kolkata":
        stamps[0] += 24.0  # 13:01:24
    if len(local) == 3 and local[1][4] == 3:
        stamps[1] += 30.0  # 9:03:30, 3.5 min after 9:00 and before 9:07
    ref = _cadence_reference(stamps, zone)
    starts = pd.Series(pd.to_datetime(np.asarray(stamps) * 1e9, utc=True)).dt.tz_convert(zone)
    assert cadence_from_stamps(starts) == ref
    ds = _dataset(zone, [(t, t + 600.0) for t in stamps])
    assert dataset_cadence_s(ds) == ref
    assert ref is not None


def test_cadence_of_the_toronto_case_uses_local_days() -> None:
    zone = "America/Toronto"
    stamps = [_utc(zone, *x) for x in [(2024, 1, 5, 20, 0), (2024, 1, 5, 22, 0), (2024, 1, 6, 9, 0),
                                      (2024, 1, 6, 10, 0)]]
    assert dataset_cadence_s(_dataset(zone, [(t, t + 60.0) for t in stamps])) == 5400.0  # median of 2 h, 1 h
    assert dataset_cadence_s(_dataset(zone, [(t, t + 60.0) for t in stamps[::-1]])) == 5400.0
    assert _cadence_reference(stamps, "UTC") == 7200.0  # UTC days would give a different answer


def test_cadence_of_fewer_than_two_scans_is_none() -> None:
    assert dataset_cadence_s(_dataset("UTC", [(1.7e9, 1.7e9 + 60.0)])) is None
    one = pd.Series(pd.to_datetime([1.7e18], utc=True))
    assert cadence_from_stamps(one) is None
    assert cadence_from_stamps(one.iloc[:0]) is None


# --- durations -------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("text", "seconds"), [
    ("2h", 7200.0), ("90min", 5400.0), ("1d", 86400.0), ("30s", 30.0), ("0", 0.0), ("45", 45.0),
    ("1w", 604800.0), ("3m", 180.0), ("12sec", 12.0), (" 1.5 h ", 5400.0), (".5d", 43200.0), ("2H", 7200.0),
    ("0.25MIN", 15.0), (7200, 7200.0), (0, 0.0), (12.5, 12.5), (True, 1.0),
])
def test_parse_duration(text: str | float, seconds: float) -> None:
    got = parse_duration(text)
    assert got == seconds and type(got) is float


@pytest.mark.parametrize("text", ["", "h", "2 hours", "2y", "-5", "1e3", "2h30", "1,5h", "abc", "5 m s"])
def test_parse_duration_refuses_malformed_text(text: str) -> None:
    with pytest.raises(EvaluationError) as err:
        parse_duration(text)
    assert str(err.value) == f"--horizon {text!r}: expected a duration like 0, 30min, 2h, 1d or 1w"


@pytest.mark.parametrize("value", [-1.0, -1, float("nan"), float("inf"), -float("inf")])
def test_parse_duration_refuses_negative_or_infinite_numbers(value: float) -> None:
    with pytest.raises(EvaluationError) as err:
        parse_duration(value)
    assert str(err.value) == f"horizon {value!r}: expected a non-negative duration"


@pytest.mark.parametrize(("seconds", "text"), [
    (0, "0"), (0.0, "0"), (7200, "2 h"), (5400, "90 min"), (3600, "1 h"), (60, "1 min"), (86400, "1 d"),
    (604800, "1 w"), (2 * 604800, "2 w"), (90000, "25 h"), (8 * 86400, "8 d"), (30, "30 s"), (90.5, "90.5 s"),
    (59, "59 s"), (7200 + 3600 * 5e-10, "2 h"), (7200 + 3600 * 3e-9, "7200 s"), (1e-3, "0.001 s"),
    (3 * 60 + 0.5, "180.5 s"),
])
def test_format_duration(seconds: float, text: str) -> None:
    # expected: the largest of w, d, h, min that divides the duration, else seconds
    assert format_duration(seconds) == text


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 999_999))  # from 10**6 s on, the text is "1e+06 s"
def test_format_duration_reads_back(seconds: int) -> None:
    text = format_duration(seconds)
    number, unit = text.split(" ")
    assert parse_duration(number + unit) == float(seconds)
    k = {"w": 604800, "d": 86400, "h": 3600, "min": 60, "s": 1}[unit]
    bigger = [u for u in (604800, 86400, 3600, 60, 1) if u > k]
    assert seconds % k == 0 and all(seconds % u for u in bigger)
