"""Times a graph is asked about: Unix seconds, zone-aware datetimes, or site-local strings."""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

import numpy as np

from psg_data.errors import GraphError

__all__ = ["TimeLike", "to_seconds"]

TimeLike = Any
"""Unix seconds (UTC, int or float), a ``datetime`` with a zone (``pandas.Timestamp`` too), a
``numpy.datetime64`` (UTC), or an ISO 8601 string (``"2025-03-20 14:00"``: site-local time unless it
carries an offset or ``Z``)."""


def to_seconds(t: TimeLike, timezone: str) -> float:
    """Unix seconds (UTC) of ``t`` (see :data:`TimeLike`); ``timezone`` (IANA) reads strings without an offset.

    Raises:
        GraphError: a naive ``datetime``, an unreadable string, a non-finite number or another type.
    """
    if isinstance(t, (bool, np.bool_)):
        raise GraphError(f"time {t!r}: expected seconds, a datetime with a zone or an ISO 8601 string")
    if isinstance(t, (int, float, np.integer, np.floating)):
        v = float(t)
        if not math.isfinite(v):
            raise GraphError(f"time {t!r}: expected a finite number of seconds since the epoch (UTC)")
        return v
    if isinstance(t, np.datetime64):
        return float(t.astype("datetime64[ns]").astype(np.int64)) / 1e9
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
