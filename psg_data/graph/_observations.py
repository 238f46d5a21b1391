"""New observations for :meth:`PredictiveGraph.update`: label rows or ``(t, object, receptacle, present)`` tuples."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import GraphError
from psg_data.graph._times import to_seconds

if TYPE_CHECKING:  # pragma: no cover
    from psg_data.graph._graph import PredictiveGraph

__all__ = ["group_observations"]

Groups = dict[tuple[str, Any], tuple[NDArray[np.float64], NDArray[np.int8]]]
_COLUMNS = ("object_id", "receptacle_id", "code")


def _columns(obs: Any) -> tuple[NDArray[np.float64], list[str], list[str], NDArray[np.int64]] | None:
    """(t_s, object ids, receptacle ids, codes) of a label table (pandas or pyarrow), None for other input."""
    try:
        import pyarrow as pa
    except ImportError:  # pragma: no cover - a runtime requirement
        pa = None
    if pa is not None and isinstance(obs, pa.Table):
        obs = obs.to_pandas()
    if not (hasattr(obs, "columns") and hasattr(obs, "to_numpy")):
        return None
    cols = set(obs.columns)
    missing = [c for c in _COLUMNS if c not in cols]
    if missing or not ({"stamp_ns", "t_s"} & cols):
        raise GraphError(f"update: label rows need columns object_id, receptacle_id, code and stamp_ns (or t_s); "
                         f"missing {missing or ['stamp_ns']}")
    t = (obs["stamp_ns"].to_numpy(np.int64) / 1e9 if "stamp_ns" in cols else obs["t_s"].to_numpy(np.float64))
    return (np.asarray(t, np.float64), [str(x) for x in obs["object_id"]], [str(x) for x in obs["receptacle_id"]],
            obs["code"].to_numpy(np.int64))


def _tuples(obs: Any, timezone: str) -> tuple[NDArray[np.float64], list[str], list[str], NDArray[np.int64]]:
    ts, a, b, y = [], [], [], []
    for k, row in enumerate(obs):
        try:
            t, o, r, present = row
        except (TypeError, ValueError):
            raise GraphError(f"update: observation {k}: expected (t, object_id, receptacle_id, present), got "
                             f"{row!r}") from None
        if present not in (0, 1, True, False):
            raise GraphError(f"update: observation {k}: present must be 0/1 or a bool, got {present!r}")
        ts.append(to_seconds(t, timezone))
        a.append(str(o))
        b.append(str(r))
        y.append(int(present))
    return np.asarray(ts, np.float64), a, b, np.asarray(y, np.int64)


def group_observations(observations: Any, graph: PredictiveGraph) -> Groups:
    """``("edge", (object, receptacle))`` / ``("door", door_id)`` -> (times, 0/1 values), each in time order.

    Label codes other than 1 / 0 are dropped. A door row ``(door, 'closed', c)`` counts as
    ``(door, 'open', 1 - c)`` unless an ``'open'`` row of that door has the same time.
    """
    cols = _columns(observations)
    t, a, b, code = cols if cols is not None else _tuples(observations, graph.timezone)
    if not np.all(np.isfinite(t)):
        raise GraphError("update: observation times must be finite")
    doors = set(graph.doors)
    keep = (code == 0) | (code == 1)
    is_door = np.array([o in doors and r in ("open", "closed") for o, r in zip(a, b)], bool)
    opened = {(a[k], t[k]) for k in np.flatnonzero(keep & is_door) if b[k] == "open"}
    order = np.argsort(t, kind="stable")
    out: dict[tuple[str, Any], tuple[list[float], list[int]]] = {}
    for k in order:
        if not keep[k]:
            continue
        if is_door[k]:
            if b[k] == "closed" and (a[k], t[k]) in opened:
                continue
            key: tuple[str, Any] = ("door", a[k])
            v = int(code[k]) if b[k] == "open" else 1 - int(code[k])
        else:
            key, v = ("edge", (a[k], b[k])), int(code[k])
        ts, ys = out.setdefault(key, ([], []))
        ts.append(float(t[k]))
        ys.append(v)
    return {k: (np.asarray(ts, np.float64), np.asarray(ys, np.int8)) for k, (ts, ys) in out.items()}
