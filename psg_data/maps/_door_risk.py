"""Routes that weigh P(open): the expected-cost door rule (optimal recourse under independent doors).

The robot walks a grid (:class:`~psg_data.maps.PlanningCache`) towards a goal's approach set. Each
door has a predicted ``P(open)``, doors are independent, and the robot learns a door's state only
on arrival: a route through a door that turns out closed ends in front of it (where the door's
cells block the path), and the robot replans from there knowing that door closed. Doors it has
walked through are known open.

**The rule** (:func:`expected_cost_route`). A *route* is the shortest path under one assumption
about the doors still unknown (each assumed open or closed; known doors as known). Walking a route
under a realisation of the unknown doors ends at the goal, or in front of the first closed door
on it. The value of a state (robot cell, known doors) is

    V(x, K) = min over routes r of  sum_R P(R | K) * [ walked(r, R) + V(stop(r, R), K + learned(r, R)) ]

(``R`` the realisations of the unknown doors, independent ``P(open)``), and ``V = 0`` when no route
reaches the goal even with every unknown door open (the robot stops: the goal is unreachable).
The rule walks the minimising route: it minimises the expected walked distance over all policies
that reach the goal whenever the goal is reachable (the Canadian traveller's problem, solved
exactly by this recursion over the few doors of a building; 2^n routes and realisations for n
unknown doors, fine for n <= 6). It therefore never gives up on a goal that some route with
non-negligible P(open) reaches: doors with ``P(open) < min_p_open`` count as closed, doors with
``P(open) > 1 - min_p_open`` as open (they are still discovered closed on arrival when they are).

Compare the threshold rule (:func:`~psg_data.graph.doors_believed_open`): plan with every door of
``P(open) < threshold`` closed and give up when that leaves no path.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.maps._planner import PlanningCache

__all__ = ["DoorRoute", "expected_cost_route", "door_blocked_cells", "MIN_P_OPEN"]

MIN_P_OPEN = 0.01
"""Doors with P(open) below this count as closed (above ``1 - MIN_P_OPEN``: open) in the expected-cost rule."""

_MAX_UNKNOWN = 8


@dataclass(frozen=True)
class DoorRoute:
    """The route the expected-cost rule walks next.

    Attributes:
        path: flat cell indices from the start to the goal's approach set under :attr:`assumed_open`.
        expected_m: expected walked distance from the start to the end of the episode (goal reached
            or found unreachable) under the rule's policy, metres.
        assumed_open: door_id -> whether the route assumes it open (known doors as known).
        uncertain: the unknown doors the route passes, in the order it meets them.
    """

    path: NDArray[np.int64]
    expected_m: float
    assumed_open: dict[str, bool]
    uncertain: tuple[str, ...]


def door_blocked_cells(cache: PlanningCache, door: str) -> NDArray[np.bool_]:
    """(H*W,) flat cells that ``door`` alone blocks when closed (free with every door open, not free
    with ``door`` closed). With several doors closed the blocked cells are the union of theirs (the
    inflation of a union of obstacles is the union of their inflations).
    """
    doors = cache.grid.door_ids
    open_all = cache.free_flat(cache.key({x: True for x in doors}))
    return open_all & ~cache.free_flat(cache.key({x: x != door for x in doors}))


class _Solver:
    """Memoised recursion of the module docstring for one goal and one set of P(open)."""

    def __init__(self, cache: PlanningCache, goal: str, p_open: Mapping[str, float]) -> None:
        self.cache, self.goal = cache, goal
        self.doors = cache.grid.door_ids
        self.p = {d: float(p_open.get(d, 1.0)) for d in self.doors}
        self.memo: dict[tuple[int, tuple[int, ...]], tuple[float, DoorRoute | None]] = {}
        self.blocked = {d: door_blocked_cells(cache, d) for d in self.doors}

    def value(self, cell: int, known: tuple[int, ...]) -> tuple[float, DoorRoute | None]:
        """(V, best route) at ``cell`` with ``known`` (per door: 1 open, 0 closed, -1 unknown)."""
        key = (cell, known)
        if key in self.memo:
            return self.memo[key]
        unknown = [d for d, k in zip(self.doors, known) if k < 0]
        best: tuple[float, DoorRoute | None] = (0.0, None)
        seen: set[tuple[int, ...]] = set()
        for guess in itertools.product((True, False), repeat=len(unknown)):
            assume = {d: bool(k) for d, k in zip(self.doors, known) if k >= 0}
            assume.update(zip(unknown, guess))
            path = self.cache.path(self.goal, self.cache.key(assume), cell)
            if path is None:
                continue
            sig = tuple(path.tolist())
            if sig in seen:
                continue
            seen.add(sig)
            exp, order = self._expected(path, known, unknown)
            if best[1] is None or exp < best[0] - 1e-9:
                best = (exp, DoorRoute(path, exp, assume, order))
        self.memo[key] = best
        return best

    def _expected(self, path: NDArray[np.int64], known: tuple[int, ...], unknown: list[str]
                  ) -> tuple[float, tuple[str, ...]]:
        """Expected walked distance of walking ``path`` then following the rule; the unknown doors it meets."""
        cum = self.cache.step_lengths(path)
        first = {}
        for d in unknown:
            hit = np.flatnonzero(self.blocked[d][path])
            if hit.size:
                first[d] = int(hit[0])
        order = tuple(sorted(first, key=lambda d: first[d]))
        total, p_so_far = 0.0, 1.0
        idx = {d: i for i, d in enumerate(self.doors)}
        learned = list(known)
        for d in order:  # the route meets its uncertain doors in this order
            q = 1.0 - self.p[d]
            kb = first[d]
            stop = int(path[kb - 1]) if kb > 0 else int(path[0])
            after = list(learned)
            after[idx[d]] = 0
            v, _ = self.value(stop, tuple(after))
            total += p_so_far * q * (float(cum[kb - 1] if kb > 0 else 0.0) + v)
            p_so_far *= 1.0 - q
            learned[idx[d]] = 1  # walked through it: known open
        total += p_so_far * float(cum[-1])
        return total, order


def _known_from(p: Mapping[str, float], known: Mapping[str, bool], doors: tuple[str, ...], min_p_open: float
                ) -> tuple[int, ...]:
    out = []
    for d in doors:
        if d in known:
            out.append(int(bool(known[d])))
        elif p[d] < min_p_open:
            out.append(0)
        elif p[d] > 1.0 - min_p_open:
            out.append(1)
        else:
            out.append(-1)
    return tuple(out)


def expected_cost_route(cache: PlanningCache, goal: str, start: int, p_open: Mapping[str, float],
                        known: Mapping[str, bool] | None = None, *, min_p_open: float = MIN_P_OPEN
                        ) -> DoorRoute | None:
    """The route the expected-cost rule walks from ``start`` to ``goal`` (module docstring).

    Args:
        cache: planning cache of the grid (doors, receptacle approach sets).
        goal: receptacle id (its approach set is the goal).
        start: flat index of the robot's cell (row-major, ``row * W + col``).
        p_open: door_id -> predicted P(open) in [0, 1] (missing or NaN: 1, a door without a model).
        known: door_id -> state the robot has seen (overrides ``p_open``).
        min_p_open: P(open) below which a door counts as closed (above ``1 - min_p_open``: open).

    Returns:
        The route, or None when no route reaches the goal even with every door of non-negligible
        P(open) open (the rule gives up: the goal is unreachable as far as the robot can know).

    Raises:
        EvaluationError: a P(open) outside [0, 1], or more than 8 doors of uncertain state.
    """
    doors = cache.grid.door_ids
    p = {}
    for d in doors:
        v = float(p_open.get(d, 1.0))
        if math.isnan(v):
            v = 1.0
        if not 0.0 <= v <= 1.0:
            raise EvaluationError(f"P(open) of door {d!r}: {v}, expected in [0, 1]")
        p[d] = v
    k = _known_from(p, known or {}, doors, float(min_p_open))
    if sum(1 for x in k if x < 0) > _MAX_UNKNOWN:
        raise EvaluationError(f"expected_cost_route: {sum(1 for x in k if x < 0)} doors of uncertain state; "
                              f"the exact rule handles at most {_MAX_UNKNOWN}")
    solver = _Solver(cache, goal, p)
    return solver.value(int(start), k)[1]
