"""The paper's simulation navigation protocols on the navigation benchmark's houses.

Two protocols (:data:`SIM_PROTOCOLS`), each one query set per scene, every method on the same queries:

``paper-sim-predictive`` ("Predictive Navigation (Simulation)": "250 predictive closed-vocabulary
queries across 10 ProcThor environments")
    Scenes 0-9 of the benchmark built **without** a test-time shift (``shift=0``: the test week
    follows the training dynamics), 25 queries each. Filters are fitted on the two training weeks
    (the validation week handed to ``fit`` as ``val_streams``) and then updated with the validation
    week's observations: the last map update is the end of week 3. A query asks at a time uniform
    in the test week ("a future time point up to one week ahead from the last map update"); the
    agent is the lab's ``sim`` agent (:func:`~psg_data.navigation.run_episode`, predictive
    setting: beliefs of the query time, stop as soon as the object is within reach and in sight).

``paper-sim-adaptive`` ("Adaptive Navigation (Simulation)": "125 queries across 5 ProcThor
environments where the agent can dynamically switch targets during navigation by consuming new
observations, evaluated under unseen test-time dynamics")
    Scenes 10-14 of the benchmark with its default shift (the stored test-week regime), 25 queries
    each. Filters as above. The agent is :func:`~psg_data.navigation._sim_agent.run_adaptive_episode`:
    it looks while it walks, updates its filters and may switch targets. Three choices the text leaves
    open are options (:meth:`SimProtocol.readings` lists every distinct combination; the run reports
    them all on the same draws):

    ``last_map`` -- "a future time point up to one week ahead from the last map update" (the one
    sentence on query times, for all three experiments). ``end-of-validation`` (default): the last map
    update is the end of week 3, as in the predictive protocol, and the query time is uniform in the
    following week; the test week is unseen before the query and the agent only adapts to what it sees
    during the episode. ``test-week``: per query the last map update is the patrol of a test-week step
    drawn uniformly (steps 0..166 of the week), the filters consume the test week's observations up to
    it and the query time is uniform between it and the end of the test week (a reading of ours, not a
    sentence of the paper).

    ``agent_memory`` -- Tool 3: "Navigation terminates when either the object is found or the target
    receptacle is reached"; the text does not say whether the agent then remembers the receptacle.
    ``visits`` (default; the orchestrating agent sees its own tool calls, and "up to two attempts"
    reads as two receptacles): a reached receptacle is not a candidate again in the episode.
    ``estimator``: the filters' beliefs, updated with what the agent saw, are its only memory.

    ``absence`` -- Tool 2: "If no receptacle exceeds the threshold, the object is reported as absent".
    ``delta`` (default, the text): the agent declares absence only when no belief is at or above delta;
    a ``visits`` agent whose candidates above delta are all reached stops without declaring absence.
    ``list-exhausted``: it then declares the object absent as well (not in the text).

Choices the paper leaves open (each documented here and in RESULTS.md section 7):

* scenes: the paper's 15 ProcTHOR scenes split 10 + 5; ours are houses 0-9 (predictive) and 10-14
  (adaptive), disjoint. 25 queries per scene (250 / 10, 125 / 5; ``queries_per_scene`` draws more
  for a verdict: the first 25 draws of a scene are the same either way).
* "a target object (either static or dynamic)": the object is drawn uniformly over the scene's
  objects; the category follows from the truth (static: on the receptacle of the last map update;
  dynamic: elsewhere; absent: not in the house), the natural mix, not the paper's quotas.
* "a starting robot pose": a free cell uniform over the main free component (as the lab's ``sim``).
* doors: the agent knows the true door states at the query time (the ``sim`` protocols' door rule).
* success (Habitat's "visible and within 1 m"): within ``reach_m`` = 1 m of the receptacle with a
  line of sight on the grid (the lab's rule); absence threshold delta = 0.2; at most two attempts.
* the robot walks at 0.5 m/s (observation times during an episode); looks every metre.
* ``process_oracle`` rows use every observation of the object (``share_updates``: a per-object
  tracker), so the ceiling conditions on what the per-edge methods see and more.
* the ``±`` of the tables is the standard deviation across scenes (the paper's); the interval
  beside it is the 95 % bootstrap over queries.

:func:`run_sim_scene` runs one scene (a worker job); :func:`run_sim_navigation` all scenes of a protocol.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError, PsgDataError
from psg_data.estimators._base import EdgeFilter, EdgeKey, EdgeStream
from psg_data.estimators._guard import PluginError
from psg_data.navigation._env import WEEK_S, NavigationEnv
from psg_data.navigation._queries import Query, make_queries
from psg_data.navigation._runner import BUILTIN_METHODS
from psg_data.navigation._sim_agent import ABSENCE_RULES, AGENT_MEMORIES

__all__ = ["SimProtocol", "SIM_PROTOCOLS", "LAST_MAPS", "run_sim_scene", "run_sim_navigation", "scene_split_ids",
           "method_filters", "scene_settings"]

log = logging.getLogger(__name__)


LAST_MAPS = ("end-of-validation", "test-week")
"""Where an adaptive query's last map update falls (module docstring)."""


