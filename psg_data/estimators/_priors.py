"""Switching priors f(t) = p_t(M = emergence) for Perpetua* (paper eqs. 9-10).

f(t) is the prior probability that the feature is present at t. Each prior is a small frozen
object, vectorised over Unix times (s), serialisable with ``to_dict`` / :func:`prior_from_dict`:

- :class:`ConstantPrior` (``prior="none"``: 0.5, no information);
- :class:`FremenPrior`: the saturated FreMEn reconstruction (eq. 9);
- :class:`SchedulePrior`: piecewise constant over the week, e.g. parsed from an LLM answer (eq. 10);
- :class:`OraclePrior`: a step function on a week grid from the training ground truth;
- :class:`ProfilePrior`: eq. 10's piecewise-constant form learned from the training observations
  (``prior="profile"``): one value per (day type, step of the day).
"""

from __future__ import annotations

import ast
import math
import re
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import EstimatorError
from psg_data.estimators._fremen import WEEK_S, FremenComponents, LocalClock

__all__ = ["SwitchingPrior", "ConstantPrior", "FremenPrior", "SchedulePrior", "OraclePrior", "ProfilePrior",
           "PROFILE_DAYS", "prior_from_dict",
           "parse_llm_schedule", "render_llm_prompt", "LLM_PROMPT_TEMPLATE", "DAYS"]

DAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")


