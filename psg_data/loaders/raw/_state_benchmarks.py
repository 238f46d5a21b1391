"""The two public real long-term benchmarks as psg-data edges: dense training rows and test periods.

- :func:`read_door_benchmark`: the office door of ``chronorobotics/framework2``
  (``greg_door_2016_min/``: ``training_data.txt``, ``test_all_1..9.txt``): one door, edges
  ``(door, 'open')`` and ``(door, 'closed')`` (the door streams of docs/FORMAT.md); the ``open``
  edge is the one scored (the other is its complement). ``state_one`` says which state a 1 is and
  ``stamps`` on which clock the stamps are (defaults from what the data show: 1 = open, local
  wall-clock time written as UTC; docs/RAW_FORMATS.md).
- :func:`read_room_presence_benchmark`: the Aruba smart home of
  ``gestom/fremen_activity_benchmark`` (``data/aruba/location.min`` / ``.names``): one "object"
  (the resident) on one "receptacle" per room name, exactly one present at a time.

The ground truth of a test period is its rows as published (one per minute). Where two rows are
more than 1.5 sample steps apart, a row with code -2 (unobserved) is inserted one step after the
first: the time integrals of psg-data's metrics skip every interval with an excluded end, so a gap
gets no weight and nothing is invented; a day that the files repeat (door test week 4 ends with
the day that opens week 5) counts in each week that holds it, as in the authors' per-week means.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import FormatError
from psg_data.loaders.raw._state_files import read_minute_index, read_time_value
from psg_data.schemas._streams import EdgeKey, EdgeStream

__all__ = ["StatePeriod", "StateBenchmark", "read_door_benchmark", "read_room_presence_benchmark",
           "DOOR_FOLDER", "DOOR_FILES", "ROOM_FOLDER", "ROOM_FILES", "DOOR_ID", "RESIDENT_ID", "GAP_CODE",
           "STAMP_CLOCKS"]

DOOR_FOLDER = "greg_door_2016_min"
DOOR_FILES = ("training_data.txt", *(f"test_all_{k}.txt" for k in range(1, 10)))
ROOM_FOLDER = "aruba_location"
ROOM_FILES = ("location.min", "location.names")
DOOR_ID = "door"
RESIDENT_ID = "resident"
GAP_CODE = -2
"""Ground-truth code of the row inserted after a gap (unobserved: excluded from every metric)."""
STAMP_CLOCKS = {"wall-clock": "local wall-clock time written as if UTC (the estimators' clock is UTC)",
                "utc": "true UTC (local time is the site's time zone)"}
"""How the door's stamps are read (``stamps=``)."""

Truth = dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]]


@dataclass(frozen=True)
class StatePeriod:
    """One test period (a week) of a benchmark.

    Attributes:
        label: ``"week 1"`` ...
        truth: edge -> (t_s, state) per published row, seconds (UTC stamps), with a -2 row after each gap.
        source: the file (or line range) it comes from.
        n_rows: published rows in the period.
        gaps: gaps inside the period, as (start_s, end_s) of the missing span.
    """

    label: str
    truth: Truth
    source: str
    n_rows: int
    gaps: tuple[tuple[float, float], ...] = ()

    @property
    def start_s(self) -> float:
        """First row's time, seconds."""
        return float(min(t[0] for t, _ in self.truth.values()))

    @property
    def end_s(self) -> float:
        """Last row's time, seconds."""
        return float(max(t[-1] for t, _ in self.truth.values()))


