"""Static catalogue of the synthetic lab: furniture categories, the paper's 21 objects, affinities.

Sizes are real-world furniture and object sizes in metres; colours are sRGB in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FurnitureSpec", "ObjectSpec", "FURNITURE", "OBJECTS", "ROOM_FURNITURE", "AFFINITY", "CONFUSABLE"]


@dataclass(frozen=True)
class FurnitureSpec:
    """A furniture category: full box size (width along the wall, depth, height) in metres."""

    category: str
    width_m: float
    depth_m: float
    height_m: float
    color: tuple[float, float, float]


@dataclass(frozen=True)
class ObjectSpec:
    """One of the 21 objects of the paper's real-world dataset.

    Attributes:
        name: object name as in the paper (also its ``object_id``).
        kind: affinity class (``dish``, ``utensil``, ``food``, ``toy``, ``personal``).
        shape: ``cylinder``, ``box`` or ``sphere`` (rendering primitive).
        size_m: (x, y, z) bounding size, metres (cylinders/spheres: diameter, diameter, height).
        color: sRGB in [0, 1].
        role: ``static`` (never moves), ``dynamic`` (moves, always present) or ``absent``
            (moves and is sometimes absent from the lab).
        description: short free-text description.
    """

    name: str
    kind: str
    shape: str
    size_m: tuple[float, float, float]
    color: tuple[float, float, float]
    role: str
    description: str


FURNITURE: dict[str, FurnitureSpec] = {f.category: f for f in [
    FurnitureSpec("table", 1.20, 0.75, 0.75, (0.62, 0.45, 0.28)),
    FurnitureSpec("desk", 1.40, 0.70, 0.74, (0.80, 0.78, 0.72)),
    FurnitureSpec("counter", 1.80, 0.60, 0.90, (0.55, 0.57, 0.60)),
    FurnitureSpec("cabinet", 0.80, 0.50, 0.90, (0.35, 0.40, 0.50)),
    FurnitureSpec("shelf", 0.90, 0.40, 1.05, (0.70, 0.60, 0.45)),
    FurnitureSpec("chair", 0.46, 0.46, 0.46, (0.20, 0.25, 0.55)),
    FurnitureSpec("bin", 0.40, 0.40, 0.50, (0.25, 0.45, 0.25)),
    FurnitureSpec("side_table", 0.50, 0.50, 0.55, (0.50, 0.32, 0.22)),
    FurnitureSpec("coffee_table", 1.00, 0.55, 0.45, (0.40, 0.28, 0.20)),
    FurnitureSpec("stool", 0.40, 0.40, 0.62, (0.60, 0.20, 0.20)),
    FurnitureSpec("cart", 0.80, 0.50, 0.85, (0.65, 0.65, 0.68)),
    FurnitureSpec("workbench", 1.60, 0.75, 0.90, (0.55, 0.50, 0.30)),
]}

ROOM_FURNITURE: dict[str, list[str]] = {
    # room theme -> categories drawn for its receptacles (cycled, then shuffled)
    "kitchen": ["counter", "table", "cabinet", "shelf", "chair", "bin", "coffee_table", "side_table", "cart",
                "chair", "stool"],
    "office": ["desk", "desk", "chair", "shelf", "cabinet", "table", "bin", "side_table", "chair", "stool"],
    "workshop": ["workbench", "shelf", "cart", "cabinet", "stool", "table", "bin", "counter"],
}

_R, _G, _B, _Y = (0.85, 0.12, 0.12), (0.15, 0.70, 0.20), (0.15, 0.30, 0.85), (0.95, 0.85, 0.10)

OBJECTS: list[ObjectSpec] = [
    ObjectSpec("greenbowl", "dish", "cylinder", (0.16, 0.16, 0.07), _G, "dynamic", "green plastic bowl"),
    ObjectSpec("bell", "toy", "cylinder", (0.09, 0.09, 0.10), (0.85, 0.70, 0.25), "static", "small brass desk bell"),
    ObjectSpec("panda", "toy", "box", (0.14, 0.12, 0.18), (0.92, 0.92, 0.92), "static", "plush panda toy"),
    ObjectSpec("penguin", "toy", "box", (0.12, 0.12, 0.17), (0.10, 0.10, 0.12), "static", "plush penguin toy"),
    ObjectSpec("redbowl", "dish", "cylinder", (0.16, 0.16, 0.07), _R, "dynamic", "red plastic bowl"),
    ObjectSpec("bluecup", "dish", "cylinder", (0.08, 0.08, 0.10), _B, "dynamic", "blue plastic cup"),
    ObjectSpec("yellowcup", "dish", "cylinder", (0.08, 0.08, 0.10), _Y, "dynamic", "yellow plastic cup"),
    ObjectSpec("greencube", "toy", "box", (0.07, 0.07, 0.07), _G, "dynamic", "green toy cube"),
    ObjectSpec("bluecube", "toy", "box", (0.07, 0.07, 0.07), _B, "static", "blue toy cube"),
    ObjectSpec("headphones", "personal", "box", (0.18, 0.16, 0.08), (0.15, 0.15, 0.15), "absent",
               "black over-ear headphones"),
    ObjectSpec("duck", "toy", "sphere", (0.10, 0.10, 0.10), (0.98, 0.90, 0.15), "static", "yellow rubber duck"),
    ObjectSpec("egg", "food", "sphere", (0.05, 0.05, 0.06), (0.96, 0.94, 0.86), "static", "toy egg"),
    ObjectSpec("carrot", "food", "box", (0.18, 0.04, 0.04), (0.95, 0.50, 0.10), "absent", "toy carrot"),
    ObjectSpec("hairbrush", "personal", "box", (0.22, 0.06, 0.04), (0.55, 0.30, 0.60), "dynamic", "purple hairbrush"),
    ObjectSpec("redbottle", "dish", "cylinder", (0.07, 0.07, 0.22), _R, "static", "red water bottle"),
    ObjectSpec("redmug", "dish", "cylinder", (0.09, 0.09, 0.10), (0.75, 0.10, 0.15), "dynamic", "red ceramic mug"),
    ObjectSpec("redplate", "dish", "cylinder", (0.22, 0.22, 0.025), (0.90, 0.18, 0.15), "dynamic", "red plate"),
    ObjectSpec("woodenspoon", "utensil", "box", (0.30, 0.05, 0.02), (0.72, 0.55, 0.32), "dynamic",
               "wooden cooking spoon"),
    ObjectSpec("spoon", "utensil", "box", (0.17, 0.04, 0.02), (0.80, 0.80, 0.82), "absent", "metal spoon"),
    ObjectSpec("spatula", "utensil", "box", (0.30, 0.07, 0.02), (0.20, 0.20, 0.20), "dynamic", "black spatula"),
    ObjectSpec("blueball", "toy", "sphere", (0.12, 0.12, 0.12), _B, "absent", "blue ball"),
]

AFFINITY: dict[str, dict[str, float]] = {
    # object kind -> receptacle category -> weight (ProcTHOR-style pickupable/receptacle relation)
    "dish": {"counter": 3, "table": 3, "coffee_table": 2, "desk": 1.5, "cabinet": 1.5, "shelf": 1,
             "side_table": 1, "cart": 1, "workbench": 0.5, "stool": 0.3, "chair": 0.2, "bin": 0.1},
    "utensil": {"counter": 3, "table": 2, "cabinet": 2, "cart": 1.5, "shelf": 1, "workbench": 1, "desk": 0.5,
                "side_table": 0.3, "coffee_table": 0.3, "bin": 0.2},
    "food": {"counter": 3, "table": 2, "cabinet": 1, "coffee_table": 1, "cart": 1, "shelf": 0.5, "bin": 0.5,
             "side_table": 0.5, "desk": 0.3},
    "toy": {"shelf": 3, "desk": 2, "coffee_table": 2, "table": 1.5, "side_table": 1.5, "chair": 1, "bin": 1,
            "stool": 1, "workbench": 0.5, "cabinet": 0.5, "cart": 0.5, "counter": 0.3},
    "personal": {"desk": 3, "table": 2, "side_table": 2, "chair": 1.5, "shelf": 1.5, "cabinet": 1, "stool": 1,
                 "coffee_table": 1, "counter": 0.3},
}

CONFUSABLE: dict[str, tuple[str, ...]] = {
    # objects a detector mistakes for each other (similar shape and colour)
    "redbowl": ("redplate",), "redplate": ("redbowl",),
    "bluecup": ("yellowcup",), "yellowcup": ("bluecup",),
    "greencube": ("bluecube",), "bluecube": ("greencube",),
    "spoon": ("woodenspoon",), "woodenspoon": ("spoon", "spatula"), "spatula": ("woodenspoon",),
    "redmug": ("redbottle",), "redbottle": ("redmug",),
    "panda": ("penguin",), "penguin": ("panda",),
    "greenbowl": ("redbowl",), "blueball": ("duck",), "duck": ("blueball",),
}
