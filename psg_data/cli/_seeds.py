"""``--seeds`` / ``--lab-seeds``: a count (``3``: seeds 0, 1, 2) or chosen seeds (``0,3,5``, ``3-7``, ``3-3``)."""

from __future__ import annotations

from typing import Any

import click

__all__ = ["SeedsType", "parse_seeds", "MAX_SEEDS", "MAX_SEED"]

MAX_SEEDS = 100
"""At most this many seeds in one run."""
MAX_SEED = 2**32 - 1
"""Largest seed (numpy's legacy generators take seeds below 2^32)."""


def parse_seeds(text: str) -> tuple[int, ...]:
    """The seeds ``text`` names: ``N`` is a count (seeds 0..N-1); a list of seeds and inclusive ranges
    (``0,3,5``, ``3-7``, ``0,10-12``; one seed alone: ``3-3``) names them, in the order given.

    Raises:
        ValueError: anything else, a repeated seed, a seed above :data:`MAX_SEED` or more than
            :data:`MAX_SEEDS` seeds (counted before any list is built).
    """
    s = str(text).strip()
    if s.isdigit():
        n = _seed(s)
        if not 1 <= n <= MAX_SEEDS:
            raise ValueError(f"a count of seeds must be in 1..{MAX_SEEDS}")
        return tuple(range(n))
    seeds: list[int] = []
    for part in (p.strip() for p in s.split(",")):
        lo, dash, hi = part.partition("-")
        if not lo.strip().isdigit() or (dash and not hi.strip().isdigit()):
            raise ValueError("expected a count (3), a list (0,3,5) or a range (3-7) of seeds >= 0")
        a, b = _seed(lo), _seed(hi) if dash else _seed(lo)
        if b < a:
            raise ValueError(f"range {part}: the end is below the start")
        if len(seeds) + (b - a + 1) > MAX_SEEDS:  # counted before any list is built
            raise ValueError(f"at most {MAX_SEEDS} seeds")
        seeds += range(a, b + 1)
    if len(set(seeds)) != len(seeds):
        raise ValueError("a seed is named twice")
    return tuple(seeds)


def _seed(digits: str) -> int:
    """A seed (or a count) of at most :data:`MAX_SEED` written as decimal ``digits``."""
    d = digits.strip().lstrip("0") or "0"
    if len(d) > len(str(MAX_SEED)) or int(d) > MAX_SEED:
        raise ValueError(f"a seed is at most {MAX_SEED} (2^32 - 1)")
    return int(d)


class SeedsType(click.ParamType):
    """A click type for :func:`parse_seeds` (a bad value is a usage error, exit 2)."""

    name = "seeds"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> tuple[int, ...]:
        """The seeds as a tuple of ints."""
        if isinstance(value, tuple):
            return value
        try:
            return parse_seeds(value)
        except ValueError as exc:
            self.fail(f"{str(value)[:40]!r}: {exc}", param, ctx)
