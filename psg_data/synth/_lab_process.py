"""The lab's step processes (generator ``steps-v2``, the default) and the schedules sampled from them.

Built from the paper's description (appendices "Hierarchical Scheduling Model" and "Real-World
Details"): a fixed delta t (the scan intervals 09-11, 11-13, 13-15, 15-17 local, one scan each),
day-level patterns with one day-level transition matrix (default D = 5: three workday variants and
two weekend patterns), per pattern an hour-level routine and affinity-weighted jumps with dwell
times uniform in whole steps, so that objects stay in places for hours or days.

Per object (roles from :data:`psg_data.synth._catalog.OBJECTS`):

* ``static``: one state (its home receptacle), never moves.
* ``dynamic``: a home receptacle and 2-3 other receptacles, drawn by object-receptacle affinity.
  The workday routine is a sequence of blocks over the 4 slots (each slot repeats the previous one
  with probability 1/2, else an affinity-weighted other state); workday variants 2 and 3 change one
  slot of it; the weekend patterns keep the object home, or take it to another of its receptacles
  for one or two midday slots.
* ``absent``: as dynamic, plus the state "absent": commuters (odd catalogue index) are in the lab
  on workdays only, for a block of slots; borrowed objects live in the lab and are away for a slot
  on workdays and for whole weekend days.

Jumps (when the dwell runs out and the routine does not act) go to a state with probability
proportional to its affinity (self included); the longest dwell of a state grows with its affinity,
``1 + round((max_dwell_steps - 1) * w / w_max)`` steps (default 8 steps: two days of scan
intervals). Doors have states open / closed: open on workdays (the second door closes for a slot
in its routine and more often off-routine), closed on weekends or open around midday.

The routine strength ``rho`` (``LabConfig.routine_strength``, default 0.8) is the probability that
the routine sets the state at a step boundary: 0 is an affinity random walk with long stays, 1 is
clockwork. The defaults are read from the paper's description, not tuned on estimator scores.
"""

from __future__ import annotations

import datetime as dt
import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.schemas._generator_model import EntityProcess, StepProcess
from psg_data.synth._catalog import ObjectSpec
from psg_data.synth._lab_schedule import DOOR_CLOSED, DOOR_OPEN, TimelineSchedule, _affinity, _pick
from psg_data.synth._layout import LabLayout
from psg_data.synth._process import EntityPath, sample_entity
from psg_data.synth._schedule import Timeline

