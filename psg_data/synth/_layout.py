"""Geometry of the synthetic three-room lab: rooms, walls, doors, receptacles and object placement.

World frame: x east, y north, z up, metres; the floor is ``z = 0``. The rooms stand in a row along x,
``room_a | door_ab | room_b | door_bc | room_c``; walls are 0.1 m thick boxes centred on the room
boundaries with doorways cut out.

Three layouts (:data:`LAYOUTS`, chosen by :attr:`~psg_data.synth.LabConfig.layout`):

- ``two_routes`` (the default from ``DEMO_VERSION`` ``...-tworoutes-...`` until ``...-corridor-...``):
  each inner wall also has a
  doorless passage (an open archway, :class:`~psg_data.schemas.Opening`, 1.0 m wide) at the far end
  of the wall from its door, so a closed door lengthens the way by a few metres and never isolates a
  room: every room is reachable with both doors closed. This follows the paper's real-world lab, where
  the robot facing a closed door on the shortest path "generate[s] a longer but feasible path"
  (its Fig. "Predictive Navigation" and the extended real-world figure), which needs a second route.
- ``chain``: the first layout, the doors are the only way between rooms (a closed door cuts the lab);
  kept so that datasets built with it (no ``layout`` in their manifest) rebuild identically.
- ``corridor`` (default since ``DEMO_VERSION`` ``...-corridor-...``): the inner walls have only
  their doors (as in ``chain``); a corridor (:data:`CORRIDOR_WIDTH_M` wide: the building's hallway
  outside the lab, a fourth ``rooms`` entry without receptacles, id ``corridor``) runs along the
  north side of the three rooms, and each room opens onto it through a doorless opening in its
  north wall, at the end of the wall farthest from the room's door (the middle room: at its
  centre). A closed door sends the robot out through the corridor and back in, a longer detour than
  ``two_routes``' passages, and every room stays reachable with both doors closed; the lab keeps 3
  rooms, 2 doors, 28 receptacles (10/10/8). It follows the same paper text as ``two_routes`` (the
  paper gives the lab's counts, not its floor plan: where the second route runs is our choice), and
  its scans also look at the doors (:attr:`LabLayout.scans_look_at_doors`), so that door streams
  from the images have observations.

All layouts of a seed share the door positions and the receptacle counts per room; the furniture is
placed from the same random stream around different keep-out zones, so positions differ and
receptacles may swap categories (and ids) between layouts.

Receptacles stand against the walls (back to the wall), leaving the centre of every room, the door
swing areas and the passages free for the robot.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from psg_data._geometry import yaw_rotation
from psg_data.schemas._records import Box, Door, Opening, Receptacle, Room
from psg_data.synth._catalog import FURNITURE, OBJECTS, ROOM_FURNITURE, ObjectSpec

__all__ = ["LabLayout", "WallBox", "Instance", "make_layout", "LAYOUTS", "OPENING_WIDTH_M", "CORRIDOR_WIDTH_M",
           "WALL_HEIGHT_M", "DOOR_WIDTH_M", "DOOR_HEIGHT_M", "WALL_THICKNESS_M",
           "ID_NONE", "ID_FLOOR", "ID_CEILING", "WALL_ID0", "DOOR_ID0", "RECEPTACLE_ID0", "OBJECT_ID0"]

log = logging.getLogger(__name__)

WALL_HEIGHT_M = 2.6
WALL_THICKNESS_M = 0.10
DOOR_WIDTH_M = 0.90
DOOR_HEIGHT_M = 2.05
LEAF_THICKNESS_M = 0.04
OPENING_WIDTH_M = 1.00
OPENING_HEIGHT_M = 2.20
CORRIDOR_WIDTH_M = 1.50
"""Width of the ``corridor`` layout's hallway (inside its walls' centre lines), metres."""
CORRIDOR_ID = "corridor"
LAYOUTS = ("two_routes", "chain", "corridor")
"""Lab layouts (module docstring): ``two_routes`` (a door and an open passage in each inner wall),
``chain`` (doors only) and ``corridor`` (doors, and a hallway along the rooms with an opening into each)."""

# Instance ids of the renderer's per-pixel id image (int32).
ID_NONE = 0
"""No surface hit (beyond the scene)."""
ID_FLOOR = 1
ID_CEILING = 2
WALL_ID0 = 10
"""Wall segment k has id ``WALL_ID0 + k``."""
DOOR_ID0 = 100
"""Door leaf i (order of :attr:`LabLayout.doors`) has id ``DOOR_ID0 + i``."""
RECEPTACLE_ID0 = 1000
"""Receptacle i (order of :attr:`LabLayout.receptacles`) has id ``RECEPTACLE_ID0 + i``."""
OBJECT_ID0 = 2000
"""Object j (order of :attr:`LabLayout.objects`) has id ``OBJECT_ID0 + j``."""

_ROOMS = [  # id, name, theme, x range, n receptacles
    ("room_a", "kitchen", "kitchen", (0.0, 6.0), 10),
    ("room_b", "office", "office", (6.0, 12.0), 10),
    ("room_c", "workshop", "workshop", (12.0, 17.0), 8),
]
_Y_RANGE = (0.0, 5.5)


@dataclass(frozen=True)
class WallBox:
    """An axis-aligned solid box of the static structure (wall segment), min/max corners, metres."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    @property
    def box(self) -> Box:
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        return Box((lo + hi) / 2, hi - lo, np.eye(3))


