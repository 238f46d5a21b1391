"""The navigation harness: every method on the same stored queries.

:func:`run_navigation` builds (or takes) a :class:`NavigationEnv`, samples or loads one query set
per seed (query times inside the dataset's scoring windows), builds one filter per edge for every
method, runs the agent (for ``delta`` and every value of ``delta_sweep``) and scores the episodes
with :mod:`psg_data.evaluation._navigation_scores` (the paper's table; metrics pooled over the
query sets, bootstrap interval over queries). Built-in methods: ``oracle`` (the physical state at
the query time), ``last_seen_map`` (the last map state) and ``random_receptacle`` (chance); any
registry estimator, estimator object, filter mapping or callable otherwise.

SR, SPL and AR are fractions in [0, 1] in the DataFrames; tables and files are written by
:mod:`psg_data.evaluation` (:func:`~psg_data.evaluation.navigation_results`).
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeFilter, EdgeKey
from psg_data.estimators._guard import PluginError
from psg_data.evaluation._navigation_scores import ABSENT_RULES, METRICS, score_records, summarise_navigation
from psg_data.graph._fit import fit_edge_filters, fresh_estimator, resolve_estimator
from psg_data.graph._graph import PredictiveGraph
from psg_data.graph._snapshot import doors_believed_open
from psg_data.maps._planner import PlanningCache
from psg_data.navigation._agent import AgentConfig, Episode, episode_record, run_episode
from psg_data.navigation._baselines import last_seen_filters, oracle_filters, random_filters
from psg_data.navigation._env import NavigationEnv
from psg_data.navigation._options import DOOR_BELIEFS, PROTOCOLS, NavigationOptions
from psg_data.navigation._queries import Query, load_queries, make_queries, save_queries

__all__ = ["NavigationResult", "run_navigation", "build_filters", "build_graph", "score_records",
           "door_belief_from_filters", "METRICS", "ABSENT_RULES"]

log = logging.getLogger(__name__)

BUILTIN_METHODS = ("oracle", "last_seen_map", "random_receptacle")

MethodSpec = Any
"""A registry name or 'oracle' / 'last_seen_map', a PersistenceEstimator (fitted or not), a
mapping edge -> EdgeFilter, or a callable ``env -> mapping edge -> EdgeFilter``."""


def build_graph(env: NavigationEnv, spec: MethodSpec, *, settings: Mapping[str, Any] | None = None
                ) -> PredictiveGraph:
    """The :class:`~psg_data.graph.PredictiveGraph` of a method on the environment: one filter per
    edge, updated with the map observations up to ``env.t_map_s`` (no door model; see :func:`build_filters`).

    Raises:
        EvaluationError: unknown spec, or the estimator failed to fit.
    """
    if isinstance(spec, str) and spec not in BUILTIN_METHODS:
        spec = resolve_estimator(spec, settings)
    if hasattr(spec, "make_filter") and not isinstance(spec, Mapping):
        return PredictiveGraph.fit(env.layout, env.map_streams, estimator=spec, door_estimator=None, grid=env.grid)
    return PredictiveGraph(env.layout, build_filters(env, spec, settings=settings), grid=env.grid)


def build_filters(env: NavigationEnv, spec: MethodSpec, *, settings: Mapping[str, Any] | None = None
                  ) -> dict[EdgeKey, EdgeFilter]:
    """One filter per edge for a method, updated with the map observations up to ``env.t_map_s``.

    Args:
        env: the environment.
        spec: see :data:`MethodSpec`.
        settings: keyword settings for a registry estimator.

    Raises:
        EvaluationError: unknown spec, or the estimator failed to fit.
    """
    if isinstance(spec, str):
        if spec == "oracle":
            return dict(oracle_filters(env.object_ids, sorted(env.receptacles), env.gt_at))
        if spec == "last_seen_map":
            return dict(last_seen_filters(env.map_streams))
        if spec == "random_receptacle":
            return dict(random_filters(env.map_streams, seed=int(dict(settings or {}).get("seed", 0))))
        spec = resolve_estimator(spec, settings)
    if isinstance(spec, Mapping):
        return dict(spec)
    if hasattr(spec, "make_filter"):
        return fit_edge_filters(resolve_estimator(spec), env.map_streams, timezone=env.timezone)
    if callable(spec):
        return dict(spec(env))
    raise EvaluationError("method spec: expected a name, estimator, filter mapping or callable, got "
                          f"{type(spec).__name__}")


def door_belief_from_filters(filters: Mapping[EdgeKey, EdgeFilter]) -> Callable[[float], dict[str, bool]]:
    """A ``door_belief`` hook from door filters (a door is an object whose "receptacles" are its states).

    Args:
        filters: edge ``(door_id, "open")`` and/or ``(door_id, "closed")`` -> filter.

    Returns:
        ``t_s -> {door_id: is_open}``: open iff P(open) >= P(closed) (with one edge only, iff its
        probability of the 'open' state is >= 0.5).
    """
    by_door: dict[str, dict[str, EdgeFilter]] = {}
    for (d, state), f in filters.items():
        if state not in ("open", "closed"):
            raise EvaluationError(f"door filter ({d}, {state}): state must be 'open' or 'closed'")
        by_door.setdefault(d, {})[state] = f

    def belief(t_s: float) -> dict[str, bool]:
        out = {}
        for d, fs in by_door.items():
            p = {s: float(np.asarray(f.predict(np.array([t_s]))).reshape(-1)[0]) for s, f in fs.items()}
            p_open = p.get("open", 1.0 - p["closed"] if "closed" in p else 0.5)
            p_closed = p.get("closed", 1.0 - p_open)
            out[d] = p_open >= p_closed
        return out

    return belief


@dataclass
class NavigationResult:
    """Result of :func:`run_navigation`.

    Attributes:
        records: per-query DataFrame (method, seed, delta, query fields, outcome, success, path_m, ...).
        per_seed: metrics per (method, seed) at ``delta``.
        summary: per method at ``delta``: ``<metric>_mean`` (pooled over the query sets),
            ``<metric>_std`` (across them), ``<metric>_ci_low`` / ``_ci_high`` (bootstrap over
            queries) and the summed counts.
        queries: seed -> the query set.
        config: run settings (JSON-able).
        timings_s: method -> seconds spent (filters + episodes).
        env, cache: the environment and planning cache (for plotting; not saved).
        trails: (method, seed, query_id) -> flat cell indices walked (at ``delta``).
        beliefs: (method, seed, query_id) -> receptacle beliefs at the query time.
        sweep: per (method, delta) the summary of every delta run (``delta_sweep``; None without).
        errors: per failed plugin method its failure (``estimator``, ``stage``, ``message``): the
            method is left out of the records and tables, the others are scored.
    """

    records: Any
    per_seed: Any
    summary: Any
    queries: dict[int, list[Query]]
    config: dict[str, Any]
    timings_s: dict[str, float] = field(default_factory=dict)
    env: NavigationEnv | None = field(default=None, repr=False)
    cache: PlanningCache | None = field(default=None, repr=False)
    trails: dict[tuple[str, int, int], Any] = field(default_factory=dict, repr=False)
    beliefs: dict[tuple[str, int, int], dict[str, float]] = field(default_factory=dict, repr=False)
    sweep: Any = None
    errors: list[dict[str, Any]] = field(default_factory=list)

    def format_table(self, *, layout: str = "auto", roles: Mapping[str, tuple[str, str]] | None = None) -> str:
        """The paper-shaped table as plain text (:func:`psg_data.evaluation.navigation_results`, rendered):
        ``layout`` ``sim`` (Table "Predictive Navigation"), ``real`` (Table "Real-World Navigation") or
        ``auto`` (``real`` for the paper-real protocol).
        """
        from psg_data.evaluation._navigation_report import navigation_results
        from psg_data.evaluation._tables import format_results

        return format_results(navigation_results(self, roles=roles, layout=layout))

    def save(self, out_dir: str | Path, *, roles: Mapping[str, tuple[str, str]] | None = None,
             info: Mapping[str, Any] | None = None) -> dict[str, Path]:
        """Write records.parquet, per_seed.csv, summary.csv and the results schema (results.json,
        table.txt) to ``out_dir`` (:func:`~psg_data.evaluation.write_navigation_results`): replaces
        each file atomically; never inside the input dataset.
        """
        from psg_data.evaluation._navigation_report import write_navigation_results

        return write_navigation_results(self, out_dir, roles=roles, info=info)

    def plot(self, method: str, query_id: int, out_path: str | Path | None = None, *, seed: int | None = None) -> Any:
        """Top-down map of one episode, a ``matplotlib.figure.Figure`` written as a PNG at
        ``out_path`` if given (see :func:`psg_data.navigation.plot_query`).
        """
        from psg_data.navigation._plots import plot_query

        if self.env is None or self.cache is None:
            raise EvaluationError("this NavigationResult has no environment attached (loaded from disk?)")
        sd = seed if seed is not None else sorted(self.queries)[0]
        q = next((x for x in self.queries[sd] if x.query_id == query_id), None)
        if q is None:
            raise EvaluationError(f"no query {query_id} in seed {sd}")
        key = (method, sd, query_id)
        if key not in self.trails:
            raise EvaluationError(f"no episode for method {method!r}, seed {sd}, query {query_id}")
        return plot_query(self.env, q, out_path, beliefs=self.beliefs.get(key), trail=self.trails[key],
                          cache=self.cache, title=f"{method}: {q.object_id} ({q.category})")


def _methods(estimators: Any) -> list[tuple[str, MethodSpec]]:
    if isinstance(estimators, Mapping):
        return [(str(k), v) for k, v in estimators.items()]
    out = []
    for e in estimators:
        if isinstance(e, str):
            out.append((e, e))
        elif isinstance(e, tuple) and len(e) == 2:
            out.append((str(e[0]), e[1]))
        else:
            out.append((getattr(e, "name", type(e).__name__), e))
    return out


def _door_hooks(env: NavigationEnv, name: str, spec: MethodSpec, options: NavigationOptions,
                settings: Mapping[str, Any] | None, graph: PredictiveGraph
                ) -> Callable[[Sequence[float]], list[dict[str, bool]] | None]:
    """Door states a method plans with at a batch of query times (None = the true states)."""
    mode = options.door_belief
    door_ids = list(env.grid.door_ids)
    if mode == "truth" or not door_ids or (mode == "predicted" and spec == "oracle"):
        return lambda ts: None
    if mode == "last_map":
        return lambda ts: [dict(env.map_doors) for _ in ts]
    if mode == "all_open" or spec == "random_receptacle":  # chance has no door model: it plans all doors open
        return lambda ts: [{d: True for d in door_ids} for _ in ts]
    if spec == "last_seen_map":
        filters: Mapping[str, EdgeFilter] = {s.edge[0]: f for s, f in zip(env.door_streams, last_seen_filters(
            env.door_streams).values())}
        missing = [d for d in door_ids if d not in filters]
        if missing:
            log.info("%s: doors never observed on the map (believed open): %s", name, missing)
        doors = graph.with_door_filters(filters)
    elif isinstance(spec, str) or hasattr(spec, "get_params"):
        est = spec if isinstance(spec, str) else fresh_estimator(spec)
        doors = graph.with_door_model(est, env.door_streams, settings=settings)
        unseen = [d for d, k in doors.door_kinds.items() if k == "prior"]
        if unseen:
            log.info("%s: doors without observations use P(open) = 0.5 (believed open): %s", name, unseen)
    else:
        raise EvaluationError(f"method {name}: door_belief='predicted' needs a registry name or an estimator "
                              "(to fit on the door streams); got a filter mapping or callable")

    def hook(ts: Sequence[float]) -> list[dict[str, bool]]:
        p = doors.door_probabilities(np.asarray(ts, np.float64))
        out = []
        for row in p:
            believed = doors_believed_open(dict(zip(doors.doors, row)))
            out.append({d: believed.get(d, True) for d in door_ids})
        return out

    return hook


def _query_windows(env: NavigationEnv, options: NavigationOptions) -> Any:
    """(K, 2) UTC seconds of the scoring windows after the map, or None (``windows="none"`` / unknown)."""
    if options.windows == "none":
        return None
    if options.windows == "auto":
        w = env.windows
    else:
        from psg_data.evaluation._windows import parse_windows

        w = parse_windows(options.windows, env.timezone)
    return None if w is None else w.intervals(env.t_map_s, env.t_end_s)


def _query_sets(env: NavigationEnv, options: NavigationOptions, out_dir: str | Path | None) -> dict[int, list[Query]]:
    """One query set per seed: loaded from ``out_dir/queries`` when stored there, else drawn (and stored)."""
    qsets: dict[int, list[Query]] = {}
    start = env.start_cell() if options.start == "fixed" else None
    windows = _query_windows(env, options)
    for sd in options.seeds:
        qpath = Path(out_dir) / "queries" / f"{env.name}_seed{sd}{options.query_tag}.parquet" if out_dir else None
        if qpath is not None and qpath.is_file():
            qsets[sd] = load_queries(qpath)
            log.info("loaded %d queries from %s", len(qsets[sd]), qpath)
            continue
        qsets[sd] = make_queries(env, options.n_queries, seed=sd, horizon_s=options.horizon_s,
                                 reachable_only=options.reachable_only, reach_m=options.reach_m,
                                 quotas=dict(options.quotas) if options.quotas else None, start_cell=start,
                                 windows=windows)
        if qpath is not None:
            save_queries(qsets[sd], qpath)
            save_queries(qsets[sd], qpath.with_suffix(".json"))
    return qsets


def _initial_beliefs(name: str, qs: list[Query], graph: PredictiveGraph) -> dict[int, dict[str, float]]:
    """Beliefs at the query times, one vectorised predict per edge."""
    bel0: dict[int, dict[str, float]] = {}
    known = set(graph.objects)
    for o in {q.object_id for q in qs}:
        mine = [q for q in qs if q.object_id == o]
        t = np.array([q.t_s for q in mine], dtype=np.float64)
        preds = graph.object_probabilities(o, t) if o in known else {}
        for r, v in preds.items():
            if v.shape != t.shape or not np.all(np.isfinite(v)):
                raise EvaluationError(f"method {name}: edge ({o}, {r}) predicted non-finite or misshaped beliefs")
        for k, q in enumerate(mine):
            bel0[q.query_id] = {r: float(v[k]) for r, v in preds.items()}
    return bel0


def _episodes(env: NavigationEnv, cache: PlanningCache, name: str, qs: list[Query], graph: PredictiveGraph,
              doors_for: Callable[[Sequence[float]], Any], cfg: AgentConfig
              ) -> list[tuple[Query, dict[str, bool] | None, Episode]]:
    """Every query of one set for one method: (query, door belief, episode)."""
    bel0 = _initial_beliefs(name, qs, graph)
    door_bel = doors_for([q.t_s for q in qs]) or [None] * len(qs)
    return [(q, db, run_episode(cache, q, graph.filters_of(q.object_id), cfg, beliefs=bel0[q.query_id],
                                door_belief=db, observation=env.observation)) for q, db in zip(qs, door_bel)]


def _summarise(records: Any, names: list[str], options: NavigationOptions) -> tuple[Any, Any, Any]:
    """(per_seed, summary) at ``delta`` and the sweep summary over every delta (None without a sweep)."""
    import pandas as pd

    def summary_at(delta: float) -> tuple[Any, Any]:
        return summarise_navigation(records[records["delta"] == delta], names,
                                    absent_in_overall=options.absent_in_overall, unreachable=options.unreachable)

    per_seed, summary = summary_at(float(options.delta))
    if not options.delta_sweep:
        return per_seed, summary, None
    parts = []
    for d in options.deltas:
        _, sm = summary_at(d)
        parts.append(sm.assign(delta=d))
    return per_seed, summary, pd.concat(parts, ignore_index=True)


class _MethodRuns:
    """Every method's episodes on the same queries (filters fitted once per registry name and settings)."""

    def __init__(self, env: NavigationEnv, cache: PlanningCache, opts: NavigationOptions, cfg: AgentConfig,
                 qsets: dict[int, list[Query]], hook: Any) -> None:
        self.env, self.cache, self.opts, self.cfg, self.qsets, self.hook = env, cache, opts, cfg, qsets, hook
        self.rows: list[dict[str, Any]] = []
        self.trails: dict[tuple[str, int, int], Any] = {}
        self.beliefs: dict[tuple[str, int, int], dict[str, float]] = {}
        self.timings: dict[str, float] = {}
        self.fitted: dict[Any, PredictiveGraph] = {}
        self.errors: list[dict[str, Any]] = []

    def guarded(self, name: str, spec: MethodSpec, settings: Mapping[str, Any] | None, mode: str | None) -> bool:
        """:meth:`method`; a plugin's failure is recorded and its partial rows dropped (False)."""
        n = len(self.rows)
        try:
            self.method(name, spec, settings, mode)
            return True
        except PluginError as e:
            del self.rows[n:]
            for d in (self.trails, self.beliefs):
                for k in [k for k in d if k[0] == name]:
                    del d[k]
            self.errors.append(e.record(name))
            log.error("%s", self.errors[-1]["message"])
            return False

    def _graph(self, spec: MethodSpec, settings: Mapping[str, Any] | None) -> PredictiveGraph:
        key = (spec, repr(sorted((settings or {}).items()))) if isinstance(spec, str) else id(spec)
        if key not in self.fitted:
            self.fitted[key] = build_graph(self.env, spec, settings=settings)
        return self.fitted[key]

    def method(self, name: str, spec: MethodSpec, settings: Mapping[str, Any] | None, mode: str | None) -> None:
        opts = self.opts
        graph = self._graph(spec, settings)
        m_opts = replace(opts, door_belief=mode) if mode is not None else opts
        doors_for = _door_hooks(self.env, name, spec, m_opts, settings, graph) if self.hook is None else (
            lambda ts, h=self.hook: [dict(h) if isinstance(h, Mapping) else dict(h(t)) for t in ts])
        for delta in opts.deltas:
            cfg = replace(self.cfg, delta=delta)
            for sd in opts.seeds:
                for q, db, ep in _episodes(self.env, self.cache, name, self.qsets[sd], graph, doors_for, cfg):
                    self.rows.append(episode_record(
                        ep, method=name, seed=sd, delta=delta, t_s=q.t_s, start_x_m=q.start_xy[0],
                        start_y_m=q.start_xy[1], gt_receptacle=q.gt_receptacle, map_receptacle=q.map_receptacle,
                        doors_believed=json.dumps(db, sort_keys=True) if db is not None else None))
                    if opts.keep_trails and delta == float(opts.delta):
                        self.trails[(name, sd, q.query_id)] = ep.trail
                        self.beliefs[(name, sd, q.query_id)] = ep.beliefs


