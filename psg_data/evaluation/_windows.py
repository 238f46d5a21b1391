"""Scoring windows and scan cadence of a dataset.

A dataset is scored only where somebody could look: its *scoring windows* are daily local-time
ranges (the robot's operating hours). Every time integral of the persistence task is bounded by
them (:func:`psg_data.metrics.window_weights`) and navigation queries are drawn inside them.

Where they come from (:func:`dataset_windows`, unless ``--windows`` / ``windows=`` says otherwise):

- a synthetic lab (``psg-data synth``): its bi-hourly steps, from the first scan hour to the end of
  the last step (the default lab: 9:00-17:00 local);
- a dataset whose manifest ``extra`` states ``operating_hours`` (``09:00-17:00``; ``convert`` stores
  the ``operating_hours`` of a site file, which ``psg-data synth --format ros1|...`` writes): those;
- any other dataset: the local hours its scans cover, from the earliest scan start (rounded down
  to the hour) to the latest scan end (rounded up).

The *cadence* (:func:`dataset_cadence_s`) is the typical time between two consecutive scans of a
day (the lab's step, 2 h; otherwise the median gap between consecutive scans of one local day,
rounded to the minute); the persistence task's default forecast horizon is one cadence.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError

__all__ = ["DailyWindows", "parse_windows", "dataset_windows", "dataset_cadence_s", "parse_duration",
           "format_duration"]

_HOUR = re.compile(r"^\s*(\d{1,2})(?::(\d{2}))?\s*$")


@dataclass(frozen=True)
class DailyWindows:
    """Daily local-time scoring windows.

    Attributes:
        hours: ``((lo, hi), ...)`` local hours of the day, ``0 <= lo < hi <= 24``, sorted and
            disjoint (e.g. ``((9.0, 17.0),)``).
        timezone: IANA zone the hours are in.
        source: how they were chosen (stored with the results).
    """

    hours: tuple[tuple[float, float], ...]
    timezone: str
    source: str = "configured"

    def __post_init__(self) -> None:
        hs = tuple((float(lo), float(hi)) for lo, hi in self.hours)
        if not hs:
            raise EvaluationError("scoring windows: none given")
        for lo, hi in hs:
            if not (0.0 <= lo < hi <= 24.0):
                raise EvaluationError(f"scoring window {lo:g}-{hi:g} h: expected 0 <= start < end <= 24 (local hours)")
        for (_, a_hi), (b_lo, _) in zip(hs, hs[1:]):
            if b_lo < a_hi:
                raise EvaluationError(f"scoring windows {self.describe_hours(hs)}: expected sorted, disjoint ranges")
        object.__setattr__(self, "hours", hs)

    @staticmethod
    def describe_hours(hours: Sequence[tuple[float, float]]) -> str:
        """Hour ranges as text, e.g. ``09:00-17:00``."""
        return ",".join(f"{_hhmm(lo)}-{_hhmm(hi)}" for lo, hi in hours)

    def describe(self) -> str:
        """E.g. ``09:00-17:00 America/Toronto``."""
        return f"{self.describe_hours(self.hours)} {self.timezone}"

    def intervals(self, t0_s: float, t1_s: float) -> NDArray[np.float64]:
        """The windows between two instants as a (K, 2) array of ``[start, end]`` UTC seconds (clipped)."""
        from zoneinfo import ZoneInfo

        tz = ZoneInfo(self.timezone)
        d0 = dt.datetime.fromtimestamp(t0_s, tz).date() - dt.timedelta(days=1)
        d1 = dt.datetime.fromtimestamp(t1_s, tz).date() + dt.timedelta(days=1)
        out = []
        day = d0
        while day <= d1:
            for lo, hi in self.hours:
                a, b = _local(day, lo, tz), _local(day, hi, tz)
                a, b = max(a, t0_s), min(b, t1_s)
                if b > a:
                    out.append((a, b))
            day += dt.timedelta(days=1)
        return np.asarray(out, dtype=np.float64).reshape(-1, 2)

    def contains(self, t_s: Any) -> NDArray[np.bool_]:
        """Whether each instant (UTC seconds) falls inside a window (``lo <= local hour < hi``)."""
        import pandas as pd

        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        if t.size == 0:
            return np.zeros(0, bool)
        local = pd.to_datetime(t, unit="s", utc=True).tz_convert(self.timezone)
        hod = local.hour.to_numpy() + local.minute.to_numpy() / 60.0 + local.second.to_numpy() / 3600.0
        out = np.zeros(t.size, bool)
        for lo, hi in self.hours:
            out |= (hod >= lo) & (hod < hi)
        return out

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        return {"hours": [list(h) for h in self.hours], "timezone": self.timezone, "source": self.source,
                "text": self.describe()}


def _hhmm(h: float) -> str:
    m = int(round(h * 60))
    return f"{m // 60:02d}:{m % 60:02d}"


def _local(day: dt.date, hour: float, tz: Any) -> float:
    """UTC seconds of a local wall-clock hour of ``day`` (24 = the next midnight)."""
    base = dt.datetime.combine(day, dt.time(0), tzinfo=tz)
    whole = int(math.floor(hour))
    rest = dt.timedelta(seconds=round((hour - whole) * 3600))
    if whole >= 24:
        return (dt.datetime.combine(day + dt.timedelta(days=1), dt.time(0), tzinfo=tz) + rest).timestamp()
    return (base.replace(hour=whole) + rest).timestamp()


def parse_windows(text: str, timezone: str) -> DailyWindows:
    """``"9-17"``, ``"09:00-12:00,13:00-17:30"`` -> :class:`DailyWindows` (local hours).

    Raises:
        EvaluationError: a malformed range (the message quotes it).
    """
    hours = []
    for part in str(text).split(","):
        lo_s, dash, hi_s = part.partition("-")
        lo, hi = _hour(lo_s), _hour(hi_s)
        if not dash or lo is None or hi is None:
            raise EvaluationError(f"--windows {text!r}: expected local hour ranges like 9-17 or "
                                  "09:00-12:00,13:00-17:00, "
                                  f"got {part.strip()!r}")
        hours.append((lo, hi))
    return DailyWindows(tuple(sorted(hours)), timezone, source="configured")


def _hour(text: str) -> float | None:
    m = _HOUR.match(text)
    if not m:
        return None
    h, mins = int(m.group(1)), int(m.group(2) or 0)
    if mins >= 60 or h > 24 or (h == 24 and mins):
        return None
    return h + mins / 60.0


def _synth_hours(extra: dict[str, Any]) -> tuple[float, float] | None:
    if extra.get("generator") != "psg_data.synth":
        return None
    hours = sorted(float(h) for h in (extra.get("scan_hours") or [9, 11, 13, 15]))
    step = float(np.median(np.diff(hours))) if len(hours) > 1 else 2.0
    return hours[0], min(24.0, hours[-1] + step)


def _scan_local_hours(ds: Any) -> tuple[Any, Any]:
    import pandas as pd

    scans = ds.df("scans")
    tz = ds.info.timezone or "UTC"
    start = pd.to_datetime(scans["start_stamp_ns"], utc=True).dt.tz_convert(tz)
    end = pd.to_datetime(scans["end_stamp_ns"], utc=True).dt.tz_convert(tz)
    return start, end


def dataset_windows(ds: Any) -> DailyWindows:
    """The scoring windows of a dataset (module docstring)."""
    tz = ds.info.timezone or "UTC"
    synth = _synth_hours(dict(ds.info.extra))
    if synth is not None:
        return DailyWindows((synth,), tz, source="the lab's scan steps")
    stated = ds.info.extra.get("operating_hours")
    if isinstance(stated, str) and stated:
        return replace(parse_windows(stated, tz), source="the dataset's operating hours")
    start, end = _scan_local_hours(ds)
    lo = float((start.dt.hour + start.dt.minute / 60.0).min())
    hi = float((end.dt.hour + end.dt.minute / 60.0 + end.dt.second / 3600.0).max())
    lo_h = float(math.floor(lo))
    hi_h = float(min(24.0, math.ceil(hi) if hi > lo_h else lo_h + 1.0))
    return DailyWindows(((lo_h, hi_h),), tz, source="the hours the scans cover")


def dataset_cadence_s(ds: Any) -> float | None:
    """Typical time between two consecutive scans of a day, seconds (module docstring); None for < 2 scans."""
    synth = dict(ds.info.extra)
    if synth.get("generator") == "psg_data.synth":
        hours = sorted(float(h) for h in (synth.get("scan_hours") or [9, 11, 13, 15]))
        return float(np.median(np.diff(hours)) * 3600.0) if len(hours) > 1 else 86400.0
    start, _ = _scan_local_hours(ds)
    return cadence_from_stamps(start)


def cadence_from_stamps(local_starts: Any) -> float | None:
    """Median gap between consecutive scans of one local day (pandas tz-aware timestamps), minutes rounded."""
    s = local_starts.sort_values()
    if len(s) < 2:
        return None
    days = s.dt.date.to_numpy()
    t = s.astype("int64").to_numpy() / 1e9
    gaps = np.diff(t)[days[1:] == days[:-1]]
    if gaps.size == 0:
        gaps = np.diff(t)
    return float(round(float(np.median(gaps)) / 60.0) * 60.0)


_UNITS = {"s": 1.0, "sec": 1.0, "min": 60.0, "m": 60.0, "h": 3600.0, "d": 86400.0, "w": 7 * 86400.0}


def parse_duration(text: str | float) -> float:
    """``"2h"``, ``"90min"``, ``"1d"``, ``"30s"``, ``"0"`` or a number of seconds -> seconds.

    Raises:
        EvaluationError: malformed or negative.
    """
    if isinstance(text, (int, float)):
        value = float(text)
    else:
        m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([a-z]*)\s*", str(text).lower())
        if not m or (m.group(2) and m.group(2) not in _UNITS):
            raise EvaluationError(f"--horizon {text!r}: expected a duration like 0, 30min, 2h, 1d or 1w")
        value = float(m.group(1)) * _UNITS.get(m.group(2) or "s", 1.0)
    if not (math.isfinite(value) and value >= 0):
        raise EvaluationError(f"horizon {text!r}: expected a non-negative duration")
    return value


def format_duration(seconds: float) -> str:
    """``7200 -> '2 h'``, ``5400 -> '90 min'``, ``0 -> '0'``."""
    s = float(seconds)
    if s == 0:
        return "0"
    for unit, k in (("w", 7 * 86400.0), ("d", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if s >= k and abs(s / k - round(s / k)) < 1e-9:
            return f"{int(round(s / k))} {unit}"
    return f"{s:g} s"
