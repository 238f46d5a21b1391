"""The offset table of FreMEn's wall clock as main 97528cb built it (pandas on the whole 900 s grid),
kept as the reference of tests/estimators/test_est_fremen_offsets.py."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._fremen import _PANDAS_FIRST_S, _PANDAS_LAST_S


def pandas_offsets(t: NDArray[np.float64], timezone: str) -> NDArray[np.float64]:
    import pandas as pd

    ns = np.round(t * 1e9).astype(np.int64)
    try:
        idx = pd.DatetimeIndex(ns.view("datetime64[ns]")).tz_localize("UTC").tz_convert(timezone)
    except Exception as exc:  # unknown zone names raise several pandas/zoneinfo errors
        raise EstimatorError(f"unknown timezone {timezone!r}: {exc}") from exc
    return (idx.tz_localize(None).asi8 - ns).astype(np.float64) / 1e9


def offset_table(timezone: str, lo: float, hi: float
                 ) -> tuple[float, float, NDArray[np.float64], NDArray[np.float64]]:
    """(a, b, transition times, offsets) of a fresh table covering [lo, hi] (no cache)."""
    a = max(math.floor(lo / 900.0) * 900.0 - 400 * 86400.0, _PANDAS_FIRST_S)
    b = min(math.ceil(hi / 900.0) * 900.0 + 400 * 86400.0, _PANDAS_LAST_S)
    grid = np.arange(a, b + 900.0, 900.0)  # zone transitions happen on quarter hours
    off = pandas_offsets(grid, timezone)
    ch = np.flatnonzero(np.diff(off) != 0) + 1
    trans = np.concatenate([[-np.inf], grid[ch]])
    offs = np.concatenate([[off[0]], off[ch]])
    return a, b, trans, offs
