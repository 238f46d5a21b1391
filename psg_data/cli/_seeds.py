"""``--seeds`` / ``--lab-seeds``: a count (``3``: seeds 0, 1, 2) or chosen seeds (``0,3,5``, ``3-7``, ``3-3``)."""

from __future__ import annotations

from typing import Any

import click

__all__ = ["SeedsType", "parse_seeds", "MAX_SEEDS"]

MAX_SEEDS = 100
"""At most this many seeds in one run."""


def parse_seeds(text: str) -> tuple[int, ...]:
    """The seeds ``text`` names: ``N`` is a count (seeds 0..N-1); a list of seeds and inclusive ranges
    (``0,3,5``, ``3-7``, ``0,10-12``; one seed alone: ``3-3``) names them, in the order given.

    Raises:
        ValueError: anything else, a repeated seed, or more than :data:`MAX_SEEDS` seeds.
    """
    s = str(text).strip()
    if s.isdigit():
        n = int(s)
        if not 1 <= n <= MAX_SEEDS:
            raise ValueError(f"a count of seeds must be in 1..{MAX_SEEDS}")
        return tuple(range(n))
    seeds: list[int] = []
    for part in (p.strip() for p in s.split(",")):
        lo, dash, hi = part.partition("-")
        if not lo.strip().isdigit() or (dash and not hi.strip().isdigit()):
            raise ValueError("expected a count (3), a list (0,3,5) or a range (3-7) of seeds >= 0")
        a, b = int(lo), int(hi) if dash else int(lo)
        if b < a:
            raise ValueError(f"range {part}: the end is below the start")
        seeds += range(a, b + 1)
        if len(seeds) > MAX_SEEDS:
            raise ValueError(f"at most {MAX_SEEDS} seeds")
    if len(set(seeds)) != len(seeds):
        raise ValueError("a seed is named twice")
    return tuple(seeds)


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
            self.fail(f"{value!r}: {exc}", param, ctx)
