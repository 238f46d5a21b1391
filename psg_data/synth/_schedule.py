"""Hierarchical Markov schedules (paper appendix "Hierarchical Scheduling Model").

Every entity (an object, or a door) follows a three-level model:

* **week level**: a Markov chain over *week patterns* (``week_transition``), one step per
  calendar week (Monday 00:00 local);
* **day level**: each week pattern has one transition matrix over *day patterns*, restricted per
  weekday by an ``allowed`` mask (e.g. Saturday/Sunday only allow the weekend pattern), one step
  per local day;
* **hour level**: each day pattern has one transition matrix over the entity's states
  (receptacles or "absent" for objects, open/closed for doors). Outside an activity window
  ``[start, end)`` (hours of the local day, both drawn from uniform ranges every day) the entity is
  in the pattern's ``off_state``; inside, it starts from ``initial`` and stays in each state for a
  duration drawn from the state's uniform range ``dwell_h`` before jumping according to the matrix.

The result is a continuous-time, piecewise-constant timeline (``change_ns``, ``states``) per entity.
State ``-1`` of an object means absent. The transition weights of object patterns come from
object-receptacle affinities (:data:`psg_data.synth._catalog.AFFINITY`), following
Kurenkov et al. (2023) as the paper does.

Randomness is drawn from streams keyed by ``(seed, entity, day)``, so a distribution shift that
forces some days to another pattern changes exactly those days.
"""

from __future__ import annotations

import datetime as dt
import logging
import zoneinfo
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["HourPattern", "WeekPattern", "EntityModel", "Timeline", "DenseSchedule", "generate_timeline",
           "local_midnights_ns", "SHIFTS", "WEEKDAYS"]

log = logging.getLogger(__name__)

WEEKDAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")
SHIFTS = ("long-weekend",)
"""Supported distribution shifts: ``long-weekend`` makes chosen weekdays of the test days follow the
weekend (Saturday) day patterns."""

_HOUR_NS = 3_600_000_000_000


@dataclass(frozen=True)
class HourPattern:
    """Hour-level pattern (one day pattern): an activity window and a Markov chain inside it.

    Attributes:
        name: pattern name (``workday``, ``weekend``, ...).
        states: state values (receptacle index, -1 = absent; or door state 0 open / 1 closed).
        off_state: state outside the activity window.
        window_start_h: uniform range (lo, hi) of the window start, local hours.
        window_end_h: uniform range (lo, hi) of the window end, local hours.
        initial: (S,) probabilities of the first state at the window start.
        transition: (S, S) row-stochastic transition matrix (zero diagonal unless S == 1).
        dwell_h: (S, 2) uniform range of the stay in each state, hours.
    """

    name: str
    states: tuple[int, ...]
    off_state: int
    window_start_h: tuple[float, float] = (8.0, 9.0)
    window_end_h: tuple[float, float] = (17.0, 19.0)
    initial: tuple[float, ...] = ()
    transition: tuple[tuple[float, ...], ...] = ()
    dwell_h: tuple[tuple[float, float], ...] = ()

    @staticmethod
    def constant(name: str, state: int) -> HourPattern:
        """A pattern that stays in ``state`` all day."""
        return HourPattern(name, (state,), state, (0.0, 0.0), (0.0, 0.0), (1.0,), ((1.0,),), ((24.0, 24.0),))


@dataclass(frozen=True)
class WeekPattern:
    """Day-level model of one week pattern.

    Attributes:
        name: week pattern name.
        day_transition: (P, P) transition matrix over the entity's day patterns.
        allowed: 7 tuples (Mon..Sun) of the day-pattern indices allowed on that weekday.
    """

    name: str
    day_transition: tuple[tuple[float, ...], ...]
    allowed: tuple[tuple[int, ...], ...]