_LEGACY = {"seed": "seeds"}


def _resolve_options(options: NavigationOptions | None, overrides: dict[str, Any]) -> tuple[NavigationOptions, Any]:
    """The run's options with ``overrides`` applied, and a custom door-belief hook (or None)."""
    overrides = dict(overrides)
    hook = overrides.pop("door_belief", None)
    if isinstance(hook, str):
        overrides["door_belief"], hook = hook, None
    for old, new in _LEGACY.items():
        if old in overrides:
            v = overrides.pop(old)
            overrides[new] = (v,) if isinstance(v, (int, np.integer)) else tuple(v)
    base = options if options is not None else PROTOCOLS["sim"]
    if "protocol" not in overrides and overrides:
        overrides["protocol"] = f"{base.protocol}+custom"
    try:
        return replace(base, **overrides), hook
    except TypeError as exc:
        raise EvaluationError(f"run_navigation: {exc}") from None


def _checked_methods(estimators: Any, door_modes: Mapping[str, str] | None
                     ) -> tuple[list[tuple[str, MethodSpec]], list[str], dict[str, str]]:
    """(methods, their names, door modes by method) of :func:`run_navigation`, checked."""
    methods = _methods(estimators)
    if not methods:
        raise EvaluationError("run_navigation: no methods")
    names = [m for m, _ in methods]
    if len(set(names)) != len(names):
        raise EvaluationError(f"run_navigation: duplicate method names {names}")
    modes = dict(door_modes or {})
    bad = {m: v for m, v in modes.items() if m not in names or v not in DOOR_BELIEFS}
    if bad:
        raise EvaluationError(f"door_modes {bad}: expected method names {names} and modes {DOOR_BELIEFS}")
    return methods, names, modes


