"""Column tables printed as text or CSV without pandas (its import is most of a short command's time).

The text layout is ``pandas.DataFrame.to_string(index=False)``'s and the CSV ``to_csv(index=False)``'s,
so the commands print what they printed through pandas (tests compare both with pandas); one
difference: text cells longer than 50 characters are printed whole (pandas cuts them with ``...``).
A column is a list of ``str``/``None`` (text), ``int`` or ``float`` values (NaN: missing).
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Mapping, Sequence

__all__ = ["columns_to_text", "columns_to_csv", "rounded"]

Column = Sequence[object]
_DIGITS = 6  # pandas' display.precision
_DECIMAL_NUMBER = re.compile(r"^\s*[+-]?[0-9]+\.[0-9]*$")


def rounded(columns: Mapping[str, Column], decimals: Mapping[str, int]) -> dict[str, list[object]]:
    """``columns`` with the float columns named in ``decimals`` rounded as numpy rounds (half to even)."""
    import numpy as np

    out: dict[str, list[object]] = {}
    for name, col in columns.items():
        out[name] = np.round(np.asarray(col, np.float64), decimals[name]).tolist() if name in decimals else list(col)
    return out


def _is_float_column(col: Column) -> bool:
    return any(isinstance(v, float) for v in col) and all(isinstance(v, (float, int)) for v in col)


def _float_cells(col: Column) -> list[str]:
    """The fixed-width float cells of pandas: 6 decimals, trailing zeros trimmed alike; scientific for tiny
    values (and for values above 1e6 whose cells would be longer than 12 characters).
    """
    vals = [float(v) for v in col]  # type: ignore[arg-type]
    finite = [abs(v) for v in vals if not math.isnan(v)]
    cells = _trim_zeros(["NaN" if math.isnan(v) else f"{v:.{_DIGITS}f}" for v in vals])
    too_long = max(len(c) for c in cells) > _DIGITS + 6
    if any(0 < a < 10 ** -_DIGITS for a in finite) or (too_long and any(a > 1e6 for a in finite)):
        return ["NaN" if math.isnan(v) else f"{v:.{_DIGITS}e}" for v in vals]
    return cells


def _trim_zeros(cells: list[str]) -> list[str]:
    """Trailing zeros cut from every decimal number alike while all end in 0, keeping one decimal."""
    number = [_DECIMAL_NUMBER.match(c) is not None for c in cells]
    while any(number) and all(c.endswith("0") for c, k in zip(cells, number) if k):
        cells = [c[:-1] if k else c for c, k in zip(cells, number)]
    return [c + "0" if k and c.endswith(".") else c for c, k in zip(cells, number)]


def _cells(col: Column) -> tuple[list[str], bool]:
    """The column's cells and whether pandas treats it as numeric (its header gets a leading space)."""
    if col and _is_float_column(col):
        return _float_cells(col), True
    if col and all(isinstance(v, int) and not isinstance(v, bool) for v in col):
        return [f"{v:d}" for v in col], True  # type: ignore[str-format]
    missing = "NaN" if any(isinstance(v, str) for v in col) else "None"  # pandas' string columns show NaN
    return [missing if v is None or (isinstance(v, float) and math.isnan(v)) else str(v) for v in col], False


def columns_to_text(columns: Mapping[str, Column]) -> str:
    """The table as ``DataFrame(columns).to_string(index=False)`` prints it (module docstring)."""
    names = list(columns)
    n = len(next(iter(columns.values()))) if columns else 0
    if n == 0:
        return f"Empty DataFrame\nColumns: [{', '.join(names)}]\nIndex: []"
    blocks = []
    for name in names:
        cells, numeric = _cells(columns[name])
        header = " " + name if numeric else name
        width = max(len(header), *(len(c) for c in cells))
        blocks.append([header.rjust(width)] + [c.rjust(width) for c in cells])
    return "\n".join(" ".join(row) for row in zip(*blocks))


def columns_to_csv(columns: Mapping[str, Column]) -> str:
    """The table as ``DataFrame(columns).to_csv(index=False)`` writes it: shortest float repr, NaN/None empty."""
    def cell(v: object) -> object:
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return ""
        return repr(v) if isinstance(v, float) else v

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(columns))
    w.writerows(zip(*([cell(v) for v in col] for col in columns.values())))
    return buf.getvalue()
