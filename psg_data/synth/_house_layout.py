"""Procedural multi-room houses: floor plan, doors, receptacles, pickupable objects and the patrol.

World frame: x east, y north, z up, metres; floor ``z = 0``. A house is a rectangle cut into 5-8
rectangular rooms by guillotine cuts (each cut splits a group of rooms in two, along the longer
side of its rectangle, in proportion to the rooms' target areas: living room 1.6, kitchen 1.1,
bedroom 1.0, office 0.8, hallway 0.6, bathroom 0.5). Room polygons are the wall centre lines
(walls 0.1 m thick, as the lab's). Every room has a kitchen, a living room, a bedroom and a
bathroom; 1-4 more rooms are drawn from bedroom, office, hallway, bedroom.

Doors: **every** pair of rooms sharing at least 1.5 m of wall gets a 0.9 m door in the middle of
the shared wall, so the door graph is the adjacency graph itself: wherever the floor plan has a
route around a door, the house has it (a door is a bridge of the door graph exactly when it is a
bridge of the adjacency graph), and every room is reachable with all doors open (plans whose
adjacency graph is not connected are redrawn). ``semi_static_doors`` of them (chosen among the
doors with a way around them first) open and close on a schedule; the others stay open.

Receptacles: per room kind the categories of :data:`~psg_data.synth._house_catalog.ROOM_RECEPTACLES`
in order, one per 3.5 m2 of floor (at least 2), against the walls, outside the door swing zones and
at least 0.7 m from the room centre (the robot's patrol point). Navigable area = the rooms' floor
inside the walls minus the receptacle footprints; a plan outside ``area_m2`` is redrawn.

Objects: ``n_objects`` distinct pickupable types with a positive affinity for at least two of the
house's receptacles; roles ``static`` (25 %), ``absent`` (20 %, sometimes out of the house) and
``dynamic`` (the rest).

Patrol (the privileged labels' sensor): one point per room at its centre; every hour the robot
visits the points of the rooms it can reach from the dock room (the hallway, else the living
room) through open doors, and sees a receptacle (or a doorway) when the 2-D segment from a
visited point to its centre is at most ``view_range_m`` long and crosses no wall and no closed
door (:meth:`HouseLayout.visible`). This is line of sight on the same walls and doorways that
:func:`psg_data.navigation.grid_from_geometry` rasterises into the occupancy grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data._geometry import yaw_rotation
from psg_data.errors import PsgDataError
from psg_data.schemas._records import Box, Door, Receptacle, Room
from psg_data.synth._house_catalog import PICKUPABLES, RECEPTACLE_SIZES, ROOM_RECEPTACLES, affinity

__all__ = ["HouseParams", "HouseLayout", "HouseObject", "make_house", "WALL_M", "DOOR_WIDTH_M"]

WALL_M = 0.10
DOOR_WIDTH_M = 0.90
DOOR_HEIGHT_M = 2.05
MIN_SHARED_M = 1.5
_SHARE = {"living_room": 1.6, "kitchen": 1.1, "bedroom": 1.0, "office": 0.8, "hallway": 0.6, "bathroom": 0.5}
_EXTRA_ROOMS = ("bedroom", "office", "hallway", "bedroom")


@dataclass(frozen=True)
class HouseParams:
    """Generator parameters of a house's geometry and objects (stored in the manifest).

    Attributes:
        rooms: (min, max) number of rooms, inclusive.
        area_m2: (min, max) navigable area, m2.
        n_objects: pickupable objects per house.
        semi_static_doors: doors with their own open/closed schedule (the others stay open).
        view_range_m: longest line of sight of the patrol, metres (the lab's depth range, 6 m).
    """

    rooms: tuple[int, int] = (5, 8)
    area_m2: tuple[float, float] = (100.0, 150.0)
    n_objects: int = 18
    semi_static_doors: int = 3
    view_range_m: float = 6.0


@dataclass(frozen=True)
class HouseObject:
    """A pickupable object of a house: id, AI2-THOR type, role (``static``, ``dynamic``, ``absent``)."""

    object_id: str
    object_type: str
    role: str


@dataclass
class HouseLayout:
    """Static geometry of one house (deterministic from its seed).

    Attributes:
        seed: the house seed.
        rooms: rooms with floor polygons (wall centre lines, counter-clockwise).
        kinds: room id -> room kind.
        doors: doors; the box is the doorway (x along the wall normal).
        receptacles: receptacles, boxes with x along the wall they stand against.
        objects: the pickupable objects.
        semi_static: ids of the doors with a schedule.
        dock_room: where the patrol starts.
        patrol_points: room id -> (x, y) patrol point.
        view_range_m: longest line of sight, metres.
    """

    seed: int
    rooms: list[Room]
    kinds: dict[str, str]
    doors: list[Door]
    receptacles: list[Receptacle]
    objects: list[HouseObject]
    semi_static: tuple[str, ...]
    dock_room: str
    patrol_points: dict[str, tuple[float, float]]
    view_range_m: float = 6.0
    _walls: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 4)), repr=False)

    def __post_init__(self) -> None:
        segs = []
        for r in self.rooms:
            p = np.asarray(r.floor_polygon_m, float)
            for k in range(len(p)):
                segs.append([*p[k], *p[(k + 1) % len(p)]])
        self._walls = np.asarray(segs, float).reshape(-1, 4)

    # -- lookups ----------------------------------------------------------------------------------
    @property
    def room_ids(self) -> list[str]:
        """Room ids in layout order."""
        return [r.room_id for r in self.rooms]

    @property
    def door_ids(self) -> list[str]:
        """Door ids in layout order."""
        return [d.door_id for d in self.doors]

    @property
    def receptacle_ids(self) -> list[str]:
        """Receptacle ids in layout order."""
        return [r.receptacle_id for r in self.receptacles]

    @property
    def object_ids(self) -> list[str]:
        """Object ids in layout order."""
        return [o.object_id for o in self.objects]

    def room_area_m2(self, room_id: str) -> float:
        """Floor area inside the walls, m2."""
        x0, x1, y0, y1 = _bounds(next(r for r in self.rooms if r.room_id == room_id))
        return (x1 - x0 - WALL_M) * (y1 - y0 - WALL_M)

    @property
    def navigable_m2(self) -> float:
        """Floor inside the walls minus the receptacle footprints, m2 (module docstring)."""
        floor = sum(self.room_area_m2(r) for r in self.room_ids)
        return float(floor - sum(r.box.extent_m[0] * r.box.extent_m[1] for r in self.receptacles))

    # -- connectivity ------------------------------------------------------------------------------
    def reachable_rooms(self, door_open: dict[str, bool] | None = None, start: str | None = None) -> list[str]:
        """Rooms reachable from ``start`` (default the dock room) through open doors (missing = open), BFS order."""
        door_open = door_open or {}
        start = start or self.dock_room
        seen, queue = [start], [start]
        while queue:
            a = queue.pop(0)
            for d in self.doors:
                if not door_open.get(d.door_id, True) or a not in (d.room_a, d.room_b):
                    continue
                b = d.room_b if d.room_a == a else d.room_a
                if b not in seen:
                    seen.append(b)
                    queue.append(b)
        return seen

    def bridges(self) -> list[str]:
        """Doors whose closing disconnects the house (no route around them)."""
        n = len(self.rooms)
        return [d.door_id for d in self.doors if len(self.reachable_rooms({d.door_id: False}, d.room_a)) < n]

    # -- line of sight -----------------------------------------------------------------------------
    def visible(self, points: NDArray[np.float64], targets: NDArray[np.float64], door_open: dict[str, bool]
                ) -> NDArray[np.bool_]:
        """(P, T) whether target ``t`` is in line of sight of point ``p``: within ``view_range_m`` and the
        segment crosses no wall outside an open doorway (walls and doors as 2-D segments, metres).
        """
        P = np.asarray(points, float).reshape(-1, 2)
        T = np.asarray(targets, float).reshape(-1, 2)
        a = np.repeat(P, len(T), axis=0)
        b = np.tile(T, (len(P), 1))
        ok = np.linalg.norm(b - a, axis=1) <= self.view_range_m
        w = self._walls
        d = b - a
        e = w[:, 2:] - w[:, :2]
        den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
        q = w[None, :, :2] - a[:, None, :]
        par = np.abs(den) <= 1e-12  # parallel: never a crossing
        den = np.where(par, 1.0, den)
        t = (q[..., 0] * e[None, :, 1] - q[..., 1] * e[None, :, 0]) / den
        u = (q[..., 0] * d[:, None, 1] - q[..., 1] * d[:, None, 0]) / den
        hit = ~par & (t > 1e-9) & (t < 1 - 1e-6) & (u >= 0) & (u <= 1)
        px = a[:, None, :] + t[..., None] * d[:, None, :]
        for dr in self.doors:
            if not door_open.get(dr.door_id, True):
                continue
            c = np.asarray(dr.box.center_m[:2], float)
            along = np.abs(np.asarray(dr.box.rotation)[:2, 1])  # the doorway's width axis
            gap = (np.abs((px - c) @ along) <= DOOR_WIDTH_M / 2) & (np.abs((px - c) @ (1 - along)) <= WALL_M)
            hit &= ~gap
        return (ok & ~hit.any(axis=1)).reshape(len(P), len(T))

    def patrol_visibility(self, door_open: dict[str, bool]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Per receptacle and per door, how many visited patrol points see it (0 = not seen) under ``door_open``."""
        rooms = self.reachable_rooms(door_open)
        pts = np.array([self.patrol_points[r] for r in rooms], float)
        rec = np.array([r.box.center_m[:2] for r in self.receptacles], float).reshape(-1, 2)
        doors = np.array([d.box.center_m[:2] for d in self.doors], float).reshape(-1, 2)
        return (self.visible(pts, rec, door_open).sum(axis=0).astype(np.int64),
                self.visible(pts, doors, door_open).sum(axis=0).astype(np.int64))

    def to_dict(self) -> dict[str, Any]:
        """What the dataset's manifest records of the house (kinds, semi-static doors, patrol)."""
        return {"room_kinds": dict(self.kinds), "semi_static_doors": list(self.semi_static),
                "dock_room": self.dock_room, "patrol_points": {k: list(v) for k, v in self.patrol_points.items()},
                "view_range_m": self.view_range_m, "navigable_m2": round(self.navigable_m2, 3),
                "objects": [{"object_id": o.object_id, "type": o.object_type, "role": o.role} for o in self.objects]}


def _bounds(room: Room) -> tuple[float, float, float, float]:
    p = np.asarray(room.floor_polygon_m, float)
    return float(p[:, 0].min()), float(p[:, 0].max()), float(p[:, 1].min()), float(p[:, 1].max())


# -- floor plan ------------------------------------------------------------------------------------
def _guillotine(rect: tuple[float, float, float, float], areas: list[float], rng: np.random.Generator
                ) -> list[tuple[float, float, float, float]]:
    """Cut ``rect`` (x0, x1, y0, y1) into one rectangle per target area (same order)."""
    if len(areas) == 1:
        return [rect]
    x0, x1, y0, y1 = rect
    cum = np.cumsum(areas) / sum(areas)
    k = int(np.argmin(np.abs(cum[:-1] - 0.5))) + 1
    f = float(cum[k - 1])
    if x1 - x0 >= y1 - y0:
        xm = round(x0 + f * (x1 - x0), 1)
        a, b = (x0, xm, y0, y1), (xm, x1, y0, y1)
    else:
        ym = round(y0 + f * (y1 - y0), 1)
        a, b = (x0, x1, y0, ym), (x0, x1, ym, y1)
    return _guillotine(a, areas[:k], rng) + _guillotine(b, areas[k:], rng)


def _shared_wall(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, str] | None:
    """(x, y, length, axis) of the middle of the wall two rectangles share, or None (axis: the wall's
    direction, 'y' for a wall at constant x).
    """
    for i, j in ((1, 0), (0, 1)):  # a's east wall is b's west wall, or the other way round
        if abs(a[i] - b[j]) < 1e-9:
            lo, hi = max(a[2], b[2]), min(a[3], b[3])
            if hi - lo >= MIN_SHARED_M:
                return a[i], (lo + hi) / 2, hi - lo, "y"
    for i, j in ((3, 2), (2, 3)):
        if abs(a[i] - b[j]) < 1e-9:
            lo, hi = max(a[0], b[0]), min(a[1], b[1])
            if hi - lo >= MIN_SHARED_M:
                return (lo + hi) / 2, a[i], hi - lo, "x"
    return None


def _plan(rng: np.random.Generator, params: HouseParams) -> tuple[list[str], list[tuple[float, float, float, float]]]:
    n = int(rng.integers(params.rooms[0], params.rooms[1] + 1))
    kinds = ["living_room", "kitchen", "bedroom", "bathroom", *[str(k) for k in rng.permutation(_EXTRA_ROOMS)][: n - 4]]
    order = list(rng.permutation(n))
    kinds = [kinds[i] for i in order]
    floor = float(rng.uniform(params.area_m2[0], params.area_m2[1])) * 1.12  # furniture takes about a tenth
    aspect = float(rng.uniform(1.1, 1.6))
    W = round(float(np.sqrt(floor * aspect)), 1)
    H = round(floor / W, 1)
    areas = [_SHARE[k] for k in kinds]
    return kinds, _guillotine((0.0, W, 0.0, H), areas, rng)


# -- receptacles -------------------------------------------------------------------------------------
def _place(rng: np.random.Generator, rect: tuple[float, ...], cats: list[str], forbidden: list[tuple[float, ...]],
           room_id: str, kind: str) -> list[Receptacle]:
    t = WALL_M / 2
    ix0, ix1, iy0, iy1 = rect[0] + t, rect[1] - t, rect[2] + t, rect[3] - t
    cx0, cy0 = (ix0 + ix1) / 2, (iy0 + iy1) / 2
    centre = (cx0 - 0.7, cx0 + 0.7, cy0 - 0.7, cy0 + 0.7)
    placed = [*forbidden, centre]
    out: list[Receptacle] = []
    for cat in cats:
        s = RECEPTACLE_SIZES[cat]
        w, d = s.width_m, s.depth_m
        for _ in range(400):
            side = int(rng.integers(4))
            if side in (0, 1):
                if ix1 - ix0 < w + 0.1:
                    continue
                cx = float(rng.uniform(ix0 + w / 2 + 0.05, ix1 - w / 2 - 0.05))
                cy = iy0 + d / 2 + 0.03 if side == 0 else iy1 - d / 2 - 0.03
                yaw, fp = (0.0 if side == 0 else np.pi), (cx - w / 2, cx + w / 2, cy - d / 2, cy + d / 2)
            else:
                if iy1 - iy0 < w + 0.1:
                    continue
                cy = float(rng.uniform(iy0 + w / 2 + 0.05, iy1 - w / 2 - 0.05))
                cx = ix0 + d / 2 + 0.03 if side == 2 else ix1 - d / 2 - 0.03
                yaw, fp = (-np.pi / 2 if side == 2 else np.pi / 2), (cx - d / 2, cx + d / 2, cy - w / 2, cy + w / 2)
            if any(not (fp[1] + 0.1 <= q[0] or q[1] + 0.1 <= fp[0] or fp[3] + 0.1 <= q[2] or q[3] + 0.1 <= fp[2])
                   for q in placed):
                continue
            placed.append(fp)
            rid = f"{room_id}_{len(out) + 1:02d}_{cat.lower()}"
            out.append(Receptacle(rid, f"{cat} {len(out) + 1} ({kind.replace('_', ' ')})", room_id,
                                  Box(np.array([cx, cy, s.height_m / 2]), np.array([w, d, s.height_m]),
                                      yaw_rotation(yaw)), cat))
            break
    return out


def _door_box(x: float, y: float, axis: str) -> Box:
    return Box(np.array([x, y, DOOR_HEIGHT_M / 2]), np.array([WALL_M + 0.04, DOOR_WIDTH_M, DOOR_HEIGHT_M]),
               np.eye(3) if axis == "y" else yaw_rotation(np.pi / 2))


def _objects(rng: np.random.Generator, receptacles: list[Receptacle], n: int) -> list[HouseObject]:
    cats = [r.category or "" for r in receptacles]
    ok = [t for t in PICKUPABLES if sum(affinity(t, c) > 0 for c in cats) >= 2]
    if len(ok) < n:
        raise PsgDataError(f"house: only {len(ok)} object types fit its receptacles, {n} requested")
    types = sorted(rng.choice(ok, size=n, replace=False).tolist())
    order = rng.permutation(n)
    n_static, n_absent = round(0.25 * n), round(0.2 * n)
    roles = ["static"] * n_static + ["absent"] * n_absent + ["dynamic"] * (n - n_static - n_absent)
    return [HouseObject(types[i].lower(), types[i], roles[int(np.flatnonzero(order == i)[0])]) for i in range(n)]


def make_house(seed: int, params: HouseParams | None = None) -> HouseLayout:
    """Draw the house of ``seed`` (module docstring); plans that miss a constraint are redrawn.

    Raises:
        PsgDataError: no valid plan in 200 draws (impossible constraints).
    """
    params = params or HouseParams()
    for attempt in range(200):
        rng = np.random.default_rng([int(seed), 2501, attempt])
        house = _attempt(rng, int(seed), params)
        if house is not None:
            return house
    raise PsgDataError(f"make_house: no plan with {params.rooms} rooms and {params.area_m2} m2 for seed {seed}")


def _attempt(rng: np.random.Generator, seed: int, params: HouseParams) -> HouseLayout | None:
    kinds, rects = _plan(rng, params)
    if any(min(r[1] - r[0], r[3] - r[2]) < (1.8 if k == "hallway" else 2.4) for k, r in zip(kinds, rects)):
        return None
    ids = [f"room_{i}" for i in range(len(kinds))]
    rooms = [Room(i, f"{k.replace('_', ' ')} {n}", np.array([[r[0], r[2]], [r[1], r[2]], [r[1], r[3]], [r[0], r[3]]]))
             for n, (i, k, r) in enumerate(zip(ids, kinds, rects))]
    doors: list[Door] = []
    for a in range(len(rects)):
        for b in range(a + 1, len(rects)):
            sw = _shared_wall(rects[a], rects[b])
            if sw is not None:
                x, y, _, axis = sw
                doors.append(Door(f"door_{a}{b}", f"door {kinds[a]} - {kinds[b]}", ids[a], ids[b],
                                  _door_box(x, y, axis)))
    zones: dict[str, list[tuple[float, ...]]] = {i: [] for i in ids}  # door swing zones on both sides of each doorway
    for d in doors:
        x, y = d.box.center_m[:2]
        vertical = abs(d.box.rotation[0][0]) > 0.5
        z = (x - 1.0, x + 1.0, y - 0.75, y + 0.75) if vertical else (x - 0.75, x + 0.75, y - 1.0, y + 1.0)
        zones[d.room_a].append(z)
        zones[d.room_b].append(z)
    receptacles: list[Receptacle] = []
    for i, k, r in zip(ids, kinds, rects):
        area = (r[1] - r[0] - WALL_M) * (r[3] - r[2] - WALL_M)
        cats = list(ROOM_RECEPTACLES[k])[: max(2, min(len(ROOM_RECEPTACLES[k]), int(area / 3.5)))]
        receptacles += _place(rng, r, cats, zones[i], i, k)
    dock = ids[kinds.index("hallway")] if "hallway" in kinds else ids[kinds.index("living_room")]
    points = {i: ((r[0] + r[1]) / 2, (r[2] + r[3]) / 2) for i, r in zip(ids, rects)}
    house = HouseLayout(seed, rooms, dict(zip(ids, kinds)), doors, receptacles, [], (), dock, points,
                        params.view_range_m)
    if len(house.reachable_rooms()) < len(rooms):
        return None
    if not params.area_m2[0] <= house.navigable_m2 <= params.area_m2[1]:
        return None
    try:
        house.objects = _objects(rng, receptacles, params.n_objects)
    except PsgDataError:
        return None
    bridges = set(house.bridges())
    order = [d.door_id for d in doors]
    rng.shuffle(order)
    order.sort(key=lambda d: d in bridges)  # doors with a way around them first
    house.semi_static = tuple(sorted(order[: params.semi_static_doors]))
    return house
