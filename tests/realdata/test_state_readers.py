"""The readers of the real benchmarks' two formats, on files the tests write in the published layouts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psg_data.errors import FormatError
from psg_data.evaluation._state_protocols import PatrolPlan, patrol_streams
from psg_data.loaders.raw import (
    read_door_benchmark,
    read_minute_index,
    read_room_presence_benchmark,
    read_time_value,
)
from psg_data.metrics._time_weights import trapezoid_weights
from tests.realdata._layout import MONDAY, ROOMS, write_door, write_rooms


def test_door_files_read_as_published(tmp_path: Path) -> None:
    write_door(tmp_path, train_weeks=2, test_weeks=2)
    raw = np.loadtxt(tmp_path / "greg_door_2016_min" / "test_all_2.txt")
    b = read_door_benchmark(tmp_path)
    assert b.scored == (("door", "open"),) and set(b.edges) == {("door", "open"), ("door", "closed")}
    t, y = b.periods[1].truth[("door", "open")]
    np.testing.assert_array_equal(t, raw[:, 0])
    np.testing.assert_array_equal(y, raw[:, 1])
    tc, yc = b.periods[1].truth[("door", "closed")]
    np.testing.assert_array_equal(yc, 1 - raw[:, 1])
    assert b.timezone == "UTC" and b.train[("door", "open")][0].size == 2 * 7 * 1440
    swapped = read_door_benchmark(tmp_path, state_one="closed")
    np.testing.assert_array_equal(swapped.periods[1].truth[("door", "open")][1], 1 - raw[:, 1])


def test_a_gap_gets_a_minus_two_row_and_no_weight(tmp_path: Path) -> None:
    write_door(tmp_path, gap_days=(3, 6), test_gap=True)
    b = read_door_benchmark(tmp_path)
    t_train, _ = b.train[("door", "open")]
    assert np.max(np.diff(t_train)) == 3 * 86400 + 60  # the training gap is kept as it is (observations)
    p = b.periods[0]
    t, y = p.truth[("door", "open")]
    assert p.n_rows == 6 * 1440 + 1 and len(p.gaps) == 1
    k = int(np.flatnonzero(y == -2)[0])
    assert np.sum(y == -2) == 1 and t[k] - t[k - 1] == 60.0
    w = trapezoid_weights(t, y >= 0)
    assert w[k] == 0.0
    # the integrated time is the published rows' time: 6 days of minutes, the missing day weighs nothing
    assert np.sum(w) == pytest.approx((6 * 1440 - 1) * 60.0)


def test_dst_shift_patrol_local_hours(tmp_path: Path) -> None:
    """Read as true UTC (stamps=utc), a 09:00 patrol in Lincoln is 09:00 UTC in winter and 08:00 UTC in summer;
    read as wall-clock (the default) it stays at 09:00 of the stamps."""
    folder = tmp_path / "greg_door_2016_min"
    folder.mkdir()
    t = 1458518400 + 60 * np.arange(14 * 1440)  # Mon 2016-03-21 .. 04-03: UK DST starts 2016-03-27 01:00 UTC
    y = ((t % 86400) // 3600 >= 8).astype(int)
    (folder / "training_data.txt").write_text("".join(f"{a} {b}\n" for a, b in zip(t, y)))
    for k in range(1, 10):
        (folder / f"test_all_{k}.txt").write_text("".join(f"{a}\t{b}\n" for a, b in zip(t[:1441], y[:1441])))
    plan = PatrolPlan(9, 9, 1)
    for stamps, hours in (("wall-clock", {9}), ("utc", {8, 9})):
        b = read_door_benchmark(tmp_path, stamps=stamps)
        s = patrol_streams(b.train, plan, b.timezone)[0]
        utc_hours = set(((s.t_s % 86400) // 3600).astype(int).tolist())
        assert utc_hours == hours
        local = pd.to_datetime(s.t_s, unit="s", utc=True).tz_convert(b.timezone)
        assert set(local.hour) == {9} and len(s) == 14


def test_room_presence_is_one_hot(tmp_path: Path) -> None:
    write_rooms(tmp_path, weeks=4)
    b = read_room_presence_benchmark(tmp_path, train_weeks=2)
    assert b.one_hot and len(b.edges) == len(ROOMS) and len(b.periods) == 2
    ys = np.stack([b.periods[0].truth[e][1] for e in b.edges])
    assert np.all(ys.sum(axis=0) == 1)
    codes, names = read_minute_index(tmp_path / "aruba_location" / "location.min",
                                     tmp_path / "aruba_location" / "location.names")
    assert names == ROOMS
    np.testing.assert_array_equal(ys.argmax(axis=0), codes[2 * 7 * 1440: 3 * 7 * 1440])
    t0 = b.periods[0].truth[b.edges[0]][0][0]
    assert t0 == pd.Timestamp("2010-11-04", tz="UTC").value / 1e9 + 2 * 7 * 86400
    assert np.sum(b.train[("resident", "Outside")][1]) == 0


@pytest.mark.parametrize("content, line, what", [
    ("1451865600 0\n1451865660 1\n1451865660 0\n", 3, "does not increase"),
    ("1451865600 0\n1451865660 2\n", 2, "expected 0 or 1"),
    ("1451865600 0\n1451865660\n", 2, "two fields"),
    ("1451865600 0\nabc 1\n", 2, "not a number"),
    ("1451865600 0\nnan 1\n", 2, "not finite"),
    ("", None, "empty file"),
])
def test_bad_time_value_files_name_file_and_line(tmp_path: Path, content: str, line: int | None, what: str) -> None:
    p = tmp_path / "training_data.txt"
    p.write_text(content)
    with pytest.raises(FormatError) as exc:
        read_time_value(p)
    msg = str(exc.value)
    assert what in msg and "\n" not in msg
    assert msg.startswith(f"{p}:{line}:" if line else f"{p}:")


def test_names_with_fewer_names_than_ids(tmp_path: Path) -> None:
    write_rooms(tmp_path, weeks=1, names=["Bedroom", "Bathroom", "Living_Room"])  # id 4 (kitchen) has no name
    folder = tmp_path / "aruba_location"
    first = int(np.flatnonzero(np.loadtxt(folder / "location.min") == 4)[0]) + 1
    with pytest.raises(FormatError, match=rf"location.min:{first}: id 4 is not a line of .*location.names \(3 names\)"):
        read_minute_index(folder / "location.min", folder / "location.names")


@pytest.mark.parametrize("content, line", [("1\n0\n", 2), ("1\nx\n", 2), ("1\n-3\n", 2)])
def test_bad_minute_index_values(tmp_path: Path, content: str, line: int) -> None:
    (tmp_path / "location.min").write_text(content)
    (tmp_path / "location.names").write_text("A\nB\n")
    with pytest.raises(FormatError, match=rf"location.min:{line}: "):
        read_minute_index(tmp_path / "location.min", tmp_path / "location.names")


def test_missing_folder_says_what_is_expected(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="greg_door_2016_min"):
        read_door_benchmark(tmp_path)
    write_rooms(tmp_path, weeks=1)
    with pytest.raises(FormatError, match="train_weeks 1; the file holds 1 whole weeks"):
        read_room_presence_benchmark(tmp_path, train_weeks=1)


def test_monday_constant_is_a_monday() -> None:
    assert pd.Timestamp(MONDAY, unit="s").day_name() == "Monday"
