"""Times a graph is asked about: Unix seconds, zone-aware datetimes, or site-local strings."""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

import numpy as np

from psg_data.errors import GraphError

__all__ = ["TimeLike", "to_seconds", "FIRST_S", "LAST_S"]

_UTC = dt.timezone.utc
FIRST_S = dt.datetime(1, 1, 2, tzinfo=_UTC).timestamp()
"""Earliest time a graph is asked about (0001-01-02 UTC): every local time of it is a valid ``datetime``."""
LAST_S = dt.datetime(9999, 12, 30, tzinfo=_UTC).timestamp()
"""Latest time a graph is asked about (9999-12-30 UTC), likewise."""

TimeLike = Any
"""Unix seconds (UTC, int or float), a ``datetime`` with a zone (``pandas.Timestamp`` too), a
``numpy.datetime64`` (UTC), or an ISO 8601 string (``"2025-03-20 14:00"``: site-local time unless it
carries an offset or ``Z``)."""


def to_seconds(t: TimeLike, timezone: str) -> float:
    """Unix seconds (UTC) of ``t`` (see :data:`TimeLike`); ``timezone`` (IANA) reads strings without an offset.

    Raises:
        GraphError: a naive ``datetime``, an unreadable string, a non-finite number, a time outside
            :data:`FIRST_S` .. :data:`LAST_S` (years 1 to 9999) or another type.
    """
    try:
        v = _seconds(t, timezone)
    except (OverflowError, ValueError) as exc:
        if isinstance(exc, GraphError):
            raise
        v = math.inf
    if not FIRST_S <= v <= LAST_S:
        raise GraphError(f"time {str(t)[:40]!r}: outside the years 1 to 9999; expected a time from "
                         "0001-01-02 to 9999-12-30 (UTC)")
    return v


def _seconds(t: TimeLike, timezone: str) -> float:
    if isinstance(t, (bool, np.bool_)):
        raise GraphError(f"time {t!r}: expected seconds, a datetime with a zone or an ISO 8601 string")
    if isinstance(t, (int, float, np.integer, np.floating)):
        v = float(t)
        if not math.isfinite(v):
            raise GraphError(f"time {t!r}: expected a finite number of seconds since the epoch (UTC)")
        return v
    if isinstance(t, np.datetime64):
        if np.isnat(t):
            raise GraphError(f"time {t!r}: expected a date and time, got NaT")
        d = t.astype("datetime64[us]").astype(object)  # a datetime for years 1 to 9999, else an int
        return d.replace(tzinfo=_UTC).timestamp() if isinstance(d, dt.datetime) else math.inf
    if isinstance(t, str):
        return _from_string(t, timezone)
    if isinstance(t, dt.datetime):
        if t.tzinfo is None or t.tzinfo.utcoffset(t) is None:
            raise GraphError(f"time {t.isoformat()}: a datetime without a zone is ambiguous; give tzinfo (e.g. "
                             f"ZoneInfo({timezone!r})) or a string in site time")
        return t.timestamp()
    raise GraphError(f"time {t!r}: expected seconds, a datetime with a zone or an ISO 8601 string, got "
                     f"{type(t).__name__}")


def _from_string(text: str, timezone: str) -> float:
    s = text.strip()
    try:
        d = dt.datetime.fromisoformat(s[:-1] + "+00:00" if s.endswith(("Z", "z")) else s)
    except ValueError:
        raise GraphError(f"time {text!r}: expected ISO 8601 like '2025-03-20 14:00' (site time, {timezone}) or "
                         "'2025-03-20T14:00+01:00'") from None
    if d.tzinfo is None:
        from zoneinfo import ZoneInfo

        d = d.replace(tzinfo=ZoneInfo(timezone))
    return d.timestamp()
