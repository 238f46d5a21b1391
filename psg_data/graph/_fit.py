"""Fitting a graph's filters: one per (object, receptacle) edge, one P(open) filter per door.

A door is a semi-static "object" whose "receptacles" are its states: an estimator fitted on the
``(door_id, 'open')`` streams (1 seen open, 0 seen closed) predicts P(open) per door. These are the
functions the navigation and door tasks use; :class:`~psg_data.graph.PredictiveGraph` calls them.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError, NotFittedError, PsgDataError
from psg_data.estimators._base import EdgeFilter, EdgeKey, EdgeStream
from psg_data.estimators._guard import GuardedEstimator, PluginError, guarded_call, isolate
from psg_data.estimators._simple import ConstantFilter

__all__ = ["resolve_estimator", "fresh_estimator", "fit_edge_filters", "fit_door_filters", "door_open_probabilities",
           "open_streams"]

log = logging.getLogger(__name__)


def resolve_estimator(spec: Any, settings: Mapping[str, Any] | None = None) -> Any:
    """An estimator instance: ``spec`` itself, or the registry estimator named ``spec`` with ``settings``;
    a plugin isolated (:func:`psg_data.estimators._guard.isolate`: every call guarded).

    Raises:
        EstimatorError: unknown name or invalid settings. PluginError: a plugin's ``__init__`` failed.
    """
    if isinstance(spec, str):
        from psg_data.estimators._registry import get_estimator

        kw = dict(settings or {})
        return isolate(guarded_call(spec, "__init__", lambda: get_estimator(spec, **kw), passthrough=(PsgDataError,)),
                       spec)
    return isolate(spec) if hasattr(spec, "make_filter") and hasattr(spec, "get_params") else spec


def fresh_estimator(estimator: Any) -> Any:
    """An unfitted copy of an estimator with the same settings (scikit-learn's ``clone``)."""
    if isinstance(estimator, GuardedEstimator):
        return estimator.fresh()
    try:
        params = estimator.get_params(deep=False)
    except TypeError:  # a plugin whose get_params takes no ``deep``
        params = estimator.get_params()
    return type(estimator)(**params)


def _merged(streams: Sequence[EdgeStream]) -> list[EdgeStream]:
    """One stream per edge, in first-seen order (several streams of an edge joined in time order)."""
    by: dict[EdgeKey, list[EdgeStream]] = {}
    for s in streams:
        by.setdefault(s.edge, []).append(s)
    out = []
    for e, ss in by.items():
        if len(ss) == 1:
            out.append(ss[0])
            continue
        t = np.concatenate([s.t_s for s in ss])
        order = np.argsort(t, kind="stable")
        out.append(EdgeStream(e, t[order], np.concatenate([s.y for s in ss])[order], dict(ss[0].meta)))
    return out


def fit_edge_filters(estimator: Any, streams: Sequence[EdgeStream], *, timezone: str = "UTC",
                     val_streams: Sequence[EdgeStream] | None = None) -> dict[EdgeKey, EdgeFilter]:
    """One filter per edge of ``streams``, updated with the edge's observations.

    The estimator is fitted on ``streams`` unless it is fitted already (``make_filter`` does not
    raise :class:`~psg_data.errors.NotFittedError`); then each edge gets ``make_filter(edge)``
    followed by ``update_many`` with its whole stream.

    Raises:
        EvaluationError: the fit failed.
    """
    streams = _merged(streams)
    est = estimator
    try:
        est.make_filter(streams[0].edge) if streams else None
    except NotFittedError:
        kw = {"val_streams": val_streams} if val_streams is not None else {}
        try:
            est.fit(streams, timezone=timezone, **kw)
        except PluginError:
            raise
        except PsgDataError as exc:
            raise EvaluationError(f"{type(est).__name__}: fit on the map observations failed ({exc})") from exc
    out: dict[EdgeKey, EdgeFilter] = {}
    for s in streams:
        f = est.make_filter(s.edge)
        f.update_many(s.t_s, s.y)
        out[s.edge] = f
    return out


def open_streams(streams: Sequence[EdgeStream]) -> dict[str, EdgeStream]:
    """door_id -> its ``(door_id, 'open')`` stream (``'closed'`` streams are ignored).

    Raises:
        EvaluationError: a door stream whose state is neither 'open' nor 'closed'.
    """
    out: dict[str, EdgeStream] = {}
    for s in streams:
        if s.edge[1] == "open":
            out[s.edge[0]] = s
        elif s.edge[1] != "closed":
            raise EvaluationError(f"door stream {s.edge}: state must be 'open' or 'closed'")
    return out


def fit_door_filters(estimator: Any, streams: Sequence[EdgeStream], door_ids: Sequence[str], *,
                     timezone: str = "UTC", unseen_prior: float = 0.5, settings: Mapping[str, Any] | None = None
                     ) -> tuple[dict[str, EdgeFilter], dict[str, str]]:
    """One P(open) filter per door from the door streams.

    The estimator (registry name or instance) is fitted on the ``(door_id, 'open')`` streams with
    observations; each such door's filter is updated with its history. A door without observations
    gets the constant ``unseen_prior`` (reported as ``"prior"`` in the second return value).

    Returns:
        (door_id -> filter, door_id -> ``"estimator"`` or ``"prior"``).

    Raises:
        EvaluationError: unknown estimator or failed fit.
    """
    if not 0.0 <= unseen_prior <= 1.0:
        raise EvaluationError(f"unseen_prior: {unseen_prior}, expected a probability in [0, 1]")
    by_door = open_streams(streams)
    seen = [by_door[d] for d in door_ids if d in by_door and len(by_door[d]) > 0]
    filters: dict[str, EdgeFilter] = {}
    kind: dict[str, str] = {}
    est = estimator
    if seen:
        try:
            est = resolve_estimator(est, settings)
        except PluginError:
            raise
        except PsgDataError as exc:
            raise EvaluationError(f"estimator {estimator!r}: {exc}") from exc
        try:
            est.fit(seen, timezone=timezone)
        except PluginError:
            raise
        except PsgDataError as exc:
            raise EvaluationError(f"{type(est).__name__}: fit on the door streams failed ({exc})") from exc
    for d in door_ids:
        s = by_door.get(d)
        if s is None or len(s) == 0:
            filters[d], kind[d] = ConstantFilter((d, "open"), "prior", unseen_prior), "prior"
            continue
        f = est.make_filter(s.edge)
        f.update_many(s.t_s, s.y)
        filters[d], kind[d] = f, "estimator"
    return filters, kind


def door_open_probabilities(filters: Mapping[str, EdgeFilter], t_s: float, door_ids: Sequence[str], *,
                            prior: float = 0.5) -> dict[str, float]:
    """P(open) per door at ``t_s`` (clipped to [0, 1]); doors without a filter or with a non-finite
    prediction get ``prior`` (a warning is logged for the latter).
    """
    out = {}
    for d in door_ids:
        f = filters.get(d)
        if f is None:
            out[d] = float(prior)
            continue
        v = float(np.asarray(f.predict(np.array([t_s], np.float64))).reshape(-1)[0])
        if not math.isfinite(v):
            log.warning("door %s: filter predicted %s at t=%s; using the prior %s", d, v, t_s, prior)
            v = float(prior)
        out[d] = min(max(v, 0.0), 1.0)
    return out
