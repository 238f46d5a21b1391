"""The generator-model format (``generator/process.json``): the step process behind the v2 lab schedules.

This module owns the format (the records, their JSON form, the structural checks and the loader);
sampling paths and exact inference over the model live in :mod:`psg_data.synth._process`.

Time is a sequence of *steps*: every local day has ``K`` steps starting at ``step_hours`` (local
wall-clock hours, the scan intervals: 09, 11, 13, 15 for the lab, so delta t = 2 h); the state of
the last step of a day holds through the night until the first step of the next day. An entity
(an object, or a door) changes state only at a step boundary.

Per entity (all arrays are stored with the dataset, see docs/FORMAT.md):

* **day level**: ``D`` day patterns with one transition matrix ``pattern_transition`` (D, D) and
  a calendar mask ``pattern_allowed`` (7, D) (weekdays Mon..Sun): the pattern of day ``d`` is
  drawn at the first step of the day from row ``p_{d-1}`` of the matrix restricted to the
  patterns allowed on that weekday (renormalised; ``pattern_initial`` for day 0). Shifted days
  (``shifted_days``) use Saturday's mask.
* **hour level**: the latent state is (state ``s``, remaining dwell ``r`` >= 1, in steps). At the
  boundary into slot ``k`` of a day with pattern ``p``:

  - with probability ``rho = routine_strength[p, k]`` the *routine* acts: the entity is put on
    ``routine[p, k]`` (a stay if it is already there) and a fresh dwell is drawn;
  - otherwise the entity's own semi-Markov dynamics go on: if ``r > 1`` it stays and ``r`` drops
    by one; if ``r == 1`` it jumps to ``s'`` with probability ``jump[p, s, s']`` (self-transitions
    allowed) and draws a fresh dwell.

  Fresh dwells are uniform on the whole steps ``dwell[p, s', 0] .. dwell[p, s', 1]``. Before the
  first boundary the state is drawn from ``state_initial`` with ``r = 1``.

``rho = 0`` is an affinity-weighted random walk with stays of hours or days; ``rho = 1`` is a
clockwork routine (the state is ``routine[p, k]`` at every step). Because the model is a Markov
chain over (pattern, state, dwell), the posterior given observations is computed exactly by the
forward algorithm (:class:`ForwardBelief`).
"""


from __future__ import annotations

import datetime as dt
import json
import math
import zoneinfo
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import PsgDataError
from psg_data.schemas._paths import inside_dataset, real_root

__all__ = ["EntityProcess", "StepProcess", "StepClock", "PROCESS_FORMAT", "PROCESS_VERSION", "PROCESS_FILE",
           "WEEKDAYS", "SATURDAY", "load_process", "normalize_rows"]

PROCESS_FORMAT = "psg-step-process"
PROCESS_VERSION = 1
PROCESS_FILE = "generator/process.json"
"""Path of the process file inside a dataset (listed in ``tables/files.parquet``)."""

WEEKDAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")
SATURDAY = 5