@dataclass(frozen=True)
class SimProtocol:
    """One simulation protocol (module docstring).

    Attributes:
        name: ``paper-sim-predictive`` or ``paper-sim-adaptive`` (``+quick`` for the CI form).
        scenes: benchmark house seeds used.
        queries_per_scene: queries drawn per scene.
        shift: test-time shift of the houses (0 = none; None = the benchmark's default).
        adaptive: filters consume test-week observations and the agent adapts during the episode.
        delta: absence threshold.
        max_attempts: receptacles inspected without the object before the agent gives up.
        reach_m: success radius, metres.
        horizon_s: latest query time after the last map update, seconds.
        speed_mps: walking speed, m/s (times of the observations made during an episode).
        look_every_m: metres walked between looks (adaptive agent).
        agent_memory: the adaptive agent's memory, ``visits`` or ``estimator`` (module docstring).
        absence: when the adaptive agent declares the object absent, ``delta`` or ``list-exhausted``.
        last_map: where the last map update of an adaptive query falls, ``end-of-validation`` or ``test-week``.
    """

    name: str
    scenes: tuple[int, ...]
    queries_per_scene: int
    shift: float | None
    adaptive: bool
    delta: float = 0.2
    max_attempts: int = 2
    reach_m: float = 1.0
    horizon_s: float = WEEK_S
    speed_mps: float = 0.5
    look_every_m: float = 1.0
    agent_memory: str = "visits"
    absence: str = "delta"
    last_map: str = "end-of-validation"

    def __post_init__(self) -> None:
        for field, value, allowed in (("agent_memory", self.agent_memory, AGENT_MEMORIES),
                                      ("absence", self.absence, ABSENCE_RULES), ("last_map", self.last_map, LAST_MAPS)):
            if value not in allowed:
                raise EvaluationError(f"{field}: expected one of {', '.join(allowed)}, got {value!r}")
        if self.queries_per_scene < 1:
            raise EvaluationError(f"queries per scene: expected a positive count, got {self.queries_per_scene}")

    @property
    def n_queries(self) -> int:
        """Queries of the protocol (scenes x queries per scene)."""
        return len(self.scenes) * self.queries_per_scene

    @property
    def reading(self) -> tuple[str, str, str]:
        """(last_map, agent_memory, absence): the reading of the paper's open choices this protocol runs."""
        return self.last_map, self.agent_memory, self.absence

    def readings(self) -> list[tuple[str, str, str]]:
        """Every distinct reading of an adaptive protocol, its own first (``estimator`` keeps no list, so
        its two absence rules are one reading, named ``delta``); the predictive protocol has one.
        """
        if not self.adaptive:
            return [self.reading]
        same = lambda r: (r[0], r[1], "delta" if r[1] == "estimator" else r[2])  # noqa: E731
        out = [self.reading]
        for r in ((last, mem, ab) for last in LAST_MAPS for mem in AGENT_MEMORIES for ab in ABSENCE_RULES):
            if same(r) not in {same(o) for o in out}:
                out.append(r)
        return out

    def quick(self) -> SimProtocol:
        """The CI form: two scenes, six queries each (same rules)."""
        return replace(self, name=self.name + "+quick", scenes=self.scenes[:2], queries_per_scene=6)

    def to_dict(self) -> dict[str, Any]:
        """The protocol as a JSON-ready dictionary (stored with the results)."""
        d = asdict(self)
        d["scenes"] = list(self.scenes)
        return d


SIM_PROTOCOLS: dict[str, SimProtocol] = {
    "paper-sim-predictive": SimProtocol("paper-sim-predictive", tuple(range(10)), 25, 0.0, False),
    "paper-sim-adaptive": SimProtocol("paper-sim-adaptive", tuple(range(10, 15)), 25, None, True),
}
"""The two protocols (module docstring)."""


