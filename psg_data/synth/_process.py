"""Sampling and exact inference for the step process (its format: :mod:`psg_data.schemas._generator_model`).

:func:`sample_entity` draws an entity's path, :class:`ForwardBelief` is the exact forward
algorithm over (pattern, state, dwell), :func:`llm_schedules` writes the routines in the paper's
LLM format and :func:`save_process` writes a process file.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import PsgDataError
from psg_data.schemas._generator_model import WEEKDAYS, EntityProcess, StepProcess, normalize_rows

__all__ = ["ForwardBelief", "sample_entity", "EntityPath", "llm_schedules", "observation_likelihood", "save_process"]


def save_process(process: StepProcess, path: str | Path) -> None:
    """Write ``process`` as JSON to ``path``: replaces the file atomically (an interrupted call
    leaves the previous one as it was).
    """
    from psg_data.writers._safe_output import write_atomically

    text = process.to_json()
    write_atomically(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


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
    models that differ in one parameter share their random numbers). From a regime's start day on
    the regime's model of the entity is used (:meth:`StepProcess.entity_on`).
    """
    K = process.n_slots
    s = _pick(entity.state_initial, float(rng.random()))
    u = rng.random((n_steps, 4))  # drawn after the initial state: a longer path extends a shorter one
    before, r, p = s, 1, -1
    days = -(-n_steps // K)
    pats = np.zeros(days, np.int64)
    st, dw, ev, fr = (np.zeros(n_steps, np.int64) for _ in range(4))
    base = entity
    for n in range(n_steps):
        day, k = divmod(n, K)
        if k == 0:
            entity = process.entity_on(base.entity_id, day, base)
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


@dataclass(frozen=True)
class _SlotKernel:
    """Constants of the one-step kernel into slot ``k`` for one entity model."""

    rho: NDArray[np.float64]  # (P, 1) routine strength
    one_minus_rho: NDArray[np.float64]  # (P, 1, 1)
    rows: NDArray[np.int64]  # (P,) rows p * S + routine[p, k] of the (P * S, R) view
    u_routine: NDArray[np.float64]  # (P, R) fresh-dwell pmf of the routine state


class ForwardBelief:
    """Exact filtering and forecasting for one entity: the belief over (pattern, state, dwell).

    ``alpha[p, s, r - 1]`` is P(pattern p on the current day, state s, remaining dwell r | the
    observations absorbed so far) at step ``n``. Start with :meth:`start` (the belief at step 0),
    absorb observations with :meth:`observe`, move on with :meth:`advance_to`.
    """

    def __init__(self, process: StepProcess, entity: EntityProcess) -> None:
        self.process = process
        self.entity = entity
        self._base = entity
        self.U = entity.dwell_pmf()
        self.n = -1
        self.alpha = np.zeros((entity.n_patterns, entity.n_states, entity.max_dwell))
        self.log_evidence = 0.0
        self._slots: dict[int, _SlotKernel] = {}  # constants of the current entity's kernel, per slot
        self._days: dict[int, NDArray[np.float64]] = {}  # day matrices (a function of the day alone), shared

    def copy(self) -> ForwardBelief:
        """An independent copy of the belief (same process, own state)."""
        out = ForwardBelief.__new__(ForwardBelief)
        out.process, out.entity, out.U, out._base = self.process, self.entity, self.U, self._base
        out.n, out.alpha, out.log_evidence = self.n, self.alpha.copy(), self.log_evidence
        out._slots, out._days = self._slots, self._days  # read-only constants of the same model
        return out

    def snapshot(self) -> tuple[int, NDArray[np.float64], EntityProcess, NDArray[np.float64], dict[int, _SlotKernel]]:
        """The belief's state as it is now (arrays shared: the belief never changes them in place);
        :meth:`restore` puts it back, on this belief or a copy of it.
        """
        return self.n, self.alpha, self.entity, self.U, self._slots

    def restore(self, state: tuple[int, NDArray[np.float64], EntityProcess, NDArray[np.float64],
                                   dict[int, _SlotKernel]]) -> None:
        """Take back a :meth:`snapshot` (of this belief or of a copy; the log evidence is kept)."""
        self.n, self.alpha, self.entity, self.U, self._slots = state

    def start(self) -> ForwardBelief:
        """The belief at step 0 (no observation)."""
        e = self.entity
        pre = np.zeros_like(self.alpha)
        pre[:, :, 0] = self.process.day_initial(e)[:, None] * e.state_initial[None, :]
        self.alpha = self._hour_kernel(pre, 0)
        self.n = 0
        return self

    def _slot(self, k: int) -> _SlotKernel:
        c = self._slots.get(k)
        if c is None:
            e = self.entity
            idx = np.arange(e.n_patterns)
            rk = e.routine[:, k]
            rho = e.routine_strength[:, k][:, None, None]
            c = self._slots[k] = _SlotKernel(rho[:, :, 0], 1.0 - rho, idx * e.n_states + rk, self.U[idx, rk, :])
        return c

    def _hour_kernel(self, beta: NDArray[np.float64], k: int) -> NDArray[np.float64]:
        """``rho * routine + (1 - rho) * (hold + jumped * U)``, the routine term added only where it is
        not zero (the same floating-point operations on every element as the full expression).
        """
        c = self._slot(k)
        tot = beta.sum(axis=(1, 2))
        jumped = np.einsum("ps,pst->pt", beta[:, :, 0], self.entity.jump)
        out = jumped[:, :, None] * self.U  # the hold term (dwell - 1) added to it: x + 0 = x at the last dwell
        out[:, :, :-1] += beta[:, :, 1:]
        out *= c.one_minus_rho
        flat = out.reshape(-1, out.shape[2])  # a view: (pattern, state) rows
        flat[c.rows] += c.rho * (tot[:, None] * c.u_routine)
        return out

    def _day_matrix(self, day: int) -> NDArray[np.float64]:
        m = self._days.get(day)
        if m is None:
            m = self._days[day] = self.process.day_matrix(self.entity, day)
        return m

    def advance(self) -> None:
        """Move the belief one step ahead (no observation); at a regime's first day the regime's model
        of the entity takes over.
        """
        n = self.n + 1
        day, k = divmod(n, self.process.n_slots)
        beta = self.alpha
        if k == 0:
            if self.process.regimes:
                e = self.process.entity_on(self._base.entity_id, day, self._base)
                if e is not self.entity:
                    self.entity, self.U, self._slots = e, e.dwell_pmf(), {}
            beta = np.einsum("psr,pq->qsr", beta, self._day_matrix(day))
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
        """Absorb an observation at the current step given its likelihood per state, (S,) (or (1, S, 1)).

        Raises:
            PsgDataError: the observation is impossible under the model (zero evidence).
        """
        lik = likelihood if getattr(likelihood, "ndim", 1) == 3 else np.asarray(likelihood, np.float64)[None, :, None]
        a = self.alpha * lik
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
    p = normalize_rows(entity.pattern_initial * entity.pattern_allowed[process.clock.weekday(0)])
    plain = StepProcess(process.timezone, process.start_date, process.days, process.step_hours,
                        {entity.entity_id: entity})
    by_weekday: dict[int, NDArray[np.float64]] = {}  # no shifted days: a day's matrix is its weekday's
    for day in range(1, 7 * weeks):
        wd = plain.clock.weekday(day)
        if wd not in by_weekday:
            by_weekday[wd] = plain.day_matrix(entity, day)
        p = p @ by_weekday[wd]
        if day >= 7 * (weeks - 8):
            acc[plain.clock.weekday(day)] += p
    return normalize_rows(acc)


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