def normalize_rows(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """``p`` scaled to sum to 1 along its last axis; rows without mass become zeros."""
    s = p.sum(axis=-1, keepdims=True)
    return np.where(s > 0, p / np.where(s > 0, s, 1.0), 0.0)


@dataclass(eq=False)
class EntityProcess:
    """The step process of one entity (see the module docstring for the kernel).

    Attributes:
        entity_id: object id or door id.
        kind: ``object`` or ``door``.
        role: free-form role (``static``, ``dynamic``, ``absent``, ``door``).
        states: state labels: receptacle ids (None = absent) or door states ``open`` / ``closed``.
        patterns: names of the D day patterns.
        pattern_allowed: (7, D) bool, patterns allowed on each weekday (Mon..Sun).
        pattern_initial: (D,) distribution of day 0's pattern (before the mask).
        pattern_transition: (D, D) row-stochastic day-level matrix.
        state_initial: (S,) distribution of the state before the first step.
        routine: (D, K) int, the routine state of every slot.
        routine_strength: (D, K) probability that the routine acts at the boundary into the slot.
        jump: (D, S, S) row-stochastic jump matrices (when a dwell runs out).
        dwell: (D, S, 2) int, inclusive range of a fresh dwell, steps (1 <= lo <= hi).
    """

    entity_id: str
    kind: str
    role: str
    states: tuple[str | None, ...]
    patterns: tuple[str, ...]
    pattern_allowed: NDArray[np.bool_]
    pattern_initial: NDArray[np.float64]
    pattern_transition: NDArray[np.float64]
    state_initial: NDArray[np.float64]
    routine: NDArray[np.int64]
    routine_strength: NDArray[np.float64]
    jump: NDArray[np.float64]
    dwell: NDArray[np.int64]

    def __post_init__(self) -> None:
        self.pattern_allowed = np.asarray(self.pattern_allowed, bool)
        self.pattern_initial = np.asarray(self.pattern_initial, np.float64)
        self.pattern_transition = np.asarray(self.pattern_transition, np.float64)
        self.state_initial = np.asarray(self.state_initial, np.float64)
        self.routine = np.asarray(self.routine, np.int64)
        self.routine_strength = np.asarray(self.routine_strength, np.float64)
        self.jump = np.asarray(self.jump, np.float64)
        self.dwell = np.asarray(self.dwell, np.int64)
        self.states = tuple(self.states)
        self.patterns = tuple(self.patterns)

    @property
    def n_states(self) -> int:
        """Number of states."""
        return len(self.states)

    @property
    def n_patterns(self) -> int:
        """Number of day patterns."""
        return len(self.patterns)

    @property
    def max_dwell(self) -> int:
        """Longest dwell, in steps."""
        return int(self.dwell[..., 1].max())

    def state_index(self, label: str | None) -> int:
        """Index of a state label (-1 if the entity never takes it)."""
        try:
            return self.states.index(label)
        except ValueError:
            return -1

    def dwell_pmf(self) -> NDArray[np.float64]:
        """(D, S, R) probability of a fresh dwell of r = 1..R steps."""
        R = self.max_dwell
        r = np.arange(1, R + 1)
        lo, hi = self.dwell[..., 0:1], self.dwell[..., 1:2]
        inside = (r >= lo) & (r <= hi)
        return inside / (hi - lo + 1)

    def to_dict(self) -> dict[str, Any]:
        """The entity as a JSON-ready dictionary."""
        return {
            "entity_id": self.entity_id, "kind": self.kind, "role": self.role, "states": list(self.states),
            "patterns": list(self.patterns), "pattern_allowed": self.pattern_allowed.astype(int).tolist(),
            "pattern_initial": _floats(self.pattern_initial), "pattern_transition": _floats(self.pattern_transition),
            "state_initial": _floats(self.state_initial), "routine": self.routine.tolist(),
            "routine_strength": _floats(self.routine_strength), "jump": _floats(self.jump),
            "dwell": self.dwell.tolist(),
        }

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> EntityProcess:
        """An entity from :meth:`to_dict`'s dictionary."""
        return EntityProcess(
            str(d["entity_id"]), str(d["kind"]), str(d.get("role", "")), tuple(d["states"]), tuple(d["patterns"]),
            np.asarray(d["pattern_allowed"], bool), d["pattern_initial"], d["pattern_transition"],
            d["state_initial"], d["routine"], d["routine_strength"], d["jump"], d["dwell"])

    def problems(self, n_slots: int) -> list[str]:
        """Structural problems (shapes, stochastic rows, ranges); empty when the model is valid."""
        D, S = self.n_patterns, self.n_states
        out: list[str] = []
        shapes = {"pattern_allowed": (7, D), "pattern_initial": (D,), "pattern_transition": (D, D),
                  "state_initial": (S,), "routine": (D, n_slots), "routine_strength": (D, n_slots),
                  "jump": (D, S, S), "dwell": (D, S, 2)}
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                out.append(f"{name}: shape {np.shape(getattr(self, name))}, expected {shape}")
        if out or D == 0 or S == 0:
            return out or ["patterns and states must not be empty"]
        for name in ("pattern_initial", "pattern_transition", "state_initial", "jump"):
            a = getattr(self, name)
            if not np.all(np.isfinite(a)) or a.min() < 0 or not np.allclose(a.sum(axis=-1), 1.0, atol=1e-9):
                out.append(f"{name}: rows must be probability distributions (>= 0, summing to 1)")
        rs = self.routine_strength
        if not np.all(np.isfinite(rs)) or rs.min() < 0 or rs.max() > 1:
            out.append("routine_strength: expected values in [0, 1]")
        if self.routine.min() < 0 or self.routine.max() >= S:
            out.append(f"routine: state indices must lie in [0, {S})")
        lo, hi = self.dwell[..., 0], self.dwell[..., 1]
        if lo.min() < 1 or np.any(hi < lo):
            out.append("dwell: expected 1 <= lo <= hi (whole steps)")
        if not self.pattern_allowed.any(axis=1).all():
            out.append("pattern_allowed: every weekday needs at least one allowed pattern")
        return out


def _floats(a: NDArray[np.float64]) -> Any:
    return np.round(np.asarray(a, np.float64), 12).tolist()


@dataclass(eq=False)
class StepClock:
    """Local step boundaries of a step process (DST-aware; days may extend past the dataset).

    Step ``n`` is slot ``n % K`` of day ``n // K`` (day 0 = ``start_date``).
    """

    timezone: str
    start_date: dt.date
    step_hours: tuple[float, ...]
    _starts: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def n_slots(self) -> int:
        return len(self.step_hours)

    def weekday(self, day: int) -> int:
        return (self.start_date + dt.timedelta(days=int(day))).weekday()

    def step_start_s(self, n: int) -> float:
        """Start of step ``n``, seconds since the Unix epoch (UTC)."""
        self._extend(n // self.n_slots + 1)
        return float(self._starts[n])

    def _extend(self, days: int) -> None:
        have = self._starts.size // self.n_slots
        if days <= have:
            return
        days = max(days, 2 * have, 32)
        zone = zoneinfo.ZoneInfo(self.timezone)
        out = []
        for d in range(days):
            day = self.start_date + dt.timedelta(days=d)
            base = dt.datetime(day.year, day.month, day.day, tzinfo=zone)
            for h in self.step_hours:
                wall = base + dt.timedelta(seconds=round(float(h) * 3600.0))
                out.append(wall.timestamp())
        self._starts = np.asarray(out, np.float64)

    def step_of(self, t_s: ArrayLike) -> NDArray[np.int64]:
        """Step holding each time (after the last slot of a day: that slot; before step 0: step 0)."""
        t = np.asarray(t_s, np.float64)
        if t.size:
            span = float(np.max(t)) - (self._starts[0] if self._starts.size else 0.0)
            need = int(math.ceil(max(span, 0.0) / 86400.0)) + 2 if self._starts.size else 32
            self._extend(need)
            while self._starts[-1] <= float(np.max(t)):
                self._extend(2 * (self._starts.size // self.n_slots))
        n = np.searchsorted(self._starts, t, side="right") - 1
        return np.maximum(n, 0).astype(np.int64)


@dataclass(eq=False)
class StepProcess:
    """The step processes of all entities of a dataset plus their shared clock.

    Attributes:
        timezone: IANA zone of the local step hours.
        start_date: local date of day 0.
        days: days the dataset covers (the process itself continues past them).
        step_hours: local start hours of the K steps of a day.
        shifted_days: day indices that use Saturday's pattern mask (distribution shift).
        entities: entity id -> :class:`EntityProcess`.
        parameters: the generator parameters the process was built from (provenance).
    """

    timezone: str
    start_date: dt.date
    days: int
    step_hours: tuple[float, ...]
    entities: dict[str, EntityProcess]
    shifted_days: tuple[int, ...] = ()
    parameters: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.step_hours = tuple(float(h) for h in self.step_hours)
        self.shifted_days = tuple(int(d) for d in self.shifted_days)
        self.clock = StepClock(self.timezone, self.start_date, self.step_hours)
        self._shifted = frozenset(self.shifted_days)

    @property
    def n_slots(self) -> int:
        """Steps per day."""
        return len(self.step_hours)

    @property
    def n_steps(self) -> int:
        """Steps of the whole process."""
        return self.days * self.n_slots

    def allowed(self, entity: EntityProcess, day: int) -> NDArray[np.bool_]:
        """(D,) patterns allowed on ``day`` (Saturday's mask on shifted days)."""
        wd = SATURDAY if day in self._shifted else self.clock.weekday(day)
        return entity.pattern_allowed[wd]

    def day_matrix(self, entity: EntityProcess, day: int) -> NDArray[np.float64]:
        """(D, D) pattern transition into ``day`` (mask applied, rows renormalised; a row with no
        allowed mass becomes uniform over the allowed patterns).
        """
        a = self.allowed(entity, day).astype(np.float64)
        m = entity.pattern_transition * a[None, :]
        empty = m.sum(axis=1) <= 0
        m[empty] = a
        return normalize_rows(m)

    def day_initial(self, entity: EntityProcess) -> NDArray[np.float64]:
        """The entity's day-pattern distribution on day 0 (its initial one, restricted to the allowed patterns)."""
        a = self.allowed(entity, 0).astype(np.float64)
        p = entity.pattern_initial * a
        return normalize_rows(p if p.sum() > 0 else a)

    # -- serialisation ------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The process as the JSON document of the generator-model format (docs/FORMAT.md)."""
        return {"format": PROCESS_FORMAT, "version": PROCESS_VERSION, "timezone": self.timezone,
                "start_date": self.start_date.isoformat(), "days": self.days, "step_hours": list(self.step_hours),
                "shifted_days": list(self.shifted_days), "parameters": dict(self.parameters),
                "entities": [e.to_dict() for e in self.entities.values()]}

    def to_json(self) -> str:
        """The process as compact JSON text."""
        return json.dumps(self.to_dict(), separators=(",", ":"), allow_nan=False) + "\n"

    @staticmethod
    def from_dict(d: Mapping[str, Any], where: str = "process", *, check: bool = True) -> StepProcess:
        """Parse (and with ``check``, check) a process dict; raise :class:`PsgDataError` naming the
        first problem (:meth:`problems` lists them all).
        """
        if not isinstance(d, Mapping) or d.get("format") != PROCESS_FORMAT:
            raise PsgDataError(f"{where}: format: expected {PROCESS_FORMAT!r}")
        if int(d.get("version", 0)) > PROCESS_VERSION:
            raise PsgDataError(f"{where}: version {d.get('version')} is newer than this psg-data reads "
                               f"({PROCESS_VERSION})")
        try:
            ents = {}
            for e in d["entities"]:
                ep = EntityProcess.from_dict(e)
                ents[ep.entity_id] = ep
            proc = StepProcess(str(d["timezone"]), dt.date.fromisoformat(d["start_date"]), int(d["days"]),
                               tuple(d["step_hours"]), ents, tuple(d.get("shifted_days", ())),
                               dict(d.get("parameters", {})))
        except (KeyError, TypeError, ValueError) as exc:
            raise PsgDataError(f"{where}: malformed process ({type(exc).__name__}: {exc})") from None
        probs = proc.problems() if check else []
        if probs:
            raise PsgDataError(f"{where}: {probs[0]}")
        return proc

    def problems(self) -> list[str]:
        """Every structural problem, as ``entity: field: message`` lines."""
        out = []
        if not self.step_hours or any(b <= a for a, b in zip(self.step_hours, self.step_hours[1:])):
            out.append("step_hours: expected increasing local hours")
        try:
            zoneinfo.ZoneInfo(self.timezone)
        except (zoneinfo.ZoneInfoNotFoundError, ValueError):
            out.append(f"timezone: {self.timezone!r} is not an IANA name")
        for eid, e in self.entities.items():
            out += [f"{eid}: {p}" for p in e.problems(self.n_slots)]
        return out


def load_process(source: Any) -> StepProcess:
    """A :class:`StepProcess` from a dataset (object or directory), a process JSON file or a dict.

    Raises:
        PsgDataError: no process stored (not a v2 synthetic dataset) or a malformed file.
    """
    if isinstance(source, StepProcess):
        return source
    if isinstance(source, Mapping):
        return StepProcess.from_dict(source)
    root = Path(source.root) if hasattr(source, "table") else Path(source)  # a Dataset, or a path
    path = root / PROCESS_FILE if root.is_dir() else root
    if root.is_dir() and path.is_file():
        inside_dataset(real_root(root), PROCESS_FILE, f"{root}: generator model")
    if not path.is_file():
        raise PsgDataError(f"{root}: no generator process ({PROCESS_FILE}); the exact model is stored only by "
                           "psg-data synth (generator steps-v2) datasets")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PsgDataError(f"{path}: not valid JSON ({exc})") from None
    return StepProcess.from_dict(data, str(path))
