"""Seeded navigation queries: target object, query time and start pose, stored so that every
estimator is scored on the same set.

Sampling (per query, from ``numpy.random.default_rng([seed, 8801])``): a query time uniform in
``(t_map, min(t_map + horizon, t_end)]`` (horizon one week by default, the paper's "up to one week
ahead of the last map update") restricted to the scoring windows when given (the dataset's operating
hours: a robot is not asked at night), a target object uniform over the environment's objects, and a
start cell uniform over the cells that are free with *every* door closed (so the start is free
under any door configuration and never inside a doorway) and lie in the largest 8-connected
component of the free space with every door open (no starts in isolated pockets). With a fixed
start (the paper's real-world protocol) every query starts from the same cell.

Categories (the paper's): ``static`` = the object is present and on the same receptacle as at the
last map update; ``dynamic`` = present on another receptacle (or present now but absent at the map
update); ``absent`` = not in the scene at the query time.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError
from psg_data.maps._grid import OccupancyGrid
from psg_data.navigation._env import WEEK_S, NavigationEnv

__all__ = ["Query", "make_queries", "start_cells", "queries_to_frame", "queries_from_frame", "save_queries",
           "load_queries", "CATEGORIES"]

log = logging.getLogger(__name__)

CATEGORIES = ("static", "dynamic", "absent")


@dataclass(frozen=True)
class Query:
    """One navigation query.

    Attributes:
        query_id: index within its set.
        seed: seed of the set.
        object_id: target object.
        t_s: query time, float seconds UTC.
        start_cell: (row, col) start cell.
        start_xy: world (x, y) of the start cell centre, metres.
        category: 'static', 'dynamic' or 'absent'.
        gt_receptacle: receptacle holding the object at ``t_s`` (None = absent).
        map_receptacle: receptacle holding it at the last map update (None = absent).
        doors_open: true door states at ``t_s``.
    """

    query_id: int
    seed: int
    object_id: str
    t_s: float
    start_cell: tuple[int, int]
    start_xy: tuple[float, float]
    category: str
    gt_receptacle: str | None
    map_receptacle: str | None
    doors_open: dict[str, bool] = field(default_factory=dict)


def start_cells(grid: OccupancyGrid, name: str = "grid") -> np.ndarray:
    """Flat indices of the cells a query may start from (module docstring).

    Raises:
        EvaluationError: the grid has no free cell.
    """
    from scipy.ndimage import label

    g = grid
    closed = g.free({d: False for d in g.door_ids})
    open_ = g.free({d: True for d in g.door_ids})
    lab, n = label(open_, structure=np.ones((3, 3), dtype=int))
    if n == 0:
        raise EvaluationError(f"{name}: the occupancy grid has no free cell")
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    main = lab == int(np.argmax(sizes))
    cells = np.flatnonzero((closed & main).ravel())
    if cells.size == 0:
        cells = np.flatnonzero(main.ravel())
    return cells


def make_queries(env: NavigationEnv, n_queries: int = 250, *, seed: int = 0, horizon_s: float = WEEK_S,
                 objects: list[str] | None = None, reachable_only: bool = False, reach_m: float = 1.0,
                 max_tries: int = 100, quotas: Mapping[str, int] | None = None,
                 start_cell: tuple[int, int] | None = None, windows: Any = None) -> list[Query]:
    """Sample ``n_queries`` queries (deterministic for ``env`` and ``seed``).

    Args:
        env: the environment.
        n_queries: number of queries (ignored when ``quotas`` are given).
        seed: seed of the set.
        horizon_s: latest query time after the last map update, seconds (default one week).
        objects: restrict the targets to these objects.
        reachable_only: redraw a query (time, object, start) whose present target cannot be
            reached from the start with the true door states (up to ``max_tries`` draws; the last
            draw is kept). Default False: unreachable targets occur and are reported separately.
        reach_m: success radius used for the reachability test, metres.
        max_tries: draws per query with ``reachable_only``.
        quotas: category -> number of queries (e.g. the paper's real-world 10 static, 10 dynamic,
            5 absent): draws are kept while their category is not full (and, with
            ``reachable_only``, their present target is reachable), in draw order.
        start_cell: one start cell for every query (default: a random start cell per query).
        windows: (K, 2) ``[start, end]`` UTC seconds: query times are drawn uniformly inside them
            (None: anywhere in the window after the map).

    Raises:
        EvaluationError: no objects, no time window, no free start cell, or quotas that cannot be
            filled (too few targets of a category in the query window).
    """
    objs = list(objects) if objects is not None else list(env.object_ids)
    if not objs:
        raise EvaluationError(f"{env.name}: no target objects to query")
    t_lo = env.t_map_s
    t_hi = min(env.t_map_s + float(horizon_s), env.t_end_s)
    if not t_hi > t_lo:
        raise EvaluationError(f"{env.name}: no ground truth after the last map update (t_end <= t_map)")
    rng = np.random.default_rng([int(seed), 8801])
    when = _time_sampler(t_lo, t_hi, windows, env.name)
    cells = start_cells(env.grid, env.name)
    W = env.grid.shape[1]
    fixed = None if start_cell is None else int(start_cell[0]) * W + int(start_cell[1])
    cache = None
    if reachable_only:
        from psg_data.maps._planner import PlanningCache

        cache = PlanningCache(env.grid, reach_m=reach_m)

    def draw() -> tuple[float, str, int, str | None, dict[str, bool], str]:
        t = when(float(rng.uniform(0.0, 1.0)))
        o = objs[int(rng.integers(len(objs)))]
        c = int(cells[int(rng.integers(cells.size))]) if fixed is None else fixed
        gt = env.gt_at(o, t)
        doors = {k: bool(v) for k, v in env.doors_at(t).items()}
        cat = "absent" if gt is None else ("static" if gt == env.map_state.get(o) else "dynamic")
        return t, o, c, gt, doors, cat

    def reachable(gt: str | None, doors: dict[str, bool], c: int) -> bool:
        return cache is None or gt is None or bool(np.isfinite(cache.distance(gt, cache.key(doors), c)))

    def query(k: int, d: tuple[float, str, int, str | None, dict[str, bool], str]) -> Query:
        t, o, c, gt, doors, cat = d
        ij = (c // W, c % W)
        xy = env.grid.cell_to_world(ij)
        return Query(k, int(seed), o, t, ij, (float(xy[0]), float(xy[1])), cat, gt, env.map_state.get(o), doors)

    if quotas is not None:
        return _fill_quotas(quotas, draw, reachable, query, env.name)
    if n_queries < 1:
        raise EvaluationError(f"n_queries must be >= 1, got {n_queries}")
    out: list[Query] = []
    for q in range(n_queries):
        for _ in range(max(1, max_tries)):
            d = draw()
            if reachable(d[3], d[4], d[2]):
                break
        out.append(query(q, d))
    return out


def _fill_quotas(quotas: Mapping[str, int], draw: Any, reachable: Any, query: Any, name: str) -> list[Query]:
    """Draws kept while their category is not full (and their present target reachable), in draw order."""
    want = {c: int(n) for c, n in quotas.items() if int(n) > 0}
    got = {c: 0 for c in want}
    budget = 2000 * max(sum(want.values()), 1)
    out: list[Query] = []
    for _ in range(budget):
        if got == want:
            break
        d = draw()
        if got.get(d[5], 0) < want.get(d[5], 0) and reachable(d[3], d[4], d[2]):
            got[d[5]] += 1
            out.append(query(len(out), d))
    if got != want:
        raise EvaluationError(f"{name}: could not draw the query quotas {want} in {budget} draws (got {got}); "
                              "the query window has too few targets of some category")
    return out


def _time_sampler(t_lo: float, t_hi: float, windows: Any, name: str) -> Any:
    """``u in [0, 1) -> t``: uniform in ``(t_lo, t_hi]``, or uniform over the windows' parts inside it."""
    if windows is None:
        return lambda u: float(t_hi - u * (t_hi - t_lo))
    w = np.asarray(windows, dtype=np.float64).reshape(-1, 2)
    w = np.column_stack([np.maximum(w[:, 0], t_lo), np.minimum(w[:, 1], t_hi)])
    w = w[w[:, 1] > w[:, 0]]
    if w.size == 0:
        raise EvaluationError(f"{name}: no scoring-window time between the last map update and the end of the "
                              "ground truth; check --windows")
    cum = np.concatenate([[0.0], np.cumsum(w[:, 1] - w[:, 0])])

    def at(u: float) -> float:
        x = u * cum[-1]
        k = min(int(np.searchsorted(cum, x, side="right")) - 1, len(w) - 1)
        return float(w[k, 1] - (cum[k + 1] - x))  # in (start, end] of window k

    return at