@dataclass(frozen=True)
class EntityModel:
    """The hierarchical schedule model of one entity (object or door)."""

    key: str
    day_patterns: tuple[HourPattern, ...]
    week_patterns: tuple[WeekPattern, ...]
    week_transition: tuple[tuple[float, ...], ...] = ((1.0,),)
    weekend_pattern_days: tuple[int, ...] = (5,)
    """Weekdays whose allowed day patterns a shifted day uses (5 = Saturday)."""


@dataclass
class Timeline:
    """Piecewise-constant state of one entity: ``states[i]`` holds on ``[change_ns[i], change_ns[i+1])``.

    Attributes:
        change_ns: (K,) increasing int64 UTC nanoseconds; the first is the start of the first day.
        states: (K,) int states.
        day_patterns: name of the day pattern of every day.
        week_patterns: name of the week pattern of every day.
    """

    change_ns: NDArray[np.int64]
    states: NDArray[np.int64]
    day_patterns: list[str] = field(default_factory=list)
    week_patterns: list[str] = field(default_factory=list)

    def at(self, stamp_ns: NDArray[np.int64] | int) -> NDArray[np.int64]:
        """State at each stamp (the first state before the start)."""
        i = np.searchsorted(self.change_ns, np.asarray(stamp_ns, np.int64), side="right") - 1
        return self.states[np.clip(i, 0, None)]


@dataclass
class DenseSchedule:
    """Ground truth sampled on a regular grid.

    Attributes:
        stamps_ns: (T,) int64 UTC nanoseconds.
        objects: (T, O) receptacle index into ``receptacle_ids`` per object, -1 = absent.
        doors_open: (T, D) bool, True = open.
        object_ids, receptacle_ids, door_ids: column / value labels.
    """

    stamps_ns: NDArray[np.int64]
    objects: NDArray[np.int16]
    doors_open: NDArray[np.bool_]
    object_ids: list[str]
    receptacle_ids: list[str]
    door_ids: list[str]

    def presence(self) -> NDArray[np.bool_]:
        """(T, O, R) one-hot presence of each object on each receptacle."""
        R = len(self.receptacle_ids)
        out = np.zeros((*self.objects.shape, R), bool)
        t, o = np.nonzero(self.objects >= 0)
        out[t, o, self.objects[t, o]] = True
        return out

    def to_frame(self):
        """Long pandas DataFrame: stamp_ns, object_id, receptacle_id (None = absent)."""
        import pandas as pd

        T, O = self.objects.shape
        rec = np.array(list(self.receptacle_ids) + [None], dtype=object)
        return pd.DataFrame({
            "stamp_ns": np.repeat(self.stamps_ns, O),
            "object_id": np.tile(np.array(self.object_ids, dtype=object), T),
            "receptacle_id": rec[self.objects.reshape(-1).astype(np.int64)],
        })


def local_midnights_ns(start_date: dt.date, days: int, tz: str) -> NDArray[np.int64]:
    """UTC ns of local midnight of ``days + 1`` consecutive dates from ``start_date`` (DST-aware)."""
    zone = zoneinfo.ZoneInfo(tz)
    out = []
    for d in range(days + 1):
        day = start_date + dt.timedelta(days=d)
        out.append(_ns(dt.datetime(day.year, day.month, day.day, tzinfo=zone)))
    return np.asarray(out, np.int64)


def _ns(t: dt.datetime) -> int:
    return int(round(t.timestamp())) * 1_000_000_000 + t.microsecond * 1000


def local_time_ns(day: dt.date, hours: float, tz: str) -> int:
    """UTC ns of local wall-clock time ``hours`` after midnight of ``day`` (wall-clock, DST-aware)."""
    zone = zoneinfo.ZoneInfo(tz)
    base = dt.datetime(day.year, day.month, day.day, tzinfo=zone)
    wall = base + dt.timedelta(seconds=round(hours * 3600.0))
    return int(wall.timestamp()) * 1_000_000_000


def _choice(rng: np.random.Generator, p: NDArray[np.float64]) -> int:
    p = np.asarray(p, float)
    s = p.sum()
    if s <= 0:
        return int(rng.integers(p.size))
    return int(rng.choice(p.size, p=p / s))


