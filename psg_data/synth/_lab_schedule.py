"""Schedules of the synthetic lab: hierarchical models of the 21 objects and the 2 doors.

Objects have one of three roles (:data:`psg_data.synth._catalog.OBJECTS`): ``static`` objects never
move; ``dynamic`` objects move between their home receptacle and 2-3 others on workdays (two
workday patterns, switched by a sticky day-level chain) and stay home or visit a weekend spot on
weekends; ``absent`` objects are additionally away from the lab at times (overnight and on
weekends, or borrowed for part of a day). Doors are closed at night, mostly closed on weekends
and close now and then during the workday (door B-C more often than door A-B).
"""

from __future__ import annotations

import datetime as dt
import logging

import numpy as np
from numpy.typing import NDArray

from psg_data.synth._catalog import AFFINITY, ObjectSpec
from psg_data.synth._layout import LabLayout
from psg_data.synth._schedule import (
    WEEKDAYS,
    DenseSchedule,
    EntityModel,
    HourPattern,
    Timeline,
    WeekPattern,
    generate_timeline,
    local_midnights_ns,
)

__all__ = ["LabSchedule", "TimelineSchedule", "object_model", "door_model", "DOOR_OPEN", "DOOR_CLOSED"]

log = logging.getLogger(__name__)

DOOR_OPEN = 0
DOOR_CLOSED = 1
_WEEKDAYS_ONLY = ((0, 1),) * 5


def _affinity(spec: ObjectSpec, layout: LabLayout) -> NDArray[np.float64]:
    table = AFFINITY[spec.kind]
    return np.array([table.get(r.category or "", 0.05) for r in layout.receptacles], float)


def _pick(rng: np.random.Generator, w: NDArray[np.float64], k: int, exclude: set[int]) -> list[int]:
    w = w.copy()
    w[list(exclude)] = 0.0
    out: list[int] = []
    for _ in range(k):
        i = int(rng.choice(w.size, p=w / w.sum()))
        out.append(i)
        w[i] = 0.0
    return out


def _chain(rng: np.random.Generator, name: str, states: list[int], off: int, weights: NDArray[np.float64],
           first: int, window: tuple[tuple[float, float], tuple[float, float]],
           dwell: tuple[float, float, float]) -> HourPattern:
    """A Markov hour pattern over ``states`` whose transition weights follow ``weights``."""
    S = len(states)
    P = np.zeros((S, S))
    for i in range(S):
        row = np.asarray(weights, float) * rng.dirichlet(np.full(S, 2.0))
        row[i] = 0.0
        P[i] = row / row.sum()
    init = np.full(S, 0.3 / max(S - 1, 1))
    init[first] = 0.7 if S > 1 else 1.0
    lo = rng.uniform(dwell[0], dwell[1], S)
    hi = lo + rng.uniform(0.5, dwell[2], S)
    return HourPattern(name, tuple(int(s) for s in states), int(off), window[0], window[1],
                       tuple(float(x) for x in init / init.sum()), tuple(tuple(float(x) for x in r) for r in P),
                       tuple((float(a), float(b)) for a, b in zip(lo, hi)))