@dataclass(frozen=True)
class Instance:
    """What an instance id of the rendered id image refers to.

    Attributes:
        kind: ``floor``, ``ceiling``, ``wall``, ``door``, ``receptacle`` or ``object``.
        key: the table id (``receptacle_id``, ``object_id``, ``door_id``) or a wall name.
    """

    kind: str
    key: str


@dataclass
class LabLayout:
    """Static geometry of the lab (deterministic from the seed).

    Attributes:
        rooms: the three rooms with floor polygons (wall centre lines, counter-clockwise), and in the
            ``corridor`` layout the corridor after them (no receptacles).
        doors: the two doors; their box is the doorway opening (x along the wall normal).
        receptacles: 28 receptacles, boxes with x along the wall they stand against.
        objects: the 21 object specs (ids are their names).
        walls: wall segments (solid boxes).
        door_hinges: per door, hinge position (x, y) and the swing direction (+1/-1 along x).
        dock_room: room where the robot starts every scan.
        openings: doorless passages (``two_routes``: one per inner wall; ``chain``: none;
            ``corridor``: one from each room into the corridor).
        name: the layout's name (one of :data:`LAYOUTS`).
    """

    rooms: list[Room]
    doors: list[Door]
    receptacles: list[Receptacle]
    objects: list[ObjectSpec]
    walls: list[WallBox]
    door_hinges: list[tuple[float, float, float]]
    dock_room: str = "room_b"
    receptacle_colors: list[tuple[float, float, float]] = field(default_factory=list)
    openings: list[Opening] = field(default_factory=list)
    name: str = "corridor"

    @property
    def scans_look_at_doors(self) -> bool:
        """Whether the scan route also covers the doorways (``corridor``; the older layouts keep the
        receptacle-only route their datasets were built with).
        """
        return self.name == "corridor"

    # -- lookups --------------------------------------------------------------------------------
    @property
    def receptacle_ids(self) -> list[str]:
        """Receptacle ids in layout order."""
        return [r.receptacle_id for r in self.receptacles]

    @property
    def object_ids(self) -> list[str]:
        """Object ids (names) in layout order."""
        return [o.name for o in self.objects]

    @property
    def door_ids(self) -> list[str]:
        """Door ids in layout order."""
        return [d.door_id for d in self.doors]

    @property
    def room_ids(self) -> list[str]:
        """Room ids in layout order."""
        return [r.room_id for r in self.rooms]

    @property
    def instances(self) -> dict[int, Instance]:
        """Instance id -> what it is (see the ``*_ID0`` constants)."""
        out = {ID_FLOOR: Instance("floor", "floor"), ID_CEILING: Instance("ceiling", "ceiling")}
        out.update({WALL_ID0 + k: Instance("wall", f"wall_{k:02d}") for k in range(len(self.walls))})
        out.update({DOOR_ID0 + i: Instance("door", d.door_id) for i, d in enumerate(self.doors)})
        out.update({RECEPTACLE_ID0 + i: Instance("receptacle", r.receptacle_id)
                    for i, r in enumerate(self.receptacles)})
        out.update({OBJECT_ID0 + j: Instance("object", o.name) for j, o in enumerate(self.objects)})
        return out

    def instance_id(self, key: str) -> int:
        """Instance id of a receptacle, object or door id."""
        for iid, inst in self.instances.items():
            if inst.key == key:
                return iid
        raise KeyError(f"no instance with key {key!r}")

    def room_of_point(self, xy: NDArray[np.float64]) -> str | None:
        """Room containing the (x, y) point (by floor polygon bounds), or None outside."""
        for r in self.rooms:
            p = np.asarray(r.floor_polygon_m)
            if p[:, 0].min() <= xy[0] <= p[:, 0].max() and p[:, 1].min() <= xy[1] <= p[:, 1].max():
                return r.room_id
        return None

    def room_bounds(self, room_id: str, inset_m: float = 0.0) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the room's interior (inner wall faces) shrunk by ``inset_m``."""
        p = np.asarray(next(r for r in self.rooms if r.room_id == room_id).floor_polygon_m)
        h = WALL_THICKNESS_M / 2 + inset_m
        return (p[:, 0].min() + h, p[:, 0].max() - h, p[:, 1].min() + h, p[:, 1].max() - h)

    # -- door leaves ------------------------------------------------------------------------------
    def door_leaf_box(self, i: int, is_open: bool) -> Box:
        """Box of door ``i``'s leaf: in the doorway when closed, swung 90 deg against the wall when open."""
        hx, hy, sign = self.door_hinges[i]
        w = DOOR_WIDTH_M - 0.02
        if not is_open:
            return Box(np.array([hx, hy + w / 2, DOOR_HEIGHT_M / 2 - 0.01]),
                       np.array([LEAF_THICKNESS_M, w, DOOR_HEIGHT_M - 0.03]), np.eye(3))
        return Box(np.array([hx + sign * (WALL_THICKNESS_M / 2 + w / 2), hy + LEAF_THICKNESS_M / 2 + 0.01,
                             DOOR_HEIGHT_M / 2 - 0.01]),
                   np.array([w, LEAF_THICKNESS_M, DOOR_HEIGHT_M - 0.03]), np.eye(3))

    # -- object placement -------------------------------------------------------------------------
    def object_boxes(self, placement: dict[str, str | None]) -> dict[str, Box]:
        """World boxes of the present objects given ``object_id -> receptacle_id | None``.

        Objects sharing a receptacle are spread on a grid over its top surface (in object order),
        so an object's position depends on which other objects share its receptacle.
        """
        rec = {r.receptacle_id: r for r in self.receptacles}
        by_rec: dict[str, list[int]] = {}
        for j, o in enumerate(self.objects):
            rid = placement.get(o.name)
            if rid is not None:
                by_rec.setdefault(rid, []).append(j)
        out: dict[str, Box] = {}
        for rid, js in by_rec.items():
            box = rec[rid].box
            W, D, H = np.asarray(box.extent_m)
            uw, ud = max(W - 0.16, 0.05), max(D - 0.16, 0.05)
            n = len(js)
            nx = max(1, int(np.ceil(np.sqrt(n * uw / ud))))
            ny = int(np.ceil(n / nx))
            nx = int(np.ceil(n / ny))
            for k, j in enumerate(js):
                ix, iy = k % nx, k // nx
                lx = -uw / 2 + (ix + 0.5) * uw / nx
                ly = -ud / 2 + (iy + 0.5) * ud / ny
                size = np.asarray(self.objects[j].size_m, float)
                local = np.array([lx, ly, H / 2 + size[2] / 2])
                R = np.asarray(box.rotation)
                out[self.objects[j].name] = Box(R @ local + np.asarray(box.center_m), size, R.copy())
        return out


