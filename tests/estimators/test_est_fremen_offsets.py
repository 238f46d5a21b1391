"""FreMEn's UTC-offset table from zoneinfo (a look-up per day, bisection per change) equals the table main
97528cb built with pandas on every 900 s grid time, bit for bit (tests/estimators/_fremen_offsets_reference.py);
and a filter's wall clock no longer imports pandas (a second of every psg-eval worker's start)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.estimators import _fremen
from tests.estimators._fremen_offsets_reference import offset_table

_ZONES = ["America/Toronto", "Europe/London", "Australia/Adelaide", "Asia/Kathmandu", "Pacific/Chatham",
          "America/St_Johns", "Africa/Casablanca", "Asia/Gaza", "America/Sao_Paulo", "Europe/Dublin",
          "Antarctica/Troll", "Australia/Lord_Howe", "Asia/Tehran", "America/Noronha", "Pacific/Apia"]


@pytest.mark.parametrize("zone", _ZONES)
def test_offset_table_equals_pandas_over_2020_2027(zone: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_fremen, "_OFFSET_TABLES", {})
    lo, hi = 1_577_836_800.0, 1_798_761_600.0  # 2020-01-01 .. 2027-01-01 UTC
    trans, offs = _fremen._offset_table(zone, lo, hi)
    a, b, want_trans, want_offs = offset_table(zone, lo, hi)
    assert _fremen._OFFSET_TABLES[zone][:2] == (a, b)
    np.testing.assert_array_equal(trans, want_trans)
    np.testing.assert_array_equal(offs, want_offs)
    assert trans.size > 1 or zone in ("Asia/Kathmandu", "America/Noronha")  # no change since 2020 there


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.sampled_from(_ZONES + ["America/New_York", "Europe/Berlin", "Asia/Kolkata"]),
       st.floats(-2.2e9, 4.0e9), st.floats(0.0, 3e8))
def test_offset_table_equals_pandas_anywhere_1900_2096(zone: str, lo: float, span: float) -> None:
    old = dict(_fremen._OFFSET_TABLES)
    _fremen._OFFSET_TABLES.clear()
    try:
        trans, offs = _fremen._offset_table(zone, lo, lo + span)
    finally:
        _fremen._OFFSET_TABLES.clear()
        _fremen._OFFSET_TABLES.update(old)
    _, _, want_trans, want_offs = offset_table(zone, lo, lo + span)
    np.testing.assert_array_equal(trans, want_trans)
    np.testing.assert_array_equal(offs, want_offs)


def test_wall_clock_does_not_import_pandas() -> None:
    code = ("import sys, numpy as np; from psg_data.estimators._fremen import LocalClock;"
            "c = LocalClock.before(1.74e9, 'America/Toronto'); c(np.array([1.74e9, 1.75e9]));"
            "print('pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