def queries_to_frame(queries: list[Query]) -> Any:
    """Queries as a pandas DataFrame (one row each; ``doors_open`` as a JSON string)."""
    import pandas as pd

    rows = []
    for q in queries:
        d = asdict(q)
        d["start_row"], d["start_col"] = q.start_cell
        d["start_x_m"], d["start_y_m"] = q.start_xy
        d["doors_open"] = json.dumps(q.doors_open, sort_keys=True)
        del d["start_cell"], d["start_xy"]
        rows.append(d)
    return pd.DataFrame(rows)


def queries_from_frame(df: Any) -> list[Query]:
    """Inverse of :func:`queries_to_frame`."""
    out = []
    for r in df.to_dict("records"):
        def _opt(v: Any) -> str | None:
            return None if v is None or (isinstance(v, float) and np.isnan(v)) else str(v)

        out.append(Query(int(r["query_id"]), int(r["seed"]), str(r["object_id"]), float(r["t_s"]),
                         (int(r["start_row"]), int(r["start_col"])), (float(r["start_x_m"]), float(r["start_y_m"])),
                         str(r["category"]), _opt(r["gt_receptacle"]), _opt(r["map_receptacle"]),
                         {k: bool(v) for k, v in json.loads(r["doors_open"]).items()}))
    return out


def save_queries(queries: list[Query], path: str | Path) -> Path:
    """Write queries to ``path`` (``.parquet`` or ``.json``): replaces the file atomically (an
    interrupted call leaves the previous one as it was).
    """
    from psg_data.writers._safe_output import write_atomically

    p = Path(path)
    df = queries_to_frame(queries)
    if p.suffix == ".json":
        text = json.dumps(df.to_dict("records"), indent=1)
        return write_atomically(p, lambda tmp: tmp.write_text(text))
    return write_atomically(p, lambda tmp: df.to_parquet(tmp, index=False))


def load_queries(path: str | Path) -> list[Query]:
    """Read queries written by :func:`save_queries`."""
    import pandas as pd

    p = Path(path)
    if not p.is_file():
        raise EvaluationError(f"{p}: no query file")
    df = pd.DataFrame(json.loads(p.read_text())) if p.suffix == ".json" else pd.read_parquet(p)
    return queries_from_frame(df)