def _opening_y(door_y: float) -> float:
    """Centre (y) of the open passage of an inner wall: at the far end of the wall from its door."""
    y0, y1 = _Y_RANGE
    mid = (y0 + y1) / 2
    margin = WALL_THICKNESS_M / 2 + 0.30 + OPENING_WIDTH_M / 2
    return y1 - margin if door_y < mid else y0 + margin


def _cut_wall(axis: int, at: float, lo: float, hi: float, gaps: list[tuple[float, float, float]]) -> list[WallBox]:
    """A wall centred on ``at`` across ``axis`` (0: the wall runs along x, 1: along y) from ``lo`` to
    ``hi``, with doorways or openings ``gaps`` ``(a, b, top)`` along it: the pieces between the gaps,
    then the lintels over them (from ``top`` to the wall height).
    """
    t, h = WALL_THICKNESS_M / 2, WALL_HEIGHT_M

    def box(a: float, b: float, z0: float) -> WallBox:
        lo3, hi3 = [at - t, at - t, z0], [at + t, at + t, h]
        lo3[axis], hi3[axis] = a, b
        return WallBox((lo3[0], lo3[1], lo3[2]), (hi3[0], hi3[1], hi3[2]))

    pieces, lintels = [], []
    for a, b, top in sorted(gaps):
        pieces.append(box(lo, a, 0.0))
        lintels.append(box(a, b, top))
        lo = b
    return [*pieces, box(lo, hi, 0.0), *lintels]