def scene_split_ids(dataset: Any) -> dict[str, list[str]]:
    """Split -> scan ids (train / val / test) of a benchmark scene."""
    sc = dataset.df("scans")
    return {s: sc.loc[sc["split"] == s, "scan_id"].tolist() for s in ("train", "val", "test")}


def _split_stream(s: EdgeStream, t_cut: float) -> tuple[EdgeStream, EdgeStream]:
    a = s.t_s < t_cut
    return EdgeStream(s.edge, s.t_s[a], s.y[a], dict(s.meta)), EdgeStream(s.edge, s.t_s[~a], s.y[~a], dict(s.meta))


def method_filters(env: NavigationEnv, name: str, spec: str, settings: Mapping[str, Any] | None, val_start_s: float
                   ) -> dict[EdgeKey, EdgeFilter]:
    """One filter per map edge: fitted on the training weeks (validation week as ``val_streams``), then
    updated with the validation week. Built-ins ``oracle``, ``last_seen_map``, ``random_receptacle``.
    """
    from psg_data.graph._fit import resolve_estimator
    from psg_data.navigation._runner import build_filters

    if isinstance(spec, str) and spec in BUILTIN_METHODS:
        return build_filters(env, spec, settings=settings)  # the map streams are all they read
    est = resolve_estimator(spec, settings)
    parts = [_split_stream(s, val_start_s) for s in env.map_streams]
    train = [a for a, _ in parts if len(a)]
    val = [b for _, b in parts if len(b)]
    try:
        est.fit(train, val_streams=val, timezone=env.timezone)
        out: dict[EdgeKey, EdgeFilter] = {}
        for a, b in parts:
            f = est.make_filter(a.edge)
            for part in (a, b):
                if len(part):
                    f.update_many(part.t_s, part.y)
            out[a.edge] = f
    except PluginError:
        raise
    except PsgDataError as exc:
        raise EvaluationError(f"method {name}: fit / update on the map observations failed ({exc})") from exc
    return out


def _adaptive_queries(env: NavigationEnv, test_starts_s: np.ndarray, n: int, scene: int, protocol: SimProtocol,
                      last_map: str = "test-week") -> list[tuple[Query, float]]:
    """(query, time of its last map update) pairs: the update at a uniform test-week step (not the last), or
    at the end of the validation week (``last_map``); the same draws of object and start either way.
    """
    rng = np.random.default_rng([scene, 2525])
    out = []
    for k in range(n):
        t_m = float(test_starts_s[int(rng.integers(len(test_starts_s) - 1))])
        if last_map == "end-of-validation":
            t_m = env.t_map_s
        sub = replace(env, t_map_s=t_m, map_state={o: env.gt_at(o, t_m) for o in env.object_ids})
        q = make_queries(sub, 1, seed=int(rng.integers(2**31)), horizon_s=protocol.horizon_s, windows=None)[0]
        out.append((replace(q, query_id=k, seed=scene), t_m))
    return out


def _test_streams(dataset: Any, labels: str, test_ids: list[str], label_seed: int) -> dict[EdgeKey, EdgeStream]:
    from psg_data.graph._sources import source_observations

    return {s.edge: s for s in source_observations(dataset, labels, test_ids, seed=label_seed).object_streams}


def _house_sight(dataset: Any) -> Any:
    from psg_data.navigation._sim_agent import HouseSight
    from psg_data.synth._house_layout import HouseParams, make_house

    extra = dataset.info.extra
    geo: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in dict(extra["geometry"]).items()}
    return HouseSight.of_house(make_house(int(extra["seed"]), HouseParams(**geo)))


def scene_settings(dataset: Any, name: str, settings: Mapping[str, Any] | None) -> dict[str, Any]:
    """A method's settings on one scene: the user's, plus the scene's hints (``process_oracle``: its
    generator model, and ``share_updates`` unless given; module docstring).
    """
    from psg_data.evaluation._hints import EstimatorSpec, dataset_hints, with_hints

    given = dict(settings or {})
    if name in BUILTIN_METHODS:
        return given
    spec = with_hints(EstimatorSpec(name, name, tuple(given.items())), dataset_hints(dataset))
    out = dict(spec.settings)
    if name == "process_oracle":
        out.setdefault("share_updates", True)
    return out


def _fed_filters(graph: Any, q: Query, t_m: float, test: Mapping[EdgeKey, EdgeStream]) -> dict[str, EdgeFilter]:
    """Copies of the object's filters fed the test week up to ``t_m`` (none at the end of the validation week)."""
    fs: dict[str, EdgeFilter] = copy.deepcopy(graph.filters_of(q.object_id))  # one deepcopy: a shared tracker
    # stays shared
    for r, f in fs.items():
        s = test.get((q.object_id, r))
        if s is not None:
            m = s.t_s <= t_m
            if m.any():
                f.update_many(s.t_s[m], s.y[m])
    return fs


