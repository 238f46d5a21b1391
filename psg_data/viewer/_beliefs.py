"""Estimator beliefs over time, per scored edge, into a Rerun recording."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from psg_data.viewer._dataset_log import TIMELINE, edge_path, step_lines, timestamps
from psg_data.viewer._recording import import_rerun

__all__ = ["log_beliefs", "log_graph"]


def log_beliefs(rec: Any, traces: Sequence[Any], *, seed: int | None = None) -> int:
    """Log each :class:`~psg_data.evaluation.PredictionTrace` of one seed as time series.

    Per edge ``beliefs/OBJECT/RECEPTACLE``: one child per estimator (its belief at every evaluation
    time), ``ground_truth`` (1/0 where scored, drawn as steps) and ``observations`` (the test observations), all
    on the ``time`` timeline, so the viewer plots them in one panel per edge.

    Args:
        rec: a ``rerun.RecordingStream``.
        traces: ``PersistenceResult.traces``.
        seed: the seed to show (default: the smallest).

    Returns:
        The number of edges logged.
    """
    rr = import_rerun()
    if not traces:
        return 0
    seed = min(t.seed for t in traces) if seed is None else seed
    done: set[tuple[str, str]] = set()
    for tr in (t for t in traces if t.seed == seed):
        base = edge_path("beliefs", tr.edge)
        rec.send_columns(f"{base}/{rr.escape_entity_path_part(tr.estimator)}",
                         indexes=[rr.TimeColumn(TIMELINE, timestamp=timestamps(tr.t_s))],
                         columns=rr.Scalars.columns(scalars=np.asarray(tr.belief, np.float64)))
        if tr.edge in done:
            continue
        done.add(tr.edge)
        ok = (tr.truth == 0) | (tr.truth == 1)
        rec.send_columns(f"{base}/ground_truth", indexes=[rr.TimeColumn(TIMELINE, timestamp=timestamps(tr.t_s[ok]))],
                         columns=rr.Scalars.columns(scalars=tr.truth[ok].astype(np.float64)))
        rec.log(f"{base}/ground_truth", step_lines(rr), static=True)
        if len(tr.obs_t_s):
            rec.send_columns(f"{base}/observations",
                             indexes=[rr.TimeColumn(TIMELINE, timestamp=timestamps(tr.obs_t_s))],
                             columns=rr.Scalars.columns(scalars=np.asarray(tr.obs_y, np.float64)))
            rec.log(f"{base}/observations", rr.SeriesPoints(markers="cross", marker_sizes=4.0), static=True)
    return len(done)


def log_graph(rec: Any, graph: Any, times_s: Any, *, name: str | None = None) -> int:
    """Log a :class:`~psg_data.graph.PredictiveGraph`'s beliefs at ``times_s`` as time series.

    Per edge ``beliefs/OBJECT/RECEPTACLE/NAME`` (the entity paths of :func:`log_beliefs`, so a
    graph's beliefs sit beside an evaluation's) and per door ``beliefs/doors/DOOR/NAME`` (P(open);
    doors without a model are left out), on the ``time`` timeline. ``NAME`` defaults to the
    graph's estimator name. One vectorised prediction per filter
    (:meth:`~psg_data.graph.PredictiveGraph.edge_probabilities`).

    Returns:
        The number of edges and doors logged.
    """
    rr = import_rerun()
    t = np.asarray(times_s, np.float64).reshape(-1)
    label = name or getattr(graph.estimator, "name", None) or "graph"
    idx = [rr.TimeColumn(TIMELINE, timestamp=timestamps(t))]
    p = graph.edge_probabilities(t)
    for k, edge in enumerate(graph.edges):
        rec.send_columns(f"{edge_path('beliefs', edge)}/{rr.escape_entity_path_part(label)}", indexes=idx,
                         columns=rr.Scalars.columns(scalars=p[:, k]))
    po = graph.door_probabilities(t)
    n = len(graph.edges)
    for k, d in enumerate(graph.doors):
        if np.all(np.isfinite(po[:, k])):
            rec.send_columns(f"{edge_path('beliefs', ('doors', d))}/{rr.escape_entity_path_part(label)}", indexes=idx,
                             columns=rr.Scalars.columns(scalars=po[:, k]))
            n += 1
    return n
