"""The adaptive agent of the simulation benchmark: it looks while it walks, updates its filters and may switch targets.

The paper's "Navigate to Receptacle" tool: "During navigation, the agent continuously: (1) executes
path planning toward the receptacle, (2) updates [the graph] with RGBD observations, and (3) checks
whether the target object is in view. Navigation terminates when either the object is found or the
target receptacle is reached"; and its adaptive experiment, "the agent can dynamically switch
targets during navigation by consuming new observations". :func:`run_adaptive_episode` does this:

1. Beliefs ``b_r`` of the target's edges at the current time ``t`` (query time plus walking time at
   ``speed_mps``). Candidates: receptacles with ``b_r >= delta``, most believed first; with
   ``memory="visits"`` the receptacles already inspected in this episode are left out, with
   ``memory="estimator"`` they are not (the filters' beliefs, updated by what the agent saw, are its
   only memory: an estimator that does not move on a ``y = 0`` may send it back). No belief at or
   above delta: **abort** (the object is reported absent; Tool 2, "If no receptacle exceeds the
   threshold, the object is reported as absent"). Candidates above delta but all inspected (``visits``
   only): with ``absence="delta"`` the agent stops without declaring absence (``exhausted``), with
   ``absence="list-exhausted"`` it declares the object absent (``abort``), a rule the paper does not
   state.
2. The agent walks the shortest path (A* field of the planning cache, true door states: the
   ``sim`` protocols' door rule) towards the best candidate in steps of ``look_every_m``.
3. After each step it looks (:class:`HouseSight`: line of sight through open doorways, as the
   privileged labels' sensor, within AI2-THOR's object visibility distance of 1.5 m): every
   receptacle of the target's edges that comes into view for the first time in the episode
   updates its filter with ``y = 1`` if the object is on it and ``y = 0`` if not (one observation
   per receptacle per episode: the state does not change during an episode, so repeated looks add
   no information, only double counting).
   Beliefs are recomputed; if another receptacle is now the best candidate the agent switches
   (``n_switches``; a switch spends no attempt). If the object itself is in view the agent goes to
   the receptacle holding it (even one outside its edges: it has seen it).
4. Success: the agent stands within ``reach_m`` of the object's receptacle with a line of sight
   (the approach set, as in :mod:`._agent`) and the object is present: it stops there (outcome
   ``found``).
5. Arriving at a candidate that does not hold the object spends one attempt (the paper's "up to two
   attempts"); after ``max_attempts`` such arrivals it stops (``exhausted``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeFilter
from psg_data.graph._plan import ranked_candidates
from psg_data.maps._planner import PlanningCache
from psg_data.navigation._agent import AgentConfig, Episode, true_shortest_path
from psg_data.navigation._queries import Query

__all__ = ["HouseSight", "run_adaptive_episode", "AGENT_MEMORIES", "ABSENCE_RULES"]

AGENT_MEMORIES = ("visits", "estimator")
"""Does the agent remember the receptacles it inspected (``visits``) or only its filters' beliefs (``estimator``)."""
ABSENCE_RULES = ("delta", "list-exhausted")
"""When the object is declared absent: no belief at or above delta, or also when every candidate is inspected."""


