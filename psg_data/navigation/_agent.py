"""The navigation agent: rank receptacles by belief, walk to them, stop when the object is seen.

Episode (the paper's location-prediction and active-navigation tools):

1. Beliefs ``b_r`` of the target's edges at the current time come from the estimator's filters
   (one per (object, receptacle) edge). Candidates are the receptacles not tried yet with
   ``b_r >= delta``, ranked by belief (ties by receptacle id). If there is none the agent
   **aborts**: it reports the object absent (outcome ``abort``). If it has used
   ``max_attempts`` attempts it stops (outcome ``exhausted``).
2. Otherwise it walks towards the best candidate that is reachable under the door states it
   believes (``door_belief``; by default the true states at the query time). Candidates that are
   unreachable under the belief are skipped without spending an attempt. The path is a shortest
   path to the receptacle's approach set (cells within ``reach_m`` of it with line of sight).
3. While walking, if the path enters a cell that is blocked in reality (a door it believed open is
   closed), it stops in front of it, marks that door closed and replans (the walked distance
   counts). With ``detect_en_route`` it stops as soon as it stands in the approach set of the
   receptacle that really holds the object (the object is then within reach and visible).
4. Arriving at the candidate, it looks whether the object is there. If it sees it, it stops
   (outcome ``found``, or ``false_positive`` when the object is not really there). If not: in the
   ``adaptive`` setting it updates that edge's filter with ``y = 0`` at the current time (query
   time plus the walking time at ``speed_mps``) and recomputes all beliefs before the next
   decision; in the ``predictive`` setting beliefs stay those of the query time. Then back to 1.

Looking (on arrival, and when a path first enters the approach set of the receptacle that holds
the object, with ``detect_en_route``) goes through the environment's sighting model
(:class:`~psg_data.graph._sources.ObservationModel`): exact for ground-truth and privileged
labels, with the source's miss and false-positive rates for noisy or perception labels. A missed
object is walked past.

Success: the object is present and the final cell is in the approach set of its true receptacle
under the true door states (within ``reach_m`` = 1 m with line of sight on the grid).
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeFilter
from psg_data.graph._plan import ranked_candidates
from psg_data.graph._sources import ObservationModel
from psg_data.maps._planner import PlanningCache
from psg_data.navigation._queries import Query

__all__ = ["AgentConfig", "Episode", "run_episode", "episode_record", "SETTINGS", "OUTCOMES"]

log = logging.getLogger(__name__)

SETTINGS = ("predictive", "adaptive")
OUTCOMES = ("found", "false_positive", "abort", "exhausted", "no_path")


@dataclass(frozen=True)
class AgentConfig:
    """Agent settings.

    Attributes:
        setting: 'predictive' (beliefs of the query time) or 'adaptive' (observations update filters).
        delta: belief threshold below which a receptacle is not considered (the paper's 0.2).
        max_attempts: receptacles the agent may walk to (the paper's two attempts).
        detect_en_route: stop as soon as the object is within reach and in sight on the way.
        speed_mps: walking speed used to time observations in the adaptive setting, m/s.
    """

    setting: str = "predictive"
    delta: float = 0.2
    max_attempts: int = 2
    detect_en_route: bool = True
    speed_mps: float = 0.5

    def __post_init__(self) -> None:
        if self.setting not in SETTINGS:
            raise EvaluationError(f"setting: expected one of {SETTINGS}, got {self.setting!r}")
        if not 0.0 <= self.delta <= 1.0:
            raise EvaluationError(f"delta must be in [0, 1], got {self.delta}")
        if self.max_attempts < 1:
            raise EvaluationError(f"max_attempts must be >= 1, got {self.max_attempts}")
        if not self.speed_mps > 0:
            raise EvaluationError(f"speed_mps must be > 0, got {self.speed_mps}")


@dataclass
class Episode:
    """Outcome of one query for one method (a row of the per-query records).

    Lengths in metres; ``shortest_path_m`` is NaN for absent or unreachable targets.
    """

    query_id: int
    object_id: str
    category: str
    outcome: str
    success: bool
    aborted: bool
    path_m: float
    shortest_path_m: float
    reachable: bool
    n_attempts: int
    visited: list[str]
    predicted_receptacle: str | None
    best_belief: float
    final_xy: tuple[float, float]
    doors_discovered: list[str] = field(default_factory=list)
    beliefs: dict[str, float] = field(default_factory=dict)
    n_missed: int = 0
    trail: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)


def _predict(f: EdgeFilter, t_s: float) -> float:
    v = float(np.asarray(f.predict(np.array([t_s], dtype=np.float64))).reshape(-1)[0])
    if not math.isfinite(v):
        raise EvaluationError(f"filter of edge {getattr(f, 'edge', '?')} predicted {v} at t={t_s}")
    return min(max(v, 0.0), 1.0)


def true_shortest_path(cache: PlanningCache, query: Query) -> tuple[bool, float]:
    """(reachable, shortest path length in metres) from the start to the target's true receptacle
    under the true door states; (False, nan) for absent or unreachable targets.
    """
    if query.gt_receptacle is None:
        return False, float("nan")
    if query.gt_receptacle not in cache.grid.receptacle_cells:
        raise EvaluationError(f"query {query.query_id}: receptacle {query.gt_receptacle!r} not in the grid")
    cfg = cache.key(query.doors_open)
    W = cache.grid.shape[1]
    d = cache.distance(query.gt_receptacle, cfg, query.start_cell[0] * W + query.start_cell[1])
    return (True, d) if math.isfinite(d) else (False, float("nan"))


def _closed_doors_at(cache: PlanningCache, bel_doors: Mapping[str, bool], query: Query, cell: int) -> list[str]:
    """The doors believed open but closed that block ``cell`` (one if one explains it, else all of them)."""
    wrong = [d for d, o in bel_doors.items() if o and not query.doors_open.get(d, True)]
    for d in wrong:
        if not cache.free_flat(cache.key({**bel_doors, d: False}))[cell]:
            return [d]
    if not wrong:
        raise EvaluationError(f"query {query.query_id}: path blocked by a non-door cell {cell}")
    return wrong  # several doors together: learn all the closed ones


def run_episode(
    cache: PlanningCache,
    query: Query,
    filters: Mapping[str, EdgeFilter],
    config: AgentConfig,
    *,
    beliefs: Mapping[str, float] | None = None,
    door_belief: Mapping[str, bool] | None = None,
    observation: ObservationModel | None = None,
) -> Episode:
    """Run one query.

    Args:
        cache: planning cache of the environment's grid.
        query: the query.
        filters: receptacle_id -> filter of the edge (query.object_id, receptacle_id). In the
            adaptive setting they are copied before being updated (the caller's are untouched).
        config: agent settings.
        beliefs: precomputed beliefs at the query time (receptacle_id -> P(present)); default:
            predicted from ``filters``.
        door_belief: door states the agent plans with (default: the true states at the query time).
        observation: sighting model (default: exact sightings).

    Returns:
        The :class:`Episode`.
    """
    grid = cache.grid
    walk = _Walk(cache, query, config, door_belief, observation)
    adaptive = config.setting == "adaptive"
    if adaptive:
        filters = {r: copy.deepcopy(f) for r, f in filters.items()}
    if beliefs is None:
        bel = {r: _predict(f, query.t_s) for r, f in filters.items()}
    else:
        bel = {r: min(max(float(b), 0.0), 1.0) for r, b in beliefs.items()}
    bel = {r: b for r, b in bel.items() if r in grid.receptacle_cells}
    initial = dict(bel)
    pred_rec = min(bel, key=lambda r: (-bel[r], r)) if bel else None
    outcome = ""
    while not outcome:
        target, outcome = walk.next_target(bel)
        if target is None:
            break
        event = walk.go_to(target)
        if event == "found":
            outcome = "found"
            break
        if event == "unreachable":
            continue  # the target became unreachable once a closed door was seen: next candidate
        walk.visited.append(target)
        there = bool(walk.gt == target and walk.at_target())
        if walk.sees(target, there):
            outcome = "found"
            break
        walk.n_missed += int(there)
        if adaptive:
            t_now = query.t_s + walk.walked / config.speed_mps
            f = filters.get(target)
            if f is not None:
                f.update(t_now, 0)
            bel = {r: _predict(fl, t_now) for r, fl in filters.items() if r in grid.receptacle_cells}
    success = bool(outcome == "found" and walk.gt is not None and walk.at_target())
    if outcome == "found" and not success:
        outcome = "false_positive"
    reachable, l_star = true_shortest_path(cache, query)
    xy = grid.cell_to_world(divmod(walk.cur, grid.shape[1]))
    return Episode(
        query_id=query.query_id, object_id=query.object_id, category=query.category, outcome=outcome,
        success=success, aborted=outcome == "abort", path_m=walk.walked,
        shortest_path_m=l_star if reachable else float("nan"), reachable=reachable, n_attempts=walk.attempts,
        visited=walk.visited, predicted_receptacle=pred_rec,
        best_belief=float(initial[pred_rec]) if pred_rec is not None else 0.0,
        final_xy=(float(xy[0]), float(xy[1])), doors_discovered=walk.discovered, beliefs=initial,
        trail=np.concatenate(walk.trail), n_missed=walk.n_missed)


class _Walk:
    """One episode's agent: where it is, what it walked, tried and saw, and the doors it believes in."""

    def __init__(self, cache: PlanningCache, query: Query, config: AgentConfig,
                 door_belief: Mapping[str, bool] | None, observation: ObservationModel | None) -> None:
        grid = cache.grid
        self.cache, self.query, self.config = cache, query, config
        self.bel_doors = dict(query.doors_open if door_belief is None else door_belief)
        self.cfg_bel = cache.key(self.bel_doors)
        cfg_true = cache.key(query.doors_open)
        self.free_true = cache.free_flat(cfg_true)
        self.gt = query.gt_receptacle
        self.approach_true = (cache.approach(self.gt, cfg_true).ravel()
                              if self.gt is not None and self.gt in grid.receptacle_cells else None)
        self.model = observation or ObservationModel()
        self.rec_index = {r: k for k, r in enumerate(sorted(grid.receptacle_cells))}
        self.looks: dict[str, int] = {}
        self.cur = query.start_cell[0] * grid.shape[1] + query.start_cell[1]
        self.trail: list[NDArray[np.int64]] = [np.array([self.cur], dtype=np.int64)]
        self.walked = 0.0
        self.tried: list[str] = []
        self.visited: list[str] = []
        self.discovered: list[str] = []
        self.attempts = 0
        self.n_missed = 0

    def at_target(self) -> bool:
        """Whether the agent stands where the true receptacle can be seen."""
        return self.approach_true is not None and bool(self.approach_true[self.cur])

    def sees(self, rec: str, there: bool) -> bool:
        """The sighting model's answer at ``rec`` (its k-th look there)."""
        k = self.looks.get(rec, 0)
        self.looks[rec] = k + 1
        q = self.query
        return self.model.sees(there, (q.seed, q.query_id, self.rec_index.get(rec, -1), k))

    def next_target(self, bel: Mapping[str, float]) -> tuple[str | None, str]:
        """The most believed receptacle not tried yet that is reachable under the believed doors
        (one attempt spent), or None and why the episode ends.
        """
        cands = ranked_candidates(bel, self.config.delta, self.tried)
        if not cands:
            return None, "abort"
        if self.attempts >= self.config.max_attempts:
            return None, "exhausted"
        for r in cands:
            self.tried.append(r)
            if math.isfinite(self.cache.distance(r, self.cfg_bel, self.cur)):
                self.attempts += 1
                return r, ""
            # unreachable under the believed doors: skipped, no attempt spent
        return None, "no_path"

    def go_to(self, target: str) -> str:
        """Walk to ``target``, replanning at each closed door found (at most one replan per door);
        returns ``found`` (seen on the way), ``arrived`` or ``unreachable``.
        """
        cache, config = self.cache, self.config
        for _ in range(len(cache.grid.door_ids) + 1):
            path = cache.path(target, self.cfg_bel, self.cur)
            if path is None:
                break
            stop, event = path.size - 1, "arrived"
            blocked = np.flatnonzero(~self.free_true[path])
            kb = int(blocked[0]) if blocked.size else -1
            if kb >= 0:
                stop, event = kb - 1, "blocked"
            if config.detect_en_route and self.approach_true is not None and self.gt is not None:
                hits = np.flatnonzero(self.approach_true[path[: stop + 1]])
                if hits.size:
                    if self.sees(self.gt, True):
                        stop, event = int(hits[0]), "found"
                    else:
                        self.n_missed += 1
            seg = path[: stop + 1]
            self.walked += float(cache.step_lengths(seg)[-1])
            self.trail.append(seg[1:])
            self.cur = int(seg[-1])
            if event != "blocked":
                return event
            for d in _closed_doors_at(cache, self.bel_doors, self.query, int(path[kb])):
                self.bel_doors[d] = False
                self.discovered.append(d)
            self.cfg_bel = cache.key(self.bel_doors)
        return "unreachable"


def episode_record(ep: Episode, **extra: Any) -> dict[str, Any]:
    """Flat dict of an episode for the records table (lists as JSON strings, no trail)."""
    import json

    return {**extra, "query_id": ep.query_id, "object_id": ep.object_id, "category": ep.category,
            "outcome": ep.outcome, "success": ep.success, "aborted": ep.aborted, "path_m": ep.path_m,
            "shortest_path_m": ep.shortest_path_m, "reachable": ep.reachable, "n_attempts": ep.n_attempts,
            "visited": json.dumps(ep.visited), "predicted_receptacle": ep.predicted_receptacle,
            "best_belief": ep.best_belief, "final_x_m": ep.final_xy[0], "final_y_m": ep.final_xy[1],
            "doors_discovered": json.dumps(ep.doors_discovered), "n_missed": ep.n_missed}
