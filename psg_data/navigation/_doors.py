"""Door-aware navigation: plan with predicted door states, replan at closed doors, report the cost.

A door is a semi-static "object" whose "receptacles" are its states; an estimator fitted on the
door streams (the ``(door_id, 'open')`` edges, :func:`psg_data.labeling.load_label_streams` with
``doors="only"``) predicts ``P(open)`` per door at the query time (:func:`door_open_probabilities`).

Episode (:func:`run_door_episode`): the robot plans a shortest path to the goal receptacle's
approach set with every door whose ``P(open) < threshold`` closed (default 0.5). If that leaves no
path, by default (``no_path="decline"``) it does not go: it reports the goal unreachable (correct
when a door on every route is closed, a failure otherwise); with ``no_path="optimistic"`` it
falls back to assuming the doors it has not seen closed are open. It walks the plan; when the
next cell is blocked in reality (a closed door), it stops in front of it, marks that door closed
and replans from there (the walked distance counts). The *first plan* is *blocked* when it runs
into a door that is closed at the query time. Success: the robot reaches the goal's approach
set. Extra distance: walked minus the shortest path under the true door states (successful
episodes). Wasted distance: metres walked towards goals that no route reaches at the query time
(ideal 0: the planner that knows the doors does not set off).

With ``rule="expected_cost"`` the episode walks the route of :func:`psg_data.maps.expected_cost_route`
instead: P(open) is used as a probability (the route of least expected walked distance when doors
are discovered on arrival), the robot learns each door it reaches or walks through and replans, and it
gives up only when no route with non-negligible P(open) is left.

:func:`run_door_navigation` runs every method on the same queries and returns the table
(estimator, queries, blocked_first_plans, blocked_rate, mean_extra_distance_m, SR, SPL); the
methods are registry estimators plus the baselines ``all_open`` (assume every door open) and
``oracle`` (the true door states). Worlds: :meth:`DoorWorld.from_dataset` (a dataset's own grid,
doors, door states and door streams of a label source) and :func:`door_loop_world` (a unit-test
world: two rooms joined by a direct door and by an always-open hallway, the direct door following
the synthetic lab's weekly door schedule). :func:`plot_door_query` draws the paper's "Predictive
Navigation" figure.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeStream
from psg_data.estimators._guard import PluginError
from psg_data.graph._fit import door_open_probabilities, fit_door_filters
from psg_data.graph._graph import PredictiveGraph
from psg_data.graph._layout import SceneLayout
from psg_data.graph._snapshot import doors_believed_open
from psg_data.maps._grid import OccupancyGrid, grid_from_geometry
from psg_data.maps._planner import PlanningCache

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["DOOR_BASELINES", "DOOR_RULES", "DoorWorld", "DoorQuery", "DoorEpisode", "DoorNavigationResult",
           "fit_door_filters", "door_open_probabilities", "run_door_episode", "make_door_queries",
           "run_door_navigation", "door_loop_world", "plot_door_query"]

log = logging.getLogger(__name__)

DOOR_BASELINES = ("all_open", "oracle")
TABLE_COLUMNS = ("estimator", "queries", "blocked_first_plans", "blocked_rate", "mean_extra_distance_m", "SR", "SPL")
NO_PATH_RULES = ("decline", "optimistic")
DOOR_RULES = ("threshold", "expected_cost")
"""How the agent uses P(open): ``threshold`` (plan with doors of P < threshold closed) or
``expected_cost`` (:func:`psg_data.maps.expected_cost_route`: minimise the expected walked distance)."""


@dataclass
class DoorWorld:
    """A navigation world with doors whose states change over time.

    Attributes:
        grid: occupancy grid (doorways switchable).
        doors_at: ``t_s -> {door_id: is_open}``, the true door states (t_s: Unix seconds UTC).
        train_streams: door observations up to ``t_train_end_s`` (``(door_id, 'open')`` edges;
            ``'closed'`` edges are ignored).
        t_train_end_s: end of the training window (queries come after it), Unix seconds.
        t_end_s: end of the query window, Unix seconds.
        timezone: IANA site timezone.
        start_cells: room name -> (N, 2) candidate start cells (row, col).
        goals: room name -> receptacle ids in that room (query goals).
        name: label of the world.
        hours: local hours ``[lo, hi)`` of the query times (the robot's operating hours), or None
            for any time of day.
        info: provenance (dataset, label source, where the door streams came from).
    """

    grid: OccupancyGrid
    doors_at: Callable[[float], dict[str, bool]]
    train_streams: list[EdgeStream]
    t_train_end_s: float
    t_end_s: float
    timezone: str
    start_cells: dict[str, NDArray[np.int64]]
    goals: dict[str, list[str]]
    name: str = "doors"
    hours: tuple[float, float] | None = (9.0, 16.0)
    info: dict[str, Any] = field(default_factory=dict)
    _cache: PlanningCache | None = field(default=None, repr=False)

    @classmethod
    def from_dataset(cls, dataset: Any, **kwargs: Any) -> DoorWorld:
        """The door world of a psg-dataset (see :func:`psg_data.navigation.door_world_from_dataset`)."""
        from psg_data.navigation._door_dataset import door_world_from_dataset

        return door_world_from_dataset(dataset, **kwargs)

    @property
    def cache(self) -> PlanningCache:
        """The planning cache of the world's grid, built on first use."""
        if self._cache is None:
            self._cache = PlanningCache(self.grid)
        return self._cache

    @property
    def door_ids(self) -> tuple[str, ...]:
        """Door ids of the grid."""
        return self.grid.door_ids


@dataclass(frozen=True)
class DoorQuery:
    """One query: walk from ``start_cell`` to ``goal`` (a receptacle's approach set) at ``t_s``."""

    query_id: int
    t_s: float
    start_cell: tuple[int, int]
    goal: str
    doors_open: dict[str, bool]


@dataclass
class DoorEpisode:
    """Outcome of one query for one method; lengths in metres (``shortest_m`` NaN when unreachable)."""

    query_id: int
    method: str
    success: bool
    first_plan_blocked: bool
    walked_m: float
    shortest_m: float
    n_replans: int
    fallback: bool
    declined: bool
    p_open: dict[str, float]
    doors_discovered: list[str]
    first_plan: NDArray[np.int64] = field(repr=False)
    trail: NDArray[np.int64] = field(repr=False)

    @property
    def extra_m(self) -> float:
        """Metres walked beyond the shortest path of a successful episode (NaN otherwise)."""
        if not (self.success and math.isfinite(self.shortest_m)):
            return float("nan")
        d = self.walked_m - self.shortest_m
        return 0.0 if abs(d) < 1e-6 else d  # float round-off of two sums of the same steps


def run_door_episode(cache: PlanningCache, query: DoorQuery, p_open: Mapping[str, float], *,
                     threshold: float = 0.5, method: str = "", no_path: str = "decline",
                     rule: str = "threshold") -> DoorEpisode:
    """Run one door-aware query (module docstring).

    Args:
        cache: planning cache of the grid.
        query: the query (its ``doors_open`` is the truth).
        p_open: door_id -> predicted P(open) (missing doors count as open, P = 1).
        threshold: doors with ``P(open) < threshold`` are planned as closed.
        method: label stored in the episode.
        no_path: what to do when the believed doors leave no path: ``decline`` (stop, report the
            goal unreachable) or ``optimistic`` (assume the doors not seen closed are open).
        rule: ``threshold`` (above) or ``expected_cost`` (:func:`psg_data.maps.expected_cost_route`;
            ``threshold`` and ``no_path`` are then unused: it gives up only when no route with
            non-negligible P(open) is left).
    """
    if no_path not in NO_PATH_RULES:
        raise EvaluationError(f"no_path: expected one of {NO_PATH_RULES}, got {no_path!r}")
    if rule not in DOOR_RULES:
        raise EvaluationError(f"rule: expected one of {DOOR_RULES}, got {rule!r}")
    if rule == "expected_cost":
        return _expected_cost_episode(cache, query, p_open, method)
    grid = cache.grid
    W = grid.shape[1]
    doors = grid.door_ids
    truth = {d: bool(query.doors_open.get(d, True)) for d in doors}
    cfg_true = cache.key(truth)
    free_true = cache.free_flat(cfg_true)
    start = int(query.start_cell[0] * W + query.start_cell[1])
    shortest = cache.distance(query.goal, cfg_true, start)
    shortest = shortest if math.isfinite(shortest) else float("nan")
    known_closed: set[str] = set()
    cur, walked, n_replans = start, 0.0, 0
    trail: list[NDArray[np.int64]] = [np.array([cur], np.int64)]
    first_plan: NDArray[np.int64] | None = None
    first_blocked = False
    fallback_used = False
    declined = False
    success = False
    planned = doors_believed_open({d: float(p_open.get(d, 1.0)) for d in doors}, threshold)
    for _ in range(len(doors) + 1):
        belief = {d: planned[d] and d not in known_closed for d in doors}
        path = cache.path(query.goal, cache.key(belief), cur)
        if path is None and no_path == "decline":
            declined = first_plan is None
            break
        if path is None:
            optimistic = {d: d not in known_closed for d in doors}
            path = cache.path(query.goal, cache.key(optimistic), cur)
            fallback_used = fallback_used or path is not None
            belief = optimistic
        if path is None:
            break
        blocked = np.flatnonzero(~free_true[path])
        if first_plan is None:
            first_plan = path
            first_blocked = bool(blocked.size)
        if not blocked.size:
            walked += float(cache.step_lengths(path)[-1])
            trail.append(path[1:])
            cur = int(path[-1])
            success = True
            break
        kb = int(blocked[0])
        seg = path[:kb]
        walked += float(cache.step_lengths(seg)[-1]) if seg.size else 0.0
        trail.append(seg[1:])
        cur = int(seg[-1]) if seg.size else cur
        cell = int(path[kb])
        culprits = [d for d in doors if belief[d] and not truth[d]
                    and not cache.free_flat(cache.key({**belief, d: False}))[cell]]
        if not culprits:
            culprits = [d for d in doors if belief[d] and not truth[d]]
        if not culprits:
            raise EvaluationError(f"door query {query.query_id}: path blocked by a non-door cell {cell}")
        known_closed.update(culprits)
        n_replans += 1
    return DoorEpisode(query.query_id, method, success, first_blocked, walked, shortest, n_replans, fallback_used,
                       declined, {d: float(p_open.get(d, 1.0)) for d in doors}, sorted(known_closed),
                       first_plan if first_plan is not None else np.zeros(0, np.int64), np.concatenate(trail))


def _expected_cost_episode(cache: PlanningCache, query: DoorQuery, p_open: Mapping[str, float],
                           method: str) -> DoorEpisode:
    """:func:`run_door_episode` with the expected-cost rule: walk its route, learn doors on arrival, replan."""
    from psg_data.maps._door_risk import door_blocked_cells, expected_cost_route

    W = cache.grid.shape[1]
    doors = cache.grid.door_ids
    truth = {d: bool(query.doors_open.get(d, True)) for d in doors}
    free_true = cache.free_flat(cache.key(truth))
    start = int(query.start_cell[0] * W + query.start_cell[1])
    shortest = cache.distance(query.goal, cache.key(truth), start)
    shortest = shortest if math.isfinite(shortest) else float("nan")
    p = {d: float(p_open.get(d, 1.0)) for d in doors}
    known: dict[str, bool] = {}
    cur, walked, n_replans, success, declined = start, 0.0, 0, False, False
    trail: list[NDArray[np.int64]] = [np.array([cur], np.int64)]
    first_plan: NDArray[np.int64] | None = None
    first_blocked = False
    for _ in range(len(doors) + 1):
        route = expected_cost_route(cache, query.goal, cur, p, known)
        if route is None:
            declined = first_plan is None
            break
        path = route.path
        blocked = np.flatnonzero(~free_true[path])
        if first_plan is None:
            first_plan, first_blocked = path, bool(blocked.size)
        seg = path if not blocked.size else path[:int(blocked[0])]
        for d in doors:  # doors walked through (their cells passed) are seen open
            if truth[d] and seg.size and door_blocked_cells(cache, d)[seg].any():
                known[d] = True
        walked += float(cache.step_lengths(seg)[-1]) if seg.size else 0.0
        trail.append(seg[1:])
        cur = int(seg[-1]) if seg.size else cur
        if not blocked.size:
            success = True
            break
        cell = int(path[int(blocked[0])])
        culprits = [d for d in doors if not truth[d] and door_blocked_cells(cache, d)[cell]]
        if not culprits:
            raise EvaluationError(f"door query {query.query_id}: path blocked by a non-door cell {cell}")
        known.update({d: False for d in culprits})
        n_replans += 1
    return DoorEpisode(query.query_id, method, success, first_blocked, walked, shortest, n_replans, False,
                       declined, p, sorted(d for d, v in known.items() if not v),
                       first_plan if first_plan is not None else np.zeros(0, np.int64), np.concatenate(trail))


def _open_plan_blocked(cache: PlanningCache, query: DoorQuery) -> bool:
    """Whether the shortest path with every door open meets a door closed at the query time (the query's
    shortest route is cut: door knowledge can save distance on it).
    """
    W = cache.grid.shape[1]
    start = int(query.start_cell[0] * W + query.start_cell[1])
    path = cache.path(query.goal, cache.key({d: True for d in cache.grid.door_ids}), start)
    if path is None:
        return False
    free = cache.free_flat(cache.key({d: bool(query.doors_open.get(d, True)) for d in cache.grid.door_ids}))
    return bool((~free[path]).any())


def make_door_queries(world: DoorWorld, n: int, *, seed: int = 0, hours: tuple[float, float] | None | str = "world"
                      ) -> list[DoorQuery]:
    """Seeded queries after the training window: a start cell in one room, a goal in another room.

    Args:
        world: the world.
        n: number of queries.
        seed: random seed.
        hours: local hours ``[lo, hi)`` of the query times (the robot's operating hours); None =
            any time of day; default ``"world"``: the world's :attr:`DoorWorld.hours`.
    """
    if isinstance(hours, str):
        if hours != "world":
            raise EvaluationError(f"hours: expected (lo, hi), None or 'world', got {hours!r}")
        hours = world.hours
    import datetime as dt
    from zoneinfo import ZoneInfo

    rng = np.random.default_rng([int(seed), 4242])
    tz = ZoneInfo(world.timezone)
    rooms = sorted(r for r in world.start_cells if len(world.start_cells[r]))
    goal_rooms = sorted(r for r in world.goals if world.goals[r])
    if len(rooms) < 1 or len(set(rooms) | set(goal_rooms)) < 2:
        raise EvaluationError("make_door_queries: the world needs start cells and goals in two rooms")
    d0 = dt.datetime.fromtimestamp(world.t_train_end_s, tz).date()
    d1 = dt.datetime.fromtimestamp(world.t_end_s, tz).date()
    n_days = max((d1 - d0).days, 1)
    out: list[DoorQuery] = []
    k = 0
    while len(out) < n:
        k += 1
        if k > 100 * n + 100:
            raise EvaluationError("make_door_queries: could not sample queries inside the query window")
        day = d0 + dt.timedelta(days=int(rng.integers(n_days)))
        h = float(rng.uniform(*hours)) if hours is not None else float(rng.uniform(0.0, 24.0))
        t = dt.datetime.combine(day, dt.time()).replace(tzinfo=tz) + dt.timedelta(hours=h)
        t_s = t.timestamp()
        room = rooms[int(rng.integers(len(rooms)))]
        others = [r for r in goal_rooms if r != room]
        if not others or not (world.t_train_end_s <= t_s < world.t_end_s):
            continue
        goal_room = others[int(rng.integers(len(others)))]
        goal = world.goals[goal_room][int(rng.integers(len(world.goals[goal_room])))]
        cells = world.start_cells[room]
        c = cells[int(rng.integers(len(cells)))]
        out.append(DoorQuery(len(out), float(t_s), (int(c[0]), int(c[1])), goal, dict(world.doors_at(t_s))))
    return out


@dataclass
class DoorNavigationResult:
    """Output of :func:`run_door_navigation`.

    Attributes:
        table: one row per method (``TABLE_COLUMNS`` plus ``n_reachable``, ``mean_walked_m``,
            ``unseen_doors``); rates are fractions in [0, 1].
        records: one row per (method, query).
        queries: the queries.
        episodes: method -> episodes (same order as ``queries``).
        p_open: method -> per-query P(open) dicts.
        errors: per failed plugin estimator its failure (``estimator``, ``stage``, ``message``); its
            rows are left out, the other methods are scored.
    """

    table: Any
    records: Any
    queries: list[DoorQuery]
    episodes: dict[str, list[DoorEpisode]]
    p_open: dict[str, list[dict[str, float]]]
    errors: list[dict[str, Any]] = field(default_factory=list)

    def format_table(self) -> str:
        """The results as a plain-text table."""
        t = self.table.copy()
        for c in ("blocked_rate", "SR", "SPL"):
            t[c] = (100 * t[c]).round(1)
        t["mean_extra_distance_m"] = t["mean_extra_distance_m"].round(2)
        return t[list(TABLE_COLUMNS)].to_string(index=False)


def _door_methods(world: DoorWorld, estimators: Sequence[Any], baselines: Sequence[str], unseen_prior: float,
                  settings: Mapping[str, Mapping[str, Any]] | None, errors: list[dict[str, Any]]
                  ) -> list[tuple[str, Callable[[DoorQuery], dict[str, float]], list[str]]]:
    """(label, query -> P(open) per door, doors without observations) for every method; a plugin
    whose fit fails is left out and its failure appended to ``errors``.
    """
    bad = [b for b in baselines if b not in DOOR_BASELINES]
    if bad:
        raise EvaluationError(f"baselines {bad}: expected any of {DOOR_BASELINES}")
    doors = world.door_ids
    methods: list[tuple[str, Callable[[DoorQuery], dict[str, float]], list[str]]] = []
    for b in baselines:
        if b == "all_open":
            methods.append(("all_open", lambda q: {d: 1.0 for d in doors}, []))
        else:
            methods.append(("oracle", lambda q: {d: float(q.doors_open.get(d, True)) for d in doors}, []))
    for e in estimators:
        label, est = (e if isinstance(e, tuple) else (e if isinstance(e, str) else type(e).__name__, e))
        try:
            graph = PredictiveGraph(SceneLayout(timezone=world.timezone), {}).with_door_model(
                est, world.train_streams, settings=(settings or {}).get(str(label)), unseen_prior=unseen_prior,
                door_ids=doors)
        except PluginError as exc:
            errors.append(exc.record(str(label)))
            continue
        unseen = [d for d, k in graph.door_kinds.items() if k == "prior"]
        if unseen:
            log.info("%s: doors without training observations use P(open) = %s: %s", label, unseen_prior, unseen)

        def belief(q: DoorQuery, graph: PredictiveGraph = graph) -> dict[str, float]:
            return graph.door_open_probabilities(q.t_s, prior=unseen_prior)

        methods.append((str(label), belief, unseen))
    return methods


def _door_row(label: str, eps: Sequence[DoorEpisode], unseen: Sequence[str]) -> dict[str, Any]:
    """One row of the door table (module docstring)."""
    from psg_data.metrics import spl, success_rate

    reach = np.array([math.isfinite(e.shortest_m) for e in eps])
    succ = np.array([e.success for e in eps])[reach]
    short = np.array([e.shortest_m for e in eps])[reach]
    walk_all = np.array([e.walked_m for e in eps])
    walk = walk_all[reach]
    extra = np.array([e.extra_m for e in eps])
    extra = extra[np.isfinite(extra)]
    nb = int(sum(e.first_plan_blocked for e in eps))
    return {"estimator": label, "queries": len(eps), "blocked_first_plans": nb,
            "blocked_rate": nb / len(eps), "mean_extra_distance_m": float(extra.mean()) if extra.size else 0.0,
            "SR": success_rate(succ) if succ.size else float("nan"),
            "SPL": spl(succ, short, walk) if succ.size else float("nan"),
            "n_reachable": int(reach.sum()), "declined": int(sum(e.declined for e in eps)),
            "declined_reachable": int(sum(e.declined for e, r in zip(eps, reach) if r)),
            "wasted_m": float(walk_all[~reach].mean()) if (~reach).any() else 0.0,
            "mean_walked_m": float(walk.mean()) if walk.size else 0.0, "unseen_doors": ",".join(unseen)}


def run_door_navigation(world: DoorWorld, estimators: Sequence[Any] = ("perpetua_star", "time_of_week_frequency"),
                        *, n_queries: int = 200, seed: int = 0, threshold: float = 0.5,
                        hours: tuple[float, float] | None | str = "world", baselines: Sequence[str] = DOOR_BASELINES,
                        queries: Sequence[DoorQuery] | None = None, unseen_prior: float = 0.5,
                        settings: Mapping[str, Mapping[str, Any]] | None = None,
                        no_path: str = "decline", rules: Sequence[str] = ("threshold",)) -> DoorNavigationResult:
    """Every method on the same door queries; the small comparison table.

    Args:
        world: the world (grid, true door states, training streams).
        estimators: registry names (or ``(label, estimator)`` pairs) predicting P(open) per door.
        n_queries: queries to sample (:func:`make_door_queries`).
        seed: seed of the sampling.
        hours: local hours the queries fall in (default: the world's).
        threshold: doors with predicted ``P(open) < threshold`` are planned closed.
        baselines: any of ``all_open`` (every door assumed open) and ``oracle`` (true states).
        queries: fixed queries (overrides the sampling).
        unseen_prior: P(open) of a door without training observations.
        settings: estimator name -> keyword settings.
        no_path: policy when the believed doors leave no path (:func:`run_door_episode`).
        rules: door rules of the estimator rows (:data:`DOOR_RULES`); the ``threshold`` row is
            labelled with the estimator's name, the ``expected_cost`` row ``NAME (expected cost)``.
            The baselines (P(open) 0 or 1) run once: both rules plan alike on them.

    Returns:
        :class:`DoorNavigationResult`; table columns estimator, queries, blocked_first_plans,
        blocked_rate, mean_extra_distance_m (successful episodes), SR, SPL (over reachable
        goals), and n_reachable, declined (did not set off), declined_reachable (of which the goal
        was reachable), wasted_m (mean walked towards unreachable goals), mean_walked_m,
        unseen_doors.
    """
    import pandas as pd

    from psg_data.evaluation._door_report import EXPECTED_COST_SUFFIX

    qs = list(queries) if queries is not None else make_door_queries(world, n_queries, seed=seed, hours=hours)
    if not qs:
        raise EvaluationError("run_door_navigation: no queries")
    doors = world.door_ids
    rows, recs = [], []
    episodes: dict[str, list[DoorEpisode]] = {}
    probs: dict[str, list[dict[str, float]]] = {}
    bad = [r for r in rules if r not in DOOR_RULES]
    if bad or not rules:
        raise EvaluationError(f"rules {list(rules)}: expected one or more of {DOOR_RULES}")
    errors: list[dict[str, Any]] = []
    runs = []
    for label, belief, unseen in _door_methods(world, estimators, baselines, unseen_prior, settings, errors):
        if label in DOOR_BASELINES:
            runs.append((label, "threshold", belief, unseen))
            continue
        runs += [(label if r == "threshold" else f"{label}{EXPECTED_COST_SUFFIX}", r, belief, unseen)
                 for r in rules]
    open_blocked = [_open_plan_blocked(world.cache, q) for q in qs]
    for label, rule, belief, unseen in runs:
        eps: list[DoorEpisode] = []
        try:
            ps = [belief(q) for q in qs]
        except PluginError as exc:
            errors.append(exc.record(label))
            continue
        for q, ob, p in zip(qs, open_blocked, ps):
            ep = run_door_episode(world.cache, q, p, threshold=threshold, method=label, no_path=no_path, rule=rule)
            eps.append(ep)
            recs.append({"estimator": label, "rule": rule, "query_id": q.query_id, "t_s": q.t_s, "goal": q.goal,
                         "success": ep.success, "first_plan_blocked": ep.first_plan_blocked, "walked_m": ep.walked_m,
                         "shortest_m": ep.shortest_m, "extra_m": ep.extra_m, "n_replans": ep.n_replans,
                         "fallback": ep.fallback, "declined": ep.declined, "open_plan_blocked": ob,
                         **{f"p_open:{d}": v for d, v in p.items()},
                         **{f"open:{d}": bool(q.doors_open.get(d, True)) for d in doors}})
        episodes[label], probs[label] = eps, ps
        rows.append(_door_row(label, eps, unseen))
    return DoorNavigationResult(pd.DataFrame(rows), pd.DataFrame(recs), qs, episodes, probs, errors)


# -- the evaluation world ---------------------------------------------------------------------------
def door_loop_world(door_ab_open: Callable[[float], bool], train_streams: Sequence[EdgeStream], *,
                    t_train_end_s: float, t_end_s: float, timezone: str = "UTC", resolution_m: float = 0.1,
                    robot_radius_m: float = 0.2, name: str = "door_loop") -> DoorWorld:
    """Two rooms joined by a direct door and by a hallway: the paper's "Predictive Navigation" setting.

    Layout (metres, world x east, y north): room A ``[0, 6] x [0, 8]``, room B ``[6, 12] x [0, 8]``,
    hallway ``[0, 12] x [-2.5, 0]``; desks (the goals) at y = 2.5 against the outer walls, starts
    in the southern half of the rooms (y in [0.8, 4]). ``door_ab`` (x = 6, y = 7) joins A and B
    directly (the shorter route, at the far end of the rooms); ``door_a_hall`` (x = 1, y = 0) and
    ``door_b_hall`` (x = 11, y = 0) lead through the hallway (a few metres longer) and are always
    open. Finding ``door_ab`` closed costs the walk to it and back (about 10 m or more), believing
    it closed when it is open costs the longer route.

    Args:
        door_ab_open: whether ``door_ab`` is open at a time (seconds since the epoch, UTC).
        train_streams: the doors' training observations (edges ``(door_id, "open")``).
        t_train_end_s: end of training, seconds since the epoch.
        t_end_s: end of the world's time span, seconds since the epoch.
        timezone: IANA timezone of the world's clock.
        resolution_m: occupancy grid cell size, metres.
        robot_radius_m: robot radius the obstacles are inflated by, metres.
        name: a label for reports.
    """
    from psg_data.schemas._records import Box, Door, Receptacle, Room

    rooms = [Room("room_a", "room A", np.array([[0, 0], [6, 0], [6, 8], [0, 8.0]])),
             Room("room_b", "room B", np.array([[6, 0], [12, 0], [12, 8], [6, 8.0]])),
             Room("hall", "hallway", np.array([[0, -2.5], [12, -2.5], [12, 0], [0, 0.0]]))]
    ext_x = np.array([0.14, 0.9, 2.05])
    ext_y = np.array([0.9, 0.14, 2.05])
    doors = [Door("door_ab", "door A-B", "room_a", "room_b", Box(np.array([6.0, 7.0, 1.025]), ext_x)),
             Door("door_a_hall", "door A-hall", "room_a", "hall", Box(np.array([1.0, 0.0, 1.025]), ext_y)),
             Door("door_b_hall", "door B-hall", "room_b", "hall", Box(np.array([11.0, 0.0, 1.025]), ext_y))]
    desk = np.array([0.6, 0.8, 0.74])
    recs = [Receptacle("a_desk", "desk A", "room_a", Box(np.array([0.5, 2.5, 0.37]), desk), "desk"),
            Receptacle("b_desk", "desk B", "room_b", Box(np.array([11.5, 2.5, 0.37]), desk.copy()), "desk")]
    grid = grid_from_geometry(rooms, recs, doors, resolution_m=resolution_m, robot_radius_m=robot_radius_m)

    def doors_at(t_s: float) -> dict[str, bool]:
        return {"door_ab": bool(door_ab_open(t_s)), "door_a_hall": True, "door_b_hall": True}

    free = grid.free(grid.door_config({d.door_id: True for d in doors}))
    centers = grid.cell_centers()
    W = grid.shape[1]
    starts = {}
    for rid, (x0, x1) in (("room_a", (1.0, 5.0)), ("room_b", (7.0, 11.0))):
        m = (free.ravel() & (centers[:, 0] >= x0) & (centers[:, 0] <= x1) & (centers[:, 1] >= 0.8)
             & (centers[:, 1] <= 4.0))
        starts[rid] = np.stack(np.divmod(np.flatnonzero(m), W), axis=1).astype(np.int64)
    return DoorWorld(grid, doors_at, list(train_streams), t_train_end_s, t_end_s, timezone, starts,
                     {"room_a": ["a_desk"], "room_b": ["b_desk"]}, name=name)


# -- the figure -------------------------------------------------------------------------------------
def plot_door_query(world: DoorWorld, query: DoorQuery, episode: DoorEpisode, out_path: str | Path | None = None, *,
                    title: str | None = None, dpi: int = 120, baseline: DoorEpisode | None = None) -> Figure:
    """A figure like the paper's "Predictive Navigation" one: a ``matplotlib.figure.Figure``, written
    as a PNG at ``out_path`` if given (replaced atomically; no pyplot, the user's backend is left alone).

    Shows the grid (free light, obstacles dark), each door's cells coloured by the predicted
    P(open) (pink = low, teal = high; label with the value and the true state), the path the
    method walked (blue, with a red cross where it met a closed door), the shortest path under the
    true door states (dashed black), the start (blue dot) and the goal receptacle (gold); with
    ``baseline`` also another method's walk (dotted grey, e.g. the all-doors-open planner).
    """
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LinearSegmentedColormap, Normalize
    from matplotlib.figure import Figure

    grid = world.grid
    H, W = grid.shape
    cmap = LinearSegmentedColormap.from_list("door_p", ["#e75480", "#f2e6c9", "#008080"])
    fig = Figure(figsize=(8, 5))
    ax = fig.subplots()
    ext = grid.extent_m
    img = np.where(grid.static_obstacle, 0.25, 0.97)
    ax.imshow(img, origin="lower", extent=ext, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    for d in grid.door_ids:
        m = grid.door_cells[d]
        p = episode.p_open.get(d, 1.0)
        rgba = np.zeros((H, W, 4))
        rgba[m] = cmap(p)
        ax.imshow(rgba, origin="lower", extent=ext, interpolation="nearest")
        ii, jj = np.nonzero(m)
        xy = grid.cell_to_world(np.array([ii.mean(), jj.mean()]))
        state = "open" if query.doors_open.get(d, True) else "closed"
        ax.annotate(f"{d}\nP(open)={p:.2f}\n(truly {state})", (float(xy[0]), float(xy[1])), fontsize=7,
                    ha="center", va="bottom", xytext=(0, 8), textcoords="offset points")
    goal = grid.receptacle_cells[query.goal]
    gi, gj = np.nonzero(goal)
    gxy = grid.cell_to_world(np.stack([gi, gj], 1))
    ax.scatter(gxy[:, 0], gxy[:, 1], s=4, c="gold", marker="s", label=f"goal {query.goal}")
    cache = world.cache
    cfg_true = cache.key(query.doors_open)
    start = query.start_cell[0] * W + query.start_cell[1]
    sp = cache.path(query.goal, cfg_true, start)
    if sp is not None:
        xy = grid.cell_to_world(np.stack(np.divmod(sp, W), 1))
        ax.plot(xy[:, 0], xy[:, 1], "k--", lw=1.2, label="shortest (true doors)")
    if baseline is not None and baseline.trail.size > 1:
        bt = grid.cell_to_world(np.stack(np.divmod(baseline.trail, W), 1))
        ax.plot(bt[:, 0], bt[:, 1], ":", color="0.35", lw=2.0,
                label=f"walked by {baseline.method} ({baseline.walked_m:.1f} m"
                      f"{', met a closed door' if baseline.first_plan_blocked else ''})")
    tr = grid.cell_to_world(np.stack(np.divmod(episode.trail, W), 1))
    what = "declined: no route with the predicted doors" if episode.declined else f"{episode.walked_m:.1f} m"
    ax.plot(tr[:, 0], tr[:, 1], "-", color="#1f4fbf", lw=2.0, alpha=0.8, label=f"walked by {episode.method} ({what})")
    if episode.first_plan_blocked and episode.first_plan.size:
        free_true = cache.free_flat(cfg_true)
        kb = int(np.flatnonzero(~free_true[episode.first_plan])[0])
        bxy = grid.cell_to_world(np.array(divmod(int(episode.first_plan[max(kb - 1, 0)]), W)))
        ax.plot(bxy[0], bxy[1], "rx", ms=10, mew=2, label="met a closed door")
    sxy = grid.cell_to_world(np.array(query.start_cell))
    ax.plot(sxy[0], sxy[1], "o", color="#1f4fbf", ms=8, label="start")
    sm = ScalarMappable(cmap=cmap, norm=Normalize(0, 1))
    fig.colorbar(sm, ax=ax, fraction=0.03, pad=0.02, shrink=0.8, label="predicted P(open)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    from matplotlib.patches import Patch

    handles, _ = ax.get_legend_handles_labels()
    handles += [Patch(facecolor="0.25", label="walls and furniture (obstacles)"),
                Patch(facecolor=cmap(0.9), edgecolor="0.3", label="door: colour = predicted P(open), text = truth")]
    ax.legend(handles=handles, loc="upper center", fontsize=7, ncol=2, bbox_to_anchor=(0.45, -0.2))
    short = f"{episode.shortest_m:.1f} m" if math.isfinite(episode.shortest_m) else "none (no route is open)"
    ax.set_title(title or f"query {query.query_id} to {query.goal}\n{episode.method} walked {episode.walked_m:.1f} m; "
                          f"shortest with the true doors {short}", fontsize=10)
    from psg_data.evaluation._persistence_plots import save_figure

    return save_figure(fig, out_path, dpi)