@dataclass
class HouseSight:
    """What the robot sees from a point: receptacles in line of sight within ``range_m``.

    Attributes:
        layout: the house (:class:`psg_data.synth.HouseLayout`): its ``visible(points, targets,
            door_open)`` is the line of sight of the privileged labels' patrol sensor (walls and
            closed doors block).
        receptacle_xy: receptacle id -> (x, y) centre, metres.
        range_m: how far the agent sees an object on a receptacle, metres: AI2-THOR's
            ``visibilityDistance`` default, 1.5 m (an object is visible when in frame, within that
            distance and not obstructed; AI2-THOR documentation, "Concepts").
    """

    layout: Any
    receptacle_xy: dict[str, tuple[float, float]]
    range_m: float = 1.5

    @classmethod
    def of_house(cls, layout: Any, range_m: float = 1.5) -> HouseSight:
        """The sight of a :class:`psg_data.synth.HouseLayout` (receptacle centres from its boxes)."""
        return cls(layout, {r.receptacle_id: (float(r.box.center_m[0]), float(r.box.center_m[1]))
                            for r in layout.receptacles}, range_m)

    def visible(self, xy: Sequence[float] | NDArray[np.float64], receptacles: Sequence[str],
                door_open: Mapping[str, bool]) -> set[str]:
        """The receptacles among ``receptacles`` in sight of ``xy`` (metres) under ``door_open``."""
        recs = [r for r in receptacles if r in self.receptacle_xy]
        if not recs:
            return set()
        p = np.asarray(xy, float).reshape(1, 2)
        targets = np.array([self.receptacle_xy[r] for r in recs], float)
        near = np.linalg.norm(targets - p, axis=1) <= self.range_m
        seen = self.layout.visible(p, targets, dict(door_open))[0] & near
        return {r for r, s in zip(recs, seen) if s}


def _predict(f: EdgeFilter, t_s: float) -> float:
    v = float(np.asarray(f.predict(np.array([t_s], dtype=np.float64))).reshape(-1)[0])
    return min(max(v, 0.0), 1.0) if math.isfinite(v) else 0.0


class _Walker:
    """Position, distance walked, trail, and one look per receptacle."""

    def __init__(self, cache: PlanningCache, query: Query, config: AgentConfig, sight: HouseSight,
                 look_every_m: float) -> None:
        g = cache.grid
        self.cache, self.q, self.cfg, self.sight, self.step_m = cache, query, config, sight, look_every_m
        self.W = g.shape[1]
        self.doors = cache.key(query.doors_open)
        self.gt = query.gt_receptacle
        self.approach_true = (cache.approach(self.gt, self.doors).ravel()
                              if self.gt is not None and self.gt in g.receptacle_cells else None)
        self.cur = query.start_cell[0] * self.W + query.start_cell[1]
        self.walked = 0.0
        self.trail: list[NDArray[np.int64]] = [np.array([self.cur], np.int64)]
        self.looked: set[str] = set()

    @property
    def t(self) -> float:
        return self.q.t_s + self.walked / self.cfg.speed_mps

    def at_object(self) -> bool:
        return self.approach_true is not None and bool(self.approach_true[self.cur])

    def step(self, target: str) -> str:
        """Walk up to ``look_every_m`` towards ``target``: ``moved``, ``arrived``, ``at_object`` or ``no_path``."""
        path = self.cache.path(target, self.doors, self.cur)
        if path is None:
            return "no_path"
        if path.size <= 1:
            return "at_object" if self.at_object() else "arrived"
        lengths = self.cache.step_lengths(path)
        stop = int(np.searchsorted(lengths, self.step_m, side="left"))
        stop = min(max(stop, 1), path.size - 1)
        if self.approach_true is not None:
            hits = np.flatnonzero(self.approach_true[path[1: stop + 1]])
            if hits.size:
                stop = int(hits[0]) + 1
        self.walked += float(lengths[stop])
        self.trail.append(path[1: stop + 1])
        self.cur = int(path[stop])
        if self.at_object():
            return "at_object"
        return "arrived" if stop == path.size - 1 else "moved"

    def look(self, filters: Mapping[str, EdgeFilter]) -> bool:
        """Update the filters of newly seen receptacles; True when the object itself is in view."""
        xy = self.cache.grid.cell_to_world(divmod(self.cur, self.W))
        cands = list(filters) + ([self.gt] if self.gt is not None and self.gt not in filters else [])
        seen = self.sight.visible(xy, cands, self.q.doors_open)
        t = self.t
        for r in sorted(seen - self.looked):
            if r in filters:
                filters[r].update(t, int(r == self.gt))
        self.looked |= seen
        return self.gt is not None and self.gt in seen


