"""What a predictive graph says at one time: :class:`Snapshot` (edges and doors) and :class:`Ranking` (one object)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import GraphError
from psg_data.graph._layout import SceneLayout

__all__ = ["Snapshot", "Ranking", "doors_believed_open"]


def doors_believed_open(p_open: Any, threshold: float = 0.5) -> dict[str, bool]:
    """door_id -> planned open: ``P(open) >= threshold``; a door without a model (NaN) counts as open.

    This is the rule of the navigation agent, the door task and :meth:`PredictiveGraph.plan`.
    """
    return {str(d): bool(not math.isfinite(float(p)) or float(p) >= threshold) for d, p in dict(p_open).items()}


@dataclass(frozen=True)
class Snapshot:
    """P(object on receptacle) of every edge and P(open) of every door at one time.

    Arrays are aligned with the graph's edge and door order; probabilities are the filters' own
    predictions (NaN for a door without a filter: no door model, planned open).

    Attributes:
        t_s: the time, Unix seconds (UTC).
        objects: (E,) object id of each edge.
        receptacles: (E,) receptacle id of each edge.
        p: (E,) P(object on receptacle) at ``t_s``.
        doors: (D,) door ids.
        p_open: (D,) P(door open) at ``t_s``.
        layout: the geometry (positions, rooms) the conversions attach.
    """

    t_s: float
    objects: NDArray[np.str_]
    receptacles: NDArray[np.str_]
    p: NDArray[np.float64]
    doors: NDArray[np.str_]
    p_open: NDArray[np.float64]
    layout: SceneLayout = field(repr=False)

    def __len__(self) -> int:
        return int(self.p.size)

    def probability(self, object_id: str, receptacle_id: str) -> float:
        """P(``object_id`` on ``receptacle_id``); 0 for a pair the graph has no edge for."""
        m = (self.objects == object_id) & (self.receptacles == receptacle_id)
        return float(self.p[m][0]) if m.any() else 0.0

    def beliefs(self, object_id: str) -> dict[str, float]:
        """receptacle_id -> P(``object_id`` on it), over the object's edges."""
        m = self.objects == object_id
        return {str(r): float(v) for r, v in zip(self.receptacles[m], self.p[m])}

    def door_probabilities(self) -> dict[str, float]:
        """door_id -> P(open) (NaN: no door model)."""
        return {str(d): float(v) for d, v in zip(self.doors, self.p_open)}

    def doors_open(self, threshold: float = 0.5) -> dict[str, bool]:
        """door_id -> planned open (:func:`doors_believed_open`)."""
        return doors_believed_open(self.door_probabilities(), threshold)

    # -- conversions -------------------------------------------------------------------------------
    def to_pydict(self) -> dict[str, list[Any]]:
        """:meth:`to_pandas`'s columns as lists (the receptacle's box centre x_m, y_m, z_m: world frame, metres)."""
        xyz = self.layout.receptacle_xyz(self.receptacles.tolist())
        recs = self.layout.receptacles
        rec_ids = self.receptacles.tolist()
        return {"object_id": self.objects.tolist(), "receptacle_id": rec_ids, "p": self.p.tolist(),
                "room_id": [recs[r].room_id if r in recs else None for r in rec_ids],
                "x_m": xyz[:, 0].tolist(), "y_m": xyz[:, 1].tolist(), "z_m": xyz[:, 2].tolist()}

    def doors_to_pydict(self) -> dict[str, list[Any]]:
        """:meth:`doors_to_pandas`'s columns as lists (door_id, p_open, room_a, room_b, x_m, y_m, z_m; metres)."""
        xyz = self.layout.door_xyz(self.doors.tolist())
        rec = self.layout.doors
        ids = self.doors.tolist()
        return {"door_id": ids, "p_open": self.p_open.tolist(),
                "room_a": [rec[d].room_a if d in rec else None for d in ids],
                "room_b": [rec[d].room_b if d in rec else None for d in ids],
                "x_m": xyz[:, 0].tolist(), "y_m": xyz[:, 1].tolist(), "z_m": xyz[:, 2].tolist()}

    def to_pandas(self) -> Any:
        """The edges as a ``pandas.DataFrame``: object_id, receptacle_id, p, room_id, x_m, y_m, z_m
        (the receptacle's box centre, world frame, metres).
        """
        import pandas as pd

        xyz = self.layout.receptacle_xyz(self.receptacles.tolist())
        recs = self.layout.receptacles
        return pd.DataFrame({"object_id": self.objects.astype(object), "receptacle_id": self.receptacles.astype(object),
                             "p": self.p, "room_id": [recs[r].room_id if r in recs else None
                                                      for r in self.receptacles.tolist()],
                             "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2]})

    def doors_to_pandas(self) -> Any:
        """The doors as a ``pandas.DataFrame``: door_id, p_open, room_a, room_b, x_m, y_m, z_m."""
        import pandas as pd

        xyz = self.layout.door_xyz(self.doors.tolist())
        rec = self.layout.doors
        ids = self.doors.tolist()
        return pd.DataFrame({"door_id": self.doors.astype(object), "p_open": self.p_open,
                             "room_a": [rec[d].room_a if d in rec else None for d in ids],
                             "room_b": [rec[d].room_b if d in rec else None for d in ids],
                             "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2]})

    def to_networkx(self) -> Any:
        """A ``networkx.DiGraph`` (extra ``psg-data[graph]``): see :func:`psg_data.graph.snapshot_to_networkx`."""
        from psg_data.graph._convert import snapshot_to_networkx

        return snapshot_to_networkx(self)

    def to_spark_dsg(self) -> Any:
        """A spark-dsg ``DynamicSceneGraph`` (extra ``psg-data[graph]``): see ``snapshot_to_spark_dsg``."""
        from psg_data.graph._convert import snapshot_to_spark_dsg

        return snapshot_to_spark_dsg(self)


@dataclass(frozen=True)
class Ranking:
    """The receptacles of one object ranked by P(object on receptacle) at one time (ties by id).

    Attributes:
        object_id: the object.
        t_s: the time, Unix seconds (UTC).
        receptacles: (K,) receptacle ids, most probable first.
        p: (K,) their probabilities.
        xyz: (K, 3) receptacle box centres, world frame, metres.
        rooms: (K,) room of each receptacle (None without a record).
    """

    object_id: str
    t_s: float
    receptacles: tuple[str, ...]
    p: NDArray[np.float64]
    xyz: NDArray[np.float64]
    rooms: tuple[str | None, ...]

    def __len__(self) -> int:
        return len(self.receptacles)

    @property
    def best(self) -> str | None:
        """The most probable receptacle (None for an object without edges)."""
        return self.receptacles[0] if self.receptacles else None

    def to_pydict(self) -> dict[str, list[Any]]:
        """:meth:`to_pandas`'s columns as lists: rank (1 = best), receptacle_id, p, room_id, x_m, y_m, z_m (metres)."""
        return {"rank": list(range(1, len(self) + 1)), "receptacle_id": list(self.receptacles), "p": self.p.tolist(),
                "room_id": list(self.rooms), "x_m": self.xyz[:, 0].tolist(), "y_m": self.xyz[:, 1].tolist(),
                "z_m": self.xyz[:, 2].tolist()}

    def to_pandas(self) -> Any:
        """Rank (1 = best), receptacle_id, p, room_id, x_m, y_m, z_m as a ``pandas.DataFrame``."""
        import pandas as pd

        return pd.DataFrame({"rank": np.arange(1, len(self) + 1), "receptacle_id": list(self.receptacles), "p": self.p,
                             "room_id": list(self.rooms), "x_m": self.xyz[:, 0], "y_m": self.xyz[:, 1],
                             "z_m": self.xyz[:, 2]})


def ranking(layout: SceneLayout, object_id: str, t_s: float, beliefs: dict[str, float], top: int | None) -> Ranking:
    """The :class:`Ranking` of ``beliefs`` (receptacle -> p), first ``top`` entries (all when None)."""
    if top is not None and top < 1:
        raise GraphError(f"top: {top}, expected a positive number of receptacles (or None for all)")
    order = sorted(beliefs, key=lambda r: (-beliefs[r], r))[:top]
    recs = layout.receptacles
    return Ranking(object_id, t_s, tuple(order), np.array([beliefs[r] for r in order], np.float64),
                   layout.receptacle_xyz(order).reshape(-1, 3),
                   tuple(recs[r].room_id if r in recs else None for r in order))