@dataclass(frozen=True)
class StateBenchmark:
    """A dense real benchmark: training rows and test periods per edge.

    Attributes:
        name: ``door-benchmark`` or ``room-presence-benchmark``.
        edges: every edge (object_id, receptacle_id), or (door_id, state) for a door.
        scored: the edges the benchmark scores.
        train: edge -> (t_s, y) of the training rows (one per minute), seconds and 0/1.
        periods: the test periods.
        timezone: the site clock on which estimators read local time (``UTC`` when the stamps are
            local wall-clock time written as UTC).
        one_hot: exactly one receptacle holds the object at any time (room presence).
        sample_s: the rows' spacing, seconds.
        info: provenance: source, clock, state mapping, split.
    """

    name: str
    edges: tuple[EdgeKey, ...]
    scored: tuple[EdgeKey, ...]
    train: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int8]]]
    periods: tuple[StatePeriod, ...]
    timezone: str
    one_hot: bool = False
    sample_s: float = 60.0
    info: dict[str, Any] = field(default_factory=dict)

    def train_streams(self) -> list[EdgeStream]:
        """The training rows of every edge as observation streams (the dense protocol's training data)."""
        return [EdgeStream(e, t, y) for e, (t, y) in self.train.items()]


def _with_gap_codes(t: NDArray[np.float64], y: NDArray[np.int64], step_s: float
                    ) -> tuple[NDArray[np.float64], NDArray[np.int64], list[tuple[float, float]]]:
    """Rows with a -2 row one step after each gap longer than 1.5 steps; and the gaps."""
    gap = np.flatnonzero(np.diff(t) > 1.5 * step_s)
    if gap.size == 0:
        return t, y.astype(np.int64), []
    t2 = np.insert(t, gap + 1, t[gap] + step_s)
    y2 = np.insert(y.astype(np.int64), gap + 1, GAP_CODE)
    return t2, y2, [(float(t[i] + step_s), float(t[i + 1])) for i in gap]


def _door_states(y: NDArray[np.int8], state_one: str) -> dict[str, NDArray[np.int8]]:
    one = y.astype(np.int8)
    other = (1 - one).astype(np.int8)
    return {"open": one, "closed": other} if state_one == "open" else {"open": other, "closed": one}


def _check_choice(what: str, value: str, allowed: Any) -> None:
    if value not in allowed:
        raise FormatError(f"{what} {value!r}; expected one of {', '.join(allowed)}")


def read_door_benchmark(root: str | Path, *, state_one: str = "open", stamps: str = "wall-clock",
                        site_timezone: str = "Europe/London") -> StateBenchmark:
    """The door benchmark from ``root`` (a folder holding ``greg_door_2016_min/`` or the files themselves).

    The test weeks are ``test_all_1.txt``, ``test_all_2.txt``, ... up to the first missing number (the
    published folder has 1..9; the fetched or ``$PSG_DATA_SOURCES`` copy is checked to hold all nine).

    Args:
        root: the folder.
        state_one: which door state a 1 in the files is (``open``: what the data show).
        stamps: ``wall-clock`` (default: the stamps are local wall-clock time written as UTC, which
            reproduces the authors' numbers; estimators read local time as UTC) or ``utc`` (true
            UTC; estimators read local time in ``site_timezone``).
        site_timezone: the door's time zone (Lincoln, UK), used with ``stamps="utc"``.
    """
    _check_choice("door state_one", state_one, ("open", "closed"))
    _check_choice("door stamps", stamps, tuple(STAMP_CLOCKS))
    folder = _folder(Path(root), DOOR_FOLDER, DOOR_FILES[0])
    t, y = read_time_value(folder / DOOR_FILES[0])
    train = {(DOOR_ID, s): (t, v) for s, v in _door_states(y, state_one).items()}
    periods = []
    names = [n for n in DOOR_FILES[1:] if (folder / n).exists()]
    names = names[:next((i for i, n in enumerate(names) if n != DOOR_FILES[1 + i]), len(names))]
    if not names:
        raise FormatError(f"{folder}: no test_all_1.txt; expected the test weeks test_all_1.txt .. test_all_9.txt")
    for k, name in enumerate(names, 1):
        tk, yk = read_time_value(folder / name)
        truth: Truth = {}
        gaps: list[tuple[float, float]] = []
        for s, v in _door_states(yk, state_one).items():
            t2, y2, gaps = _with_gap_codes(tk, v.astype(np.int64), 60.0)
            truth[(DOOR_ID, s)] = (t2, y2)
        periods.append(StatePeriod(f"week {k}", truth, name, int(tk.size), tuple(gaps)))
    tz = "UTC" if stamps == "wall-clock" else site_timezone
    info = {"dataset": "door-benchmark", "source": "chronorobotics/framework2 greg_door_2016_min",
            "folder": str(folder), "state_one": state_one, "stamps": stamps, "clock": STAMP_CLOCKS[stamps],
            "timezone": tz, "split": f"training_data.txt train; test_all_1..{len(names)}.txt, one week each, test",
            "train_rows": int(t.size)}
    return StateBenchmark("door-benchmark", ((DOOR_ID, "open"), (DOOR_ID, "closed")), ((DOOR_ID, "open"),),
                          train, tuple(periods), tz, False, 60.0, info)