def object_model(spec: ObjectSpec, j: int, layout: LabLayout, seed: int) -> EntityModel:
    """The hierarchical schedule model of object ``j`` (receptacle indices; -1 = absent)."""
    rng = np.random.default_rng([int(seed), 301, j])
    w = _affinity(spec, layout)
    home = _pick(rng, w, 1, set())[0]
    regular = WeekPattern("regular", ((1.0,),), ((0,),) * 7)
    if spec.role == "static":
        return EntityModel(spec.name, (HourPattern.constant("static", home),), (regular,))
    others = _pick(rng, w, int(rng.integers(2, 4)), {home})
    states = [home, *others]
    sw = np.array([w[s] for s in states])
    work_window = ((7.5, 9.5), (16.0, 19.0))
    day_T = ((0.7, 0.3, 0.0), (0.3, 0.7, 0.0), (0.5, 0.5, 0.0))
    week = WeekPattern("regular", day_T, _WEEKDAYS_ONLY + ((2,), (2,)))
    if spec.role == "dynamic":
        wa = _chain(rng, "workday_a", states, home, sw, 1, work_window, (1.0, 2.5, 3.0))
        wb = _chain(rng, "workday_b", states, home, sw, 2 if len(states) > 2 else 0, work_window, (1.5, 3.0, 3.0))
        if rng.random() < 0.5:
            wk = HourPattern.constant("weekend", home)
        else:
            spot = _pick(rng, w, 1, set(states))[0]
            wk = _chain(rng, "weekend", [home, spot], home, np.ones(2), 1, ((10.0, 12.0), (15.0, 17.0)),
                        (2.0, 4.0, 2.0))
        return EntityModel(spec.name, (wa, wb, wk), (week,))
    # sometimes absent
    if j % 2 == 1:  # commuter: in the lab during work hours only
        wa = _chain(rng, "workday_a", states, -1, sw, 0, ((8.5, 10.0), (15.5, 18.5)), (1.5, 3.0, 2.0))
        wb = _chain(rng, "workday_b", states, -1, sw, 1, ((8.5, 10.0), (15.5, 18.5)), (1.5, 3.0, 2.0))
        return EntityModel(spec.name, (wa, wb, HourPattern.constant("weekend", -1)), (week,))
    # borrowed: lives in the lab, is away for part of some days
    st = [*states, -1]
    sw2 = np.append(sw, sw.mean())
    wa = _chain(rng, "workday_a", st, home, sw2, len(st) - 1, work_window, (1.0, 2.5, 3.0))
    wb = _chain(rng, "workday_b", st, home, sw2, 1, work_window, (1.0, 2.5, 3.0))
    away = HourPattern.constant("weekend_away", -1)
    at_home = HourPattern.constant("weekend", home)
    week = WeekPattern("regular", ((0.7, 0.3, 0.0, 0.0), (0.3, 0.7, 0.0, 0.0), (0.5, 0.5, 0.0, 0.0),
                                   (0.5, 0.5, 0.0, 0.0)), _WEEKDAYS_ONLY + ((2, 3), (2, 3)))
    return EntityModel(spec.name, (wa, wb, at_home, away), (week,))


def door_model(k: int, door_id: str, seed: int) -> EntityModel:
    """Door ``k``'s model: states 0 = open, 1 = closed."""
    busy = k % 2 == 1  # the second door closes more often during the day
    work = HourPattern("workday", (DOOR_OPEN, DOOR_CLOSED), DOOR_CLOSED, (7.0, 8.75), (17.5, 19.5),
                       (0.6, 0.4) if busy else (0.9, 0.1), ((0.0, 1.0), (1.0, 0.0)),
                       ((1.0, 3.0), (1.0, 3.0)) if busy else ((2.0, 5.0), (0.4, 1.5)))
    closed = HourPattern.constant("weekend_closed", DOOR_CLOSED)
    wk_open = HourPattern("weekend_open", (DOOR_OPEN, DOOR_CLOSED), DOOR_CLOSED, (9.5, 11.0), (14.0, 17.0),
                          (1.0, 0.0), ((0.0, 1.0), (1.0, 0.0)), ((3.0, 6.0), (1.0, 2.0)))
    week = WeekPattern("regular", ((1.0, 0.0, 0.0), (0.6, 0.4, 0.0), (0.6, 0.0, 0.4)),
                       ((0,),) * 5 + ((1, 2), (1, 2)))
    return EntityModel(door_id, (work, closed, wk_open), (week,))


