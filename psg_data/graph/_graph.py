"""The PredictiveGraph: a scene's geometry with one fitted filter per object-receptacle edge and per door.

Nodes are rooms, receptacles, doors and objects (:class:`~psg_data.graph.SceneLayout`); each edge
(object, receptacle) carries a recursive filter of a persistence estimator (any registered one or a
plugin instance), each door a P(open) filter. The graph answers for any time ``t`` (Unix seconds,
a zone-aware datetime or a site-local string): :meth:`PredictiveGraph.at` (every edge and door),
:meth:`~PredictiveGraph.locate` (one object's receptacles, ranked), :meth:`~PredictiveGraph.plan`
(the navigation agent's targets, doors and path), and it is updated online from new observations
(:meth:`~PredictiveGraph.update`) without refitting.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError, GraphError, NotFittedError, PsgDataError
from psg_data.estimators._base import EdgeFilter, EdgeKey, EdgeStream
from psg_data.estimators._guard import PluginError
from psg_data.graph._fit import fit_door_filters, fit_edge_filters, fresh_estimator, resolve_estimator
from psg_data.graph._layout import SceneLayout
from psg_data.graph._snapshot import Ranking, Snapshot, ranking
from psg_data.graph._times import TimeLike, to_seconds

if TYPE_CHECKING:  # pragma: no cover
    from psg_data.graph._plan import Plan

__all__ = ["PredictiveGraph"]

log = logging.getLogger(__name__)

GRID_DEFAULTS = {"resolution_m": 0.05, "robot_radius_m": 0.25}


class PredictiveGraph:
    """A time-varying 3D scene graph whose object-receptacle edges and doors are persistence filters.

    Build one with :meth:`from_dataset` (a psg-dataset and a label source) or :meth:`fit` (a
    layout and observation streams); the constructor takes filters that exist already.

    Args:
        layout: rooms, receptacles, doors and objects (geometry, world frame, metres).
        filters: (object_id, receptacle_id) -> filter; the edge order is kept.
        door_filters: door_id -> P(open) filter (a door without one has no model: P(open) NaN,
            planned open).
        estimator: the estimator that made ``filters`` (needed by :meth:`update` for new edges and by
            :meth:`save`).
        door_estimator: the estimator that made the door filters.
        door_kinds: door_id -> ``"estimator"`` (fitted filter), ``"prior"`` (constant: no training
            observation) or ``"given"``.
        grid: the occupancy grid :meth:`plan` walks on (default: built from the layout on first use).
        grid_options: ``resolution_m`` / ``robot_radius_m`` of that grid (default 0.05 / 0.25 m).
        info: provenance (dataset, label source, training scans); saved with the graph.
    """

    def __init__(self, layout: SceneLayout, filters: Mapping[EdgeKey, EdgeFilter],
                 door_filters: Mapping[str, EdgeFilter] | None = None, *, estimator: Any = None,
                 door_estimator: Any = None, door_kinds: Mapping[str, str] | None = None, grid: Any = None,
                 grid_options: Mapping[str, float] | None = None, info: Mapping[str, Any] | None = None) -> None:
        self.layout = layout
        self._edges: list[EdgeKey] = []
        self._filters: list[EdgeFilter] = []
        self._index: dict[EdgeKey, int] = {}
        self._by_object: dict[str, list[int]] = {}
        for e, f in filters.items():
            self._add_edge((str(e[0]), str(e[1])), f)
        self._door_filters: dict[str, EdgeFilter] = {str(d): f for d, f in (door_filters or {}).items()}
        self.doors: tuple[str, ...] = tuple(sorted(set(layout.doors) | set(self._door_filters)))
        self.door_kinds: dict[str, str] = {d: (door_kinds or {}).get(d, "given") for d in self._door_filters}
        self.estimator = estimator
        self.door_estimator = door_estimator
        self._grid = grid
        self.grid_options = {**GRID_DEFAULTS, **dict(grid_options or {})}
        self._caches: dict[float, Any] = {}
        self.info: dict[str, Any] = dict(info or {})
        self.new_edge_state: dict[str, Any] | None = None
        """A loaded graph's filter state for an edge its estimator never saw (new edges start from it)."""

    def _add_edge(self, e: EdgeKey, f: EdgeFilter) -> None:
        if e in self._index:
            raise GraphError(f"edge {e}: given twice")
        self._index[e] = len(self._edges)
        self._by_object.setdefault(e[0], []).append(len(self._edges))
        self._edges.append(e)
        self._filters.append(f)

    # -- construction ------------------------------------------------------------------------------
    @classmethod
    def fit(cls, layout: SceneLayout, streams: Sequence[EdgeStream], *, door_streams: Sequence[EdgeStream] = (),
            estimator: Any = "perpetua_star", door_estimator: Any = "same",
            settings: Mapping[str, Any] | None = None, door_settings: Mapping[str, Any] | None = None,
            val_streams: Sequence[EdgeStream] | None = None, unseen_prior: float = 0.5, grid: Any = None,
            grid_options: Mapping[str, float] | None = None, info: Mapping[str, Any] | None = None
            ) -> PredictiveGraph:
        """Fit one filter per edge of ``streams`` and one P(open) filter per door.

        Args:
            layout: the scene's geometry (its timezone is the estimators' clock).
            streams: object-receptacle observation streams (one edge per stream; times Unix s).
            door_streams: ``(door_id, 'open')`` streams (1 seen open, 0 seen closed).
            estimator: a registry name or an estimator instance (fitted on ``streams`` unless it is
                fitted already).
            door_estimator: ``"same"`` (a fresh copy of ``estimator``), a registry name, an
                instance, or None (no door model: every door planned open).
            settings: keyword settings of a registry ``estimator``.
            door_settings: keyword settings of a registry ``door_estimator``.
            val_streams: validation streams handed to the estimator's ``fit``.
            unseen_prior: P(open) of a door without training observations.
            grid: the planning grid (see the class).
            grid_options: its resolution and robot radius (see the class).
            info: provenance (see the class).

        Raises:
            EstimatorError: unknown estimator or settings. EvaluationError: a fit failed.
        """
        est = resolve_estimator(estimator, settings)
        filters = fit_edge_filters(est, streams, timezone=layout.timezone, val_streams=val_streams)
        g = cls(layout, filters, estimator=est, grid=grid, grid_options=grid_options, info=info)
        if door_estimator is None:
            return g
        if isinstance(door_estimator, str) and door_estimator == "same":
            door_estimator, door_settings = fresh_estimator(est), None
        return g.with_door_model(door_estimator, door_streams, settings=door_settings, unseen_prior=unseen_prior)

    @classmethod
    def from_dataset(cls, dataset: Any, estimator: Any = "perpetua_star", *, labels: str = "gt",
                     train_scans: Sequence[str] | None = None, door_estimator: Any = "same",
                     settings: Mapping[str, Any] | None = None, door_settings: Mapping[str, Any] | None = None,
                     label_seed: int = 0, unseen_prior: float = 0.5, grid_source: str = "geometry",
                     resolution_m: float = 0.05, robot_radius_m: float = 0.25) -> PredictiveGraph:
        """The graph of a psg-dataset, fitted on its training scans.

        Args:
            dataset: a :class:`~psg_data.loaders.Dataset` or its path.
            estimator: see :meth:`fit`.
            labels: label source of the observations (``gt``, ``privileged``, ``noisy:P[,P_F]``,
                ``detections:FILE``; :mod:`psg_data.graph._sources`): object edges are the receptacles
                the source saw each object on in the training scans.
            train_scans: scan ids to fit on (default: split ``train``, else the first two thirds).
            door_estimator: see :meth:`fit`.
            settings: see :meth:`fit`.
            door_settings: see :meth:`fit`.
            unseen_prior: see :meth:`fit`.
            label_seed: seed of on-the-fly label noise.
            grid_source: ``geometry`` (room polygons, boxes; built on first :meth:`plan`) or ``scans``
                (fused depth, built now).
            resolution_m: cell size of the planning grid, metres.
            robot_radius_m: robot radius its obstacles are inflated by, metres.

        Raises:
            EvaluationError: no scans, labels missing (the message names the command to run).
        """
        from psg_data.graph._sources import source_observations
        from psg_data.graph._timeline import DatasetTimeline

        if isinstance(dataset, (str, Path)):
            from psg_data.loaders import open_dataset

            dataset = open_dataset(dataset)
        ds = dataset
        tl = DatasetTimeline.from_dataset(ds, train_scans, need_schedule=False)
        src = source_observations(ds, labels, tl.map_ids, seed=label_seed)
        options = {"resolution_m": float(resolution_m), "robot_radius_m": float(robot_radius_m)}
        grid = None
        if grid_source != "geometry":
            from psg_data.maps._grid import grid_from_dataset

            grid = grid_from_dataset(ds, source=grid_source, **options)
        info = {"dataset": str(ds.root), "labels": labels, "train_scans": len(tl.map_ids),
                "t_train_end_s": tl.t_map_s, "grid_source": grid_source, "sources": src.info}
        return cls.fit(SceneLayout.from_dataset(ds), src.object_streams, door_streams=src.door_streams,
                       estimator=estimator, door_estimator=door_estimator, settings=settings,
                       door_settings=door_settings, unseen_prior=unseen_prior, grid=grid, grid_options=options,
                       info=info)

    def with_door_model(self, estimator: Any, door_streams: Sequence[EdgeStream], *,
                        settings: Mapping[str, Any] | None = None, unseen_prior: float = 0.5,
                        door_ids: Sequence[str] | None = None) -> PredictiveGraph:
        """This graph (its edge filters shared, not copied) with door filters fitted on ``door_streams``
        (:func:`~psg_data.graph.fit_door_filters`: a registry name or an unfitted instance; doors
        without observations get ``unseen_prior``). ``door_ids`` default: the layout's doors and
        those of the streams.

        Raises:
            EvaluationError: unknown estimator or a failed fit.
        """
        try:
            est = resolve_estimator(estimator, settings)
        except PluginError:
            raise
        except PsgDataError as exc:
            raise EvaluationError(f"estimator {estimator!r}: {exc}") from exc
        ids = sorted(set(self.layout.doors) | {s.edge[0] for s in door_streams}) if door_ids is None else door_ids
        filters, kinds = fit_door_filters(est, door_streams, ids, timezone=self.timezone, unseen_prior=unseen_prior)
        return self.with_door_filters(filters, kinds=kinds, door_estimator=est)

    def with_door_filters(self, door_filters: Mapping[str, EdgeFilter], *, kinds: Mapping[str, str] | None = None,
                          door_estimator: Any = None) -> PredictiveGraph:
        """This graph (its edge filters shared, not copied) with other door filters."""
        g = PredictiveGraph(self.layout, dict(zip(self._edges, self._filters)), door_filters,
                            estimator=self.estimator, door_estimator=door_estimator, door_kinds=kinds,
                            grid=self._grid, grid_options=self.grid_options, info=self.info)
        g._caches, g.new_edge_state = self._caches, self.new_edge_state
        return g

    def copy(self) -> PredictiveGraph:
        """An independent copy: filters deep-copied (updating it leaves this graph unchanged), geometry shared."""
        g = PredictiveGraph(self.layout, {e: copy.deepcopy(f) for e, f in zip(self._edges, self._filters)},
                            {d: copy.deepcopy(f) for d, f in self._door_filters.items()}, estimator=self.estimator,
                            door_estimator=self.door_estimator, door_kinds=self.door_kinds, grid=self._grid,
                            grid_options=self.grid_options, info=self.info)
        g._caches, g.new_edge_state = self._caches, self.new_edge_state
        return g

    # -- structure ---------------------------------------------------------------------------------
    @property
    def timezone(self) -> str:
        """IANA site timezone (of the layout)."""
        return self.layout.timezone

    @property
    def edges(self) -> list[EdgeKey]:
        """The (object_id, receptacle_id) edges, in the graph's order."""
        return list(self._edges)

    @property
    def objects(self) -> list[str]:
        """Object ids: the layout's and those with edges, sorted."""
        return sorted(set(self.layout.objects) | set(self._by_object))

    def filter(self, edge: EdgeKey) -> EdgeFilter:
        """The filter of ``edge`` (object_id, receptacle_id)."""
        k = self._index.get((str(edge[0]), str(edge[1])))
        if k is None:
            raise GraphError(f"edge {tuple(edge)}: not in the graph ({len(self._edges)} edges)")
        return self._filters[k]

    def filters_of(self, object_id: str) -> dict[str, EdgeFilter]:
        """receptacle_id -> filter of every edge of ``object_id`` (empty for an object without edges)."""
        return {self._edges[k][1]: self._filters[k] for k in self._by_object.get(object_id, [])}

    def door_filter(self, door_id: str) -> EdgeFilter | None:
        """The P(open) filter of ``door_id`` (None: no door model)."""
        return self._door_filters.get(door_id)

    def door_open_probabilities(self, t: TimeLike, *, prior: float = 0.5) -> dict[str, float]:
        """door_id -> P(open) at ``t`` clipped to [0, 1], ``prior`` for a door without a model or with a
        non-finite prediction (:func:`~psg_data.graph.door_open_probabilities`, as the door task reads it).
        """
        from psg_data.graph._fit import door_open_probabilities

        return door_open_probabilities(self._door_filters, to_seconds(t, self.timezone), self.doors, prior=prior)

    def __len__(self) -> int:
        return len(self._edges)

    def __repr__(self) -> str:
        name = getattr(self.estimator, "name", type(self.estimator).__name__ if self.estimator is not None else None)
        return (f"PredictiveGraph({len(self._edges)} edges, {len(self._by_object)} objects with edges, "
                f"{len(self.layout.receptacles)} receptacles, {len(self.doors)} doors, estimator={name})")

    # -- queries -----------------------------------------------------------------------------------
    def _times(self, times: TimeLike | Iterable[TimeLike]) -> NDArray[np.float64]:
        if isinstance(times, np.ndarray) and times.dtype.kind in "fiu":
            return np.asarray(times, np.float64).reshape(-1)
        if isinstance(times, (str, bytes)) or not isinstance(times, Iterable):
            return np.array([to_seconds(times, self.timezone)])
        return np.array([to_seconds(t, self.timezone) for t in times], np.float64)

    @staticmethod
    def _predict(f: EdgeFilter, t: NDArray[np.float64], what: Any) -> NDArray[np.float64]:
        v = np.asarray(f.predict(t), np.float64).reshape(-1)
        if v.shape != t.shape:
            raise GraphError(f"filter of {what} returned shape {v.shape} for {t.size} times")
        return v

    def edge_probabilities(self, times: TimeLike | Iterable[TimeLike]) -> NDArray[np.float64]:
        """(T, E) P(object on receptacle) of every edge at each time: one vectorised ``predict`` per filter."""
        t = self._times(times)
        out = np.empty((t.size, len(self._filters)))
        for k, f in enumerate(self._filters):
            out[:, k] = self._predict(f, t, self._edges[k])
        return out

    def door_probabilities(self, times: TimeLike | Iterable[TimeLike]) -> NDArray[np.float64]:
        """(T, D) P(open) of every door (:attr:`doors` order) at each time; NaN for a door without a model."""
        t = self._times(times)
        out = np.full((t.size, len(self.doors)), np.nan)
        for k, d in enumerate(self.doors):
            f = self._door_filters.get(d)
            if f is not None:
                out[:, k] = self._predict(f, t, f"door {d}")
        return out

    def object_probabilities(self, object_id: str, times: TimeLike | Iterable[TimeLike]) -> dict[str, NDArray]:
        """receptacle_id -> (T,) P(``object_id`` on it) at each time, one ``predict`` per edge."""
        t = self._times(times)
        return {self._edges[k][1]: self._predict(self._filters[k], t, self._edges[k])
                for k in self._by_object.get(self._known(object_id), [])}

    def _known(self, object_id: str) -> str:
        if object_id not in self._by_object and object_id not in self.layout.objects:
            some = ", ".join(self.objects[:5])
            raise GraphError(f"object {object_id!r}: not in the graph (objects: {some}"
                             f"{', ...' if len(self.objects) > 5 else ''})")
        return object_id

    def at(self, t: TimeLike) -> Snapshot:
        """The :class:`Snapshot` at ``t``: every edge's P(present) and every door's P(open)."""
        ts = self._times(t)
        if ts.size != 1:
            raise GraphError(f"at: one time expected, got {ts.size} (edge_probabilities takes many)")
        p = self.edge_probabilities(ts)[0]
        objs = np.array([e[0] for e in self._edges], dtype=np.str_)
        recs = np.array([e[1] for e in self._edges], dtype=np.str_)
        return Snapshot(float(ts[0]), objs, recs, p, np.array(self.doors, dtype=np.str_),
                        self.door_probabilities(ts)[0], self.layout)

    def locate(self, object_id: str, t: TimeLike, *, top: int | None = None) -> Ranking:
        """The receptacles of ``object_id`` ranked by P(present) at ``t`` (ties by receptacle id),
        the first ``top`` of them (all when None), with their positions and rooms.
        """
        ts = self._times(t)
        if ts.size != 1:
            raise GraphError(f"locate: one time expected, got {ts.size}")
        bel = {r: float(v[0]) for r, v in self.object_probabilities(object_id, ts).items()}
        return ranking(self.layout, object_id, float(ts[0]), bel, top)

    # -- online update -----------------------------------------------------------------------------
    def update(self, observations: Any) -> int:
        """Apply new observations to the filters (no refit); returns how many were applied.

        Args:
            observations: rows of the ``labels`` table (a ``pandas.DataFrame`` or ``pyarrow.Table``
                with object_id, receptacle_id, stamp_ns, code; codes -1 / -2 are skipped; door rows
                have the door as object_id and ``open`` / ``closed`` as receptacle_id), or an iterable
                of ``(t, object_id, receptacle_id, present)`` tuples (``t`` as in :meth:`at`;
                doors: ``(t, door_id, "open", is_open)``).

        Observations are applied in time order, per edge with ``update_many`` (equal to one
        ``update`` at a time). An object seen present on a receptacle it has no edge to gets a new
        edge (a fresh filter of :attr:`estimator`, updated with this batch's observations of it);
        absences on pairs without an edge are skipped (they carry no ranking information).

        Raises:
            GraphError: an unknown receptacle, an observation earlier than its edge's last one, a bad
                row; nothing is applied then.
        """
        from psg_data.graph._observations import group_observations

        groups = group_observations(observations, self)
        plan: list[tuple[str, Any, EdgeFilter, NDArray[np.float64], NDArray[np.int8]]] = []
        for (kind, key), (t, y) in groups.items():
            f = self._door_filters.get(key) if kind == "door" else self._edge_filter(key)
            if f is None and kind == "door":
                log.debug("door %s: no door model, observations skipped", key)
                continue
            if f is None:
                if not np.any(y == 1):
                    continue
                f = self._new_filter(key)
            last = f.last_t_s
            if last is not None and t[0] < last:
                raise GraphError(f"observation of {key} at t={t[0]:.3f} s: earlier than its last observation "
                                 f"({last:.3f} s); observations must come in time order")
            plan.append((kind, key, f, t, y))
        n = 0
        for kind, key, f, t, y in plan:
            if kind == "edge" and key not in self._index:
                self._add_edge(key, f)
            if kind == "door" and self.door_kinds.get(key) == "prior":
                f = self._door_from_prior(key, f)
            f.update_many(t, y)
            n += int(t.size)
        return n

    def _edge_filter(self, e: EdgeKey) -> EdgeFilter | None:
        k = self._index.get(e)
        return None if k is None else self._filters[k]

    def _new_filter(self, e: EdgeKey) -> EdgeFilter:
        if e[1] not in self.layout.receptacles and not any(r == e[1] for _, r in self._edges):
            raise GraphError(f"observation of {e}: unknown receptacle {e[1]!r}")
        if self.estimator is None or not hasattr(self.estimator, "make_filter"):
            raise GraphError(f"observation of {e}: a new edge needs the graph's estimator (this graph has none)")
        try:
            return self.estimator.make_filter(e)
        except NotFittedError:
            if self.new_edge_state is None:
                raise GraphError(f"new edge {e}: the graph's estimator is not fitted (a loaded graph without a "
                                 "saved new-edge state); load it with a fitted estimator=") from None
            return self.estimator.filter_from_state({**self.new_edge_state, "edge": [e[0], e[1]]})
        except PsgDataError as exc:
            raise GraphError(f"new edge {e}: {type(self.estimator).__name__}.make_filter failed ({exc})") from None

    def _door_from_prior(self, d: str, f: EdgeFilter) -> EdgeFilter:
        """A door that had no training observation: a fitted door estimator's fresh filter, else the prior."""
        est = self.door_estimator
        try:
            new = est.make_filter((d, "open")) if est is not None else None
        except NotFittedError:
            new = None
        if new is None:
            log.info("door %s: no fitted door estimator; it keeps its prior P(open)", d)
            return f
        self._door_filters[d], self.door_kinds[d] = new, "estimator"
        return new

    # -- planning ----------------------------------------------------------------------------------
    @property
    def grid(self) -> Any:
        """The occupancy grid :meth:`plan` uses (built from the layout's rooms, receptacles and doors
        on first use; :func:`psg_data.maps.grid_from_geometry`).

        Raises:
            GraphError: the layout has no room with a floor polygon and no grid was given.
        """
        if self._grid is None:
            from psg_data.maps._grid import grid_from_geometry

            L = self.layout
            if not any(r.floor_polygon_m is not None and len(r.floor_polygon_m) >= 3 for r in L.rooms.values()):
                raise GraphError("plan: the layout has no room floor polygons to build a map from; pass grid=")
            self._grid = grid_from_geometry(list(L.rooms.values()), list(L.receptacles.values()),
                                            list(L.doors.values()), openings=list(L.openings.values()),
                                            **self.grid_options)
        return self._grid

    def planning_cache(self, reach_m: float = 1.0) -> Any:
        """The :class:`~psg_data.maps.PlanningCache` of :attr:`grid` for approach radius ``reach_m`` (cached)."""
        key = float(reach_m)
        if key not in self._caches:
            from psg_data.maps._planner import PlanningCache

            self._caches[key] = PlanningCache(self.grid, reach_m=key)
        return self._caches[key]

    def plan(self, start_xy: Sequence[float], object_id: str, t: TimeLike, *, delta: float = 0.2,
             threshold: float = 0.5, exclude: Iterable[str] = (), reach_m: float = 1.0,
             door_rule: str = "threshold") -> Plan:
        """The navigation agent's plan to find ``object_id`` at ``t`` from ``start_xy`` (world x, y, metres).

        Candidates are the object's receptacles with P(present) >= ``delta`` not in ``exclude``,
        ranked by probability (ties by id); with ``door_rule="threshold"`` doors with P(open) <
        ``threshold`` are planned closed, the target is the first candidate reachable under those
        doors and the path a shortest path to its approach set (cells within ``reach_m`` in line of
        sight): the same rules as the navigation task's agent (:func:`psg_data.navigation.run_episode`).
        With ``door_rule="expected_cost"`` each candidate's distance is the expected walked distance
        of :func:`psg_data.maps.expected_cost_route` (P(open) as a probability, doors discovered on
        arrival), the target the first candidate some route with non-negligible P(open) reaches, and
        the path that rule's route (``doors_open``: the door states it assumes).

        Returns:
            A :class:`~psg_data.graph.Plan`.
        """
        from psg_data.graph._plan import make_plan

        return make_plan(self, start_xy, object_id, to_seconds(t, self.timezone), delta=delta, threshold=threshold,
                         exclude=exclude, reach_m=reach_m, door_rule=door_rule)

    # -- storage -----------------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write the graph to one JSON file (versioned; filters' state, no code): see :mod:`psg_data.graph._store`."""
        from psg_data.graph._store import save_graph

        return save_graph(self, path)

    @classmethod
    def load(cls, path: str | Path, *, estimator: Any = None, door_estimator: Any = None) -> PredictiveGraph:
        """A graph :meth:`save` wrote; ``estimator`` / ``door_estimator`` replace the registry lookups
        (for plugin estimators that are not registered).
        """
        from psg_data.graph._store import load_graph

        return load_graph(path, estimator=estimator, door_estimator=door_estimator)
