"""Saving and loading a fitted predictive graph: one versioned JSON file, filters' state, no code.

File (``format: "psg-predictive-graph"``, ``version: 1``)::

    {"format", "version", "written_by",
     "layout": SceneLayout.to_dict(),
     "estimator": {"name", "params"} | null, "door_estimator": {"name", "params"} | null,
     "edges": [[object_id, receptacle_id], ...], "filters": [EdgeFilter.get_state(), ...],
     "new_edge": the state of estimator.make_filter for an edge it never saw (or null),
     "doors": {door_id: {"kind": "estimator", "state": {...}} | {"kind": "prior", "value", "last_t_s"}},
     "grid": {"options": {...}} | {"options": {...}, "arrays": {...}}, "info": {...}}

Filters are saved by the plugin protocol's own methods: ``EdgeFilter.get_state()`` (JSON) and
``PersistenceEstimator.filter_from_state(state)``, which must rebuild the filter on a *fresh,
unfitted* estimator with the same settings (the state holds the learned parameters). Every
built-in estimator does, except ``process_oracle`` (its filters read the generator model); an
estimator whose filters cannot be rebuilt that way is refused at :func:`save_graph` with one line,
before anything is written. Estimators are rebuilt from the registry by name and settings
(``get_params``), or given to :func:`load_graph` (plugins that are not registered).
"""

from __future__ import annotations

import base64
import json
import math
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from psg_data.errors import GraphError, PsgDataError
from psg_data.graph._fit import fresh_estimator
from psg_data.graph._graph_check import GRAPH_FORMAT, GRAPH_VERSION, read_graph_file, unpack_mask
from psg_data.graph._layout import SceneLayout

if TYPE_CHECKING:  # pragma: no cover
    from psg_data.graph._graph import PredictiveGraph

__all__ = ["GRAPH_FORMAT", "GRAPH_VERSION", "save_graph", "load_graph"]

_NEW_EDGE = ("\x00new-object", "\x00new-receptacle")
_CHECK_AFTER_S = (0.0, 3600.0, 7 * 86400.0)
"""Times after each filter's last observation at which a restored filter must predict identically."""


def _spec(est: Any, what: str) -> dict[str, Any] | None:
    if est is None:
        return None
    name = getattr(est, "name", None)
    if not isinstance(name, str):
        raise GraphError(f"save: the {what} {type(est).__name__} has no registry name (attribute 'name')")
    try:
        params = est.get_params(deep=False)
    except TypeError:
        params = est.get_params()
    try:
        json.dumps(params)
    except (TypeError, ValueError) as exc:
        raise GraphError(f"save: the {what} {name}'s settings are not JSON-serialisable ({exc})") from None
    return {"name": name, "params": params}


def _restorer(est: Any, what: str) -> Any:
    """A fresh, unfitted copy of ``est`` (what :func:`load_graph` will have)."""
    try:
        return fresh_estimator(est)
    except (TypeError, ValueError, AttributeError) as exc:
        raise GraphError(f"save: the {what} {type(est).__name__} cannot be rebuilt from get_params ({exc})") from None


def _checked_state(f: Any, restorer: Any, name: str, what: Any) -> dict[str, Any]:
    """``f.get_state()`` after checking that a fresh estimator restores a filter predicting identically."""
    if not hasattr(f, "get_state"):
        raise GraphError(f"save: the filter of {what} ({type(f).__name__}) has no get_state(); it cannot be saved")
    state = f.get_state()
    try:
        text = json.dumps(state)
        g = restorer.filter_from_state(json.loads(text))
    except (PsgDataError, KeyError, TypeError, ValueError, AttributeError) as exc:
        raise GraphError(f"save: estimator {name!r} cannot rebuild its filters from their state alone "
                         f"({type(exc).__name__}: {exc}); a saveable filter's get_state() holds everything "
                         "filter_from_state needs on an unfitted estimator") from None
    last = f.last_t_s if f.last_t_s is not None else 0.0
    t = np.asarray([last + d for d in _CHECK_AFTER_S], np.float64)
    if not np.array_equal(np.asarray(f.predict(t)), np.asarray(g.predict(t)), equal_nan=True):
        raise GraphError(f"save: estimator {name!r}: the filter of {what} restored from its state predicts "
                         "differently; its get_state() is incomplete")
    return state