def _folder(root: Path, sub: str, probe: str) -> Path:
    if (root / sub / probe).is_file():
        return root / sub
    if (root / probe).is_file():
        return root
    raise FormatError(f"{root}: neither {root / sub / probe} nor {root / probe} exists; expected the benchmark's "
                      f"folder {sub}/ as published")


def read_room_presence_benchmark(root: str | Path, *, start: str = "2010-11-04", train_weeks: int = 8
                                 ) -> StateBenchmark:
    """The room-presence benchmark from ``root`` (a folder holding ``aruba_location/`` or the files).

    The ``.min`` file has no stamps: line ``i`` is minute ``i`` after midnight of ``start`` (local
    wall-clock time written as UTC; 2010-11-04 is the first day of the same recording in
    ``chronorobotics/temporal_model_transfer``). The first ``train_weeks`` whole weeks train, every
    following whole week is a test period (16 weeks: 8 and 8); a trailing partial week is dropped.
    """
    import pandas as pd

    folder = _folder(Path(root), ROOM_FOLDER, ROOM_FILES[0])
    codes, names = read_minute_index(folder / ROOM_FILES[0], folder / ROOM_FILES[1])
    try:
        t0 = float(pd.Timestamp(start, tz="UTC").value // 10**9)
    except (ValueError, TypeError):
        raise FormatError(f"room start {start!r}; expected a date such as 2010-11-04") from None
    week = 7 * 1440
    n_weeks = codes.size // week
    if not 1 <= train_weeks < n_weeks:
        raise FormatError(f"room train_weeks {train_weeks}; the file holds {n_weeks} whole weeks, so expected "
                          f"1..{n_weeks - 1}")
    t = t0 + 60.0 * np.arange(codes.size, dtype=np.float64)
    edges = tuple((RESIDENT_ID, n) for n in names)
    cut = train_weeks * week
    train = {e: (t[:cut], (codes[:cut] == k).astype(np.int8)) for k, e in enumerate(edges)}
    periods = []
    for w in range(train_weeks, n_weeks):
        sl = slice(w * week, (w + 1) * week)
        truth: Truth = {e: (t[sl], (codes[sl] == k).astype(np.int64)) for k, e in enumerate(edges)}
        periods.append(StatePeriod(f"week {w + 1}", truth, f"{ROOM_FILES[0]} lines {sl.start + 1}-{sl.stop}",
                                   week))
    seen = np.bincount(codes, minlength=len(names))
    info = {"dataset": "room-presence-benchmark", "source": "gestom/fremen_activity_benchmark data/aruba",
            "folder": str(folder), "start": start, "clock": "local wall-clock time written as UTC (no stamps: "
            "line i is minute i after the start day's midnight)", "timezone": "UTC",
            "split": f"weeks 1-{train_weeks} train, weeks {train_weeks + 1}-{n_weeks} test (one period each)",
            "rooms": names, "minutes_per_room": seen.tolist(), "dropped_rows": int(codes.size - n_weeks * week)}
    return StateBenchmark("room-presence-benchmark", edges, edges, train, tuple(periods), "UTC", True, 60.0, info)