def _day_segments(pat: HourPattern, day: dt.date, day0: int, day1: int, tz: str, rng: np.random.Generator
                  ) -> list[tuple[int, int]]:
    ws = rng.uniform(*pat.window_start_h)
    we = rng.uniform(*pat.window_end_h)
    segs = [(day0, pat.off_state)]
    if we <= ws or len(pat.states) == 0:
        return segs
    t0, t1 = local_time_ns(day, ws, tz), min(local_time_ns(day, we, tz), day1)
    P = np.asarray(pat.transition, float)
    dwell = np.asarray(pat.dwell_h, float)
    s = _choice(rng, np.asarray(pat.initial, float))
    t = t0
    while t < t1:
        segs.append((t, pat.states[s]))
        t += int(rng.uniform(dwell[s, 0], dwell[s, 1]) * _HOUR_NS)
        if len(pat.states) > 1:
            s = _choice(rng, P[s])
    if t1 < day1:
        segs.append((t1, pat.off_state))
    return segs


def generate_timeline(model: EntityModel, entity_index: int, seed: int, start_date: dt.date, days: int, tz: str,
                      shifted_days: frozenset[int] = frozenset()) -> Timeline:
    """Sample the timeline of one entity over ``days`` local days from ``start_date``.

    Args:
        model: the entity's hierarchical model.
        entity_index: index used to key the random streams.
        seed: lab seed.
        start_date: first local date (the timeline starts at its local midnight).
        days: number of days.
        tz: IANA timezone of the site.
        shifted_days: day indices that follow the weekend day patterns (distribution shift).
    """
    mid = local_midnights_ns(start_date, days, tz)
    chain_rng = np.random.default_rng([int(seed), 201, entity_index])
    Pw = np.asarray(model.week_transition, float)
    week = _choice(chain_rng, np.ones(len(model.week_patterns)) if Pw.shape[0] > 1 else np.ones(1))
    day_pat: list[int] = []
    week_names: list[str] = []
    prev = -1
    for d in range(days):
        date = start_date + dt.timedelta(days=d)
        wd = date.weekday()
        if d > 0 and wd == 0:
            week = _choice(chain_rng, Pw[week])
        wp = model.week_patterns[week]
        allowed = np.zeros(len(model.day_patterns))
        allowed[list(wp.allowed[wd])] = 1.0
        row = np.asarray(wp.day_transition, float)[prev] if prev >= 0 else np.ones(len(model.day_patterns))
        p = _choice(chain_rng, row * allowed if (row * allowed).sum() > 0 else allowed)
        prev = p
        day_pat.append(p)
        week_names.append(wp.name)
    names: list[str] = []
    change: list[int] = []
    states: list[int] = []
    for d in range(days):
        date = start_date + dt.timedelta(days=d)
        p = day_pat[d]
        if d in shifted_days:
            wp = next(w for w in model.week_patterns if w.name == week_names[d])
            wk_allowed = sorted({i for wd in model.weekend_pattern_days for i in wp.allowed[wd]})
            srng = np.random.default_rng([int(seed), 203, entity_index, d])
            p = wk_allowed[int(srng.integers(len(wk_allowed)))]
        names.append(model.day_patterns[p].name)
        rng = np.random.default_rng([int(seed), 202, entity_index, d, p])
        for t, s in _day_segments(model.day_patterns[p], date, int(mid[d]), int(mid[d + 1]), tz, rng):
            if states and states[-1] == s:
                continue
            if change and t <= change[-1]:  # zero-length window edge: replace the last state
                states[-1] = s
                continue
            change.append(t)
            states.append(s)
    keep = [0] + [i for i in range(1, len(states)) if states[i] != states[i - 1]]
    return Timeline(np.asarray(change, np.int64)[keep], np.asarray(states, np.int64)[keep], names, week_names)