def _pack(mask: Any) -> str:
    return base64.b64encode(zlib.compress(np.packbits(np.asarray(mask, bool).ravel()).tobytes())).decode("ascii")




def _grid_dict(g: PredictiveGraph) -> dict[str, Any]:
    out: dict[str, Any] = {"options": dict(g.grid_options)}
    grid = g._grid
    if grid is None:
        return out
    out["arrays"] = {"shape": list(grid.shape), "origin_m": np.asarray(grid.origin_m, float).tolist(),
                     "resolution_m": float(grid.resolution_m), "robot_radius_m": float(grid.robot_radius_m),
                     "source": grid.source, "static_obstacle": _pack(grid.static_obstacle),
                     "door_cells": {d: _pack(m) for d, m in grid.door_cells.items()},
                     "receptacle_cells": {r: _pack(m) for r, m in grid.receptacle_cells.items()}}
    return out


def graph_to_dict(g: PredictiveGraph) -> dict[str, Any]:
    """The file's content (module docstring); GraphError for a graph that cannot be saved."""
    from psg_data import __version__

    est_spec = _spec(g.estimator, "estimator")
    if g.edges and est_spec is None:
        raise GraphError("save: this graph's filters were given without their estimator; only graphs with an "
                         "estimator (PredictiveGraph.fit / from_dataset) can be saved")
    states, new_edge = [], None
    if est_spec is not None:
        fresh = _restorer(g.estimator, "estimator")
        states = [_checked_state(g.filter(e), fresh, est_spec["name"], e) for e in g.edges]
        try:
            new_edge = g.estimator.make_filter(_NEW_EDGE).get_state()
        except PsgDataError:
            new_edge = None
    door_spec = _spec(g.door_estimator, "door estimator")
    doors: dict[str, Any] = {}
    for d in g.doors:
        f, kind = g.door_filter(d), g.door_kinds.get(d)
        if f is None:
            continue
        if kind == "prior":
            doors[d] = {"kind": "prior", "value": float(f.predict(np.zeros(1))[0]), "last_t_s": f.last_t_s}
        elif door_spec is not None and kind == "estimator":
            doors[d] = {"kind": "estimator", "state": _checked_state(
                f, _restorer(g.door_estimator, "door estimator"), door_spec["name"], f"door {d}")}
        else:
            raise GraphError(f"save: door {d}'s filter was given without its estimator; it cannot be saved")
    return {"format": GRAPH_FORMAT, "version": GRAPH_VERSION, "written_by": f"psg-data {__version__}",
            "layout": g.layout.to_dict(), "estimator": est_spec, "door_estimator": door_spec,
            "edges": [list(e) for e in g.edges], "filters": states, "new_edge": new_edge, "doors": doors,
            "grid": _grid_dict(g), "info": g.info}


