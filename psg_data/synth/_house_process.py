"""The step processes of a procedural house (generator ``house-v1``) and its test-time shift.

Time: delta t = 1 h around the clock (24 steps a day, local hours 0..23), 4 weeks: weeks 1-2
train, week 3 validation, week 4 test (:data:`SPLITS`). The model is the steps-v2 hierarchical
model (:mod:`psg_data.schemas._generator_model`): per entity 5 day patterns (3 workday variants, 2
weekend patterns) with one day-level matrix (0.6 on the diagonal), per pattern an hour-level
routine, affinity-weighted jumps and dwell times uniform in whole steps.

Objects (roles from :class:`~psg_data.synth._house_layout.HouseObject`):

* ``static``: one state, its home receptacle (drawn by affinity).
* ``dynamic``: its home and 2-3 other receptacles (drawn by affinity). The workday routine keeps
  it home overnight and puts it on other receptacles for 1-3 blocks of 2-5 hours between 07:00 and
  23:00; the two other workday variants move one block by 1-2 hours or send it to another state;
  weekend patterns: home all day, or one 4-8 hour outing between 09:00 and 21:00.
* ``absent``: as dynamic, plus the state "absent" (the object leaves the house): on workdays
  for a block of 6-10 hours starting between 07:00 and 10:00; on weekends away most of one
  pattern's day, home the other's.

Jumps go to a state with probability proportional to its affinity (self included); the longest
dwell grows with the affinity, ``1 + round((max_dwell_steps - 1) w / w_max)`` hours (default 48 h,
two days, as the lab's 8 steps are two days of its scan intervals). The routine strength per hour
is ``1 - sqrt(1 - 0.8) = 0.553``: the same probability per two hours as the lab's 0.8 per
two-hour step, so that a deviation from the routine lasts as long in both. Doors: semi-static
doors are closed overnight (a block of 6-9 hours starting 22:00-00:00) and for a 1-3 hour block
on workdays; the other doors are always open (routine open, strength 1).

**Test-time shift** (``shift``, default 0.5; 0 = no shift): ``round(shift * n)`` of the ``n``
dynamic and absent objects get, from the first day of the test week on, a perturbed copy of their
model (a :class:`~psg_data.schemas._generator_model.Regime` stored in the same process file): every
routine moved in time by 3-6 hours (earlier or later, wrapping around midnight) **and** the
receptacle preferences changed (the object's receptacles permuted without a fixed point: the
routine, the affinity weights of the jumps and the dwell ranges follow the permutation, so the
object's new favourite spot is one of its other receptacles). Everything else is unchanged.
Why 0.5 (chosen from the paper before any estimator ran on the houses): the paper's adaptation
experiments are "evaluated under unseen test-time dynamics" and its figure shows one object's
routine over its receptacles changing in the test week; the Sec. V-A benchmark changes two of
the seven days. Half of the moving objects changed keeps the other half as a control that the
training model still predicts, while making the shift a large part of what moves.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.schemas._generator_model import EntityProcess, Regime, StepProcess
from psg_data.synth._house_catalog import affinity
from psg_data.synth._house_layout import HouseLayout

__all__ = ["HouseProcessParams", "house_process", "SPLITS", "HOURS", "TEST_DAY", "shifted_objects"]

HOURS = tuple(float(h) for h in range(24))
"""Local start hours of the steps (delta t = 1 h around the clock)."""

SPLITS = (("train", 0, 14), ("val", 14, 21), ("test", 21, 28))
"""(split, first day, end day): weeks 1-2 train, week 3 validation, week 4 test."""

TEST_DAY = 21
"""First day of the test week (the shift's regime starts there)."""

_N_WORK, _N_WEEKEND = 3, 2


@dataclass(frozen=True)
class HouseProcessParams:
    """Schedule parameters of a house (stored in the manifest and the process file)."""

    routine_strength: float = round(1.0 - float(np.sqrt(0.2)), 4)
    day_persistence: float = 0.6
    max_dwell_steps: int = 48
    shift: float = 0.5


def _choose(rng: np.random.Generator, w: NDArray[np.float64], exclude: set[int]) -> int:
    p = w.copy()
    p[list(exclude)] = 0.0
    if p.sum() <= 0:
        p = np.ones_like(w)
        p[list(exclude)] = 0.0
    return int(rng.choice(p.size, p=p / p.sum()))


def _day_level(rng: np.random.Generator, persistence: float) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    D = _N_WORK + _N_WEEKEND
    allowed = np.zeros((7, D), bool)
    allowed[:5, :_N_WORK] = True
    allowed[5:, _N_WORK:] = True
    T = np.zeros((D, D))
    for p in range(D):
        T[p] = np.insert(rng.dirichlet(np.full(D - 1, 2.0)) * (1.0 - persistence), p, persistence)
    return allowed, T


def _paint(day: list[int], start: int, length: int, state: int) -> None:
    for h in range(start, min(start + length, 24)):
        day[h] = state


def _workday(rng: np.random.Generator, w: NDArray[np.float64], home: int
             ) -> tuple[list[int], list[tuple[int, int, int]]]:
    day = [home] * 24
    blocks = []
    for _ in range(int(rng.integers(1, 4))):
        b = (int(rng.integers(7, 21)), int(rng.integers(2, 6)), _choose(rng, w, {home}))
        _paint(day, *b)
        blocks.append(b)
    return day, blocks


def _variant(rng: np.random.Generator, home: int, blocks: list[tuple[int, int, int]], w: NDArray[np.float64]
             ) -> list[int]:
    k = int(rng.integers(len(blocks)))
    day = [home] * 24
    for i, (s, n, st) in enumerate(blocks):
        if i == k:
            if rng.random() < 0.5:
                s = int(np.clip(s + rng.choice([-2, -1, 1, 2]), 0, 22))
            else:
                st = _choose(rng, w, {home, st})
        _paint(day, s, n, st)
    return day


def _entity(eid: str, kind: str, role: str, states: list[Any], routines: list[list[int]], w: NDArray[np.float64],
            initial: int, rng: np.random.Generator, params: HouseProcessParams, strength: float | None = None
            ) -> EntityProcess:
    D, S = len(routines), len(states)
    allowed, T = _day_level(rng, params.day_persistence)
    hi = (1 + np.round((params.max_dwell_steps - 1) * w / w.max())).astype(np.int64)
    dwell = np.broadcast_to(np.stack([np.ones(S, np.int64), hi], axis=1), (D, S, 2)).copy()
    rho = params.routine_strength if strength is None else strength
    names = [f"workday_{c}" for c in "abc"] + [f"weekend_{c}" for c in "ab"]
    return EntityProcess(eid, kind, role, tuple(states), tuple(names), allowed, np.full(D, 1.0 / D), T,
                         np.eye(S)[initial], np.asarray(routines, np.int64), np.full((D, 24), float(rho)),
                         np.broadcast_to(w / w.sum(), (D, S, S)).copy(), dwell)


def _object(house: HouseLayout, j: int, params: HouseProcessParams) -> EntityProcess:
    o = house.objects[j]
    rng = np.random.default_rng([house.seed, 2511, j])
    w_all = np.array([affinity(o.object_type, r.category or "") for r in house.receptacles], float)
    home = _choose(rng, w_all, set())
    ids = house.receptacle_ids
    if o.role == "static":
        return EntityProcess(o.object_id, "object", "static", (ids[home],), ("static",), np.ones((7, 1), bool),
                             np.ones(1), np.ones((1, 1)), np.ones(1), np.zeros((1, 24), np.int64), np.ones((1, 24)),
                             np.ones((1, 1, 1)), np.ones((1, 1, 2), np.int64))
    n_other = min(int(rng.integers(2, 4)), int((w_all > 0).sum()) - 1)
    others: list[int] = []
    for _ in range(n_other):
        others.append(_choose(rng, w_all, {home, *others}))
    recs = [home, *others]
    states: list[Any] = [ids[r] for r in recs]
    w = w_all[recs]
    wr = w.copy()
    if o.role == "absent":
        states.append(None)
        w = np.append(w, w.mean())
    A = len(states) - 1
    base, blocks = _workday(rng, wr, 0)
    work = [base] + [_variant(rng, 0, blocks, wr) for _ in range(_N_WORK - 1)]
    if o.role == "absent":
        for day in work:
            _paint(day, int(rng.integers(7, 11)), int(rng.integers(6, 11)), A)
        weekend = [[A if 9 <= h < 21 else 0 for h in range(24)], [0] * 24]
    else:
        out = [0] * 24
        _paint(out, int(rng.integers(9, 15)), int(rng.integers(4, 9)), _choose(rng, wr, {0}))
        weekend = [[0] * 24, out]
    return _entity(o.object_id, "object", o.role, states, work + weekend, w, 0, rng, params)


def _door(house: HouseLayout, k: int, params: HouseProcessParams) -> EntityProcess:
    d = house.doors[k]
    rng = np.random.default_rng([house.seed, 2512, k])
    if d.door_id not in house.semi_static:
        return _entity(d.door_id, "door", "door", ["open", "closed"], [[0] * 24] * 5, np.array([1.0, 1e-3]), 0, rng,
                       params, strength=1.0)
    night = [0] * 24
    start, n = int(rng.choice([22, 23, 0])), int(rng.integers(6, 10))
    for h in range(n):
        night[(start + h) % 24] = 1
    work = []
    for _ in range(_N_WORK):
        day = list(night)
        _paint(day, int(rng.integers(8, 19)), int(rng.integers(1, 4)), 1)
        work.append(day)
    return _entity(d.door_id, "door", "door", ["open", "closed"], work + [list(night), list(night)],
                   np.array([0.7, 0.3]), 0, rng, params)


def shifted_objects(house: HouseLayout, share: float) -> list[str]:
    """The ids of the moving objects whose test-week model is perturbed at shift ``share`` (module docstring)."""
    moving = [o.object_id for o in house.objects if o.role != "static"]
    rng = np.random.default_rng([house.seed, 2513])
    k = int(round(float(share) * len(moving)))
    return sorted(str(x) for x in rng.choice(moving, size=k, replace=False)) if k else []


def _perturbed(e: EntityProcess, rng: np.random.Generator) -> EntityProcess:
    """``e`` with its routines moved by 3-6 hours and its receptacles' roles permuted (no fixed point)."""
    recs = [i for i, s in enumerate(e.states) if s is not None]
    perm = np.arange(e.n_states)
    while len(recs) > 1:
        q = rng.permutation(recs)
        if np.all(q != np.asarray(recs)):
            perm[recs] = q
            break
    lag = int(rng.choice([-6, -5, -4, -3, 3, 4, 5, 6]))
    inv = np.argsort(perm)
    w = e.jump[0, 0][inv]  # the weight state perm[i] gets is the old weight of state i
    return EntityProcess(e.entity_id, e.kind, e.role, e.states, e.patterns, e.pattern_allowed, e.pattern_initial,
                         e.pattern_transition, e.state_initial, np.roll(perm[e.routine], lag, axis=1),
                         e.routine_strength, np.broadcast_to(w, e.jump.shape).copy(), e.dwell[:, inv, :].copy())


def house_process(house: HouseLayout, params: HouseProcessParams, start_date: dt.date, timezone: str,
                  days: int = 28) -> StepProcess:
    """The generating model of a house: the training model, plus (``params.shift > 0``) the test-week
    regime of the shifted objects (module docstring). ``process.base_model()`` is the training model.
    """
    ents = {o.object_id: _object(house, j, params) for j, o in enumerate(house.objects)}
    for k, d in enumerate(house.doors):
        ents[d.door_id] = _door(house, k, params)
    regimes: tuple[Regime, ...] = ()
    changed = shifted_objects(house, params.shift)
    if changed:
        rng = np.random.default_rng([house.seed, 2514])
        regimes = (Regime(TEST_DAY, "test-shift", {eid: _perturbed(ents[eid], rng) for eid in changed}),)
    return StepProcess(timezone, start_date, days, HOURS, ents, (), {
        "generator": "house-v1", "seed": house.seed, "routine_strength": params.routine_strength,
        "day_persistence": params.day_persistence, "max_dwell_steps": params.max_dwell_steps,
        "shift": params.shift, "shifted_objects": changed}, regimes)