def _check_out_dir(out_dir: str | Path | None, env: NavigationEnv) -> None:
    """Refuse an ``out_dir`` that is or lies inside the input dataset (its files would be written into it)."""
    from psg_data.evaluation._navigation_report import input_dataset
    from psg_data.writers._safe_output import check_not_input

    if out_dir is not None:
        check_not_input(Path(out_dir) / "results.json", [input_dataset(env)])


def run_navigation(
    dataset_or_lab: Any,
    estimators: Any = BUILTIN_METHODS,
    options: NavigationOptions | None = None,
    *,
    out_dir: str | Path | None = None,
    estimator_settings: Mapping[str, Mapping[str, Any]] | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    door_modes: Mapping[str, str] | None = None,
    **overrides: Any,
) -> NavigationResult:
    """Run semi-static object navigation for several methods on the same queries.

    Args:
        dataset_or_lab: a :class:`NavigationEnv`, a psg-dataset (or its path) or a synthetic
            ``LabModel``.
        estimators: methods: a mapping name -> spec or a sequence of specs (see :func:`build_filters`;
            'oracle' and 'last_seen_map' are built in, other names come from the estimator registry).
        options: the run settings (:class:`~psg_data.navigation.NavigationOptions`; default the
            ``sim`` protocol).
        out_dir: if given, query sets are loaded from / stored to ``out_dir/queries/`` (Parquet and
            JSON) and the results are saved there (:meth:`NavigationResult.save`); each file is
            replaced atomically, never inside the input dataset.
        estimator_settings: name -> keyword settings for registry estimators.
        env_kwargs: extra arguments of :meth:`NavigationEnv.from_dataset`.
        door_modes: method name -> door belief (one of ``truth``, ``predicted``, ``last_map``,
            ``all_open``) replacing ``options.door_belief`` for that method. Methods with the same
            registry name and settings share one fit (filters are copied before any update).
        **overrides: fields of :class:`NavigationOptions` replacing those of ``options`` (``seed``
            is accepted for ``seeds``; ``door_belief`` may also be a mapping or a callable
            ``t_s -> {door_id: is_open}`` used for every method).

    Returns:
        A :class:`NavigationResult`.

    Raises:
        UnsafeOutputError: ``out_dir`` is or lies inside the input dataset (checked before the run).
    """
    opts, hook = _resolve_options(options, overrides)
    cfg = AgentConfig(setting=opts.setting, delta=opts.delta, max_attempts=opts.max_attempts,
                      detect_en_route=opts.detect_en_route)
    env = NavigationEnv.coerce(dataset_or_lab, resolution_m=opts.resolution_m, robot_radius_m=opts.robot_radius_m,
                               **({"labels": opts.labels, "label_seed": opts.label_seed} if opts.labels != "gt"
                                  or opts.label_seed else {}),
                               **({"grid_source": opts.grid_source} if opts.grid_source != "geometry" else {}),
                               **dict(env_kwargs or {}))
    if isinstance(dataset_or_lab, NavigationEnv) and (opts.labels != env.labels):
        raise EvaluationError(f"labels {opts.labels!r}: the given environment was built with labels {env.labels!r}")
    _check_out_dir(out_dir, env)
    cache = PlanningCache(env.grid, reach_m=opts.reach_m)
    methods, names, modes = _checked_methods(estimators, door_modes)
    qsets = _query_sets(env, opts, out_dir)

    import pandas as pd

    run = _MethodRuns(env, cache, opts, cfg, qsets, hook)
    for name, spec in methods:
        t0 = time.perf_counter()
        if not run.guarded(name, spec, (estimator_settings or {}).get(name), modes.get(name)):
            names.remove(name)
            continue
        run.timings[name] = time.perf_counter() - t0
        log.info("navigation: %s done in %.2f s", name, run.timings[name])
    if not names:
        raise EvaluationError("navigation: no method could be scored: " + "; ".join(e["message"] for e in run.errors))
    rows, trails, beliefs_out, timings = run.rows, run.trails, run.beliefs, run.timings
    records = pd.DataFrame(rows)
    per_seed, summary, sweep = _summarise(records, names, opts)
    config = {"env": env.name, **opts.to_dict(), "door_belief": opts.door_belief if hook is None else "custom",
              "door_modes": modes or None,
              "resolution_m": env.grid.resolution_m, "robot_radius_m": env.grid.robot_radius_m,
              "grid_source": env.grid.source, "methods": names, "labels_info": env.extra.get("labels"),
              "sightings": {"p_miss": env.observation.p_miss, "p_false": env.observation.p_false},
              "truth": env.truth, "windows": env.windows.to_dict() if env.windows is not None else None,
              "query_windows": opts.windows}
    res = NavigationResult(records, per_seed, summary, qsets, config, timings, env, cache, trails, beliefs_out, sweep,
                           run.errors)
    if out_dir is not None:
        res.save(out_dir)
    return res