def save_graph(g: PredictiveGraph, path: str | Path) -> Path:
    """Write ``g`` to ``path`` (one JSON file, replaced atomically; nothing is written when ``g`` cannot be saved).

    Raises:
        GraphError: filters without an estimator, an estimator whose filters need the fitted
            estimator to be rebuilt (``process_oracle``), settings that are not JSON.
    """
    from psg_data.writers._safe_output import write_atomically

    text = json.dumps(graph_to_dict(g), allow_nan=True, default=_json_default)
    inputs = [g.info.get("dataset")] if isinstance(g.info.get("dataset"), str) else []
    return write_atomically(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"), inputs=inputs)


def _json_default(x: Any) -> Any:
    if isinstance(x, (np.integer, np.floating, np.bool_)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON-serialisable")


def _estimator(spec: dict[str, Any] | None, given: Any, path: Path, what: str) -> Any:
    if given is not None:
        return given
    if spec is None:
        return None
    from psg_data.estimators._registry import get_estimator

    try:
        return get_estimator(spec["name"], **dict(spec.get("params") or {}))
    except PsgDataError as exc:
        raise GraphError(f"{path}: {what} {spec.get('name')!r}: {exc}; pass {what.replace(' ', '_')}= to "
                         "PredictiveGraph.load") from None


def _grid(d: dict[str, Any]) -> Any:
    a = d.get("arrays")
    if not a:
        return None
    from psg_data.maps._grid import OccupancyGrid

    shape = (int(a["shape"][0]), int(a["shape"][1]))
    w = "grid.arrays."
    doors = {k: unpack_mask(v, shape, f"{w}door_cells.{k}") for k, v in a["door_cells"].items()}
    recs = {k: unpack_mask(v, shape, f"{w}receptacle_cells.{k}") for k, v in a["receptacle_cells"].items()}
    return OccupancyGrid(unpack_mask(a["static_obstacle"], shape, w + "static_obstacle"),
                         np.asarray(a["origin_m"], np.float64), float(a["resolution_m"]), float(a["robot_radius_m"]),
                         doors, recs, str(a["source"]))


_PROBE_ERRORS = (PsgDataError, KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError,
                 ZeroDivisionError, FloatingPointError)


def _probe(f: Any, what: str) -> Any:
    """``f`` after one prediction at its last time and a week later (a state it cannot predict from is refused now)."""
    last = f.last_t_s if f.last_t_s is not None and math.isfinite(f.last_t_s) else 0.0
    try:
        v = np.asarray(f.predict(np.asarray([last, last + _CHECK_AFTER_S[-1]], np.float64)), np.float64)
    except _PROBE_ERRORS as exc:
        raise GraphError(f"{what}: the restored filter cannot predict ({type(exc).__name__}: {exc})") from None
    if v.shape != (2,):
        raise GraphError(f"{what}: the restored filter predicts shape {v.shape} for 2 times")
    return f


def load_graph(path: str | Path, *, estimator: Any = None, door_estimator: Any = None) -> PredictiveGraph:
    """The graph :func:`save_graph` wrote to ``path``.

    Raises:
        GraphError: not such a file, a newer version, a malformed field, an estimator that is not
            registered (pass it), a state the estimator rejects.
    """
    from psg_data.estimators._simple import ConstantFilter
    from psg_data.graph._graph import PredictiveGraph

    path = Path(path)
    d = read_graph_file(path)
    try:
        layout = SceneLayout.from_dict(d["layout"])
        est = _estimator(d["estimator"], estimator, path, "estimator")
        dest = _estimator(d["door_estimator"], door_estimator, path, "door estimator")
        filters = {(e[0], e[1]): _probe(est.filter_from_state(s), f"filters[{i}]")
                   for i, (e, s) in enumerate(zip(d["edges"], d["filters"]))}
        door_filters, kinds = {}, {}
        for door, v in d["doors"].items():
            if v["kind"] == "prior":
                f = ConstantFilter((door, "open"), "prior", float(v["value"]))
                if v.get("last_t_s") is not None:  # the constant prior keeps only the time of its last update
                    f._last_t = float(v["last_t_s"])
                door_filters[door], kinds[door] = f, "prior"
            else:
                door_filters[door] = _probe(dest.filter_from_state(v["state"]), f"doors.{door}.state")
                kinds[door] = "estimator"
        g = PredictiveGraph(layout, filters, door_filters, estimator=est, door_estimator=dest, door_kinds=kinds,
                            grid=_grid(d["grid"]), grid_options=d["grid"].get("options"), info=d.get("info") or {})
    except GraphError as exc:
        raise GraphError(f"{path}: malformed predictive graph: {exc}") from None
    except _PROBE_ERRORS as exc:
        raise GraphError(f"{path}: malformed predictive graph ({type(exc).__name__}: {exc})") from None
    g.new_edge_state = d.get("new_edge")
    return g