def _next_target(bel: Mapping[str, float], config: AgentConfig, inspected: Sequence[str], blocked: set[str],
                 cache: PlanningCache, w: _Walker, memory: str, absence: str) -> tuple[str | None, str]:
    """(the best reachable candidate, "") or (None, the outcome that ends the episode): step 1 of the module
    docstring.
    """
    above = ranked_candidates(bel, config.delta)
    if not above:
        return None, "abort"
    ranked = [r for r in above if r not in inspected] if memory == "visits" else above
    if not ranked:
        return None, "abort" if absence == "list-exhausted" else "exhausted"
    cands = [r for r in ranked if r not in blocked and math.isfinite(cache.distance(r, w.doors, w.cur))]
    if not cands:
        return None, "no_path"
    return cands[0], ""


def run_adaptive_episode(cache: PlanningCache, query: Query, filters: Mapping[str, EdgeFilter], config: AgentConfig,
                         sight: HouseSight, *, look_every_m: float = 1.0, memory: str = "visits",
                         absence: str = "delta") -> tuple[Episode, int]:
    """One query with looking, belief updates and target switching (module docstring).

    Args:
        cache: planning cache of the scene's grid.
        query: the query (true door states in ``doors_open``).
        filters: receptacle id -> the filter of edge (query.object_id, receptacle); **updated in place**
            (pass copies).
        config: delta, max_attempts, speed_mps (its ``setting`` is ignored: this agent is adaptive).
        sight: what the robot sees from a point.
        look_every_m: metres walked between looks.
        memory: ``visits`` or ``estimator`` (:data:`AGENT_MEMORIES`, module docstring).
        absence: ``delta`` or ``list-exhausted`` (:data:`ABSENCE_RULES`, module docstring).

    Returns:
        (the :class:`~psg_data.navigation.Episode`, the number of target switches).
    """
    if memory not in AGENT_MEMORIES or absence not in ABSENCE_RULES:
        raise EvaluationError(f"memory / absence: expected one of {AGENT_MEMORIES} / {ABSENCE_RULES}, "
                              f"got {memory!r} / {absence!r}")
    grid = cache.grid
    w = _Walker(cache, query, config, sight, look_every_m)
    known = {r: f for r, f in filters.items() if r in grid.receptacle_cells}
    bel0 = {r: _predict(f, query.t_s) for r, f in known.items()}
    pred = min(bel0, key=lambda r: (-bel0[r], r)) if bel0 else None
    inspected: list[str] = []
    blocked: set[str] = set()
    attempts = switches = 0
    target: str | None = None
    seen_object = w.look(known)
    outcome = ""
    for _ in range(100000):
        if w.at_object():
            outcome = "found"
            break
        nxt: str | None = w.gt if seen_object and w.gt not in inspected else None
        if nxt is None:
            bel = {r: _predict(f, w.t) for r, f in known.items()}
            nxt, end = _next_target(bel, config, inspected, blocked, cache, w, memory, absence)
            if nxt is None:
                outcome = end
                break
            if attempts >= config.max_attempts:
                outcome = "exhausted"
                break
        if target is not None and nxt != target:
            switches += 1
        target = nxt
        event = w.step(target)
        if event == "no_path":
            inspected.append(target)
            blocked.add(target)  # not an observation: left out whatever the memory
            continue
        if event == "at_object":
            outcome = "found"
            break
        seen_object = w.look(known) or seen_object
        if event == "arrived":
            inspected.append(target)
            attempts += 1
            f = known.get(target)
            if f is not None and target not in w.looked:
                f.update(w.t, 0)
                w.looked.add(target)
    success = bool(outcome == "found" and w.gt is not None and w.at_object())
    reachable, l_star = true_shortest_path(cache, query)
    xy = grid.cell_to_world(divmod(w.cur, grid.shape[1]))
    ep = Episode(query_id=query.query_id, object_id=query.object_id, category=query.category, outcome=outcome,
                 success=success, aborted=outcome == "abort", path_m=w.walked,
                 shortest_path_m=l_star if reachable else float("nan"), reachable=reachable, n_attempts=attempts,
                 visited=inspected, predicted_receptacle=pred, best_belief=float(bel0[pred]) if pred else 0.0,
                 final_xy=(float(xy[0]), float(xy[1])), beliefs=bel0, trail=np.concatenate(w.trail))
    return ep, switches
