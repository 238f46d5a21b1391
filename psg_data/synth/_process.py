"""The step process: the discrete hierarchical Markov model behind the v2 lab schedules.

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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data.errors import PsgDataError

__all__ = ["EntityProcess", "StepProcess", "StepClock", "ForwardBelief", "PROCESS_FORMAT", "PROCESS_VERSION",
           "PROCESS_FILE", "sample_entity", "EntityPath", "llm_schedules", "load_process"]

PROCESS_FORMAT = "psg-step-process"
PROCESS_VERSION = 1
PROCESS_FILE = "generator/process.json"
"""Path of the process file inside a dataset (listed in ``tables/files.parquet``)."""

WEEKDAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")
SATURDAY = 5


def _norm(p: NDArray[np.float64]) -> NDArray[np.float64]:
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
        return _norm(m)

    def day_initial(self, entity: EntityProcess) -> NDArray[np.float64]:
        """The entity's day-pattern distribution on day 0 (its initial one, restricted to the allowed patterns)."""
        a = self.allowed(entity, 0).astype(np.float64)
        p = entity.pattern_initial * a
        return _norm(p if p.sum() > 0 else a)

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

    def save(self, path: str | Path) -> None:
        """Write the process as JSON to ``path``: replaces the file atomically (an interrupted call
        leaves the previous one as it was).
        """
        from psg_data.writers._safe_output import write_atomically

        text = self.to_json()
        write_atomically(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


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
    if not path.is_file():
        raise PsgDataError(f"{root}: no generator process ({PROCESS_FILE}); the exact model is stored only by "
                           "psg-data synth (generator steps-v2) datasets")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PsgDataError(f"{path}: not valid JSON ({exc})") from None
    return StepProcess.from_dict(data, str(path))


# -- sampling -------------------------------------------------------------------------------------


@dataclass
class EntityPath:
    """One sampled path of an entity over ``n`` steps.

    Attributes:
        patterns: (days,) pattern index of every day.
        states: (n,) state index during every step.
        dwell: (n,) remaining dwell after the boundary into every step.
        events: (n,) 0 = routine placement, 1 = hold, 2 = jump (free dynamics).
        fresh: (n,) dwell drawn at the boundary (0 when none was drawn: a hold).
        before: state index before step 0.
    """

    patterns: NDArray[np.int64]
    states: NDArray[np.int64]
    dwell: NDArray[np.int64]
    events: NDArray[np.int64]
    fresh: NDArray[np.int64]
    before: int


def _pick(p: NDArray[np.float64], u: float) -> int:
    c = np.cumsum(p)
    return int(min(np.searchsorted(c, u * c[-1], side="right"), p.size - 1))


def sample_entity(process: StepProcess, entity: EntityProcess, n_steps: int, rng: np.random.Generator) -> EntityPath:
    """Sample an entity's path over ``n_steps`` steps (four uniforms per step, so paths of two
    models that differ in one parameter share their random numbers).
    """
    K = process.n_slots
    s = _pick(entity.state_initial, float(rng.random()))
    u = rng.random((n_steps, 4))  # drawn after the initial state: a longer path extends a shorter one
    before, r, p = s, 1, -1
    days = -(-n_steps // K)
    pats = np.zeros(days, np.int64)
    st, dw, ev, fr = (np.zeros(n_steps, np.int64) for _ in range(4))
    for n in range(n_steps):
        day, k = divmod(n, K)
        if k == 0:
            row = process.day_initial(entity) if day == 0 else process.day_matrix(entity, day)[p]
            p = _pick(row, u[n, 0])
            pats[day] = p
        if u[n, 1] < entity.routine_strength[p, k]:
            s, event = int(entity.routine[p, k]), 0
        elif r > 1:
            r, event = r - 1, 1
        else:
            s, event = _pick(entity.jump[p, s], u[n, 2]), 2
        if event != 1:
            lo, hi = entity.dwell[p, s]
            r = int(lo + min(int(u[n, 3] * (hi - lo + 1)), hi - lo))
            fr[n] = r
        st[n], dw[n], ev[n] = s, r, event
    return EntityPath(pats, st, dw, ev, fr, before)


# -- exact inference ------------------------------------------------------------------------------


class ForwardBelief:
    """Exact filtering and forecasting for one entity: the belief over (pattern, state, dwell).

    ``alpha[p, s, r - 1]`` is P(pattern p on the current day, state s, remaining dwell r | the
    observations absorbed so far) at step ``n``. Start with :meth:`start` (the belief at step 0),
    absorb observations with :meth:`observe`, move on with :meth:`advance_to`.
    """

    def __init__(self, process: StepProcess, entity: EntityProcess) -> None:
        self.process = process
        self.entity = entity
        self.U = entity.dwell_pmf()
        self.n = -1
        self.alpha = np.zeros((entity.n_patterns, entity.n_states, entity.max_dwell))
        self.log_evidence = 0.0

    def copy(self) -> ForwardBelief:
        """An independent copy of the belief (same process, own state)."""
        out = ForwardBelief.__new__(ForwardBelief)
        out.process, out.entity, out.U = self.process, self.entity, self.U
        out.n, out.alpha, out.log_evidence = self.n, self.alpha.copy(), self.log_evidence
        return out

    def start(self) -> ForwardBelief:
        """The belief at step 0 (no observation)."""
        e = self.entity
        pre = np.zeros_like(self.alpha)
        pre[:, :, 0] = self.process.day_initial(e)[:, None] * e.state_initial[None, :]
        self.alpha = self._hour_kernel(pre, 0)
        self.n = 0
        return self

    def _hour_kernel(self, beta: NDArray[np.float64], k: int) -> NDArray[np.float64]:
        e = self.entity
        rho = e.routine_strength[:, k][:, None, None]
        tot = beta.sum(axis=(1, 2))
        routine = np.zeros_like(beta)
        idx = np.arange(e.n_patterns)
        routine[idx, e.routine[:, k], :] = tot[:, None] * self.U[idx, e.routine[:, k], :]
        hold = np.zeros_like(beta)
        hold[:, :, :-1] = beta[:, :, 1:]
        jumped = np.einsum("ps,pst->pt", beta[:, :, 0], e.jump)
        return rho * routine + (1.0 - rho) * (hold + jumped[:, :, None] * self.U)

    def advance(self) -> None:
        """Move the belief one step ahead (no observation)."""
        n = self.n + 1
        day, k = divmod(n, self.process.n_slots)
        beta = self.alpha
        if k == 0:
            beta = np.einsum("psr,pq->qsr", beta, self.process.day_matrix(self.entity, day))
        self.alpha = self._hour_kernel(beta, k)
        self.n = n

    def advance_to(self, n: int) -> None:
        """Advance the belief to step ``n`` without observations.

        Raises:
            PsgDataError: ``n`` is before the current step.
        """
        if n < self.n:
            raise PsgDataError(f"ForwardBelief: cannot go back from step {self.n} to {n}")
        while self.n < n:
            self.advance()

    def observe(self, likelihood: NDArray[np.float64]) -> None:
        """Absorb an observation at the current step given its likelihood per state, (S,).

        Raises:
            PsgDataError: the observation is impossible under the model (zero evidence).
        """
        a = self.alpha * np.asarray(likelihood, np.float64)[None, :, None]
        z = float(a.sum())
        if not z > 0.0:
            raise PsgDataError(f"{self.entity.entity_id}: observation at step {self.n} is impossible under the "
                               "generator model (zero likelihood); noisy labels need p_m/p_f > 0")
        self.alpha = a / z
        self.log_evidence += math.log(z)

    def state_marginal(self) -> NDArray[np.float64]:
        """(S,) P(state) at the current step."""
        return self.alpha.sum(axis=(0, 2))

    def forecast(self, steps: Sequence[int] | NDArray[np.int64]) -> NDArray[np.float64]:
        """(len(steps), S) state marginals at future steps (>= the current one), without changing the belief."""
        steps = np.asarray(steps, np.int64)
        out = np.zeros((steps.size, self.entity.n_states))
        if steps.size == 0:
            return out
        order = np.argsort(steps, kind="stable")
        b = self.copy()
        for i in order:
            b.advance_to(int(max(steps[i], self.n)))
            out[i] = b.state_marginal()
        return out


def observation_likelihood(entity: EntityProcess, label: str | None, y: int, p_m: float, p_f: float
                           ) -> NDArray[np.float64]:
    """(S,) P(y | state) of an edge observation: edge ``(entity, label)`` seen present (1) or absent (0).

    P(y=1 | at label) = 1 - p_m, P(y=1 | elsewhere) = p_f; a label the entity never takes gives
    P(y=1) = p_f in every state.
    """
    j = entity.state_index(label)
    at = np.zeros(entity.n_states, bool)
    if j >= 0:
        at[j] = True
    p1 = np.where(at, 1.0 - p_m, p_f)
    return p1 if int(y) == 1 else 1.0 - p1


# -- LLM-format schedules -------------------------------------------------------------------------


def weekday_pattern_marginals(process: StepProcess, entity: EntityProcess, weeks: int = 30) -> NDArray[np.float64]:
    """(7, D) long-run P(pattern | weekday) of the day chain (unshifted calendar)."""
    D = entity.n_patterns
    acc = np.zeros((7, D))
    p = _norm(entity.pattern_initial * entity.pattern_allowed[process.clock.weekday(0)])
    plain = StepProcess(process.timezone, process.start_date, process.days, process.step_hours,
                        {entity.entity_id: entity})
    for day in range(1, 7 * weeks):
        p = p @ plain.day_matrix(entity, day)
        if day >= 7 * (weeks - 8):
            acc[plain.clock.weekday(day)] += p
    return _norm(acc)


def _hhmm(h: float) -> str:
    m = int(round(h * 60))
    return f"{m // 60:02d}:{m % 60:02d}"


def llm_schedules(process: StepProcess) -> dict[tuple[str, str], list[str]]:
    """Per (entity, state label) the weekly routine in the paper's LLM output format.

    For every weekday the most likely day pattern (long-run day-chain marginal) is taken, and its
    routine slots on the label become ``'Day: HH:MM - Day: HH:MM'`` intervals (a routine on the
    last slot of a day lasts until the first step of the next day, as the state does). Absent
    states give no entry; labels never in a routine get an empty list.
    """
    K, hours = process.n_slots, process.step_hours
    out: dict[tuple[str, str], list[str]] = {}
    for e in process.entities.values():
        modal = weekday_pattern_marginals(process, e).argmax(axis=1)
        for j, label in enumerate(e.states):
            if label is None:
                continue
            on = np.array([[e.routine[modal[w], k] == j for k in range(K)] for w in range(7)]).reshape(-1)
            out[(e.entity_id, str(label))] = _intervals(on, K, hours)
    return out


def _intervals(on: NDArray[np.bool_], K: int, hours: tuple[float, ...]) -> list[str]:
    """Weekly slot mask (7 * K, Monday first) -> merged 'Day: HH:MM - Day: HH:MM' strings."""
    n = on.size
    if on.all():  # always there: one full day per entry ('Mon: 00:00 - Mon: 00:00' would be empty)
        return [f"{WEEKDAYS[d]}: 00:00 - {WEEKDAYS[(d + 1) % 7]}: 00:00" for d in range(7)]
    out = []
    start = int(np.flatnonzero(~on)[0]) + 1  # begin scanning right after an "off" slot (handles week wrap)
    i = 0
    while i < n:
        j = (start + i) % n
        if on[j]:
            k = i
            while k + 1 < n and on[(start + k + 1) % n]:
                k += 1
            a, b = j, (start + k) % n
            d0, s0 = divmod(a, K)
            d1, s1 = divmod(b, K)
            if s1 == K - 1:  # the last slot lasts until the next day's first step
                d1, end = (d1 + 1) % 7, hours[0]
            else:
                end = hours[s1 + 1]
            out.append(f"{WEEKDAYS[d0]}: {_hhmm(hours[s0])} - {WEEKDAYS[d1]}: {_hhmm(end)}")
            i = k + 1
        else:
            i += 1
    return sorted(out, key=lambda s: (WEEKDAYS.index(s[:3]), s[5:10]))