def _adaptive_query(fed: Mapping[str, EdgeFilter], q: Query, cache: Any, cfg: Any, sight: Any, protocol: SimProtocol,
                    reading: tuple[str, str, str]) -> tuple[Any, int]:
    """One adaptive episode of the ``reading``'s agent on a copy of the fed filters (:func:`_fed_filters`)."""
    from psg_data.navigation._sim_agent import run_adaptive_episode

    return run_adaptive_episode(cache, q, copy.deepcopy(dict(fed)), cfg, sight, look_every_m=protocol.look_every_m,
                                memory=reading[1], absence=reading[2])


def run_sim_scene(path: str | Path, scene: int, methods: Mapping[str, str], settings: Mapping[str, Mapping[str, Any]],
                  protocol: SimProtocol, labels: str = "gt", label_seed: int = 0,
                  keep: Sequence[int] = (), readings: Sequence[tuple[str, str, str]] | None = None
                  ) -> dict[str, Any]:
    """Every method on one scene's queries (under the protocol's reading, or every reading).

    Args:
        path: the scene dataset.
        scene: its house seed (the ``seed`` column of the records: the tables' per-scene unit).
        methods: label -> registry name or built-in.
        settings: label -> estimator settings.
        protocol: the protocol.
        labels: label source of the map and test observations (``gt``, ``privileged``, ``noisy:P``); the
            adaptive agent's own sight during an episode is exact whatever the source.
        label_seed: seed of noisy sources and sightings.
        keep: query ids whose trails and beliefs are returned (figures; the protocol's reading).
        readings: (last_map, agent_memory, absence) readings run on the same draws (default: the protocol's
            own; :meth:`SimProtocol.readings` lists every distinct one; records carry
            ``last_map``, ``agent_memory``, ``absence``; ``lab`` for the predictive protocol's agent, which
            skips the receptacles it tried and declares absence when none above delta is left), not only the
            protocol's.

    Returns:
        ``{"records": [...], "queries": [...], "trails": {(label, qid): cells}, "beliefs": {...}}``.
    """
    from psg_data.loaders import open_dataset
    from psg_data.maps._planner import PlanningCache
    from psg_data.navigation._agent import AgentConfig

    ds = open_dataset(path)
    ids = scene_split_ids(ds)
    if not (ids["train"] and ids["val"] and ids["test"]):
        raise EvaluationError(f"{path}: a benchmark scene needs train, val and test scans")
    env = NavigationEnv.from_dataset(ds, map_scans=ids["train"] + ids["val"], labels=labels, label_seed=label_seed,
                                     name=f"scene_{scene:02d}")
    starts = ds.df("scans").set_index("scan_id")["start_stamp_ns"]
    val_start = float(starts[ids["val"][0]]) / 1e9
    test_starts = np.array([float(starts[s]) / 1e9 for s in ids["test"]])
    cache = PlanningCache(env.grid, reach_m=protocol.reach_m)
    cfg = AgentConfig(setting="predictive", delta=protocol.delta, max_attempts=protocol.max_attempts,
                      speed_mps=protocol.speed_mps)
    sight: Any = None
    test: dict[EdgeKey, EdgeStream] = {}
    readings = list(readings or [protocol.reading])
    if protocol.reading not in readings:
        raise EvaluationError(f"{protocol.name}: the readings run must include the protocol's {protocol.reading}")
    if protocol.adaptive:
        pairs = {last: _adaptive_queries(env, test_starts, protocol.queries_per_scene, scene, protocol, last)
                 for last in dict.fromkeys(r[0] for r in readings)}
        test = _test_streams(ds, labels, ids["test"], label_seed)
        sight = _house_sight(ds)
    else:
        qs = make_queries(env, protocol.queries_per_scene, seed=scene, horizon_s=protocol.horizon_s, windows=None)
        pairs = {protocol.last_map: [(q, env.t_map_s) for q in qs]}
    out: dict[str, Any] = {"records": [], "queries": list(pairs[protocol.last_map]), "trails": {}, "beliefs": {},
                           "env": env.name, "settings": {}, "errors": []}
    for label, spec in methods.items():
        given = scene_settings(ds, spec, settings.get(label))
        out["settings"][label] = {k: v for k, v in given.items() if k != "dataset"}
        n = len(out["records"])
        try:
            _method_episodes(out, env, label, spec, given, val_start, pairs, readings, test, cache, cfg, sight,
                             protocol, scene, keep)
        except PluginError as exc:  # the plugin's failure is reported; the other methods are scored
            del out["records"][n:]
            for d in (out["trails"], out["beliefs"]):
                for k in [k for k in d if k[0] == label]:
                    del d[k]
            err = exc.record(label)
            out["errors"].append({**err, "scene": scene, "message": f"scene {scene}: {err['message']}"})
    return out


