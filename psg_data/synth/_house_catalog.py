"""Catalogue of the procedural houses: room kinds, receptacles by room kind, pickupables, affinities.

Names are AI2-THOR object types (``Shelf`` is AI2-THOR's ``ShelvingUnit``). Sizes are ordinary
furniture sizes in metres (width along the wall, depth, height).

**Affinity table** (object type x receptacle category), the relationship between "pickupable" and
"receptacle" objects the paper's schedules are weighted by (appendix "Hierarchical Scheduling
Model", following Kurenkov et al. 2023). Two public sources, combined by one documented rule:

* ``PROCTHOR_P[o][c]``: ProcTHOR's placement prior, ``procthor/databases/receptacles.json`` in the
  ``allenai/procthor`` repository: for receptacle type ``c`` the share ``p`` of its instances in
  the AI2-THOR scenes that hold an object of type ``o`` (rounded to 3 decimals here, kept only for
  the categories below; ``ShelvingUnit``'s numbers are used for ``Shelf``);
* ``COMPATIBLE[o]``: the "Default Compatible Receptacles" column of the AI2-THOR documentation page
  "Object Types" (https://ai2thor.allenai.org/ithor/documentation/objects/object-types), restricted
  to the categories below (the rows the documentation search showed, e.g. AlarmClock, were read
  there; the others from a public transcription of the same table that agrees with those rows).

The weight of receptacle category ``c`` for object type ``o`` is

    ``affinity(o, c) = PROCTHOR_P[o].get(c, 0) + EPSILON * (c in COMPATIBLE[o])``, ``EPSILON = 0.01``:

ProcTHOR's observed placement frequency, plus a floor of one placement in a hundred receptacles for
every pair AI2-THOR declares compatible but ProcTHOR's scenes never show; a pair neither source
lists gets 0 (the object is never put there). A house receptacle of category ``c`` gets the
weight of ``c``; the generator normalises the weights over the house's receptacles.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ROOM_KINDS", "RECEPTACLE_SIZES", "ROOM_RECEPTACLES", "PICKUPABLES", "PROCTHOR_P", "COMPATIBLE",
           "EPSILON", "affinity", "ReceptacleSize"]

ROOM_KINDS = ("kitchen", "living_room", "bedroom", "bathroom", "office", "hallway")
"""Room kinds of a house (AI2-THOR's four scene kinds plus office and hallway)."""


@dataclass(frozen=True)
class ReceptacleSize:
    """Full box size of a receptacle category: width along the wall, depth, height (metres)."""

    width_m: float
    depth_m: float
    height_m: float


RECEPTACLE_SIZES: dict[str, ReceptacleSize] = {
    "CounterTop": ReceptacleSize(1.80, 0.60, 0.90),
    "DiningTable": ReceptacleSize(1.40, 0.90, 0.75),
    "SideTable": ReceptacleSize(0.50, 0.45, 0.55),
    "CoffeeTable": ReceptacleSize(1.00, 0.55, 0.45),
    "TVStand": ReceptacleSize(1.40, 0.45, 0.55),
    "Sofa": ReceptacleSize(2.00, 0.90, 0.45),
    "ArmChair": ReceptacleSize(0.80, 0.80, 0.45),
    "Desk": ReceptacleSize(1.30, 0.65, 0.75),
    "Dresser": ReceptacleSize(1.20, 0.50, 0.90),
    "Bed": ReceptacleSize(2.00, 1.60, 0.55),
    "Shelf": ReceptacleSize(0.90, 0.40, 1.20),
    "Toilet": ReceptacleSize(0.45, 0.70, 0.40),
}

ROOM_RECEPTACLES: dict[str, tuple[str, ...]] = {
    # room kind -> receptacle categories in the order they are furnished (the first ones always,
    # the rest while the room's area allows: one receptacle per 3.5 m2, at least 2)
    "kitchen": ("CounterTop", "DiningTable", "CounterTop", "Shelf", "SideTable"),
    "living_room": ("Sofa", "CoffeeTable", "TVStand", "ArmChair", "SideTable", "Shelf", "DiningTable"),
    "bedroom": ("Bed", "SideTable", "Dresser", "Desk", "ArmChair", "Shelf"),
    "bathroom": ("CounterTop", "Toilet", "Shelf"),
    "office": ("Desk", "Shelf", "ArmChair", "SideTable"),
    "hallway": ("SideTable", "Shelf", "Dresser"),
}

EPSILON = 0.01
"""Weight floor of a pair AI2-THOR declares compatible (module docstring)."""

_TABLES = ("DiningTable", "TVStand", "CoffeeTable", "SideTable", "CounterTop")
_SURFACES = ("Dresser", "Desk", *_TABLES, "Shelf")
_SEATS = ("Sofa", "ArmChair")

COMPATIBLE: dict[str, tuple[str, ...]] = {
    "AlarmClock": _SURFACES,
    "Apple": ("DiningTable", "TVStand", "CoffeeTable", "SideTable", "Desk", "CounterTop", "Dresser"),
    "Book": (*_SEATS, "Bed", *_SURFACES),
    "Bowl": _SURFACES,
    "Candle": ("Toilet", *_SURFACES),
    "CellPhone": (*_SEATS, "Bed", *_SURFACES),
    "CreditCard": (*_SEATS, *_SURFACES),
    "Cup": _SURFACES,
    "KeyChain": (*_SEATS, *_SURFACES),
    "Laptop": (*_SEATS, "Bed", "Dresser", "Desk", *_TABLES),
    "Mug": (*_TABLES, "Shelf"),
    "Newspaper": (*_SEATS, "Bed", "Toilet", *_SURFACES),
    "Pen": _SURFACES,
    "Pencil": _SURFACES,
    "Pillow": (*_SEATS, "Bed"),
    "Plate": _SURFACES,
    "RemoteControl": (*_SEATS, *_SURFACES),
    "SoapBottle": ("Toilet", *_SURFACES),
    "SprayBottle": ("Toilet", *_SURFACES),
    "Statue": _SURFACES,
    "TeddyBear": ("Bed", *_SEATS, "Dresser", "Desk", *_TABLES),
    "TissueBox": ("Toilet", *_SURFACES),
    "ToiletPaper": ("Toilet", *_SURFACES),
    "Vase": _SURFACES,
    "Watch": _SURFACES,
    "WineBottle": _SURFACES,
}

PROCTHOR_P: dict[str, dict[str, float]] = {
    "AlarmClock": {"ArmChair": .007, "Bed": .012, "CoffeeTable": .059, "Desk": .079, "DiningTable": .012,
                   "Dresser": .120, "Shelf": .053, "SideTable": .226, "Sofa": .013, "TVStand": .105},
    "Apple": {"ArmChair": .007, "Bed": .037, "CoffeeTable": .079, "CounterTop": .158, "Desk": .158,
              "DiningTable": .238, "Shelf": .026, "SideTable": .084, "Sofa": .039, "TVStand": .026},
    "Book": {"ArmChair": .092, "Bed": .183, "CoffeeTable": .238, "CounterTop": .020, "Desk": .474,
             "DiningTable": .179, "Dresser": .253, "Shelf": .053, "SideTable": .077, "Sofa": .079, "TVStand": .026},
    "Bowl": {"ArmChair": .021, "CoffeeTable": .188, "CounterTop": .188, "Desk": .184, "DiningTable": .357,
             "Dresser": .053, "SideTable": .066, "TVStand": .079},
    "Candle": {"CoffeeTable": .050, "CounterTop": .119, "DiningTable": .060, "Dresser": .080, "SideTable": .036,
               "TVStand": .105, "Toilet": .100},
    "CellPhone": {"ArmChair": .028, "Bed": .061, "CoffeeTable": .099, "CounterTop": .020, "Desk": .237,
                  "DiningTable": .048, "Dresser": .133, "SideTable": .051, "Sofa": .013, "TVStand": .026},
    "CreditCard": {"CoffeeTable": .129, "CounterTop": .030, "Desk": .250, "DiningTable": .048, "Dresser": .080,
                   "SideTable": .033, "TVStand": .105},
    "Cup": {"CoffeeTable": .079, "CounterTop": .158, "Desk": .079, "DiningTable": .143, "Dresser": .067,
            "SideTable": .073, "TVStand": .053},
    "KeyChain": {"ArmChair": .028, "CoffeeTable": .089, "Desk": .224, "DiningTable": .024, "Dresser": .040,
                 "SideTable": .066, "TVStand": .079},
    "Laptop": {"ArmChair": .077, "Bed": .220, "CoffeeTable": .188, "Desk": .434, "DiningTable": .238,
               "Dresser": .107, "SideTable": .022, "Sofa": .197, "TVStand": .053},
    "Mug": {"CoffeeTable": .129, "CounterTop": .129, "Desk": .250, "DiningTable": .238, "Dresser": .053,
            "SideTable": .120, "TVStand": .053},
    "Newspaper": {"ArmChair": .014, "CoffeeTable": .030, "Desk": .026, "DiningTable": .060, "Dresser": .040,
                  "Shelf": .026, "SideTable": .018, "Sofa": .105, "TVStand": .026},
    "Pen": {"CoffeeTable": .040, "CounterTop": .010, "Desk": .316, "DiningTable": .048, "Dresser": .093,
            "SideTable": .036},
    "Pencil": {"CoffeeTable": .030, "CounterTop": .010, "Desk": .342, "DiningTable": .083, "Dresser": .093,
               "SideTable": .044, "Sofa": .013, "TVStand": .026},
    "Pillow": {"ArmChair": .148, "Bed": 1.000, "SideTable": .004, "Sofa": .645},
    "Plate": {"CoffeeTable": .109, "CounterTop": .149, "Desk": .079, "DiningTable": .393, "Dresser": .013,
              "SideTable": .033, "TVStand": .026},
    "RemoteControl": {"ArmChair": .085, "Bed": .037, "CoffeeTable": .218, "Desk": .092, "DiningTable": .083,
                      "Dresser": .107, "SideTable": .062, "Sofa": .171, "TVStand": .184},
    "SoapBottle": {"CounterTop": .505, "SideTable": .011, "Toilet": .033},
    "SprayBottle": {"CoffeeTable": .069, "CounterTop": .089, "Desk": .053, "DiningTable": .048, "Dresser": .107,
                    "Shelf": .053, "SideTable": .047, "Toilet": .200},
    "Statue": {"CoffeeTable": .168, "CounterTop": .010, "Desk": .079, "DiningTable": .155, "Dresser": .107,
               "Shelf": .053, "SideTable": .073, "TVStand": .079},
    "TeddyBear": {"ArmChair": .007, "Bed": .122, "Desk": .013, "SideTable": .007},
    "TissueBox": {"CoffeeTable": .030, "CounterTop": .040, "Desk": .026, "Dresser": .013, "SideTable": .022,
                  "TVStand": .026},
    "ToiletPaper": {"CounterTop": .129, "Toilet": .733},
    "Vase": {"CoffeeTable": .168, "CounterTop": .030, "Desk": .079, "DiningTable": .155, "Dresser": .147,
             "Shelf": .132, "SideTable": .091, "TVStand": .105},
    "Watch": {"CoffeeTable": .059, "Desk": .039, "DiningTable": .012, "Dresser": .013, "SideTable": .022,
              "TVStand": .079},
    "WineBottle": {"CounterTop": .050, "DiningTable": .036},
}

PICKUPABLES: tuple[str, ...] = tuple(sorted(COMPATIBLE))
"""The pickupable object types a house draws its objects from."""


def affinity(object_type: str, category: str) -> float:
    """Weight of receptacle ``category`` for ``object_type`` (the module docstring's rule); 0 = never there."""
    p = PROCTHOR_P.get(object_type, {}).get(category, 0.0)
    return float(p + (EPSILON if category in COMPATIBLE.get(object_type, ()) else 0.0))
