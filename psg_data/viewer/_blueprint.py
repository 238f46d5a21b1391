"""The Rerun blueprints (view layouts) sent with every recording.

- :func:`dataset_blueprint` (``psg-data view``): the 3D world large on the left, seen obliquely
  from above; the current scan's colour and depth images beside it; under them one panel per
  informative edge (the object edges whose ground truth changes most, every label source in one
  panel) and one with the doors; the time panel on the ``scan`` timeline, so that the arrow keys
  step scan by scan.
- :func:`beliefs_blueprint` (``psg-eval --rerun``): one panel per edge whose truth changes most,
  every estimator's belief beside the ground truth and the observations.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from psg_data.viewer._dataset_log import SCAN_TIMELINE, edge_path
from psg_data.viewer._recording import import_rerun

__all__ = ["dataset_blueprint", "beliefs_blueprint", "changing_edges"]


def changing_edges(series: Iterable[tuple[tuple[str, str], Any]], k: int) -> list[tuple[str, str]]:
    """The ``k`` edges whose 0/1 values change most often (ties: by edge) among (edge, values) pairs."""
    changes: dict[tuple[str, str], int] = {}
    for edge, y in series:
        changes[edge] = changes.get(edge, 0) + int(np.count_nonzero(np.diff(np.asarray(y))))
    return [e for e, n in sorted(changes.items(), key=lambda kv: (-kv[1], kv[0])) if n > 0][:k]


def _eye(ds: Any) -> tuple[list[float], list[float]]:
    """An oblique eye position above one corner of the rooms, and its target (the middle), metres."""
    pts = [r.floor_polygon_m for r in (ds.rooms.values() if ds.has_table("rooms") else ())
           if r.floor_polygon_m is not None and len(r.floor_polygon_m)]
    if not pts and ds.has_table("receptacles"):
        pts = [np.array([r.box.center_m[:2] for r in ds.receptacles.values()])]
    xy = np.concatenate(pts) if pts else np.zeros((1, 2))
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    mid, size = (lo + hi) / 2, float(max(np.max(hi - lo), 2.0))
    return [float(mid[0]), float(lo[1] - 0.3 * size), 0.55 * size], [float(mid[0]), float(mid[1]), 0.0]


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
    y_axis = rrb.ScalarAxis(range=(-0.1, 1.1), zoom_lock=True)
    plots = [rrb.TimeSeriesView(name=f"{o} on {r}", origin="labels", axis_y=y_axis,
                                contents=[edge_path(f"labels/{rr.escape_entity_path_part(s)}", (o, r))
                                          for s in sources])
             for o, r in edges]
    if doors:
        plots.append(rrb.TimeSeriesView(name="doors (1 open)", origin="labels", axis_y=y_axis,
                                        contents=[edge_path("labels/gt", ("doors", d)) for d in doors]))
    images = rrb.Horizontal(rrb.Spatial2DView(name="colour", origin="world/camera", contents="$origin/rgb"),
                            rrb.Spatial2DView(name="depth", origin="world/camera", contents="$origin/depth"))
    right = rrb.Vertical(images, *plots, row_shares=[2.0] + [1.0] * len(plots))
    world = rrb.Spatial3DView(name="lab (3D, metres, z up)", origin="world",
                              eye_controls=rrb.EyeControls3D(position=eye, look_target=target, eye_up=[0, 0, 1]))
    return rrb.Blueprint(rrb.Horizontal(world, right, column_shares=[3.0, 2.0]),
                         rrb.TimePanel(timeline=SCAN_TIMELINE, state="expanded"),
                         rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"))


def beliefs_blueprint(traces: Sequence[Any], *, k: int = 4) -> Any:
    """The layout of a beliefs recording: the ``k`` edges whose truth changes most, one panel each."""
    rr = import_rerun()
    rrb = rr.blueprint
    seed = min((t.seed for t in traces), default=0)
    truth = {t.edge: t for t in traces if t.seed == seed}
    shown = changing_edges(((e, t.truth[(t.truth == 0) | (t.truth == 1)]) for e, t in truth.items()), k) \
        or list(truth)[:k]
    y_axis = rrb.ScalarAxis(range=(-0.1, 1.1), zoom_lock=True)
    panels = [rrb.TimeSeriesView(name=f"{e[0]} on {e[1]}", origin=edge_path("beliefs", e), axis_y=y_axis)
              for e in shown]
    return rrb.Blueprint(rrb.Grid(*panels) if panels else rrb.Vertical(), rrb.TimePanel(state="expanded"),
                         rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"))