def _wall_segments(door_ys: list[float], open_ys: list[float | None], open_xs: list[float]) -> list[WallBox]:
    """The lab's walls: the outer walls (around the corridor too when there are corridor openings
    ``open_xs``), the rooms' north wall cut by those openings, and the inner walls with their doors
    and passages (``open_ys``).
    """
    t, h = WALL_THICKNESS_M / 2, WALL_HEIGHT_M
    y0, y1 = _Y_RANGE
    top = y1 + CORRIDOR_WIDTH_M if open_xs else y1
    x_all = (_ROOMS[0][3][0], _ROOMS[-1][3][1])
    walls = [
        WallBox((x_all[0] - t, y0 - t, 0.0), (x_all[1] + t, y0 + t, h)),  # south
        WallBox((x_all[0] - t, top - t, 0.0), (x_all[1] + t, top + t, h)),  # north
        WallBox((x_all[0] - t, y0 + t, 0.0), (x_all[0] + t, top - t, h)),  # west
        WallBox((x_all[1] - t, y0 + t, 0.0), (x_all[1] + t, top - t, h)),  # east
    ]
    if open_xs:  # the rooms' north wall, between them and the corridor
        walls += _cut_wall(0, y1, x_all[0] + t, x_all[1] - t,
                           [(x - OPENING_WIDTH_M / 2, x + OPENING_WIDTH_M / 2, OPENING_HEIGHT_M) for x in open_xs])
    for k, (yd, yo) in enumerate(zip(door_ys, open_ys)):
        gaps = [(yd - DOOR_WIDTH_M / 2, yd + DOOR_WIDTH_M / 2, DOOR_HEIGHT_M)]
        if yo is not None:
            gaps.append((yo - OPENING_WIDTH_M / 2, yo + OPENING_WIDTH_M / 2, OPENING_HEIGHT_M))
        walls += _cut_wall(1, _ROOMS[k][3][1], y0 + t, y1 - t, gaps)
    return walls


def _corridor_opening_xs() -> list[float]:
    """Centres (x) of the ``corridor`` layout's openings in the rooms' north wall, one per room: at the
    end of the wall farthest from the room's door (the end rooms' doors are in their inner wall), at
    the centre (the middle room).
    """
    margin = WALL_THICKNESS_M / 2 + 0.30 + OPENING_WIDTH_M / 2
    xs = []
    for k, (_, _, _, (xa, xb), _) in enumerate(_ROOMS):
        if k == 0:
            xs.append(xa + margin)
        elif k == len(_ROOMS) - 1:
            xs.append(xb - margin)
        else:
            xs.append((xa + xb) / 2)
    return xs


