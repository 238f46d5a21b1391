"""The lab geometry: counts, names, furniture sizes, no overlaps, free floor for the robot."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from scipy import ndimage

import psg_data.synth as synth
from psg_data.synth import FURNITURE, OBJECTS, make_layout

PAPER_OBJECTS = ("greenbowl bell panda penguin redbowl bluecup yellowcup greencube bluecube headphones duck egg "
                 "carrot hairbrush redbottle redmug redplate woodenspoon spoon spatula blueball").split()


def test_public_names_exported() -> None:
    assert set(synth.__all__) <= set(dir(synth))
    for name in synth.__all__:
        assert getattr(synth, name) is not None


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_counts_and_names(seed: int) -> None:
    L = make_layout(seed)
    assert [r.room_id for r in L.rooms] == ["room_a", "room_b", "room_c", "corridor"] and len(L.doors) == 2
    assert sorted(Counter(r.room_id for r in L.receptacles).values()) == [8, 10, 10]
    assert [o.name for o in L.objects] == PAPER_OBJECTS
    assert len({r.receptacle_id for r in L.receptacles}) == 28
    for o in OBJECTS:
        assert len(o.size_m) == 3 and all(0.01 < s < 0.4 for s in o.size_m) and o.description
        assert all(0.0 <= c <= 1.0 for c in o.color)
    roles = Counter(o.role for o in OBJECTS)
    assert roles["static"] >= 3 and roles["dynamic"] >= 3 and roles["absent"] >= 2


@pytest.mark.parametrize("seed", [0, 5])
def test_receptacles_real_sizes_inside_rooms_no_overlap(seed: int) -> None:
    L = make_layout(seed)
    rooms = {r.room_id: np.asarray(r.floor_polygon_m) for r in L.rooms}
    fps = []
    for r in L.receptacles:
        spec = FURNITURE[r.category]
        assert sorted(r.box.extent_m) == pytest.approx(sorted([spec.width_m, spec.depth_m, spec.height_m]))
        c = r.box.corners()
        assert c[:, 2].min() == pytest.approx(0.0, abs=1e-9)  # stands on the floor
        assert c[:, 2].max() <= 1.1  # top reachable/seeable from a 1.25 m camera
        poly = rooms[r.room_id]
        assert poly[:, 0].min() < c[:, 0].min() and c[:, 0].max() < poly[:, 0].max()
        assert poly[:, 1].min() < c[:, 1].min() and c[:, 1].max() < poly[:, 1].max()
        fps.append((c[:, 0].min(), c[:, 0].max(), c[:, 1].min(), c[:, 1].max()))
    for i in range(len(fps)):
        for j in range(i + 1, len(fps)):
            a, b = fps[i], fps[j]
            overlap = a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]
            assert not overlap, (L.receptacles[i].receptacle_id, L.receptacles[j].receptacle_id)


def test_free_floor_connects_rooms_through_doorways() -> None:
    """A 0.6 m wide robot can drive from the dock room to every room centre (occupancy grid BFS)."""
    L = make_layout(0)
    res = 0.05
    xs = np.arange(-0.5, 17.5, res)
    ys = np.arange(-0.5, 7.5, res)  # the rooms (y 0-5.5) and the corridor north of them
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, 0.3)])
    occ = np.zeros(X.size, bool)
    for w in L.walls:
        occ |= w.box.contains(pts)
    for r in L.receptacles:
        occ |= r.box.contains(pts)
    occ = occ.reshape(X.shape)
    free = ~ndimage.binary_dilation(occ, iterations=int(0.3 / res))
    lab, _ = ndimage.label(free)

    def cell(x: float, y: float) -> int:
        return int(lab[int(round((x + 0.5) / res)), int(round((y + 0.5) / res))])

    centres = [np.asarray(r.floor_polygon_m).mean(axis=0) for r in L.rooms]
    ids = {cell(*c) for c in centres}
    assert len(ids) == 1 and 0 not in ids


def test_objects_rest_on_receptacle_tops() -> None:
    L = make_layout(2)
    recs = {r.receptacle_id: r for r in L.receptacles}
    placement = {o.name: L.receptacles[(7 * j) % 5].receptacle_id for j, o in enumerate(L.objects)}
    placement["egg"] = None
    boxes = L.object_boxes(placement)
    assert "egg" not in boxes and len(boxes) == 20
    for name, b in boxes.items():
        rb = recs[placement[name]].box
        top = rb.center_m[2] + rb.extent_m[2] / 2
        assert b.corners()[:, 2].min() == pytest.approx(top)
        assert rb.contains(np.array([[b.center_m[0], b.center_m[1], top - 0.01]]))[0]
