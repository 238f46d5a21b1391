"""Small files in the published layouts of the two real benchmarks (written by the tests; no real data here).

- the door (``greg_door_2016_min/``): ``training_data.txt`` and ``test_all_K.txt``, one
  ``unix_seconds value`` line per minute (the training file space-separated, the test files
  tab-separated, as published); a door open on weekdays from about 08:30 to 17:30 local time, with
  a seeded random share of minutes flipped;
- the room presence (``aruba_location/``): ``location.min`` (one 1-based id per minute) and
  ``location.names``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

MONDAY = 1451865600  # 2016-01-04 00:00 UTC, the published training file's first stamp


def door_states(t: np.ndarray, rng: np.random.Generator, flip: float = 0.05) -> np.ndarray:
    """1 (open) on weekdays 08:30-17:30 of the stamps read as UTC, with ``flip`` of the minutes flipped."""
    day = ((t // 86400) + 3) % 7  # 1970-01-01 was a Thursday: 0 = Monday
    hod = (t % 86400) / 3600.0
    y = ((day < 5) & (hod >= 8.5) & (hod < 17.5)).astype(np.int64)
    flips = rng.random(t.size) < flip
    return np.where(flips, 1 - y, y)


def write_door(root: Path, *, train_weeks: int = 2, test_weeks: int = 2, seed: int = 0,
               gap_days: tuple[int, int] | None = None, test_gap: bool = False) -> Path:
    """A door benchmark folder under ``root`` (returns ``root``); ``gap_days`` drops training days
    ``[a, b)``; ``test_gap`` drops the second day of the first test week (as published week 4 lacks one)."""
    rng = np.random.default_rng(seed)
    folder = root / "greg_door_2016_min"
    folder.mkdir(parents=True, exist_ok=True)
    t = MONDAY + 60 * np.arange(train_weeks * 7 * 1440)
    if gap_days is not None:
        d = (t - MONDAY) // 86400
        t = t[(d < gap_days[0]) | (d >= gap_days[1])]
    y = door_states(t, rng)
    (folder / "training_data.txt").write_text("".join(f"{a} {b}\n" for a, b in zip(t, y)))
    start = MONDAY + (train_weeks + 1) * 7 * 86400
    for k in range(1, test_weeks + 1):
        tk = start + (k - 1) * 7 * 86400 + 60 * np.arange(7 * 1440 + 1)
        if test_gap and k == 1:
            d = (tk - tk[0]) // 86400
            tk = tk[d != 1]
        yk = door_states(tk, rng)
        (folder / f"test_all_{k}.txt").write_text("".join(f"{a}\t{b}\n" for a, b in zip(tk, yk)))
    return root


ROOMS = ["Bedroom", "Bathroom", "Living_Room", "Kitchen", "Outside"]


def write_rooms(root: Path, *, weeks: int = 4, seed: int = 0, names: list[str] | None = None) -> Path:
    """A room-presence folder under ``root``: bedroom at night, kitchen at meal times, living room else,
    bathroom now and then (ids 1..4; ``Outside`` never, as published)."""
    rng = np.random.default_rng(seed)
    folder = root / "aruba_location"
    folder.mkdir(parents=True, exist_ok=True)
    minute = np.arange(weeks * 7 * 1440)
    hod = (minute % 1440) / 60.0
    room = np.where((hod < 7) | (hod >= 22), 1, 3)
    room = np.where(((hod >= 7) & (hod < 8)) | ((hod >= 18) & (hod < 19)), 4, room)
    room = np.where(rng.random(minute.size) < 0.03, 2, room)
    (folder / "location.min").write_text("".join(f"{v}\n" for v in room))
    (folder / "location.names").write_text("".join(f"{n}\n" for n in (names or ROOMS)))
    return root


def sha256s(root: Path, names: list[str]) -> dict[str, str]:
    """name -> SHA-256 of ``root/name`` (to pin test files as the real ones are pinned)."""
    return {Path(n).name: hashlib.sha256((root / n).read_bytes()).hexdigest() for n in names}
