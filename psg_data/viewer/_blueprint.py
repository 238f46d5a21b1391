"""The Rerun blueprints (view layouts) sent with every recording.

- :func:`dataset_blueprint` (``psg-data view``): the 3D world large on the left, seen obliquely
  from above, from far enough back that every room, receptacle and door is in view; the current
  scan's colour and depth images beside it; under them one panel per informative edge (the
  object edges whose ground truth changes most, every label source in one panel) and one with
  the doors, each with its legend over a band above the traces; the time panel on the ``scan``
  timeline, paused, so that the viewer opens on the first scan (the viewer puts a paused
  timeline's cursor at its start, a playing or following one's at its end: Rerun's
  ``time_control`` since "Respect play state from blueprint", May 2026; rerun-sdk 0.41 here) and
  the arrow keys step scan by scan.
- :func:`beliefs_blueprint` (``psg-eval --rerun``): one panel per edge whose truth changes most,
  every estimator's belief beside the ground truth and the observations, the legend again over
  a band above the traces.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.viewer._dataset_log import SCAN_TIMELINE, edge_path
from psg_data.viewer._recording import import_rerun

__all__ = ["dataset_blueprint", "beliefs_blueprint", "changing_edges"]


def changing_edges(series: Iterable[tuple[tuple[str, str], Any]], k: int) -> list[tuple[str, str]]:
    """The ``k`` edges whose 0/1 values change most often (ties: by edge) among (edge, values) pairs."""
    changes: dict[tuple[str, str], int] = {}
    for edge, y in series:
        changes[edge] = changes.get(edge, 0) + int(np.count_nonzero(np.diff(np.asarray(y))))
    return [e for e, n in sorted(changes.items(), key=lambda kv: (-kv[1], kv[0])) if n > 0][:k]


FOV_Y_DEG = 55.0
"""Vertical field of view of Rerun's 3D view (``Eye::DEFAULT_FOV_Y`` in the viewer's ``eye.rs``)."""
_ELEVATION_DEG = 40.0
"""How steeply the 3D eye looks down on the lab (from its -y side)."""
_MARGIN = 0.9
"""Share of the half field of view the lab may fill (the rest is margin)."""


def _extent(ds: Any) -> NDArray[np.float64]:
    """Every point that must be in view, metres: the rooms' floor outlines and the corners of every
    receptacle and door box ((N, 3); the origin alone for a dataset without any).
    """
    pts = [np.column_stack([r.floor_polygon_m, np.zeros(len(r.floor_polygon_m))])
           for r in (ds.rooms.values() if ds.has_table("rooms") else ())
           if r.floor_polygon_m is not None and len(r.floor_polygon_m)]
    for table in ("receptacles", "doors"):
        if ds.has_table(table):
            pts += [item.box.corners() for item in getattr(ds, table).values()]
    return np.concatenate(pts) if pts else np.zeros((1, 3))


def _eye(ds: Any) -> tuple[list[float], list[float]]:
    """An oblique eye position over the lab's -y side and its target (the middle of the lab), metres:
    as far back as needed for every point of :func:`_extent` to lie within ``_MARGIN`` of the
    view's field of view, horizontally too on a view at least as wide as tall (the layout's 3D view
    is: three fifths of a landscape window's width, its full height).
    """
    pts = _extent(ds)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    target = (lo + hi) / 2
    el = np.radians(_ELEVATION_DEG)
    forward = np.array([0.0, np.cos(el), -np.sin(el)])  # from the eye to the target
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    k = np.tan(np.radians(FOV_Y_DEG) / 2) * _MARGIN
    rel = corners - target
    # a corner is in view when |right| and |up| <= k * its depth (rel . forward + distance)
    distance = float(np.max(np.maximum(np.abs(rel @ right), np.abs(rel @ up)) / k - rel @ forward))
    distance = max(distance, 1.0) + 0.5
    eye = target - distance * forward
    return [float(v) for v in eye], [float(v) for v in target]


LEGEND_ROW = 0.3
"""Height of one legend entry in a 0/1 plot, in the plot's y units (a plot panel of the layout is
about 150 pixels tall, an entry about 20)."""


def _legend_above(rrb: Any, entries: int) -> dict[str, Any]:
    """A 0/1 plot's y axis and legend: the legend in the top left corner, over a band above 1 that
    is kept free of traces (``LEGEND_ROW`` per entry), so that it covers none.
    """
    return {"axis_y": rrb.ScalarAxis(range=(-0.1, 1.1 + LEGEND_ROW * entries), zoom_lock=True),
            "plot_legend": rrb.PlotLegend(corner="LeftTop", visible=True)}


def dataset_blueprint(ds: Any, *, panels: int = 3) -> Any:
    """The layout of a dataset recording (module docstring).

    Args:
        ds: the open dataset: its rooms place the 3D eye, its doors get one panel.
        panels: how many object edges get a panel of their own: those whose ground truth changes
            most, every label source in one panel.
    """
    from psg_data.viewer._dataset_log import _ground_truth

    gt = _ground_truth(ds)
    if gt is not None:
        from psg_data.labeling import grid_streams

        edges = changing_edges(((s.edge, s.y) for s in grid_streams(gt)), panels)
    else:
        edges = []
    sources = ["gt", *sorted(set(ds.table("labels").column("source").to_pylist()))] if ds.has_table("labels") \
        else ["gt"]
    doors = sorted(ds.doors) if ds.has_table("doors") else []
    rr = import_rerun()
    rrb = rr.blueprint
    eye, target = _eye(ds)
    plots = [rrb.TimeSeriesView(name=f"{o} on {r}", origin="labels", **_legend_above(rrb, len(sources)),
                                contents=[edge_path(f"labels/{rr.escape_entity_path_part(s)}", (o, r))
                                          for s in sources])
             for o, r in edges]
    if doors:
        plots.append(rrb.TimeSeriesView(name="doors (1 open)", origin="labels", **_legend_above(rrb, len(doors)),
                                        contents=[edge_path("labels/gt", ("doors", d)) for d in doors]))
    images = rrb.Horizontal(rrb.Spatial2DView(name="colour", origin="world/camera", contents="$origin/rgb"),
                            rrb.Spatial2DView(name="depth", origin="world/camera", contents="$origin/depth"))
    right = rrb.Vertical(images, *plots, row_shares=[2.0] + [1.0] * len(plots))
    world = rrb.Spatial3DView(name="lab (3D, metres, z up)", origin="world",
                              eye_controls=rrb.EyeControls3D(position=eye, look_target=target, eye_up=[0, 0, 1]))
    return rrb.Blueprint(rrb.Horizontal(world, right, column_shares=[3.0, 2.0]),
                         rrb.TimePanel(timeline=SCAN_TIMELINE, state="expanded", play_state="paused"),
                         rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"))


def beliefs_blueprint(traces: Sequence[Any], *, k: int = 4) -> Any:
    """The layout of a beliefs recording: the ``k`` edges whose truth changes most, one panel each."""
    rr = import_rerun()
    rrb = rr.blueprint
    seed = min((t.seed for t in traces), default=0)
    truth = {t.edge: t for t in traces if t.seed == seed}
    shown = changing_edges(((e, t.truth[(t.truth == 0) | (t.truth == 1)]) for e, t in truth.items()), k) \
        or list(truth)[:k]
    entries = len({t.estimator for t in traces}) + 2  # the estimators, the ground truth, the observations
    panels = [rrb.TimeSeriesView(name=f"{e[0]} on {e[1]}", origin=edge_path("beliefs", e),
                                 **_legend_above(rrb, entries))
              for e in shown]
    return rrb.Blueprint(rrb.Grid(*panels) if panels else rrb.Vertical(), rrb.TimePanel(state="expanded"),
                         rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"))