class TimelineSchedule:
    """Queries shared by the lab's schedules: timelines per object / door, state at a time, dense grid.

    Subclasses set ``object_ids``, ``receptacle_ids``, ``door_ids``, ``start_date``, ``start_ns``,
    ``end_ns``, ``objects`` and ``doors`` (entity id -> :class:`Timeline`).
    """

    object_ids: list[str]
    receptacle_ids: list[str]
    door_ids: list[str]
    start_date: dt.date
    start_ns: int
    end_ns: int
    objects: dict[str, Timeline]
    doors: dict[str, Timeline]

    def _set_calendar(self, layout: LabLayout, seed: int, start_date: dt.date, days: int, timezone: str,
                      shifted_days: frozenset[int]) -> None:
        """The attributes every lab schedule has: ids, roles, calendar and day boundaries."""
        self.layout = layout
        self.seed = int(seed)
        self.start_date = start_date
        self.days = int(days)
        self.timezone = timezone
        self.shifted_days = frozenset(shifted_days)
        self.object_ids = layout.object_ids
        self.receptacle_ids = layout.receptacle_ids
        self.door_ids = layout.door_ids
        self.roles = {o.name: o.role for o in layout.objects}
        mid = local_midnights_ns(start_date, days, timezone)
        self.day_starts_ns = mid[:-1]
        self.start_ns, self.end_ns = int(mid[0]), int(mid[-1])

    def weekday_name(self, day: int) -> str:
        return WEEKDAYS[(self.start_date + dt.timedelta(days=day)).weekday()]

    def objects_at(self, stamp_ns: int) -> dict[str, str | None]:
        """``object_id -> receptacle_id`` (None = absent) at ``stamp_ns``."""
        return {o: (None if (s := int(tl.at(stamp_ns))) < 0 else self.receptacle_ids[s])
                for o, tl in self.objects.items()}

    def doors_at(self, stamp_ns: int) -> dict[str, bool]:
        """``door_id -> is_open`` at ``stamp_ns``."""
        return {d: int(tl.at(stamp_ns)) == DOOR_OPEN for d, tl in self.doors.items()}

    def dense(self, step_s: float = 3600.0, start_ns: int | None = None, end_ns: int | None = None
              ) -> DenseSchedule:
        """Ground truth on a regular grid ``[start, end)`` every ``step_s`` seconds (default: hourly, all days)."""
        a = self.start_ns if start_ns is None else int(start_ns)
        b = self.end_ns if end_ns is None else int(end_ns)
        stamps = np.arange(a, b, int(round(step_s * 1e9)), dtype=np.int64)
        objs = np.stack([self.objects[o].at(stamps) for o in self.object_ids], axis=1).astype(np.int16)
        doors = np.stack([self.doors[d].at(stamps) == DOOR_OPEN for d in self.door_ids], axis=1)
        return DenseSchedule(stamps, objs, doors, list(self.object_ids), list(self.receptacle_ids),
                             list(self.door_ids))


class LabSchedule(TimelineSchedule):
    """Ground-truth schedules of the lab's objects and doors (continuous time).

    Args:
        layout: lab geometry (receptacle order defines the state indices).
        seed: lab seed.
        start_date: first local date.
        days: number of days.
        timezone: IANA site timezone.
        shifted_days: day indices that follow the weekend pattern (distribution shift).
    """

    def __init__(self, layout: LabLayout, seed: int, start_date: dt.date, days: int, timezone: str,
                 shifted_days: frozenset[int] = frozenset()) -> None:
        self._set_calendar(layout, seed, start_date, days, timezone, shifted_days)
        self.object_models = {o.name: object_model(o, j, layout, seed) for j, o in enumerate(layout.objects)}
        self.door_models = {d: door_model(k, d, seed) for k, d in enumerate(self.door_ids)}
        self.objects: dict[str, Timeline] = {
            o: generate_timeline(m, j, seed, start_date, days, timezone, self.shifted_days)
            for j, (o, m) in enumerate(self.object_models.items())}
        self.doors: dict[str, Timeline] = {
            d: generate_timeline(m, 1000 + k, seed, start_date, days, timezone, self.shifted_days)
            for k, (d, m) in enumerate(self.door_models.items())}