def _method_episodes(out: dict[str, Any], env: NavigationEnv, label: str, spec: str, given: dict[str, Any],
                     val_start: float, pairs: Mapping[str, list[tuple[Query, float]]], readings: Sequence[Any],
                     test: Mapping[EdgeKey, EdgeStream], cache: Any, cfg: Any, sight: Any, protocol: SimProtocol,
                     scene: int, keep: Sequence[int]) -> None:
    """One method's episodes of one scene under every reading, appended to ``out`` (records, trails, beliefs)."""
    from psg_data.graph._graph import PredictiveGraph
    from psg_data.navigation._agent import episode_record, run_episode

    graph = PredictiveGraph(env.layout, method_filters(env, label, spec, given, val_start), grid=env.grid)
    fed: dict[tuple[str, int], dict[str, EdgeFilter]] = {}  # fed once per query, copied per reading
    for reading in readings:
        for q, t_m in pairs[reading[0]]:
            if protocol.adaptive:
                key = (reading[0], q.query_id)
                if key not in fed:
                    fed[key] = _fed_filters(graph, q, t_m, test)
                ep, switches = _adaptive_query(fed[key], q, cache, cfg, sight, protocol, reading)
            else:
                bel = {r: float(v[0]) for r, v in graph.object_probabilities(q.object_id, [q.t_s]).items()} \
                    if q.object_id in graph.objects else {}
                ep, switches = run_episode(cache, q, graph.filters_of(q.object_id), cfg, beliefs=bel,
                                           observation=env.observation), 0
            out["records"].append(episode_record(
                ep, method=label, seed=scene, delta=protocol.delta, t_s=q.t_s, t_map_s=t_m,
                start_x_m=q.start_xy[0], start_y_m=q.start_xy[1], gt_receptacle=q.gt_receptacle,
                map_receptacle=q.map_receptacle, n_switches=switches, last_map=reading[0],
                agent_memory=reading[1] if protocol.adaptive else "lab",
                absence=reading[2] if protocol.adaptive else "lab"))
            if q.query_id in keep and reading == protocol.reading:
                out["trails"][(label, q.query_id)] = ep.trail
                out["beliefs"][(label, q.query_id)] = ep.beliefs


def run_sim_navigation(paths: Sequence[Path], methods: Mapping[str, str], settings: Mapping[str, Mapping[str, Any]],
                       protocol: SimProtocol, *, labels: str = "gt", label_seed: int = 0, executor: Any = None,
                       progress: Callable[[int, int], None] | None = None,
                       readings: Sequence[tuple[str, str, str]] | None = None) -> tuple[Any, dict[int, dict[str, Any]]]:
    """Every scene of ``protocol`` (``paths[k]`` is house ``protocol.scenes[k]``): (records DataFrame, raw
    output per scene).

    With an ``executor`` (``submit`` / futures) scenes run in parallel; results are ordered by scene. The
    records hold every one of ``readings`` (:func:`run_sim_scene`; default the protocol's own).
    """
    import pandas as pd

    if len(paths) != len(protocol.scenes):
        raise EvaluationError(f"{protocol.name}: {len(protocol.scenes)} scenes expected, got {len(paths)} paths")
    jobs = {sc: (str(p), sc, dict(methods), {k: dict(v) for k, v in settings.items()}, protocol, labels, label_seed,
                 tuple(range(protocol.queries_per_scene)) if k == 0 else (), tuple(readings or ()))
            for k, (sc, p) in enumerate(zip(protocol.scenes, paths))}
    outs: dict[int, dict[str, Any]] = {}
    done = 0
    if executor is None:
        for sc, args in jobs.items():
            outs[sc] = run_sim_scene(*args)
            done += 1
            if progress:
                progress(done, len(jobs))
    else:
        futs = {sc: executor.submit(run_sim_scene, *args) for sc, args in jobs.items()}
        for sc, fu in futs.items():
            outs[sc] = fu.result()
            done += 1
            if progress:
                progress(done, len(jobs))
    rows = [r for sc in protocol.scenes for r in outs[sc]["records"]]
    return pd.DataFrame(rows), outs