class SwitchingPrior(Protocol):
    def __call__(self, t_s: ArrayLike) -> NDArray[np.float64]: ...

    def to_dict(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class ConstantPrior:
    value: float = 0.5

    def __call__(self, t_s: ArrayLike) -> NDArray[np.float64]:
        return np.full(np.shape(t_s), float(np.clip(self.value, 0.0, 1.0)))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        return {"kind": "constant", "value": self.value}


@dataclass(frozen=True)
class FremenPrior:
    components: FremenComponents
    clock: LocalClock

    def __call__(self, t_s: ArrayLike) -> NDArray[np.float64]:
        return self.components.predict(self.clock(t_s))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        return {"kind": "fremen", "components": self.components.to_dict(), "clock": self.clock.to_dict()}


@dataclass(frozen=True)
class SchedulePrior:
    """Piecewise constant weekly prior: ``inside`` within any interval, ``outside`` elsewhere.

    Attributes:
        intervals: (R, 2) [start, end) in seconds since local Monday 00:00; end < start wraps
            around Sunday/Monday.
        inside, outside: the values a_r (one value for all intervals) and the background.
        timezone: IANA zone of the wall-clock schedule.
    """

    intervals: tuple[tuple[float, float], ...]
    inside: float = 1.0
    outside: float = 0.0
    timezone: str = "UTC"

    def __call__(self, t_s: ArrayLike) -> NDArray[np.float64]:
        t = np.asarray(t_s, dtype=np.float64)
        clock = LocalClock(self.timezone, 0.0)
        # wall seconds since 1970-01-01 (a Thursday) -> seconds since a Monday
        ph = np.mod(clock(t) + 3 * 86400.0, WEEK_S)
        inside = np.zeros(t.shape, dtype=bool)
        for a, b in self.intervals:
            inside |= ((ph >= a) & (ph < b)) if a <= b else ((ph >= a) | (ph < b))
        return np.where(inside, float(self.inside), float(self.outside))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        return {"kind": "schedule", "intervals": [list(iv) for iv in self.intervals], "inside": self.inside,
                "outside": self.outside, "timezone": self.timezone}


@dataclass(frozen=True)
class OraclePrior:
    """Step function over the week: ``values[i]`` on [i*bin_s, (i+1)*bin_s) after the reference epoch."""

    values: tuple[float, ...]
    bin_s: float
    clock: LocalClock

    def __call__(self, t_s: ArrayLike) -> NDArray[np.float64]:
        v = np.asarray(self.values, dtype=np.float64)
        ph = np.mod(self.clock(t_s), WEEK_S)
        i = np.minimum((ph / self.bin_s).astype(np.int64), v.size - 1)
        return v[i]

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        return {"kind": "oracle", "values": list(self.values), "bin_s": self.bin_s, "clock": self.clock.to_dict()}

    @classmethod
    def from_ground_truth(cls, t_s: ArrayLike, state: ArrayLike, clock: LocalClock, bin_s: float = 60.0) -> OraclePrior:
        """Fold a dense ground-truth grid onto the week: each bin holds the fraction of time present."""
        t = np.asarray(t_s, dtype=np.float64)
        x = np.asarray(state, dtype=np.float64)
        nb = int(round(WEEK_S / bin_s))
        i = np.minimum((np.mod(clock(t), WEEK_S) / bin_s).astype(np.int64), nb - 1)
        cnt = np.bincount(i, minlength=nb).astype(np.float64)
        tot = np.bincount(i, weights=x, minlength=nb)
        mean = float(x.mean()) if x.size else 0.5
        vals = np.where(cnt > 0, tot / np.maximum(cnt, 1), np.nan)
        if np.isnan(vals).any():  # fill empty bins with the previous bin's value (step function)
            idx = np.where(~np.isnan(vals), np.arange(nb), 0)
            np.maximum.accumulate(idx, out=idx)
            vals = np.where(np.isnan(vals[idx]), mean, vals[idx])
        return cls(tuple(float(v) for v in vals), float(bin_s), clock)


PROFILE_DAYS = ("workweek", "all", "weekday")
"""Day types of :class:`ProfilePrior`: Mon-Fri / Sat-Sun, one type, or each weekday its own."""


def _day_type(weekday: NDArray[np.int64], days: str) -> NDArray[np.int64]:
    if days == "workweek":
        return (weekday >= 5).astype(np.int64)
    if days == "all":
        return np.zeros_like(weekday)
    return weekday


@dataclass(frozen=True)
class ProfilePrior:
    """Piecewise constant in (local day type, step of the local day): the eq. 10 form, learned.

    ``values[d][s]`` holds on day type d (see :data:`PROFILE_DAYS`) during the s-th step of
    ``step_s`` seconds after local midnight. :meth:`fit` sets each value to the fraction of
    present observations in that cell, smoothed toward the edge's overall fraction with
    ``pseudo_count`` observations (cells without data get that fraction).
    """

    values: tuple[tuple[float, ...], ...]
    step_s: float
    days: str
    timezone: str = "UTC"

    def _cell(self, t_s: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        t = np.asarray(t_s, dtype=np.float64)
        wall = LocalClock(self.timezone, 0.0)(t)
        day = np.floor(wall / 86400.0)
        weekday = np.mod(day + 3, 7).astype(np.int64)  # 1970-01-01 was a Thursday
        n_steps = len(self.values[0])
        step = np.minimum(((wall - day * 86400.0) / self.step_s).astype(np.int64), n_steps - 1)
        return _day_type(weekday, self.days), step

    def __call__(self, t_s: ArrayLike) -> NDArray[np.float64]:
        d, s = self._cell(t_s)
        return np.asarray(self.values, dtype=np.float64)[d, s]

    @classmethod
    def fit(cls, t_s: ArrayLike, y: ArrayLike, *, step_s: float, days: str = "workweek", timezone: str = "UTC",
            pseudo_count: float = 1.0) -> ProfilePrior:
        """Learn the profile from observations ``y`` (0/1) at Unix times ``t_s``."""
        if days not in PROFILE_DAYS:
            raise EstimatorError(f"profile prior: days must be one of {', '.join(PROFILE_DAYS)}, got {days!r}")
        if not (0 < step_s <= 86400.0):
            raise EstimatorError(f"profile prior: step_s must be in (0, 86400], got {step_s}")
        n_days = {"workweek": 2, "all": 1, "weekday": 7}[days]
        n_steps = int(math.ceil(86400.0 / step_s))
        blank = cls(tuple((0.5,) * n_steps for _ in range(n_days)), float(step_s), days, timezone)
        yy = np.asarray(y, dtype=np.float64).reshape(-1)
        if yy.size == 0:
            return blank
        d, s = blank._cell(t_s)
        idx = d.reshape(-1) * n_steps + s.reshape(-1)
        cnt = np.bincount(idx, minlength=n_days * n_steps)
        tot = np.bincount(idx, weights=yy, minlength=n_days * n_steps)
        base = float(yy.mean())
        a = float(pseudo_count)
        v = np.where(cnt > 0, (tot + a * base) / np.maximum(cnt + a, 1e-300), base).reshape(n_days, n_steps)
        return cls(tuple(tuple(float(x) for x in row) for row in v), float(step_s), days, timezone)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict."""
        return {"kind": "profile", "values": [list(r) for r in self.values], "step_s": self.step_s, "days": self.days,
                "timezone": self.timezone}


def prior_from_dict(d: dict[str, Any]) -> SwitchingPrior:
    kind = d.get("kind")
    if kind == "constant":
        return ConstantPrior(float(d["value"]))
    if kind == "fremen":
        return FremenPrior(FremenComponents.from_dict(d["components"]), LocalClock.from_dict(d["clock"]))
    if kind == "schedule":
        return SchedulePrior(tuple((float(a), float(b)) for a, b in d["intervals"]), float(d["inside"]),
                             float(d["outside"]), d["timezone"])
    if kind == "oracle":
        return OraclePrior(tuple(float(v) for v in d["values"]), float(d["bin_s"]), LocalClock.from_dict(d["clock"]))
    if kind == "profile":
        return ProfilePrior(tuple(tuple(float(x) for x in r) for r in d["values"]), float(d["step_s"]), d["days"],
                            d["timezone"])
    raise EstimatorError(f"unknown switching prior kind {kind!r}; valid: constant, fremen, schedule, oracle, profile")


_ITEM = re.compile(r"^\s*(Mon|Tue|Wed|Thu|Fri|Sat|Sun)\s*:\s*(\d{1,2}):(\d{2})\s*-\s*"
                   r"(Mon|Tue|Wed|Thu|Fri|Sat|Sun)\s*:\s*(\d{1,2}):(\d{2})\s*$")


def parse_llm_schedule(text: str) -> tuple[tuple[float, float], ...]:
    """Parse the LLM prompt's output format into weekly intervals.

    Accepts the exact format the prompt asks for, ``['Mon: 19:00 - Mon: 19:30', ...]``, optionally
    preceded by ``Schedule:`` and surrounded by other text or a code fence.

    Returns:
        ((start, end), ...) in seconds since Monday 00:00 (end < start wraps around the week;
        '24:00' is allowed as an end).

    Raises:
        EstimatorError: if no list is found or an entry does not match 'Day: HH:MM - Day: HH:MM'.
    """
    i, j = text.find("["), text.rfind("]")
    if i < 0 or j < i:
        raise EstimatorError("LLM schedule: no Python list found, expected ['Day: HH:MM - Day: HH:MM', ...]")
    try:
        items = ast.literal_eval(text[i:j + 1])
    except (ValueError, SyntaxError) as exc:
        raise EstimatorError(f"LLM schedule: not a Python list of strings: {exc}") from exc
    if not isinstance(items, (list, tuple)) or not all(isinstance(s, str) for s in items):
        raise EstimatorError("LLM schedule: expected a list of strings 'Day: HH:MM - Day: HH:MM'")
    out: list[tuple[float, float]] = []
    for k, s in enumerate(items):
        m = _ITEM.match(s)
        if not m:
            raise EstimatorError(f"LLM schedule: entry {k} {s!r} does not match 'Day: HH:MM - Day: HH:MM'")
        d0, h0, m0, d1, h1, m1 = m.groups()
        vals = []
        for d, h, mi in ((d0, h0, m0), (d1, h1, m1)):
            hh, mm = int(h), int(mi)
            if hh > 24 or mm > 59 or (hh == 24 and mm != 0):
                raise EstimatorError(f"LLM schedule: entry {k} {s!r} has an invalid time {h}:{mi}")
            vals.append(DAYS.index(d) * 86400.0 + hh * 3600.0 + mm * 60.0)
        a, b = vals[0] % WEEK_S, vals[1] % WEEK_S
        out.append((a, b))
    return tuple(out)


LLM_PROMPT_TEMPLATE = """Consider a household environment composed of two parents and two children. The environment contains various objects located in different places, where objects can appear when needed for an activity (e.g., plates for eating) or disappear when taken by a member (e.g., keys/bags when leaving). During weekdays, the parents typically leave for work in the morning and return in the evening (07:30 - 18:00), while the children attend school during the day (08:00 - 17:00). On weekends, the family tends to stay home more often, engaging in activities such as cooking, cleaning, and leisure time together.

Task: Generate a weekly schedule (Mon-Sun) for the specific object at the specific location.

Output Rules:
- Output ONLY a Python list of strings.
- Format: ['Day: HH:MM - Day: HH:MM', 'Day: HH:MM - Day: HH:MM', ...]
- Use 3-letter day abbreviations (Mon, Tue, Wed, Thu, Fri, Sat, Sun).

Example 1:
Input:
    Object: Plates
    Location: On Dinner Table
    Type: Active Location (appear when used)
Output:
    Schedule: ['Mon: 19:00 - Mon: 19:30', 'Tue: 19:00 - Tue: 19:30', ... , 'Sun: 18:00 - Sun: 18:30']

Current task:
Input:
    Object: {object_name}
    Location: {object_location}
    Type: {object_type}
Output:
    Schedule: [...]
"""


def render_llm_prompt(object_name: str, location: str, object_type: str = "Active Location (appear when used)") -> str:
    """The paper's switching-prior prompt (appendix) for one object/receptacle pair.

    Args:
        object_name: e.g. "Keys".
        location: e.g. "On Hallway Hook".
        object_type: "Active Location (appear when used)" or e.g. "Storage Location (disappear when used)".
    """
    return LLM_PROMPT_TEMPLATE.format(object_name=object_name, object_location=location, object_type=object_type)
