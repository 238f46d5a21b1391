"""The navigation harness: every method on the same stored queries, scored like the paper's table.

:func:`run_navigation` builds (or takes) a :class:`NavigationEnv`, samples or loads one query set
per seed, builds one filter per edge for every method, runs the agent and scores the episodes with
:mod:`psg_data.metrics` (``success_rate``, ``spl``, ``abort_rate``, ``distance_travelled``,
``summarize``).

Table (the paper's "Predictive Navigation" layout), one row per method:

- Static presence: SR, SPL over reachable targets that did not move since the last map update.
- Dynamic presence: SR, SPL over reachable targets that moved.
- Absence: AR (correct abort rate) and DIST (metres walked before terminating) over absent targets.
- Overall: SR, SPL over reachable present targets plus absent targets. ``absent_in_overall``
  chooses how absent targets count: ``"abort_is_success"`` (default: a correct abort is a success
  with efficiency 1, whatever was walked), ``"abort_is_success_spl_path"`` (a correct abort is a
  success; its SPL term is 1 only if the agent aborted without moving, else 0) or ``"exclude"``.

Unreachable present targets (their receptacle cannot be reached from the start with the true door
states, e.g. behind closed doors) are counted in ``n_unreachable`` and, by default
(``unreachable="exclude"``), left out of SR and SPL; ``unreachable="failure"`` counts them as
failures. No inf reaches the table; a category without queries has NaN mean and count 0.

SR, SPL and AR are fractions in [0, 1] in the DataFrames (``format_table`` prints percent);
``_mean`` / ``_std`` are across seeds (``std`` with ddof=1, 0 for a single seed).
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

from psg_data.errors import EvaluationError, NotFittedError, PsgDataError
from psg_data.estimators._base import EdgeFilter, EdgeKey
from psg_data.navigation._agent import AgentConfig, Episode, episode_record, run_episode
from psg_data.navigation._baselines import last_seen_filters, oracle_filters
from psg_data.navigation._env import NavigationEnv
from psg_data.navigation._options import DOOR_BELIEFS, PROTOCOLS, NavigationOptions
from psg_data.navigation._planner import PlanningCache
from psg_data.navigation._queries import Query, load_queries, make_queries, save_queries

__all__ = ["NavigationResult", "run_navigation", "build_filters", "score_records", "door_belief_from_filters",
           "METRICS", "ABSENT_RULES"]

log = logging.getLogger(__name__)

METRICS = ("static_sr", "static_spl", "dynamic_sr", "dynamic_spl", "absent_ar", "absent_dist_m",
           "overall_sr", "overall_spl")
ABSENT_RULES = ("abort_is_success", "abort_is_success_spl_path", "exclude")
BUILTIN_METHODS = ("oracle", "last_seen_map")

MethodSpec = Any
"""A registry name or 'oracle' / 'last_seen_map', a PersistenceEstimator (fitted or not), a
mapping edge -> EdgeFilter, or a callable ``env -> mapping edge -> EdgeFilter``."""


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
        from psg_data.estimators._registry import get_estimator

        spec = get_estimator(spec, **dict(settings or {}))
    if isinstance(spec, Mapping):
        return dict(spec)
    if hasattr(spec, "make_filter"):
        est = spec
        try:
            est.make_filter(env.map_streams[0].edge) if env.map_streams else None
        except NotFittedError:
            try:
                est.fit(env.map_streams, timezone=env.timezone)
            except PsgDataError as exc:
                raise EvaluationError(f"{type(est).__name__}: fit on the map observations failed ({exc})") from exc
        out: dict[EdgeKey, EdgeFilter] = {}
        for s in env.map_streams:
            f = est.make_filter(s.edge)
            f.update_many(s.t_s, s.y)
            out[s.edge] = f
        return out
    if callable(spec):
        return dict(spec(env))
    raise EvaluationError(f"method spec: expected a name, estimator, filter mapping or callable, got {type(spec).__name__}")


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


def _nan_if_empty(fn: Callable[[], float]) -> float:
    try:
        return float(fn())
    except EvaluationError:
        return float("nan")


def score_records(df: Any, *, absent_in_overall: str = "abort_is_success", unreachable: str = "exclude"
                  ) -> dict[str, float]:
    """Table metrics of one method on one query set (see the module docstring).

    Args:
        df: per-query records of one (method, seed) (columns of :func:`episode_record`).
        absent_in_overall: one of :data:`ABSENT_RULES`.
        unreachable: 'exclude' or 'failure'.

    Returns:
        The :data:`METRICS` (NaN for an empty category) and the counts ``n_static``, ``n_dynamic``,
        ``n_absent``, ``n_unreachable``, ``n_queries``.
    """
    from psg_data.metrics import abort_rate, distance_travelled, spl, success_rate

    if absent_in_overall not in ABSENT_RULES:
        raise EvaluationError(f"absent_in_overall: expected one of {ABSENT_RULES}, got {absent_in_overall!r}")
    if unreachable not in ("exclude", "failure"):
        raise EvaluationError(f"unreachable: expected 'exclude' or 'failure', got {unreachable!r}")
    cat = df["category"].to_numpy()
    reach = df["reachable"].to_numpy(bool)
    succ = df["success"].to_numpy(bool)
    abort = df["aborted"].to_numpy(bool)
    p = df["path_m"].to_numpy(np.float64)
    l_ = df["shortest_path_m"].to_numpy(np.float64)
    present = cat != "absent"
    scored = present & (reach if unreachable == "exclude" else True)
    l_safe = np.where(np.isfinite(l_), l_, p)  # unreachable ones only enter as failures (S = 0)
    out: dict[str, float] = {}
    for c in ("static", "dynamic"):
        m = scored & (cat == c)
        out[f"{c}_sr"] = _nan_if_empty(lambda m=m: success_rate(succ[m]))
        out[f"{c}_spl"] = _nan_if_empty(lambda m=m: spl(succ[m], l_safe[m], p[m]))
    ab = cat == "absent"
    out["absent_ar"] = _nan_if_empty(lambda: abort_rate(abort[ab]))
    out["absent_dist_m"] = _nan_if_empty(lambda: distance_travelled(p[ab]))
    sel = scored | (ab if absent_in_overall != "exclude" else False)
    s_all = np.where(ab, abort, succ)
    l_all = np.where(ab, p if absent_in_overall == "abort_is_success" else 0.0, l_safe)
    out["overall_sr"] = _nan_if_empty(lambda: success_rate(s_all[sel]))
    out["overall_spl"] = _nan_if_empty(lambda: spl(s_all[sel], l_all[sel], p[sel]))
    out.update(n_static=int(np.sum(present & reach & (cat == "static"))),
               n_dynamic=int(np.sum(present & reach & (cat == "dynamic"))), n_absent=int(np.sum(ab)),
               n_unreachable=int(np.sum(present & ~reach)), n_queries=int(len(cat)))
    return out


@dataclass
class NavigationResult:
    """Result of :func:`run_navigation`.

    Attributes:
        records: per-query DataFrame (method, seed, query fields, outcome, success, path_m, ...).
        per_seed: metrics per (method, seed).
        summary: per method, ``<metric>_mean`` / ``<metric>_std`` across seeds and total counts.
        queries: seed -> the query set.
        config: run settings (JSON-able).
        timings_s: method -> seconds spent (filters + episodes).
        env, cache: the environment and planning cache (for plotting; not saved).
        trails: (method, seed, query_id) -> flat cell indices walked.
        beliefs: (method, seed, query_id) -> receptacle beliefs at the query time.
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

    def format_table(self, digits: int = 1, *, layout: str = "auto") -> str:
        """Text table shaped like the paper's (percent for SR/SPL/AR, metres for DIST, mean ± std).

        Args:
            digits: decimals.
            layout: ``sim`` (Table "Predictive Navigation": static / dynamic SR and SPL, absence AR
                and DIST, overall SR and SPL), ``real`` (Table "Real-World Navigation": static SR,
                dynamic SR, absent AR, overall SR) or ``auto`` (``real`` for the paper-real protocol).
        """
        s = self.summary
        if layout == "auto":
            layout = "real" if str(self.config.get("protocol", "")).startswith("paper-real") else "sim"
        if layout not in ("sim", "real"):
            raise EvaluationError(f"layout: expected 'sim', 'real' or 'auto', got {layout!r}")

        def cell(row: Any, m: str) -> str:
            mu, sd = row[f"{m}_mean"], row[f"{m}_std"]
            if not np.isfinite(mu):
                return "-"
            k = 1.0 if m == "absent_dist_m" else 100.0
            return f"{k * mu:.{digits}f} ± {k * sd:.{digits}f}"

        r0 = s.iloc[0] if len(s) else None
        n = (lambda c: int(r0[c]) if r0 is not None else 0)
        n_all = n("n_queries") - (n("n_unreachable") if self.config.get("unreachable") == "exclude" else 0)
        if layout == "real":
            metrics = ("static_sr", "dynamic_sr", "absent_ar", "overall_sr")
            head = [f"Static ({n('n_static')})", f"Dynamic ({n('n_dynamic')})", f"Absent ({n('n_absent')})",
                    f"Overall ({n_all})"]
            cols = ["Estimator", "SR (%)", "SR (%)", "AR (%)", "SR (%)"]
            spans = [(1,), (2,), (3,), (4,)]
        else:
            metrics = METRICS
            head = [f"Static presence ({n('n_static')})", f"Dynamic presence ({n('n_dynamic')})",
                    f"Absence ({n('n_absent')})", f"Overall ({n_all})"]
            cols = ["Method", "SR (%)", "SPL (%)", "SR (%)", "SPL (%)", "AR (%)", "Dist (m)", "SR (%)", "SPL (%)"]
            spans = [(1, 2), (3, 4), (5, 6), (7, 8)]
        rows = [[str(r["method"])] + [cell(r, m) for m in metrics] for _, r in s.iterrows()]
        w = [max(len(c), *(len(r[i]) for r in rows)) if rows else len(c) for i, c in enumerate(cols)]
        for h, sp in zip(head, spans):  # widen the last column of a group to fit its header
            short = len(h) - (sum(w[i] for i in sp) + 3 * (len(sp) - 1))
            if short > 0:
                w[sp[-1]] += short
        line = lambda vals: " | ".join(v.ljust(w[i]) for i, v in enumerate(vals))  # noqa: E731
        groups = f"{'':{w[0]}} | " + " | ".join(f"{h:^{sum(w[i] for i in sp) + 3 * (len(sp) - 1)}}"
                                                for h, sp in zip(head, spans))
        sep = "-+-".join("-" * x for x in w)
        c = self.config
        extra = (f"\nunreachable targets: {n('n_unreachable')} (rule: {c.get('unreachable')}); seeds: {c.get('seeds')}; "
                 f"setting: {c.get('setting')}; protocol: {c.get('protocol')}; labels: {c.get('labels', 'gt')}; "
                 f"doors: {c.get('door_belief')}")
        return "\n".join([groups.rstrip(), line(cols), sep, *(line(r) for r in rows)]) + extra

    def save(self, out_dir: str | Path) -> dict[str, Path]:
        """Write records.parquet, per_seed.csv, summary.csv, summary.json and table.txt to ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {"records": out / "records.parquet", "per_seed": out / "per_seed.csv",
                 "summary": out / "summary.csv", "json": out / "summary.json", "table": out / "table.txt"}
        self.records.to_parquet(paths["records"], index=False)
        self.per_seed.to_csv(paths["per_seed"], index=False)
        self.summary.to_csv(paths["summary"], index=False)
        summ = [{k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in r.items()}
                for r in self.summary.to_dict("records")]
        paths["json"].write_text(json.dumps({"config": self.config, "summary": summ, "timings_s": self.timings_s},
                                            indent=1, default=str))
        paths["table"].write_text(self.format_table() + "\n")
        return paths

    def plot(self, method: str, query_id: int, out_path: str | Path | None = None, *, seed: int | None = None) -> Any:
        """Top-down map of one episode, a ``matplotlib.figure.Figure`` written as a PNG at
        ``out_path`` if given (see :func:`psg_data.navigation.plot_query`)."""
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


def _fresh(estimator: Any) -> Any:
    """An unfitted copy of an estimator with the same settings (scikit-learn's ``clone``)."""
    try:
        params = estimator.get_params(deep=False)
    except TypeError:  # a plugin whose get_params takes no ``deep``
        params = estimator.get_params()
    return type(estimator)(**params)


def _door_hooks(env: NavigationEnv, name: str, spec: MethodSpec, options: NavigationOptions,
                settings: Mapping[str, Any] | None) -> Callable[[Sequence[float]], list[dict[str, bool]] | None]:
    """Door states a method plans with at a batch of query times (None = the true states)."""
    mode = options.door_belief
    door_ids = list(env.grid.door_ids)
    if mode == "truth" or not door_ids or (mode == "predicted" and spec == "oracle"):
        return lambda ts: None
    if mode == "last_map":
        return lambda ts: [dict(env.map_doors) for _ in ts]
    if mode == "all_open":
        return lambda ts: [{d: True for d in door_ids} for _ in ts]
    from psg_data.navigation._doors import fit_door_filters

    if spec == "last_seen_map":
        filters: Mapping[str, EdgeFilter] = {s.edge[0]: f for s, f in zip(env.door_streams, last_seen_filters(
            env.door_streams).values())}
        missing = [d for d in door_ids if d not in filters]
        if missing:
            log.info("%s: doors never observed on the map (believed open): %s", name, missing)
    elif isinstance(spec, str) or hasattr(spec, "get_params"):
        est = spec if isinstance(spec, str) else _fresh(spec)
        filters, kind = fit_door_filters(est, env.door_streams, door_ids, timezone=env.timezone, settings=settings)
        unseen = [d for d, k in kind.items() if k == "prior"]
        if unseen:
            log.info("%s: doors without observations use P(open) = 0.5 (believed open): %s", name, unseen)
    else:
        raise EvaluationError(f"method {name}: door_belief='predicted' needs a registry name or an estimator "
                              "(to fit on the door streams); got a filter mapping or callable")

    def hook(ts: Sequence[float]) -> list[dict[str, bool]]:
        t = np.asarray(ts, np.float64)
        p = {d: np.asarray(f.predict(t), np.float64).reshape(-1) for d, f in filters.items()}
        out = []
        for k in range(t.size):
            out.append({d: bool(not np.isfinite(p[d][k]) or p[d][k] >= 0.5) if d in p else True for d in door_ids})
        return out

    return hook


def _query_sets(env: NavigationEnv, options: NavigationOptions, out_dir: str | Path | None) -> dict[int, list[Query]]:
    """One query set per seed: loaded from ``out_dir/queries`` when stored there, else drawn (and stored)."""
    qsets: dict[int, list[Query]] = {}
    start = env.start_cell() if options.start == "fixed" else None
    for sd in options.seeds:
        qpath = Path(out_dir) / "queries" / f"{env.name}_seed{sd}{options.query_tag}.parquet" if out_dir else None
        if qpath is not None and qpath.is_file():
            qsets[sd] = load_queries(qpath)
            log.info("loaded %d queries from %s", len(qsets[sd]), qpath)
            continue
        qsets[sd] = make_queries(env, options.n_queries, seed=sd, horizon_s=options.horizon_s,
                                 reachable_only=options.reachable_only, reach_m=options.reach_m,
                                 quotas=dict(options.quotas) if options.quotas else None, start_cell=start)
        if qpath is not None:
            save_queries(qsets[sd], qpath)
            save_queries(qsets[sd], qpath.with_suffix(".json"))
    return qsets


def _initial_beliefs(name: str, qs: list[Query], by_obj: Mapping[str, Mapping[str, EdgeFilter]]
                     ) -> dict[int, dict[str, float]]:
    """Beliefs at the query times, one vectorised predict per edge."""
    bel0: dict[int, dict[str, float]] = {}
    for o in {q.object_id for q in qs}:
        mine = [q for q in qs if q.object_id == o]
        t = np.array([q.t_s for q in mine], dtype=np.float64)
        preds = {r: np.asarray(f.predict(t), dtype=np.float64).reshape(-1) for r, f in by_obj.get(o, {}).items()}
        for r, v in preds.items():
            if v.shape != t.shape or not np.all(np.isfinite(v)):
                raise EvaluationError(f"method {name}: edge ({o}, {r}) predicted non-finite or misshaped beliefs")
        for k, q in enumerate(mine):
            bel0[q.query_id] = {r: float(v[k]) for r, v in preds.items()}
    return bel0


def _episodes(env: NavigationEnv, cache: PlanningCache, name: str, qs: list[Query],
              by_obj: Mapping[str, Mapping[str, EdgeFilter]], doors_for: Callable[[Sequence[float]], Any],
              cfg: AgentConfig) -> list[tuple[Query, dict[str, bool] | None, Episode]]:
    """Every query of one set for one method: (query, door belief, episode)."""
    bel0 = _initial_beliefs(name, qs, by_obj)
    door_bel = doors_for([q.t_s for q in qs]) or [None] * len(qs)
    return [(q, db, run_episode(cache, q, by_obj.get(q.object_id, {}), cfg, beliefs=bel0[q.query_id],
                                door_belief=db, observation=env.observation)) for q, db in zip(qs, door_bel)]


def _summarise(records: Any, names: list[str], options: NavigationOptions) -> tuple[Any, Any]:
    import pandas as pd

    from psg_data.evaluation import summarize

    per_seed_rows = []
    for (name, sd), df in records.groupby(["method", "seed"], sort=False):
        per_seed_rows.append({"method": name, "seed": sd, **score_records(
            df, absent_in_overall=options.absent_in_overall, unreachable=options.unreachable)})
    per_seed = pd.DataFrame(per_seed_rows)
    summ_rows = []
    for name in names:
        ps = per_seed[per_seed["method"] == name]
        row: dict[str, Any] = {"method": name, "n_seeds": len(ps)}
        for m in METRICS:
            st = summarize(ps[m].to_numpy(np.float64))
            row[f"{m}_mean"], row[f"{m}_std"] = st.mean, st.std
        for c in ("n_queries", "n_static", "n_dynamic", "n_absent", "n_unreachable"):
            row[c] = int(ps[c].sum())
        summ_rows.append(row)
    return per_seed, pd.DataFrame(summ_rows)


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
            JSON) and the results are saved there.
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
    cache = PlanningCache(env.grid, reach_m=opts.reach_m)
    methods = _methods(estimators)
    if not methods:
        raise EvaluationError("run_navigation: no methods")
    names = [m for m, _ in methods]
    if len(set(names)) != len(names):
        raise EvaluationError(f"run_navigation: duplicate method names {names}")
    qsets = _query_sets(env, opts, out_dir)

    import pandas as pd

    rows: list[dict[str, Any]] = []
    trails: dict[tuple[str, int, int], Any] = {}
    beliefs_out: dict[tuple[str, int, int], dict[str, float]] = {}
    timings: dict[str, float] = {}
    modes = dict(door_modes or {})
    bad = {m: v for m, v in modes.items() if m not in names or v not in DOOR_BELIEFS}
    if bad:
        raise EvaluationError(f"door_modes {bad}: expected method names {names} and modes {DOOR_BELIEFS}")
    fitted: dict[Any, dict[EdgeKey, EdgeFilter]] = {}
    for name, spec in methods:
        t0 = time.perf_counter()
        settings = (estimator_settings or {}).get(name)
        key = (spec, repr(sorted((settings or {}).items()))) if isinstance(spec, str) else id(spec)
        if key not in fitted:
            fitted[key] = build_filters(env, spec, settings=settings)
        filt = fitted[key]
        m_opts = replace(opts, door_belief=modes[name]) if name in modes else opts
        doors_for = _door_hooks(env, name, spec, m_opts, settings) if hook is None else (
            lambda ts, h=hook: [dict(h) if isinstance(h, Mapping) else dict(h(t)) for t in ts])
        by_obj: dict[str, dict[str, EdgeFilter]] = {}
        for (o, r), f in filt.items():
            by_obj.setdefault(o, {})[r] = f
        for sd in opts.seeds:
            for q, db, ep in _episodes(env, cache, name, qsets[sd], by_obj, doors_for, cfg):
                rows.append(episode_record(ep, method=name, seed=sd, t_s=q.t_s, start_x_m=q.start_xy[0],
                                           start_y_m=q.start_xy[1], gt_receptacle=q.gt_receptacle,
                                           map_receptacle=q.map_receptacle,
                                           doors_believed=json.dumps(db, sort_keys=True) if db is not None else None))
                if opts.keep_trails:
                    trails[(name, sd, q.query_id)] = ep.trail
                    beliefs_out[(name, sd, q.query_id)] = ep.beliefs
        timings[name] = time.perf_counter() - t0
        log.info("navigation: %s done in %.2f s", name, timings[name])

    records = pd.DataFrame(rows)
    per_seed, summary = _summarise(records, names, opts)
    config = {"env": env.name, **opts.to_dict(), "door_belief": opts.door_belief if hook is None else "custom",
              "door_modes": modes or None,
              "resolution_m": env.grid.resolution_m, "robot_radius_m": env.grid.robot_radius_m,
              "grid_source": env.grid.source, "methods": names, "labels_info": env.extra.get("labels"),
              "sightings": {"p_miss": env.observation.p_miss, "p_false": env.observation.p_false}}
    res = NavigationResult(records, per_seed, summary, qsets, config, timings, env, cache, trails, beliefs_out)
    if out_dir is not None:
        res.save(out_dir)
    return res
