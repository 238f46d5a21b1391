"""The static part of a predictive graph: rooms, receptacles, doors and objects with their geometry."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import GraphError
from psg_data.schemas._records import Box, Door, ObjectInfo, Opening, Receptacle, Room

__all__ = ["SceneLayout"]


@dataclass(frozen=True)
class SceneLayout:
    """Rooms, receptacles, doors and objects of a scene (world frame, z up, metres).

    Attributes:
        rooms: room_id -> record (floor polygon, may be None).
        receptacles: receptacle_id -> record (oriented box, room).
        doors: door_id -> record (doorway box, the two rooms it joins).
        objects: object_id -> record (name, description); objects have no fixed position.
        timezone: IANA site timezone (local time of strings and of the estimators' clocks).
        openings: opening_id -> record: doorless passages between rooms (always traversable).
    """

    rooms: Mapping[str, Room] = field(default_factory=dict)
    receptacles: Mapping[str, Receptacle] = field(default_factory=dict)
    doors: Mapping[str, Door] = field(default_factory=dict)
    objects: Mapping[str, ObjectInfo] = field(default_factory=dict)
    timezone: str = "UTC"
    openings: Mapping[str, Opening] = field(default_factory=dict)

    @classmethod
    def from_dataset(cls, dataset: Any) -> SceneLayout:
        """The layout of a :class:`~psg_data.loaders.Dataset` (its rooms, receptacles, doors, objects tables)."""
        ds = dataset

        def table(name: str) -> dict[str, Any]:
            return dict(getattr(ds, name)) if ds.has_table(name) else {}

        return cls(table("rooms"), table("receptacles"), table("doors"), table("objects"), ds.info.timezone or "UTC",
                   table("openings"))

    @classmethod
    def of(cls, *, receptacles: Iterable[Receptacle] | Mapping[str, Receptacle] = (),
           doors: Iterable[Door] | Mapping[str, Door] = (), rooms: Iterable[Room] | Mapping[str, Room] = (),
           objects: Iterable[str | ObjectInfo] = (), timezone: str = "UTC",
           openings: Iterable[Opening] | Mapping[str, Opening] = ()) -> SceneLayout:
        """A layout from records (or id -> record mappings); objects may be given by id."""
        def by_id(items: Any, key: str) -> dict[str, Any]:
            return dict(items) if isinstance(items, Mapping) else {getattr(x, key): x for x in items}

        objs = {o: ObjectInfo(o, o) if isinstance(o, str) else o for o in objects}
        return cls(by_id(rooms, "room_id"), by_id(receptacles, "receptacle_id"), by_id(doors, "door_id"),
                   {(k if isinstance(k, str) else k.object_id): v for k, v in objs.items()}, timezone,
                   by_id(openings, "opening_id"))

    def receptacle_xyz(self, receptacle_ids: Iterable[str]) -> NDArray[np.float64]:
        """(N, 3) box centres of the receptacles, metres (NaN for ids without a record)."""
        return _centres([self.receptacles.get(r) for r in receptacle_ids])

    def door_xyz(self, door_ids: Iterable[str]) -> NDArray[np.float64]:
        """(N, 3) doorway box centres, metres (NaN for ids without a record)."""
        return _centres([self.doors.get(d) for d in door_ids])

    def room_xy(self, room_id: str) -> NDArray[np.float64]:
        """(2,) mean vertex of the room's floor polygon, metres (NaN without one)."""
        r = self.rooms.get(room_id)
        if r is None or r.floor_polygon_m is None or len(r.floor_polygon_m) == 0:
            return np.full(2, np.nan)
        return np.asarray(r.floor_polygon_m, np.float64).mean(axis=0)

    # -- JSON -------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dictionary (:meth:`from_dict` restores the layout exactly)."""
        return {"timezone": self.timezone,
                "rooms": [{"room_id": r.room_id, "name": r.name,
                           "floor_polygon_m": None if r.floor_polygon_m is None else
                           np.asarray(r.floor_polygon_m, float).tolist()} for r in self.rooms.values()],
                "receptacles": [{"receptacle_id": r.receptacle_id, "name": r.name, "room_id": r.room_id,
                                 "category": r.category, "box": _box_dict(r.box)} for r in self.receptacles.values()],
                "doors": [{"door_id": d.door_id, "name": d.name, "room_a": d.room_a, "room_b": d.room_b,
                           "box": _box_dict(d.box)} for d in self.doors.values()],
                "objects": [{"object_id": o.object_id, "name": o.name, "description": o.description}
                            for o in self.objects.values()],
                "openings": [{"opening_id": o.opening_id, "name": o.name, "room_a": o.room_a, "room_b": o.room_b,
                              "box": _box_dict(o.box)} for o in self.openings.values()]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SceneLayout:
        """The layout a :meth:`to_dict` dictionary describes.

        Raises:
            GraphError: a missing or malformed field.
        """
        try:
            rooms = {r["room_id"]: Room(r["room_id"], r["name"], None if r["floor_polygon_m"] is None else
                                        np.asarray(r["floor_polygon_m"], np.float64)) for r in d["rooms"]}
            recs = {r["receptacle_id"]: Receptacle(r["receptacle_id"], r["name"], r["room_id"], _box(r["box"]),
                                                   r.get("category")) for r in d["receptacles"]}
            doors = {x["door_id"]: Door(x["door_id"], x["name"], x["room_a"], x["room_b"], _box(x["box"]))
                     for x in d["doors"]}
            objs = {o["object_id"]: ObjectInfo(o["object_id"], o["name"], o.get("description")) for o in d["objects"]}
            opens = {x["opening_id"]: Opening(x["opening_id"], x["name"], x["room_a"], x["room_b"], _box(x["box"]))
                     for x in d.get("openings", [])}
            return cls(rooms, recs, doors, objs, str(d["timezone"]), opens)
        except (KeyError, TypeError, ValueError) as exc:
            raise GraphError(f"layout: malformed ({type(exc).__name__}: {exc}); expected the fields SceneLayout."
                             "to_dict writes") from None


def _centres(records: list[Any]) -> NDArray[np.float64]:
    out = np.full((len(records), 3), np.nan)
    for k, r in enumerate(records):
        if r is not None:
            out[k] = np.asarray(r.box.center_m, np.float64)
    return out


def _box_dict(b: Box) -> dict[str, Any]:
    return {"center_m": np.asarray(b.center_m, float).tolist(), "extent_m": np.asarray(b.extent_m, float).tolist(),
            "rotation": np.asarray(b.rotation, float).tolist()}


def _box(d: Mapping[str, Any]) -> Box:
    return Box(np.asarray(d["center_m"], np.float64), np.asarray(d["extent_m"], np.float64),
               np.asarray(d["rotation"], np.float64))
