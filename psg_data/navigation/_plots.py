"""Top-down PNG of a navigation query: grid, doors, receptacle beliefs and the path walked."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from psg_data.maps._grid import box_footprint
from psg_data.maps._planner import PlanningCache
from psg_data.navigation._env import NavigationEnv
from psg_data.navigation._queries import Query

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["plot_query", "pick_door_example", "plot_door_example", "plot_snapshot"]

log = logging.getLogger(__name__)


def plot_query(
    env: NavigationEnv,
    query: Query,
    out_path: str | Path | None = None,
    *,
    beliefs: Mapping[str, float] | None = None,
    trail: NDArray[np.int64] | None = None,
    cache: PlanningCache | None = None,
    title: str | None = None,
    dpi: int = 120,
    door_p_open: Mapping[str, float] | None = None,
    compare: tuple[NDArray[np.int64], str] | None = None,
    label: str = "path",
) -> Figure:
    """A top-down map of one query: a ``matplotlib.figure.Figure``, written as a PNG at
    ``out_path`` if given (no pyplot, the user's backend is left alone).

    Shows the inflated free space with the true door states at the query time (free light, blocked
    grey, raw obstacles dark), doors (green open, red closed), receptacles coloured by the
    predicted belief (viridis, 0..1; hatched when the method has no edge to them), the true
    receptacle (gold outline), the receptacle at the last map update (dashed outline), the start
    (blue dot), the path walked (blue line) and the final pose (black cross).

    Args:
        env: the environment.
        query: the query.
        out_path: PNG path (None: do not write); the file there is replaced atomically.
        beliefs: receptacle_id -> belief at the query time.
        trail: flat cell indices of the walked path.
        cache: planning cache (only to reuse its grid); optional.
        title: figure title.
        dpi: resolution.
        door_p_open: door_id -> predicted P(open): doors are then coloured by it (pink low, teal
            high) and labelled with the value and the true state, instead of green / red truth.
        compare: (trail, label) of a second walk drawn dashed grey (e.g. the all-doors-open plan).
        label: legend label of ``trail``.

    Returns:
        The figure.
    """
    import matplotlib
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    grid = cache.grid if cache is not None else env.grid
    H, W = grid.shape
    fig = Figure(figsize=(10, max(3.0, 10 * H / max(W, 1) + 1.0)))
    ax = fig.subplots()
    _draw_free_space(ax, grid, query)
    cmap = matplotlib.colormaps["viridis"]
    _draw_receptacles(ax, env, query, dict(beliefs or {}), cmap)
    _draw_doors(ax, env, query, door_p_open)
    sx, sy = query.start_xy
    ax.plot([sx], [sy], "o", color="tab:blue", ms=7, label="start")
    if compare is not None:
        _draw_walk(ax, grid, compare[0], dict(ls="--", color="0.35", lw=1.6, label=compare[1]),
                   dict(color="0.35", ms=8, mew=2))
    if trail is not None:
        _draw_walk(ax, grid, trail, dict(ls="-", color="tab:blue", lw=2, label=label),
                   dict(color="black", ms=9, mew=2, label="final"))
    sm = ScalarMappable(cmap=cmap, norm=Normalize(0, 1))
    fig.colorbar(sm, ax=ax, fraction=0.03, pad=0.02, label="predicted P(object on receptacle)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    _query_legend(ax, door_p_open)
    ax.set_title(title or f"{query.object_id} ({query.category}), query {query.query_id}")
    from psg_data.evaluation._persistence_plots import save_figure

    return save_figure(fig, out_path, dpi)


def _draw_free_space(ax: Any, grid: Any, query: Query) -> None:
    """The inflated free space with the query's true door states: free light, blocked grey, raw obstacles dark."""
    cfg = grid.door_config(query.doors_open)
    img = np.where(grid.obstacles(cfg), 0.15, np.where(grid.free(cfg), 0.97, 0.75))
    ax.imshow(img, origin="lower", extent=grid.extent_m, cmap="gray", vmin=0, vmax=1, interpolation="nearest")


def _draw_walk(ax: Any, grid: Any, trail: NDArray[np.int64], line: dict[str, Any], end: dict[str, Any]) -> None:
    """A walked path (flat cell indices) as a line, its last cell as a cross."""
    if not np.size(trail):
        return
    t = np.asarray(trail, dtype=np.int64)
    W = grid.shape[1]
    xy = grid.cell_to_world(np.stack([t // W, t % W], axis=1))
    ax.plot(xy[:, 0], xy[:, 1], **line)
    ax.plot([xy[-1, 0]], [xy[-1, 1]], "x", **end)


_DOOR_CMAP = ("#e75480", "#f2e6c9", "#008080")  # pink (predicted closed) .. teal (predicted open)


def _draw_receptacles(ax: Any, env: NavigationEnv, query: Query, bel: Mapping[str, float], cmap: Any) -> None:
    """Receptacles coloured by belief (hatched without an edge), true one gold, last-map one dashed magenta."""
    from matplotlib.patches import Polygon

    for rid, rec in env.receptacles.items():
        fp = box_footprint(rec.box)
        b = bel.get(rid)
        face = cmap(float(b)) if b is not None else (0.85, 0.85, 0.85, 1.0)
        ax.add_patch(Polygon(fp, closed=True, facecolor=face, edgecolor="black", lw=0.6,
                             hatch=None if b is not None else "///"))
        if rid == query.gt_receptacle:
            ax.add_patch(Polygon(fp, closed=True, fill=False, edgecolor="gold", lw=2.5))
        if rid == query.map_receptacle:
            ax.add_patch(Polygon(fp, closed=True, fill=False, edgecolor="magenta", lw=1.5, ls="--"))
        if b is not None and b >= 0.05:
            c = fp.mean(axis=0)
            ax.text(c[0], c[1], f"{b:.2f}", ha="center", va="center", fontsize=6, color="white")


def _query_legend(ax: Any, door_p_open: Mapping[str, float] | None) -> None:
    """Every symbol of the map in one legend under it."""
    from matplotlib.patches import Patch

    proxies = [Patch(facecolor="none", edgecolor="gold", lw=2.5, label="true receptacle (at the query time)"),
               Patch(facecolor="none", edgecolor="magenta", ls="--", lw=1.5, label="receptacle at the last map"),
               Patch(facecolor=(0.85, 0.85, 0.85), edgecolor="black", hatch="///", label="no edge (never seen there)"),
               Patch(facecolor="0.15", label="walls"), Patch(facecolor="0.75", label="too close to an obstacle")]
    if door_p_open is None:
        proxies += [Patch(facecolor="limegreen", edgecolor="black", label="door open (truth)"),
                    Patch(facecolor="red", edgecolor="black", label="door closed (truth)")]
    else:
        proxies += [Patch(facecolor=_DOOR_CMAP[0], edgecolor="black", label="door predicted closed"),
                    Patch(facecolor=_DOOR_CMAP[2], edgecolor="black", label="door predicted open")]
    handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=handles + proxies, loc="upper center", fontsize=7, ncol=4, bbox_to_anchor=(0.5, -0.2))


def _draw_doors(ax: Any, env: NavigationEnv, query: Query, p_open: Mapping[str, float] | None) -> None:
    """Doors: green open / red closed at the query time, or coloured by a predicted P(open)."""
    from matplotlib.colors import LinearSegmentedColormap
    from matplotlib.patches import Polygon

    cmap = LinearSegmentedColormap.from_list("door_p", list(_DOOR_CMAP))
    for did, door in env.doors.items():
        is_open = query.doors_open.get(did, True)
        fp = box_footprint(door.box)
        if p_open is None:
            ax.add_patch(Polygon(fp, closed=True, facecolor="limegreen" if is_open else "red", edgecolor="black",
                                 lw=0.8, alpha=0.9))
            continue
        p = float(p_open.get(did, 1.0))
        ax.add_patch(Polygon(fp, closed=True, facecolor=cmap(p), edgecolor="black", lw=1.0))
        c = fp.mean(axis=0)
        ax.annotate(f"{did}\nP(open)={p:.2f}\n(truly {'open' if is_open else 'closed'})", c, fontsize=7,
                    ha="center", va="bottom", xytext=(0, 10), textcoords="offset points")


def pick_door_example(result: Any, label: str) -> tuple[int, int] | None:
    """(seed, query_id) of an object query of ``result`` (a run with methods ``"<label> [doors
    predicted]"`` and ``"<label> [doors all open]"``) where the predicted doors paid off: the
    prediction closed a door that was closed, the all-open plan walked into a closed door, and the
    predicted plan found the object without meeting one. Falls back to any query where the
    all-open plan met a closed door and the predicted one did not; None if there is none.
    """
    import json

    rec = result.records
    pred = rec[rec["method"] == f"{label} [doors predicted]"].set_index(["seed", "query_id"])
    base = rec[rec["method"] == f"{label} [doors all open]"].set_index(["seed", "query_id"])
    if pred.empty or base.empty:
        return None
    both = pred.merge(base, left_index=True, right_index=True, suffixes=("", "_open"))
    met = both["doors_discovered_open"].map(lambda x: bool(json.loads(x)))
    clean = both["doors_discovered"].map(lambda x: not json.loads(x))
    for pool in (both[met & clean & both["success"] & (both["path_m"] < both["path_m_open"])],
                 both[met & clean & both["reachable"]], both[met & clean]):
        if len(pool):
            k = pool.index[0]
            return int(k[0]), int(k[1])
    return None


def plot_door_example(result: Any, label: str, key: tuple[int, int], out_path: str | Path | None = None, *,
                      estimator: Any = None, settings: Mapping[str, Any] | None = None) -> Figure:
    """The paper's "Predictive Navigation" figure for an object query: doors coloured by the
    estimator's P(open), the walk with its predicted doors (blue) and with all doors open (grey).

    Args:
        result: a :class:`~psg_data.navigation.NavigationResult` with the two door modes of ``label``.
        label: the estimator label; ``estimator`` (default ``label``) is refitted on the door streams
            to show P(open).
        key: (seed, query_id), e.g. from :func:`pick_door_example`.
        out_path: PNG path (None: do not write).
        estimator: the registry name or estimator refitted for P(open) (default: ``label``'s name).
        settings: estimator settings of that fit.

    Returns:
        The figure (:func:`plot_query`).
    """
    from psg_data.graph._fit import door_open_probabilities, fit_door_filters

    env, seed, qid = result.env, key[0], key[1]
    q = next(x for x in result.queries[seed] if x.query_id == qid)
    door_ids = list(env.grid.door_ids)
    filters, _ = fit_door_filters(estimator or label.split(":", 1)[0], env.door_streams, door_ids,
                                  timezone=env.timezone, settings=settings)
    p = door_open_probabilities(filters, q.t_s, door_ids)
    pred, base = f"{label} [doors predicted]", f"{label} [doors all open]"
    rec = result.records.set_index(["method", "seed", "query_id"])
    outcome = rec.loc[(pred, seed, qid), "outcome"], rec.loc[(base, seed, qid), "outcome"]
    walked = rec.loc[(pred, seed, qid), "path_m"], rec.loc[(base, seed, qid), "path_m"]
    return plot_query(env, q, out_path, beliefs=result.beliefs.get((pred, seed, qid)),
                      trail=result.trails.get((pred, seed, qid)), cache=result.cache, door_p_open=p,
                      compare=(result.trails.get((base, seed, qid), np.zeros(0, np.int64)),
                               f"all doors open ({walked[1]:.1f} m, {outcome[1]})"),
                      label=f"{label}, predicted doors ({walked[0]:.1f} m, {outcome[0]})",
                      title=f"{label}: {q.object_id} ({q.category}), query {qid} of seed {seed}")


def plot_snapshot(snapshot: Any, out_path: str | Path | None = None, *, object_id: str | None = None,
                  title: str | None = None, dpi: int = 110) -> Figure:
    """A predictive graph's snapshot on the map (top-down, world x / y in metres): a
    ``matplotlib.figure.Figure``, written as a PNG at ``out_path`` if given (replaced atomically).

    Rooms are outlined and named; each receptacle's footprint is coloured by P(``object_id`` on it)
    (without ``object_id``: the expected number of objects on it, the sum over its edges, clipped at 1),
    hatched where there is no edge; doors by P(open) (pink low, teal high; grey: no door model),
    labelled with the value. Missing geometry (rooms without polygons) is left out.
    """
    import matplotlib
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LinearSegmentedColormap, Normalize
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch, Polygon

    L = snapshot.layout
    if object_id is not None:
        value, what = snapshot.beliefs(object_id), f"P({object_id} on receptacle)"
    else:
        value, what = {}, "expected objects on receptacle (sum of P, clipped at 1)"
        for r, p in zip(snapshot.receptacles.tolist(), snapshot.p.tolist()):
            value[r] = min(value.get(r, 0.0) + p, 1.0)
    fig = Figure(figsize=(10, 6))
    ax = fig.subplots()
    for room in L.rooms.values():
        if room.floor_polygon_m is not None and len(room.floor_polygon_m) >= 3:
            poly = np.asarray(room.floor_polygon_m, float)
            ax.add_patch(Polygon(poly, closed=True, facecolor="0.96", edgecolor="0.2", lw=1.5))
            ax.annotate(room.name, poly.mean(axis=0), ha="center", fontsize=9, color="0.4")
    cmap = matplotlib.colormaps["viridis"]
    for r, rec in L.receptacles.items():
        fp = box_footprint(rec.box)
        v = value.get(r)
        ax.add_patch(Polygon(fp, closed=True, facecolor=cmap(v) if v is not None else "white", edgecolor="black",
                             lw=0.8, hatch=None if v is not None else "////"))
        if v is not None and v >= 0.05:
            ax.annotate(f"{r}\n{v:.2f}", fp.mean(axis=0), fontsize=6, ha="center", va="center",
                        color="white" if v < 0.5 else "black")
    door_cmap = LinearSegmentedColormap.from_list("door_p", ["#e75480", "#f2e6c9", "#008080"])
    for d, p in zip(snapshot.doors.tolist(), snapshot.p_open.tolist()):
        rec = L.doors.get(d)
        if rec is None:
            continue
        fp = box_footprint(rec.box)
        ok = bool(np.isfinite(p))
        ax.add_patch(Polygon(fp, closed=True, facecolor=door_cmap(p) if ok else "0.7", edgecolor="black", lw=1.0))
        ax.annotate(f"{d}\nP(open)={p:.2f}" if ok else f"{d}\n(no model)", fp.mean(axis=0), fontsize=7,
                    ha="center", va="bottom", xytext=(0, 8), textcoords="offset points")
    ax.autoscale_view()
    fig.colorbar(ScalarMappable(cmap=cmap, norm=Normalize(0, 1)), ax=ax, fraction=0.03, pad=0.02, label=what)
    ax.legend(handles=[Patch(facecolor="white", edgecolor="black", hatch="////", label="no edge"),
                       Patch(facecolor=door_cmap(0.9), edgecolor="black", label="door: colour = P(open)"),
                       Patch(facecolor="0.96", edgecolor="0.2", label="room")], loc="upper center",
              bbox_to_anchor=(0.5, -0.2), ncol=3, fontsize=8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    import datetime as dt
    from zoneinfo import ZoneInfo

    when = dt.datetime.fromtimestamp(snapshot.t_s, ZoneInfo(L.timezone)).strftime("%Y-%m-%d %H:%M %Z")
    ax.set_title(title or (f"{object_id}: where it is predicted at {when}" if object_id else
                           f"predictive graph at {when}"), fontsize=10)
    from psg_data.evaluation._persistence_plots import save_figure

    return save_figure(fig, out_path, dpi)