def _overlap(a: tuple[float, float, float, float], b: tuple[float, float, float, float], gap: float) -> bool:
    return not (a[1] + gap <= b[0] or b[1] + gap <= a[0] or a[3] + gap <= b[2] or b[3] + gap <= a[2])


def make_layout(seed: int, layout: str = "corridor") -> LabLayout:
    """Build the lab geometry from ``seed`` (door positions, furniture choice and placement).

    Args:
        seed: the lab's seed.
        layout: one of :data:`LAYOUTS` (module docstring).
    """
    if layout not in LAYOUTS:
        raise ValueError(f"layout: expected one of {LAYOUTS}, got {layout!r}")
    rng = np.random.default_rng([int(seed), 101])
    door_ys = [float(rng.uniform(1.3, 4.2)) for _ in range(len(_ROOMS) - 1)]
    open_ys: list[float | None] = [_opening_y(y) if layout == "two_routes" else None for y in door_ys]
    open_xs = _corridor_opening_xs() if layout == "corridor" else []
    walls = _wall_segments(door_ys, open_ys, open_xs)
    rooms: list[Room] = []
    y0, y1 = _Y_RANGE
    for rid, name, _, (xa, xb), _ in _ROOMS:
        rooms.append(Room(rid, name, np.array([[xa, y0], [xb, y0], [xb, y1], [xa, y1]], float)))
    if open_xs:
        xa, xb, y2 = _ROOMS[0][3][0], _ROOMS[-1][3][1], y1 + CORRIDOR_WIDTH_M
        rooms.append(Room(CORRIDOR_ID, "corridor", np.array([[xa, y1], [xb, y1], [xb, y2], [xa, y2]], float)))
    doors: list[Door] = []
    hinges: list[tuple[float, float, float]] = []
    for k, yd in enumerate(door_ys):
        x = _ROOMS[k][3][1]
        a, b = _ROOMS[k][0], _ROOMS[k + 1][0]
        doors.append(Door(f"door_{a[-1]}{b[-1]}", f"door {a[-1].upper()}-{b[-1].upper()}", a, b,
                          Box(np.array([x, yd, DOOR_HEIGHT_M / 2]),
                              np.array([WALL_THICKNESS_M + 0.04, DOOR_WIDTH_M, DOOR_HEIGHT_M]), np.eye(3))))
        hinges.append((x, yd - DOOR_WIDTH_M / 2 + 0.01, +1.0))  # leaves swing into the eastern room
    openings: list[Opening] = []
    for k, yo in enumerate(open_ys):
        if yo is None:
            continue
        x = _ROOMS[k][3][1]
        a, b = _ROOMS[k][0], _ROOMS[k + 1][0]
        openings.append(Opening(f"passage_{a[-1]}{b[-1]}", f"open passage {a[-1].upper()}-{b[-1].upper()}", a, b,
                                Box(np.array([x, yo, OPENING_HEIGHT_M / 2]),
                                    np.array([WALL_THICKNESS_M + 0.04, OPENING_WIDTH_M, OPENING_HEIGHT_M]),
                                    np.eye(3))))

    for (rid, _, _, _, _), xo in zip(_ROOMS, open_xs):
        openings.append(Opening(f"opening_{rid[-1]}", f"opening {rid[-1].upper()}-corridor", rid, CORRIDOR_ID,
                                Box(np.array([xo, y1, OPENING_HEIGHT_M / 2]),
                                    np.array([WALL_THICKNESS_M + 0.04, OPENING_WIDTH_M, OPENING_HEIGHT_M]),
                                    yaw_rotation(np.pi / 2))))

    receptacles: list[Receptacle] = []
    colors: list[tuple[float, float, float]] = []
    forbidden = []
    for k, yd in enumerate(door_ys):  # door passage and swing zones on both sides of each doorway
        x = _ROOMS[k][3][1]
        dx = 0.9 if layout == "two_routes" else 1.1  # two_routes: room for the passages' zones too
        forbidden.append((x - dx, x + dx, yd - 0.75, yd + 0.75))
    for k, yo in enumerate(open_ys):  # and in front of the open passages
        if yo is not None:
            forbidden.append((_ROOMS[k][3][1] - 0.9, _ROOMS[k][3][1] + 0.9, yo - 0.65, yo + 0.65))
    for xo in open_xs:  # and in front of the corridor openings
        forbidden.append((xo - 0.65, xo + 0.65, y1 - 0.9, y1 + 0.9))
    for rid, name, theme, (xa, xb), n in _ROOMS:
        cats = list(ROOM_FURNITURE[theme])
        rng.shuffle(cats)
        cats = (cats * 2)[:n]
        for _room_try in range(50):  # a draw that does not fit (rare) is redrawn from the same stream
            got = _place_room(rng, rid, name, (xa, xb), cats, forbidden)
            if got is not None:
                receptacles += got[0]
                colors += got[1]
                break
        else:  # pragma: no cover - the room sizes leave ample space
            raise RuntimeError(f"could not place the furniture of {rid}")
    return LabLayout(rooms, doors, receptacles, list(OBJECTS), walls, hinges, "room_b", colors, openings, layout)