__all__ = ["ProcessParams", "lab_process", "StepSchedule"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ProcessParams:
    """Generator parameters of the lab's step processes (all stored in the manifest)."""

    routine_strength: float = 0.8
    day_patterns: int = 5
    day_persistence: float = 0.6
    max_dwell_steps: int = 8

    def split(self) -> tuple[int, int]:
        """(workday variants, weekend patterns): two weekend patterns when there is room."""
        if self.day_patterns == 1:
            return 1, 0
        n_weekend = 2 if self.day_patterns >= 4 else 1
        return self.day_patterns - n_weekend, n_weekend


def _day_level(rng: np.random.Generator, params: ProcessParams, n_work: int, n_weekend: int
               ) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """Calendar mask (7, D) and the day-level matrix: ``day_persistence`` on the diagonal, the
    rest spread by a Dirichlet(2) draw over the other patterns.
    """
    D = n_work + n_weekend
    allowed = np.zeros((7, D), bool)
    if n_weekend == 0:
        allowed[:] = True
    else:
        allowed[:5, :n_work] = True
        allowed[5:, n_work:] = True
    T = np.zeros((D, D))
    for p in range(D):
        if D == 1:
            T[p, p] = 1.0
            continue
        off = rng.dirichlet(np.full(D - 1, 2.0)) * (1.0 - params.day_persistence)
        T[p] = np.insert(off, p, params.day_persistence)
    return allowed, T


def _block_routine(rng: np.random.Generator, w: NDArray[np.float64], K: int, first: int) -> list[int]:
    """K slots of blocks: each slot repeats the previous one with probability 1/2, else an
    affinity-weighted other state.
    """
    seq = [first]
    for _ in range(1, K):
        cur = seq[-1]
        if rng.random() < 0.5 or w.size == 1:
            seq.append(cur)
        else:
            seq.append(_pick(rng, w, 1, {cur})[0])
    return seq


def _variant(rng: np.random.Generator, base: list[int], w: NDArray[np.float64]) -> list[int]:
    """The routine with one slot moved to another (affinity-weighted) state."""
    out = list(base)
    k = int(rng.integers(len(out)))
    out[k] = _pick(rng, w, 1, {out[k]})[0]
    return out


def _weekend_out(rng: np.random.Generator, home: int, w: NDArray[np.float64], K: int) -> list[int]:
    spot = _pick(rng, w, 1, {home})[0]
    a = int(rng.integers(1, max(K - 1, 2)))
    n = int(rng.integers(1, 3))
    return [spot if a <= k < a + n else home for k in range(K)]


def _entity(eid: str, kind: str, role: str, states: list[Any], names: list[str], routines: list[list[int]],
            w: NDArray[np.float64], initial: int, rng: np.random.Generator, params: ProcessParams,
            n_work: int, n_weekend: int, dwell_hi: NDArray[np.int64]) -> EntityProcess:
    D, S, K = len(routines), len(states), len(routines[0])
    allowed, T = _day_level(rng, params, n_work, n_weekend)
    jump = np.broadcast_to(w / w.sum(), (D, S, S)).copy()
    dwell = np.stack([np.ones(S, np.int64), dwell_hi], axis=1)
    return EntityProcess(
        eid, kind, role, tuple(states), tuple(names), allowed, np.full(D, 1.0 / D), T, np.eye(S)[initial],
        np.asarray(routines, np.int64), np.full((D, K), float(params.routine_strength)), jump,
        np.broadcast_to(dwell, (D, S, 2)).copy())


def _dwell_hi(w: NDArray[np.float64], params: ProcessParams) -> NDArray[np.int64]:
    return (1 + np.round((params.max_dwell_steps - 1) * w / w.max())).astype(np.int64)


def _pattern_names(n_work: int, n_weekend: int) -> list[str]:
    return [f"workday_{chr(97 + i)}" for i in range(n_work)] + [f"weekend_{chr(97 + i)}" for i in range(n_weekend)]


def object_process(spec: ObjectSpec, j: int, layout: LabLayout, seed: int, K: int, params: ProcessParams
                   ) -> EntityProcess:
    """The step process of object ``j`` (states: receptacle ids, None = absent)."""
    rng = np.random.default_rng([int(seed), 611, j])
    w_all = _affinity(spec, layout)
    home = _pick(rng, w_all, 1, set())[0]
    rec_ids = layout.receptacle_ids
    if spec.role == "static":
        allowed = np.ones((7, 1), bool)
        return EntityProcess(spec.name, "object", "static", (rec_ids[home],), ("static",), allowed, np.ones(1),
                             np.ones((1, 1)), np.ones(1), np.zeros((1, K), np.int64), np.ones((1, K)),
                             np.ones((1, 1, 1)), np.ones((1, 1, 2), np.int64))
    others = _pick(rng, w_all, int(rng.integers(2, 4)), {home})
    recs = [home, *others]
    states: list[Any] = [rec_ids[r] for r in recs]
    w = np.array([w_all[r] for r in recs], float)
    n_work, n_weekend = params.split()
    commuter = spec.role == "absent" and j % 2 == 1
    borrowed = spec.role == "absent" and not commuter
    if spec.role == "absent":
        states.append(None)
        w = np.append(w, w.mean())
    A = len(states) - 1  # index of "absent" when present
    wr = w.copy()
    if spec.role == "absent":
        wr[A] = 0.0  # routines place the object on receptacles; absences are set explicitly below
    base = _block_routine(rng, wr, K, 0 if rng.random() < 0.5 else _pick(rng, wr, 1, {0})[0])
    if len(set(base)) == 1:
        base[int(rng.integers(K))] = _pick(rng, wr, 1, {base[0]})[0]
    if commuter:
        a = int(rng.integers(0, 2))
        b = int(rng.integers(max(a + 1, K - 2), K + 1))
        base = [base[k] if a <= k < b else A for k in range(K)]
    elif borrowed:
        base[int(rng.integers(K))] = A
    work = [base] + [_variant(rng, base, wr) for _ in range(n_work - 1)]
    if commuter:
        weekend = [[A] * K] + [[A if k in (0, K - 1) else 0 for k in range(K)] for _ in range(n_weekend - 1)]
    elif borrowed:
        weekend = [[0] * K] + [[A] * K for _ in range(n_weekend - 1)]
    else:
        weekend = [[0] * K] + [_weekend_out(rng, 0, wr, K) for _ in range(n_weekend - 1)]
    routines = work + weekend[:n_weekend]
    return _entity(spec.name, "object", spec.role, states, _pattern_names(n_work, n_weekend), routines, w,
                   A if commuter else 0, rng, params, n_work, n_weekend, _dwell_hi(w, params))


def door_process(k: int, door_id: str, seed: int, K: int, params: ProcessParams) -> EntityProcess:
    """Door ``k``'s step process: states ``open`` / ``closed``."""
    rng = np.random.default_rng([int(seed), 612, k])
    busy = k % 2 == 1  # the second door closes more often during the day
    O, C = 0, 1
    base = [O] * K
    if busy:
        base[int(rng.integers(K))] = C
    n_work, n_weekend = params.split()
    w = np.array([0.5, 0.5]) if busy else np.array([0.8, 0.2])
    work = [base] + [_variant(rng, base, np.array([1.0, 1.0])) for _ in range(n_work - 1)]
    weekend = [[C] * K] + [[O if 0 < s < K - 1 else C for s in range(K)] for _ in range(n_weekend - 1)]
    routines = work + weekend[:n_weekend]
    return _entity(door_id, "door", "door", ["open", "closed"], _pattern_names(n_work, n_weekend), routines, w, C,
                   rng, params, n_work, n_weekend, np.array([4, 2], np.int64))


def lab_process(layout: LabLayout, seed: int, start_date: dt.date, days: int, timezone: str,
                step_hours: tuple[float, ...], params: ProcessParams,
                shifted_days: frozenset[int] = frozenset()) -> StepProcess:
    """The step process of every object and door of the lab."""
    K = len(step_hours)
    ents = {o.name: object_process(o, j, layout, seed, K, params) for j, o in enumerate(layout.objects)}
    for k, d in enumerate(layout.door_ids):
        ents[d] = door_process(k, d, seed, K, params)
    return StepProcess(timezone, start_date, days, step_hours, ents, tuple(sorted(shifted_days)),
                       {"generator": "steps-v2", "seed": int(seed), "routine_strength": params.routine_strength,
                        "day_patterns": params.day_patterns, "day_persistence": params.day_persistence,
                        "max_dwell_steps": params.max_dwell_steps})


class StepSchedule(TimelineSchedule):
    """Ground-truth schedules of the lab sampled from its step processes (generator ``steps-v2``).

    Same interface as :class:`~psg_data.synth.LabSchedule` (``objects``/``doors`` timelines,
    ``objects_at``, ``doors_at``, ``dense``) plus ``process`` (the model), ``paths`` (the sampled
    latent paths) and ``step_starts_ns``. A state changes only at a step start.

    Args:
        layout: lab geometry (receptacle order defines the timeline state indices).
        seed: lab seed.
        start_date: first local date.
        days: number of days.
        timezone: IANA site timezone.
        step_hours: local start hours of the steps (the scan hours).
        params: generator parameters.
        shifted_days: day indices that follow the weekend patterns (distribution shift).
    """

    def __init__(self, layout: LabLayout, seed: int, start_date: dt.date, days: int, timezone: str,
                 step_hours: tuple[float, ...], params: ProcessParams,
                 shifted_days: frozenset[int] = frozenset()) -> None:
        self._set_calendar(layout, seed, start_date, days, timezone, shifted_days)
        self.process = lab_process(layout, seed, start_date, days, timezone, step_hours, params, shifted_days)
        n = self.process.n_steps
        self.step_starts_ns = np.array([int(round(self.process.clock.step_start_s(i))) * 1_000_000_000
                                        for i in range(n)], np.int64)
        self.paths: dict[str, EntityPath] = {}
        for i, (eid, ent) in enumerate(self.process.entities.items()):
            self.paths[eid] = sample_entity(self.process, ent, n, np.random.default_rng([self.seed, 621, i]))
        rix = {r: i for i, r in enumerate(self.receptacle_ids)}
        self.objects: dict[str, Timeline] = {}
        for o in self.object_ids:
            lab_state = np.array([-1 if s is None else rix[s] for s in self.process.entities[o].states], np.int64)
            self.objects[o] = self._timeline(o, lab_state)
        door_state = np.array([DOOR_OPEN, DOOR_CLOSED], np.int64)
        self.doors: dict[str, Timeline] = {d: self._timeline(d, door_state) for d in self.door_ids}

    def _timeline(self, eid: str, value: NDArray[np.int64]) -> Timeline:
        path, ent = self.paths[eid], self.process.entities[eid]
        # from midnight of day 0 the state is that of step 0 (the latent state before the first
        # step, ``path.before``, is not part of the ground truth: no hidden change before 9:00)
        seq = path.states
        t = np.concatenate([[self.start_ns], self.step_starts_ns[1:]])
        keep = np.concatenate([[True], seq[1:] != seq[:-1]])
        names = [ent.patterns[p] for p in path.patterns[: self.days]]
        return Timeline(t[keep], value[seq[keep]], names, ["regular"] * len(names))
