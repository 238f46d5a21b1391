"""Readers of the FreMEn line of work's long-term state files (Lincoln Centre for Autonomous Systems).

Two public plain-text formats (layouts cited in docs/RAW_FORMATS.md, "Long-term state files"):

``time-value`` (``chronorobotics/framework2`` ``TimeValueLoader.hs``, the door benchmark)
    one sample per line, ``unix_seconds<whitespace>value``, value 0 or 1; the stamps strictly
    increase within a file. The files do not say which state 1 is, nor on which clock the stamps
    are: :func:`read_time_value` returns them as written.

``minute index`` (``gestom/fremen_activity_benchmark`` ``src/main/fremen.cpp``, the Aruba data)
    a ``.min`` file with one integer per line, one line per minute, no stamps; value ``k`` is line
    ``k`` of the ``.names`` file beside it (1-based: fremen.cpp stores ``dummy - 1``).

Both readers refuse a bad file with one :class:`~psg_data.errors.FormatError` naming ``FILE:LINE``
and what was expected; nothing is repaired silently.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import FormatError

__all__ = ["read_time_value", "read_minute_index", "read_names", "MAX_STATE_FILE_BYTES"]

MAX_STATE_FILE_BYTES = 512 * 2**20
"""Largest state file read (512 MiB, about 30 million minute rows); a larger one is refused unread."""


def _lines(path: Path) -> list[str]:
    """The file's lines (UTF-8), refused when it is not a regular file, too large or not text."""
    path = Path(path)
    try:
        if not path.is_file():
            raise FormatError(f"{path}: not a regular file; expected a state file")
        size = path.stat().st_size
        if size > MAX_STATE_FILE_BYTES:
            raise FormatError(f"{path}: {size} bytes, more than the {MAX_STATE_FILE_BYTES} a state file may have")
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(f"{path}: not UTF-8 text (byte {exc.start}); expected a state file") from None
    except OSError as exc:
        raise FormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise FormatError(f"{path}: empty file; expected at least one sample line")
    return lines


def read_time_value(path: str | Path) -> tuple[NDArray[np.float64], NDArray[np.int8]]:
    """A ``time-value`` file: (N,) stamps as written (seconds) and (N,) values 0/1.

    Raises:
        FormatError: ``FILE:LINE`` of the first line that is not two fields, a finite number and
            0 or 1, or whose stamp does not exceed the previous one; an empty file.
    """
    path = Path(path)
    lines = _lines(path)
    t = np.empty(len(lines), dtype=np.float64)
    y = np.empty(len(lines), dtype=np.int8)
    for i, line in enumerate(lines):
        parts = line.split()
        if len(parts) != 2:
            raise FormatError(f"{path}:{i + 1}: expected 'unix_seconds value' (two fields), got {line.strip()[:60]!r}")
        try:
            t[i] = float(parts[0])
        except ValueError:
            raise FormatError(f"{path}:{i + 1}: stamp {parts[0][:30]!r} is not a number of seconds") from None
        if parts[1] not in ("0", "1"):
            raise FormatError(f"{path}:{i + 1}: value {parts[1][:30]!r}; expected 0 or 1")
        y[i] = 1 if parts[1] == "1" else 0
    bad = ~np.isfinite(t)
    if bad.any():
        i = int(np.argmax(bad))
        raise FormatError(f"{path}:{i + 1}: stamp {lines[i].split()[0]!r} is not finite")
    back = np.diff(t) <= 0
    if back.any():
        i = int(np.argmax(back)) + 1
        raise FormatError(f"{path}:{i + 1}: stamp {t[i]:.0f} does not increase (previous line {t[i - 1]:.0f}); "
                          "expected strictly increasing stamps")
    return t, y


def read_names(path: str | Path) -> list[str]:
    """A ``.names`` file: one name per line (whitespace around a name dropped).

    Raises:
        FormatError: an empty file, an empty line or a repeated name, naming ``FILE:LINE``.
    """
    path = Path(path)
    names = [s.strip() for s in _lines(path)]
    seen: dict[str, int] = {}
    for i, n in enumerate(names):
        if not n:
            raise FormatError(f"{path}:{i + 1}: empty name; expected one name per line")
        if n in seen:
            raise FormatError(f"{path}:{i + 1}: name {n!r} repeats line {seen[n] + 1}")
        seen[n] = i
    return names


def read_minute_index(path: str | Path, names_path: str | Path) -> tuple[NDArray[np.int64], list[str]]:
    """A ``.min`` file and its ``.names``: (N,) 0-based indices into the names (minute ``i`` = line ``i + 1``).

    Raises:
        FormatError: ``FILE:LINE`` of the first value that is not an integer in ``1..len(names)``
            (a value beyond the names says which name file was read and how many names it has); an
            empty file.
    """
    path = Path(path)
    names = read_names(names_path)
    lines = _lines(path)
    codes = np.empty(len(lines), dtype=np.int64)
    for i, line in enumerate(lines):
        s = line.strip()
        if not (s.isdigit() and len(s) < 10):
            raise FormatError(f"{path}:{i + 1}: value {s[:30]!r}; expected an integer id 1..{len(names)}")
        codes[i] = int(s)
    bad = (codes < 1) | (codes > len(names))
    if bad.any():
        i = int(np.argmax(bad))
        raise FormatError(f"{path}:{i + 1}: id {codes[i]} is not a line of {names_path} ({len(names)} names); "
                          f"expected 1..{len(names)}")
    return codes - 1, names
