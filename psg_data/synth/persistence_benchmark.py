"""The paper's Sec. V-A persistence benchmark (eight features, weekly schedule, long-weekend shift).

Layout in time (local weeks starting Monday 00:00 in ``timezone``):

- week 0: validation week (``val_streams``), normal schedule, held out for FreMEn order selection;
- weeks 1 .. train_weeks: training (``train_streams``), normal schedule;
- week train_weeks + 1: test week (``test_streams``); with ``shift="long-weekend"`` Monday and
  Friday follow the weekend pattern (``shift=None``: normal schedule).

Eight features (edges): four static ones (always present) and four semi-static ones with distinct
weekday and weekend patterns (keys on the hallway hook, laptop on the desk, plates on the dinner
table, backpack in the bedroom). Every non-midnight switching time is jittered per day by a
normal offset (sigma ``jitter_min`` minutes, clipped to +-3 sigma).

Observation cadence: a robot observes all features together at intervals drawn uniformly in
[``obs_period_s[0]``, ``obs_period_s[1]``] (10-30 min by default); on each day, with probability
``gap_prob``, a gap of 2-6 hours without observations is inserted. Each observation is flipped
with probability P_M (feature present) or P_F (feature absent).

Ground truth per edge is a dense grid (``grid_s``, 60 s) of 0/1 states for every split. Training
streams carry their ground truth in ``meta['gt_t_s']`` / ``meta['gt_state']`` (used only by oracle
priors or when ground-truth durations are requested). Deterministic for a seed; the random draws do
not depend on ``shift``, so the shifted and unshifted test weeks differ only on Monday and Friday.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import PsgDataError
from psg_data.schemas._streams import EdgeKey, EdgeStream

__all__ = ["PersistenceBenchmark", "make_persistence_benchmark", "BENCHMARK_FEATURES"]

DAY_S = 86400.0
_DAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")

# (weekday intervals, weekend intervals) in local hours; None = static (always present)
BENCHMARK_FEATURES: dict[EdgeKey, tuple[list[tuple[float, float]], list[tuple[float, float]]] | None] = {
    ("sofa", "living_room"): None,
    ("tv", "living_room"): None,
    ("bookshelf", "study"): None,
    ("fridge", "kitchen"): None,
    ("keys", "hallway_hook"): ([(0.0, 7.5), (18.0, 24.0)], [(0.0, 10.0), (13.5, 24.0)]),
    ("laptop", "desk"): ([(8.5, 17.0)], []),
    ("plates", "dinner_table"): ([(17.5, 20.5)], [(11.0, 14.0), (17.0, 21.0)]),
    ("backpack", "bedroom"): ([(0.0, 7.75), (16.5, 24.0)], [(0.0, 24.0)]),
}
_MAX_BOUNDS = 8  # jitter draws per day and feature (fixed, so draws do not depend on the pattern)


@dataclass(frozen=True)
class PersistenceBenchmark:
    """A generated benchmark.

    Attributes:
        train_streams, val_streams, test_streams: observations per edge (Unix seconds).
        train_truth, val_truth, test_truth: edge -> (t_s grid, 0/1 states) dense ground truth.
        timezone: IANA zone of the schedule.
        start_s: Unix time of the validation week's Monday 00:00 (local).
        train_start_s, test_start_s, test_end_s: split boundaries (Unix seconds).
        p_m, p_f: observation noise.
        schedules: edge -> the training weekly schedule as the LLM prompt's output format.
        shift: the test-week shift ("long-weekend" or None).
    """

    train_streams: list[EdgeStream]
    val_streams: list[EdgeStream]
    test_streams: list[EdgeStream]
    train_truth: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int8]]]
    val_truth: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int8]]]
    test_truth: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int8]]]
    timezone: str
    start_s: float
    train_start_s: float
    test_start_s: float
    test_end_s: float
    p_m: float
    p_f: float
    schedules: dict[EdgeKey, list[str]] = field(default_factory=dict)
    shift: str | None = "long-weekend"

    @property
    def edges(self) -> list[EdgeKey]:
        """The benchmark's edges (features), in a fixed order."""
        return list(BENCHMARK_FEATURES)


def _hhmm(h: float) -> str:
    m = int(round(h * 60))
    return f"{m // 60:02d}:{m % 60:02d}"


