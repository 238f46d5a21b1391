"""A snapshot as a ``networkx`` graph or a spark-dsg ``DynamicSceneGraph`` (extra ``psg-data[graph]``).

Both conversions are optional: the library is imported when the conversion is called, and a
missing one is one line naming the extra.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from psg_data.errors import PsgDataError

if TYPE_CHECKING:  # pragma: no cover
    from psg_data.graph._snapshot import Snapshot

__all__ = ["snapshot_to_networkx", "snapshot_to_spark_dsg", "SPARK_DSG_LAYERS"]


def _need(module: str, dist: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise PsgDataError(f"this conversion needs {dist}: pip install 'psg-data[graph]'") from None


def snapshot_to_networkx(s: Snapshot) -> Any:
    """A ``networkx.DiGraph`` of the snapshot.

    Nodes are ``(kind, id)`` with kind ``room``, ``receptacle``, ``door`` or ``object``; attributes
    ``kind``, ``name``, ``pos`` (world x, y, z in metres: box centres, room polygon centres at z 0;
    an object at its most probable receptacle, NaN without edges) and, for doors, ``p_open``.
    Edges: object -> receptacle ``kind="on"`` with ``p`` = P(object on receptacle) at ``t_s``
    (the graph's ``t_s`` attribute); receptacle -> room ``kind="in"``; door -> each of its rooms
    ``kind="connects"`` with ``p_open``.
    """
    nx = _need("networkx", "networkx")
    L = s.layout
    G = nx.DiGraph(t_s=s.t_s, timezone=L.timezone)
    for room in L.rooms.values():
        xy = L.room_xy(room.room_id)
        G.add_node(("room", room.room_id), kind="room", name=room.name, pos=(float(xy[0]), float(xy[1]), 0.0))
    for rec in L.receptacles.values():
        G.add_node(("receptacle", rec.receptacle_id), kind="receptacle", name=rec.name, category=rec.category,
                   pos=tuple(float(v) for v in rec.box.center_m))
        if rec.room_id in L.rooms:
            G.add_edge(("receptacle", rec.receptacle_id), ("room", rec.room_id), kind="in")
    for d, p in zip(s.doors.tolist(), s.p_open.tolist()):
        door = L.doors.get(d)
        pos = tuple(float(v) for v in door.box.center_m) if door is not None else (np.nan,) * 3
        G.add_node(("door", d), kind="door", name=door.name if door else d, pos=pos, p_open=float(p))
        for room_id in (door.room_a, door.room_b) if door is not None else ():
            if room_id in L.rooms:
                G.add_edge(("door", d), ("room", room_id), kind="connects", p_open=float(p))
    objs = sorted(set(L.objects) | set(s.objects.tolist()))
    for o in objs:
        bel = s.beliefs(o)
        best = min(bel, key=lambda r: (-bel[r], r)) if bel else None
        pos = (tuple(float(v) for v in L.receptacles[best].box.center_m) if best is not None
               and best in L.receptacles else (np.nan,) * 3)
        info = L.objects.get(o)
        G.add_node(("object", o), kind="object", name=info.name if info else o, pos=pos)
    for o, r, p in zip(s.objects.tolist(), s.receptacles.tolist(), s.p.tolist()):
        if ("receptacle", r) not in G:
            G.add_node(("receptacle", r), kind="receptacle", name=r, category=None, pos=(np.nan,) * 3)
        G.add_edge(("object", o), ("receptacle", r), kind="on", p=float(p))
    return G


SPARK_DSG_LAYERS = {"object": "OBJECTS", "receptacle": "OBJECTS", "door": "PLACES", "room": "ROOMS"}
"""Which spark-dsg layer each node kind goes to (receptacles and objects are both objects there)."""


def _bbox(sd: Any, box: Any) -> Any:
    f32 = np.float32
    return sd.BoundingBox(sd.BoundingBoxType.OBB, np.asarray(box.extent_m, f32), np.asarray(box.center_m, f32),
                          np.asarray(box.rotation, f32))


def snapshot_to_spark_dsg(s: Snapshot) -> Any:
    """A spark-dsg ``DynamicSceneGraph`` of the snapshot (MIT-SPARK's scene graphs: Hydra, Khronos).

    Layers (:data:`SPARK_DSG_LAYERS`): ``OBJECTS`` holds the receptacles (``NodeSymbol('O', i)``,
    oriented bounding box, position = box centre) and the movable objects (``NodeSymbol('o', j)``,
    position = their most probable receptacle's centre); ``PLACES`` the doors (``NodeSymbol('d', k)``,
    doorway box); ``ROOMS`` the rooms (``NodeSymbol('R', m)``, polygon centre at z 0). Every node's
    ``metadata`` holds ``kind`` and ``id`` (and ``room`` for receptacles, ``p_open`` for doors).
    Edges: object - receptacle weighted by P(object on receptacle) (``metadata.p`` too), receptacle -
    room, door - its rooms (weight P(open)). The graph's metadata: ``t_s``, ``timezone``,
    ``source: psg-data predictive graph``. ``DynamicSceneGraph.save(path)`` writes spark-dsg's own
    versioned JSON.
    """
    sd = _need("spark_dsg", "spark-dsg")
    L = s.layout
    G = sd.DynamicSceneGraph()
    G.metadata.set({"t_s": s.t_s, "timezone": L.timezone, "source": "psg-data predictive graph"})
    rooms = {r: sd.NodeSymbol("R", k) for k, r in enumerate(L.rooms)}
    for r, sym in rooms.items():
        a = sd.RoomNodeAttributes()
        a.name = L.rooms[r].name
        a.position = np.append(L.room_xy(r), 0.0)
        a.metadata.set({"kind": "room", "id": r})
        G.add_node(sd.DsgLayers.ROOMS, sym, a)
    recs = {r: sd.NodeSymbol("O", k) for k, r in enumerate(sorted(set(L.receptacles) | set(s.receptacles.tolist())))}
    for r, sym in recs.items():
        a = sd.ObjectNodeAttributes()
        rec = L.receptacles.get(r)
        a.name = r
        if rec is not None:
            a.position = np.asarray(rec.box.center_m, np.float64)
            a.bounding_box = _bbox(sd, rec.box)
        a.metadata.set({"kind": "receptacle", "id": r, "room": rec.room_id if rec else None})
        G.add_node(sd.DsgLayers.OBJECTS, sym, a)
        if rec is not None and rec.room_id in rooms:
            G.insert_edge(sym, rooms[rec.room_id])
    for k, (d, p) in enumerate(zip(s.doors.tolist(), s.p_open.tolist())):
        sym, door = sd.NodeSymbol("d", k), L.doors.get(d)
        a = sd.ObjectNodeAttributes()
        a.name = d
        if door is not None:
            a.position = np.asarray(door.box.center_m, np.float64)
            a.bounding_box = _bbox(sd, door.box)
        a.metadata.set({"kind": "door", "id": d, "p_open": float(p)})
        G.add_node(sd.DsgLayers.PLACES, sym, a)
        for room in (door.room_a, door.room_b) if door is not None else ():
            if room in rooms:
                e = sd.EdgeAttributes()
                e.weight, e.weighted = float(np.nan_to_num(p, nan=1.0)), True
                G.insert_edge(sym, rooms[room], e)
    objs = sorted(set(L.objects) | set(s.objects.tolist()))
    for j, o in enumerate(objs):
        bel = s.beliefs(o)
        best = min(bel, key=lambda r: (-bel[r], r)) if bel else None
        a = sd.ObjectNodeAttributes()
        a.name = o
        if best is not None and best in L.receptacles:
            a.position = np.asarray(L.receptacles[best].box.center_m, np.float64)
        a.metadata.set({"kind": "object", "id": o})
        sym = sd.NodeSymbol("o", j)
        G.add_node(sd.DsgLayers.OBJECTS, sym, a)
        for r, p in bel.items():
            e = sd.EdgeAttributes()
            e.weight, e.weighted = float(p), True
            e.metadata.set({"p": float(p)})
            G.insert_edge(sym, recs[r], e)
    return G
