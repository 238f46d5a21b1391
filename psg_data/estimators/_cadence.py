"""Defaults derived from the training streams' cadence (each overridable; every choice is logged).

The Perpetua* paper states its settings per observation of a 60 s stream (forgetting factor
gamma = 0.99 per observation, alpha_0 = 0.01 per minute, 1000 FreMEn periods down to 10 minutes).
Carried over unchanged to a robot that scans a few times a day they mean something else: gamma =
0.99 per scan keeps about 100 scans (weeks) of evidence, and periods shorter than twice the gap
between scans alias. The cadence-derived defaults are stated in time instead, from the *typical
gap* g (median gap between consecutive distinct observation times, pooled over training streams):

- forgetting half-life ``half_life_s = g``: evidence loses half its weight per typical gap, so the
  last observation weighs as much as everything before it (per-observation factor
  ``0.5 ** (dt / half_life_s)``, i.e. gamma = 0.5 at the typical gap, and less across a night);
- annealing ``alpha0 = ln 2 / g`` (per second): at the next regular observation half of the model
  evidence is left, after a night or more almost none, and the switching prior decides;
- FreMEn candidate periods ``one week / k`` no shorter than ``2 g`` (Nyquist): ``n_periods =
  floor(week / 2g)``, at most 1000 (the paper's value);
- profile prior step ``g`` rounded to a whole number of minutes that divides a day.

``PAPER_SETTINGS`` are the paper's Sec. V-A values, used by the persistence benchmark (which
reproduces that section) unless the user sets otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from psg_data.estimators._base import EdgeStream
from psg_data.estimators._fremen import WEEK_S
from psg_data.estimators._hmm import typical_gap_s

__all__ = ["Cadence", "training_cadence", "PAPER_SETTINGS", "MAX_PERIODS"]

MAX_PERIODS = 1000
PAPER_SETTINGS = {"gamma": 0.99, "alpha0": 0.01, "n_periods": 1000}
"""The paper's Sec. V-A values: gamma per observation, alpha0 per minute (time_unit_s = 60), periods."""
_FALLBACK_GAP_S = 3600.0


@dataclass(frozen=True)
class Cadence:
    """Typical gap of the training streams and the defaults derived from it."""

    typical_gap_s: float
    measured: bool  # False when there were too few observations and the fallback (1 h) is used

    @property
    def half_life_s(self) -> float:
        """Default forgetting half-life: one typical gap, seconds."""
        return self.typical_gap_s

    @property
    def alpha0_per_s(self) -> float:
        """Default annealing decay rate: ln 2 per typical gap, per second."""
        return math.log(2.0) / self.typical_gap_s

    @property
    def n_periods(self) -> int:
        """Default number of FreMEn candidate periods: a week down to twice the typical gap (at most 1000)."""
        return int(max(1, min(MAX_PERIODS, math.floor(WEEK_S / (2.0 * self.typical_gap_s)))))

    @property
    def profile_step_s(self) -> float:
        """Default step of the profile prior: the typical gap rounded to a divisor of a day, seconds."""
        minutes = max(1, round(self.typical_gap_s / 60.0))
        divisors = [d for d in range(1, 1441) if 1440 % d == 0]
        return 60.0 * float(min(divisors, key=lambda d: (abs(d - minutes), d)))

    def to_dict(self) -> dict[str, float | bool | int]:
        """A JSON-serialisable dict."""
        return {"typical_gap_s": self.typical_gap_s, "measured": self.measured, "half_life_s": self.half_life_s,
                "alpha0_per_s": self.alpha0_per_s, "n_periods": self.n_periods, "profile_step_s": self.profile_step_s}


def training_cadence(streams: Sequence[EdgeStream]) -> Cadence:
    """The cadence of training streams (fallback gap 1 h when no stream has two observations)."""
    g = typical_gap_s(streams)
    return Cadence(g, True) if g > 0 else Cadence(_FALLBACK_GAP_S, False)