def _llm_schedule(weekday: list[tuple[float, float]], weekend: list[tuple[float, float]]) -> list[str]:
    out = []
    for d, name in enumerate(_DAYS):
        for a, b in (weekend if d >= 5 else weekday):
            out.append(f"{name}: {_hhmm(a)} - {name}: {_hhmm(b)}")
    return out


def make_persistence_benchmark(*, seed: int = 0, train_weeks: int = 4, shift: str | None = "long-weekend",
                               p_m: float = 0.1, p_f: float = 0.1, obs_period_s: tuple[float, float] = (600.0, 1800.0),
                               gap_prob: float = 0.3, jitter_min: float = 10.0, grid_s: float = 60.0,
                               start_date: str = "2024-01-01", timezone: str = "America/Toronto"
                               ) -> PersistenceBenchmark:
    """Generate the Sec. V-A style benchmark (see the module docstring for layout and cadence).

    Args:
        seed: random seed (jitter, observation times, gaps, noise).
        train_weeks: number of training weeks (4 = one month).
        shift: "long-weekend" (test Monday and Friday follow the weekend) or None.
        p_m: P(y=0 | present), the missed-detection rate.
        p_f: P(y=1 | absent), the false-positive rate.
        obs_period_s: (min, max) seconds between observations.
        gap_prob: per-day probability of a 2-6 h observation gap.
        jitter_min: sigma of the per-day switching-time jitter, minutes.
        grid_s: ground-truth grid step, seconds.
        start_date: a Monday (ISO date) starting the validation week, local time.
        timezone: IANA zone of the schedule.
    """
    _check_arguments(shift, train_weeks, p_m, p_f, start_date)
    zi = ZoneInfo(timezone)
    d0 = _dt.date.fromisoformat(start_date)
    n_days = 7 * (train_weeks + 2)
    midnights = np.array([_dt.datetime.combine(d0 + _dt.timedelta(days=i), _dt.time(0), tzinfo=zi).timestamp()
                          for i in range(n_days + 1)])
    rng = np.random.default_rng(seed)
    edges = list(BENCHMARK_FEATURES)
    jit = np.clip(rng.normal(0.0, jitter_min / 60.0, size=(n_days, len(edges), _MAX_BOUNDS)), -3 * jitter_min / 60,
                  3 * jitter_min / 60)
    test_day0 = 7 * (train_weeks + 1)
    intervals = {e: _presence_intervals(BENCHMARK_FEATURES[e], jit[:, ei], midnights, test_day0, shift)
                 for ei, e in enumerate(edges)}
    obs_t = _observation_times(rng, midnights, obs_period_s, gap_prob)
    u = rng.random((len(edges), obs_t.size))
    grid = np.arange(float(midnights[0]), float(midnights[-1]), grid_s)
    bounds = {"val": (float(midnights[0]), float(midnights[7])),
              "train": (float(midnights[7]), float(midnights[test_day0])),
              "test": (float(midnights[test_day0]), float(midnights[-1]))}
    streams: dict[str, list[EdgeStream]] = {k: [] for k in bounds}
    truth: dict[str, dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int8]]]] = {k: {} for k in bounds}
    for ei, e in enumerate(edges):
        x = _state_at(intervals[e], obs_t)
        flip = np.where(x == 1, u[ei] < p_m, u[ei] < p_f)
        y = np.where(flip, 1 - x, x).astype(np.int8)
        gx = _state_at(intervals[e], grid)
        for k, (a, b) in bounds.items():
            m = (obs_t >= a) & (obs_t < b)
            gm = (grid >= a) & (grid < b)
            truth[k][e] = (grid[gm].copy(), gx[gm].copy())
            meta = {"split": k, "gt_t_s": grid[gm].copy(), "gt_state": gx[gm].copy()} if k == "train" else {"split": k}
            streams[k].append(EdgeStream(e, obs_t[m].copy(), y[m].copy(), meta))
    schedules = {e: _llm_schedule([(0.0, 24.0)], [(0.0, 24.0)]) if spec is None else _llm_schedule(spec[0], spec[1])
                 for e, spec in BENCHMARK_FEATURES.items()}
    return PersistenceBenchmark(
        train_streams=streams["train"], val_streams=streams["val"], test_streams=streams["test"],
        train_truth=truth["train"], val_truth=truth["val"], test_truth=truth["test"], timezone=timezone,
        start_s=bounds["val"][0], train_start_s=bounds["train"][0], test_start_s=bounds["test"][0],
        test_end_s=bounds["test"][1], p_m=p_m, p_f=p_f, schedules=schedules, shift=shift)