def _place_room(rng: np.random.Generator, rid: str, name: str, x_range: tuple[float, float], cats: list[str],
                forbidden: list[tuple[float, float, float, float]]
                ) -> tuple[list[Receptacle], list[tuple[float, float, float]]] | None:
    """Receptacles (and colours) of one room against its walls, outside ``forbidden``; None if one does not fit."""
    t = WALL_THICKNESS_M / 2
    ix0, ix1, iy0, iy1 = x_range[0] + t, x_range[1] - t, _Y_RANGE[0] + t, _Y_RANGE[1] - t
    placed: list[tuple[float, float, float, float]] = list(forbidden)
    receptacles: list[Receptacle] = []
    colors: list[tuple[float, float, float]] = []
    for cat in sorted(cats, key=lambda c: -FURNITURE[c].width_m):
        spec = FURNITURE[cat]
        w, d = spec.width_m, spec.depth_m
        for _attempt in range(2000):
            side = int(rng.integers(4))
            if side in (0, 1):  # south / north wall: width along x
                cx = float(rng.uniform(ix0 + w / 2 + 0.05, ix1 - w / 2 - 0.05))
                cy = iy0 + d / 2 + 0.03 if side == 0 else iy1 - d / 2 - 0.03
                yaw = 0.0 if side == 0 else np.pi
                fp = (cx - w / 2, cx + w / 2, cy - d / 2, cy + d / 2)
            else:  # west / east wall: width along y
                cy = float(rng.uniform(iy0 + w / 2 + 0.05, iy1 - w / 2 - 0.05))
                cx = ix0 + d / 2 + 0.03 if side == 2 else ix1 - d / 2 - 0.03
                yaw = -np.pi / 2 if side == 2 else np.pi / 2
                fp = (cx - d / 2, cx + d / 2, cy - w / 2, cy + w / 2)
            if any(_overlap(fp, q, 0.15) for q in placed):
                continue
            placed.append(fp)
            count = len(receptacles) + 1
            receptacles.append(Receptacle(
                f"{rid[-1]}{count:02d}_{cat}", f"{cat.replace('_', ' ')} {count} ({name})", rid,
                Box(np.array([cx, cy, spec.height_m / 2]), np.array([w, d, spec.height_m]), yaw_rotation(yaw)),
                cat))
            jitter = rng.uniform(-0.06, 0.06, 3)
            c0, c1, c2 = (float(c) for c in np.clip(np.asarray(spec.color) + jitter, 0.05, 0.95))
            colors.append((c0, c1, c2))
            break
        else:
            return None
    return receptacles, colors
