"""Occupancy grids: polygons, walls, doors, inflation, point clouds, Bresenham lines."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.navigation import (
    OccupancyGrid,
    astar,
    box_footprint,
    bresenham,
    grid_from_geometry,
    grid_from_points,
    line_of_sight,
    points_in_polygon,
)
from psg_data.schemas import Box, Door, Receptacle, Room


def test_points_in_polygon_matches_matplotlib():
    from matplotlib.path import Path as MPath

    rng = np.random.default_rng(0)
    poly = np.array([[0, 0], [4, 0], [4, 1], [1.5, 1.2], [2, 3], [0, 3.0]])  # concave
    pts = rng.uniform(-1, 5, (4000, 2))
    ours = points_in_polygon(pts, poly)
    ref = MPath(poly).contains_points(pts)
    assert np.mean(ours == ref) == 1.0


def test_box_footprint_of_rotated_box():
    a = 0.5
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    fp = box_footprint(Box(np.array([1.0, 2.0, 0.5]), np.array([2.0, 1.0, 1.0]), R))
    assert fp.shape == (4, 2)
    x, y = fp[:, 0], fp[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1)))
    assert area == pytest.approx(2.0)
    assert fp.mean(axis=0) == pytest.approx([1.0, 2.0])


@settings(max_examples=60, deadline=None)
@given(st.integers(-30, 30), st.integers(-30, 30), st.integers(-30, 30), st.integers(-30, 30))
def test_bresenham_properties(i0, j0, i1, j1):
    line = bresenham((i0, j0), (i1, j1))
    assert tuple(line[0]) == (i0, j0) and tuple(line[-1]) == (i1, j1)
    n = max(abs(i1 - i0), abs(j1 - j0))
    assert len(line) == n + 1
    if n:
        steps = np.abs(np.diff(line, axis=0))
        assert np.all(steps.max(axis=1) == 1)  # 8-connected, one cell per step along the major axis
        # every cell lies within half a cell of the ideal line, along the minor axis
        t = np.arange(n + 1) / n
        ideal = np.array([i0, j0]) + t[:, None] * np.array([i1 - i0, j1 - j0])
        assert np.all(np.abs(line - ideal) <= 0.5 + 1e-12)


def test_bresenham_matches_textbook_on_first_octant():
    def textbook(x0, y0, x1, y1):  # classic integer Bresenham for 0 <= dy <= dx
        dx, dy = x1 - x0, y1 - y0
        D = 2 * dy - dx
        y = y0
        out = []
        for x in range(x0, x1 + 1):
            out.append((x, y))
            if D > 0:
                y += 1
                D -= 2 * dx
            D += 2 * dy
        return out

    rng = np.random.default_rng(1)
    for _ in range(200):
        dx = int(rng.integers(1, 40))
        dy = int(rng.integers(0, dx + 1))
        ref = textbook(0, 0, dx, dy)
        ours = [tuple(int(v) for v in c) for c in bresenham((0, 0), (dx, dy))]
        # rows are the major axis here; the textbook breaks exact ties downwards, we round half up
        for (x, y), (a, b) in zip(ref, ours):
            assert a == x and abs(b - y) <= 1
            if (2 * x * dy) % (2 * dx) != dx:  # no tie: identical
                assert b == y


def test_line_of_sight():
    blocked = np.zeros((5, 5), dtype=bool)
    blocked[2, 2] = True
    assert not line_of_sight(blocked, (0, 0), (4, 4))[0]
    assert line_of_sight(blocked, (0, 0), (0, 4))[0]
    assert line_of_sight(blocked, (2, 2), (2, 4))[0]  # end cells are not tested


def two_rooms(door: bool = True) -> tuple[list[Room], list[Receptacle], list[Door]]:
    rooms = [Room("a", "A", np.array([[0, 0], [3, 0], [3, 2], [0, 2.0]])),
             Room("b", "B", np.array([[3, 0], [6, 0], [6, 2], [3, 2.0]]))]
    recs = [Receptacle("r1", "r1", "a", Box(np.array([0.5, 1.0, 0.4]), np.array([0.4, 0.4, 0.8]))),
            Receptacle("r2", "r2", "b", Box(np.array([5.5, 1.0, 0.4]), np.array([0.4, 0.4, 0.8])))]
    doors = [Door("d", "d", "a", "b", Box(np.array([3.0, 1.0, 1.0]), np.array([0.14, 0.8, 2.0])))] if door else []
    return rooms, recs, doors


def test_geometry_grid_walls_doors_and_connectivity():
    rooms, recs, doors = two_rooms()
    g = grid_from_geometry(rooms, recs, doors, resolution_m=0.05, robot_radius_m=0.2)
    assert g.door_ids == ("d",)
    a = tuple(g.world_to_cell([1.5, 1.0]))
    b = tuple(g.world_to_cell([4.5, 1.0]))
    opened, closed = g.free({"d": True}), g.free({"d": False})
    assert opened[a] and opened[b] and closed[a] and closed[b]
    # wall on the shared edge: only the doorway connects the rooms
    r_open = astar(opened, a, b, g.resolution_m)
    assert r_open.found and r_open.length_m == pytest.approx(3.0, abs=0.06)
    assert math.isinf(astar(closed, a, b, g.resolution_m).length_m)
    # outside the polygons is blocked
    assert g.static_obstacle[tuple(g.world_to_cell([-0.2, 1.0]))]
    # receptacles are obstacles; cell/world round trip
    assert g.static_obstacle[tuple(g.world_to_cell([0.5, 1.0]))]
    c = g.world_to_cell(np.array([[1.23, 0.77]]))
    assert np.all(np.abs(g.cell_to_world(c) - [1.23, 0.77]) <= g.resolution_m / 2 + 1e-12)


def test_inflation_matches_brute_force():
    rng = np.random.default_rng(3)
    obs = rng.random((18, 22)) < 0.08
    g = OccupancyGrid(obs, np.array([0.0, 0.0]), 0.1, 0.25)
    free = g.free(())
    oi = np.argwhere(obs)
    for i in range(18):
        for j in range(22):
            d = np.sqrt(((oi - [i, j]) ** 2).sum(axis=1)).min() * 0.1
            assert free[i, j] == (d > 0.25)


def test_doorway_narrower_than_robot_is_blocked():
    rooms, recs, doors = two_rooms()
    g = grid_from_geometry(rooms, recs, doors, resolution_m=0.05, robot_radius_m=0.45)  # 0.8 m door
    a, b = tuple(g.world_to_cell([1.5, 1.0])), tuple(g.world_to_cell([4.5, 1.0]))
    assert math.isinf(astar(g.free({"d": True}), a, b, 0.05).length_m)


def test_rooms_without_polygons_fall_back_to_bounding_box():
    rooms = [Room("a", "A"), Room("b", "B")]
    _, recs, doors = two_rooms()
    g = grid_from_geometry(rooms, recs, doors, resolution_m=0.1, robot_radius_m=0.1)
    a, b = tuple(g.world_to_cell([1.5, 1.0])), tuple(g.world_to_cell([4.5, 1.0]))
    assert astar(g.free({"d": False}), a, b, 0.1).found  # no walls, so the door does not matter


def test_grid_from_points():
    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(0, 4, 40000), rng.uniform(0, 2, 40000), rng.normal(0, 0.01, 40000)])
    wall = np.column_stack([np.full(4000, 2.0), rng.uniform(0, 1.4, 4000), rng.uniform(0.1, 2.0, 4000)])
    g = grid_from_points(np.concatenate([floor, wall]), resolution_m=0.1, robot_radius_m=0.15,
                         floor_band_m=(-0.05, 0.05), obstacle_band_m=(0.1, 1.6))
    free = g.free(())
    a, b = tuple(g.world_to_cell([1.0, 0.5])), tuple(g.world_to_cell([3.0, 0.5]))
    assert free[a] and free[b]
    assert g.static_obstacle[tuple(g.world_to_cell([2.0, 0.5]))]
    assert g.static_obstacle[tuple(g.world_to_cell([4.3, 0.5]))]  # unobserved padding is blocked
    r = astar(free, a, b, 0.1)
    assert r.found and r.length_m > 2.0 + 2 * 0.5  # must go around the wall's end at y = 1.4


@pytest.mark.slow
def test_grid_from_scans_of_a_dataset(tmp_path):
    """A camera 1.2 m above the floor looking straight down sees floor (free) cells below it."""
    from psg_data.loaders import open_dataset
    from psg_data.navigation import grid_from_scans
    from psg_data.schemas import CameraIntrinsics
    from psg_data.writers import DatasetWriter

    cam = CameraIntrinsics("cam", 40, 30, 30.0, 30.0, 19.5, 14.5)
    with DatasetWriter(tmp_path / "ds", timezone="UTC") as w:
        w.add_camera(cam)
        rooms, recs, doors = two_rooms()
        w.set_rooms(rooms)
        w.set_receptacles(recs)
        with w.scan("s0") as sw:
            for k, x in enumerate(np.arange(1.0, 5.01, 0.25)):
                T = np.eye(4)
                T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # optical axis down (world -z)
                T[:3, 3] = [x, 1.0, 1.2]
                sw.add_frame(10**18 + k * 10**8, T, np.zeros((30, 40, 3), np.uint8),
                             np.full((30, 40), 1200, np.uint16), "cam")
    ds = open_dataset(tmp_path / "ds")
    g = grid_from_scans(ds, pixel_stride=1, voxel_size_m=None, resolution_m=0.05, robot_radius_m=0.1)
    assert g.source == "scans" and set(g.receptacle_cells) == {"r1", "r2"}
    free = g.free(())
    a, b = tuple(g.world_to_cell([1.5, 1.0])), tuple(g.world_to_cell([4.5, 1.0]))
    assert free[a] and free[b]
    assert astar(free, a, b, 0.05).length_m == pytest.approx(3.0, abs=0.06)
    assert not free[tuple(g.world_to_cell([3.0, 1.9]))]  # never observed (footprint is about 1.6 x 1.2 m)


@settings(max_examples=200, deadline=None)
@given(yaw=st.floats(-4.0, 4.0), flip=st.booleans(), ex=st.floats(0.01, 3.0), ey=st.floats(0.01, 3.0),
       cx=st.floats(-5.0, 5.0), cy=st.floats(-5.0, 5.0))
def test_yaw_only_footprint_equals_the_hull_of_the_corners(yaw, flip, ex, ey, cx, cy) -> None:  # type: ignore[no-untyped-def]
    """The four-corner shortcut for boxes turned about z returns exactly what the convex hull does."""
    from psg_data._geometry import box_footprint, convex_hull, yaw_rotation

    R = yaw_rotation(yaw) @ (np.diag([1.0, -1.0, -1.0]) if flip else np.eye(3))
    box = Box(np.array([cx, cy, 0.4]), np.array([ex, ey, 0.8]), R)
    assert np.array_equal(box_footprint(box), convex_hull(box.corners()[:, :2]))