def _check_arguments(shift: str | None, train_weeks: int, p_m: float, p_f: float, start_date: str) -> None:
    if shift not in (None, "long-weekend"):
        raise PsgDataError(f"make_persistence_benchmark: shift must be 'long-weekend' or None, got {shift!r}")
    if train_weeks < 1:
        raise PsgDataError(f"make_persistence_benchmark: train_weeks must be >= 1, got {train_weeks}")
    if not (0 <= p_m < 0.5 and 0 <= p_f < 0.5):
        raise PsgDataError("make_persistence_benchmark: p_m and p_f must be in [0, 0.5)")
    if _dt.date.fromisoformat(start_date).weekday() != 0:
        raise PsgDataError(f"make_persistence_benchmark: start_date {start_date} is not a Monday")


def _local_to_unix(midnights: NDArray[np.float64], day: int, hour: float) -> float:
    """Unix time of local ``hour`` (0-24, fractional) of day ``day`` (DST days stretch or shrink)."""
    return float(midnights[day] + hour / 24.0 * (midnights[day + 1] - midnights[day]))


def _presence_intervals(spec: Any, jit: NDArray[np.float64], midnights: NDArray[np.float64], test_day0: int,
                        shift: str | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(starts, ends) Unix seconds of one feature's presence intervals, day by day, their bounds
    jittered by ``jit`` (n_days, _MAX_BOUNDS) hours (midnight bounds stay put).
    """
    starts, ends = [], []
    for day in range(len(midnights) - 1):
        wd = day % 7
        weekend = wd >= 5 or (shift == "long-weekend" and day >= test_day0 and wd in (0, 4))
        pattern = [(0.0, 24.0)] if spec is None else spec[1] if weekend else spec[0]
        for j, (a, b) in enumerate(pattern):
            ja = 0.0 if a in (0.0, 24.0) else jit[day, 2 * j]
            jb = 0.0 if b in (0.0, 24.0) else jit[day, 2 * j + 1]
            starts.append(_local_to_unix(midnights, day, a + ja))
            ends.append(_local_to_unix(midnights, day, b + jb))
    return np.array(starts), np.array(ends)


def _state_at(interval: tuple[NDArray[np.float64], NDArray[np.float64]], t: NDArray[np.float64]) -> NDArray[np.int8]:
    """1 where ``t`` lies in one of the (sorted, disjoint) intervals, else 0."""
    s, en = interval
    if s.size == 0:
        return np.zeros(t.shape, dtype=np.int8)
    i = np.searchsorted(s, t, side="right") - 1
    return ((i >= 0) & (t < en[np.maximum(i, 0)])).astype(np.int8)


def _observation_times(rng: np.random.Generator, midnights: NDArray[np.float64], obs_period_s: tuple[float, float],
                       gap_prob: float) -> NDArray[np.float64]:
    """Observation times: uniform steps in ``obs_period_s`` plus, on a day with probability ``gap_prob``,
    a 2-6 h gap without observations.
    """
    n_days = len(midnights) - 1
    t_start, t_end = float(midnights[0]), float(midnights[-1])
    n_max = int((t_end - t_start) / obs_period_s[0]) + 2
    steps = rng.uniform(obs_period_s[0], obs_period_s[1], size=n_max)
    obs_t = t_start + np.cumsum(steps)
    obs_t = obs_t[obs_t < t_end]
    has_gap = rng.random(n_days) < gap_prob
    gap_start = rng.uniform(0.0, 22.0, n_days)
    gap_len = rng.uniform(2.0, 6.0, n_days)
    keep = np.ones(obs_t.size, dtype=bool)
    for day in np.flatnonzero(has_gap):
        a = _local_to_unix(midnights, int(day), float(gap_start[day]))
        keep &= ~((obs_t >= a) & (obs_t < a + gap_len[day] * 3600.0))
    return obs_t[keep]
