"""Top-down PNG of a navigation query: grid, doors, receptacle beliefs and the path walked."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from psg_data.navigation._env import NavigationEnv
from psg_data.navigation._grid import box_footprint
from psg_data.navigation._planner import PlanningCache
from psg_data.navigation._queries import Query

__all__ = ["plot_query"]

log = logging.getLogger(__name__)


def plot_query(
    env: NavigationEnv,
    query: Query,
    out_path: str | Path,
    *,
    beliefs: Mapping[str, float] | None = None,
    trail: NDArray[np.int64] | None = None,
    cache: PlanningCache | None = None,
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """Write a top-down map of one query as a PNG (matplotlib, Agg backend).

    Shows the inflated free space with the true door states at the query time (free light, blocked
    grey, raw obstacles dark), doors (green open, red closed), receptacles coloured by the
    predicted belief (viridis, 0..1; hatched when the method has no edge to them), the true
    receptacle (gold outline), the receptacle at the last map update (dashed outline), the start
    (blue dot), the path walked (blue line) and the final pose (black cross).

    Args:
        env: the environment.
        query: the query.
        out_path: PNG path.
        beliefs: receptacle_id -> belief at the query time.
        trail: flat cell indices of the walked path.
        cache: planning cache (only to reuse its grid); optional.
        title: figure title.
        dpi: resolution.

    Returns:
        The written path.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon

    grid = cache.grid if cache is not None else env.grid
    cfg = grid.door_config(query.doors_open)
    free = grid.free(cfg)
    obs = grid.obstacles(cfg)
    img = np.where(obs, 0.15, np.where(free, 0.97, 0.75))
    H, W = grid.shape
    aspect = H / max(W, 1)
    fig, ax = plt.subplots(figsize=(10, max(3.0, 10 * aspect + 1.0)))
    try:
        ax.imshow(img, origin="lower", extent=grid.extent_m, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        cmap = plt.get_cmap("viridis")
        bel = dict(beliefs or {})
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
        for did, door in env.doors.items():
            is_open = query.doors_open.get(did, True)
            ax.add_patch(Polygon(box_footprint(door.box), closed=True, facecolor="limegreen" if is_open else "red",
                                 edgecolor="black", lw=0.8, alpha=0.9))
        sx, sy = query.start_xy
        ax.plot([sx], [sy], "o", color="tab:blue", ms=7, label="start")
        if trail is not None and np.size(trail):
            t = np.asarray(trail, dtype=np.int64)
            xy = grid.cell_to_world(np.stack([t // W, t % W], axis=1))
            ax.plot(xy[:, 0], xy[:, 1], "-", color="tab:blue", lw=2, label="path")
            ax.plot([xy[-1, 0]], [xy[-1, 1]], "x", color="black", ms=9, mew=2, label="final")
        sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, 1))
        fig.colorbar(sm, ax=ax, fraction=0.03, pad=0.02, label="predicted P(object on receptacle)")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
        ax.legend(loc="upper right", fontsize=7)
        ax.set_title(title or f"{query.object_id} ({query.category}), query {query.query_id}")
        out = Path(out_path)
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return out
