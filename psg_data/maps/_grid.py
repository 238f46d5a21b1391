"""2-D occupancy grids: from the dataset geometry or from fused scan point clouds.

Grid convention: cell ``(i, j)`` (row ``i``, column ``j``) covers world ``x`` in
``[x0 + j * res, x0 + (j + 1) * res)`` and ``y`` in ``[y0 + i * res, y0 + (i + 1) * res)``, with
``origin_m = (x0, y0)`` the world corner of cell ``(0, 0)``; world frame x east, y north, metres.
Cells are tested at their centres.

An :class:`OccupancyGrid` stores the *raw* static obstacles (walls, unknown space, receptacle
footprints) and, per door, the doorway cells. Which doors are open is not part of the grid: every
query passes a ``door_open: dict[door_id, bool]`` (the ground truth at the query time, or what the
agent believes, e.g. a door estimator's prediction). :meth:`OccupancyGrid.free` then closes the
closed doorways and inflates all obstacles by the robot radius with a Euclidean distance transform
(``scipy.ndimage.distance_transform_edt``): a cell is free iff its centre lies more than
``robot_radius_m`` from the centre of every obstacle cell.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from psg_data._geometry import box_footprint, points_in_polygon
from psg_data.errors import EvaluationError
from psg_data.schemas._records import Door, Opening, Receptacle, Room

__all__ = [
    "OccupancyGrid",
    "grid_from_geometry",
    "grid_from_points",
    "grid_from_scans",
    "grid_from_dataset",
    "points_in_polygon",
    "box_footprint",
    "bresenham",
    "bresenham_many",
    "line_of_sight",
]

log = logging.getLogger(__name__)

DoorConfig = tuple[bool, ...]
"""Door states in the order of :attr:`OccupancyGrid.door_ids` (True = open)."""


# --------------------------------------------------------------------------------------------
# geometry helpers
# --------------------------------------------------------------------------------------------
def _segment_distance(xy: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance of each (N, 2) point to the segment a-b, metres."""
    d = b - a
    L2 = float(d @ d)
    t = np.zeros(xy.shape[0]) if L2 == 0 else np.clip((xy - a) @ d / L2, 0.0, 1.0)
    return np.linalg.norm(xy - (a + t[:, None] * d), axis=1)


# --------------------------------------------------------------------------------------------
# Bresenham lines and line of sight
# --------------------------------------------------------------------------------------------
def bresenham_many(p0: ArrayLike, p1: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
    """Bresenham lines between many cell pairs at once (integer arithmetic).

    Step ``k = 0..n`` (``n = max(|di|, |dj|)``) advances the major axis by one cell; the minor
    coordinate is the ideal line's value rounded half away from the start (Bresenham's choice with
    the error term initialised to ``n``): ``(2 k |d| + n) // (2 n)``.

    Args:
        p0: (N, 2) start cells (row, col).
        p1: (N, 2) end cells.

    Returns:
        ``(rows, cols, valid)``, each (N, K + 1) with K the longest line; ``valid[m, k]`` is True
        for the ``n_m + 1`` cells of line ``m`` (start and end included).
    """
    a = np.asarray(p0, dtype=np.int64).reshape(-1, 2)
    b = np.asarray(p1, dtype=np.int64).reshape(-1, 2)
    d = b - a
    ad = np.abs(d)
    n = ad.max(axis=1)
    K = int(n.max()) if n.size else 0
    k = np.arange(K + 1, dtype=np.int64)[None, :]
    nn = np.maximum(n, 1)[:, None]
    off_i = np.sign(d[:, :1]) * ((2 * k * ad[:, :1] + nn) // (2 * nn))
    off_j = np.sign(d[:, 1:]) * ((2 * k * ad[:, 1:] + nn) // (2 * nn))
    valid = k <= n[:, None]
    rows = np.where(valid, a[:, :1] + off_i, a[:, :1])
    cols = np.where(valid, a[:, 1:] + off_j, a[:, 1:])
    return rows, cols, valid


def bresenham(p0: Sequence[int], p1: Sequence[int]) -> NDArray[np.int64]:
    """Cells of the Bresenham line from cell ``p0`` to ``p1`` (both included), (n + 1, 2) (row, col)."""
    r, c, v = bresenham_many([p0], [p1])
    return np.stack([r[0][v[0]], c[0][v[0]]], axis=1)


def line_of_sight(blocked: NDArray[np.bool_], p0: ArrayLike, p1: ArrayLike) -> NDArray[np.bool_]:
    """Whether the Bresenham line between each pair of cells avoids ``blocked`` cells.

    The two end cells are not tested (the robot stands on one, the seen object occupies the other).

    Args:
        blocked: (H, W) bool, True = blocks sight.
        p0: (N, 2) or (2,) start cells (row, col).
        p1: (N, 2) or (2,) end cells (row, col).

    Returns:
        (N,) bool.
    """
    rows, cols, valid = bresenham_many(p0, p1)
    n = valid.sum(axis=1) - 1
    inner = valid & (np.arange(valid.shape[1])[None, :] >= 1) & (np.arange(valid.shape[1])[None, :] < n[:, None])
    H, W = blocked.shape
    rr, cc = np.clip(rows, 0, H - 1), np.clip(cols, 0, W - 1)
    return ~np.any(inner & blocked[rr, cc], axis=1)


# --------------------------------------------------------------------------------------------
# the grid
# --------------------------------------------------------------------------------------------
@dataclass(eq=False)
class OccupancyGrid:
    """A 2-D occupancy grid with switchable doorways.

    Attributes:
        static_obstacle: (H, W) bool, walls, unknown/outside space and receptacle footprints
            (doorway cells are not static obstacles).
        origin_m: (2,) world (x, y) of the outer corner of cell (0, 0), metres.
        resolution_m: cell size, metres.
        robot_radius_m: inflation radius, metres.
        door_cells: door_id -> (H, W) bool doorway cells (obstacles when the door is closed).
        receptacle_cells: receptacle_id -> (H, W) bool footprint cells.
        source: ``"geometry"`` or ``"scans"``.
    """

    static_obstacle: NDArray[np.bool_]
    origin_m: NDArray[np.float64]
    resolution_m: float
    robot_radius_m: float
    door_cells: dict[str, NDArray[np.bool_]] = field(default_factory=dict)
    receptacle_cells: dict[str, NDArray[np.bool_]] = field(default_factory=dict)
    source: str = "geometry"
    _free_cache: dict[DoorConfig, NDArray[np.bool_]] = field(default_factory=dict, repr=False, compare=False)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) cells."""
        return (int(self.static_obstacle.shape[0]), int(self.static_obstacle.shape[1]))

    @property
    def door_ids(self) -> tuple[str, ...]:
        """Door ids, sorted: the order of a :data:`DoorConfig`."""
        return tuple(sorted(self.door_cells))

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the grid, metres (for ``imshow(extent=...)``)."""
        H, W = self.shape
        x0, y0 = self.origin_m
        return (float(x0), float(x0 + W * self.resolution_m), float(y0), float(y0 + H * self.resolution_m))

    # -- coordinates ----------------------------------------------------------------------------
    def world_to_cell(self, xy: ArrayLike) -> NDArray[np.int64]:
        """(N, 2) or (2,) world (x, y) metres -> (row, col) cells (may lie outside the grid)."""
        p = np.asarray(xy, dtype=np.float64)
        ij = np.floor((p[..., ::-1] - self.origin_m[::-1]) / self.resolution_m).astype(np.int64)
        return ij

    def cell_to_world(self, ij: ArrayLike) -> NDArray[np.float64]:
        """(N, 2) or (2,) (row, col) cells -> world (x, y) of the cell centres, metres."""
        c = np.asarray(ij, dtype=np.float64)
        return (c[..., ::-1] + 0.5) * self.resolution_m + self.origin_m

    def cell_centers(self) -> NDArray[np.float64]:
        """(H * W, 2) world (x, y) of every cell centre in row-major order."""
        H, W = self.shape
        i, j = np.mgrid[0:H, 0:W]
        return self.cell_to_world(np.stack([i.ravel(), j.ravel()], axis=1))

    # -- doors ------------------------------------------------------------------------------------
    def door_config(self, door_open: Mapping[str, bool] | None) -> DoorConfig:
        """Door states as a hashable tuple in :attr:`door_ids` order; missing doors count as open."""
        door_open = door_open or {}
        unknown = set(door_open) - set(self.door_cells)
        if unknown:
            log.debug("door_open names doors the grid does not have: %s", sorted(unknown))
        return tuple(bool(door_open.get(d, True)) for d in self.door_ids)

    def obstacles(self, door_open: Mapping[str, bool] | DoorConfig | None = None) -> NDArray[np.bool_]:
        """(H, W) raw (not inflated) obstacles with the closed doorways filled."""
        cfg = door_open if isinstance(door_open, tuple) else self.door_config(door_open)
        obs = self.static_obstacle.copy()
        for d, is_open in zip(self.door_ids, cfg):
            if not is_open:
                obs |= self.door_cells[d]
        return obs

    def free(self, door_open: Mapping[str, bool] | DoorConfig | None = None) -> NDArray[np.bool_]:
        """(H, W) cells the robot centre may occupy: farther than the robot radius from any obstacle.

        Cached per door configuration; do not modify the returned array.
        """
        cfg = door_open if isinstance(door_open, tuple) else self.door_config(door_open)
        if cfg not in self._free_cache:
            from scipy.ndimage import distance_transform_edt

            obs = self.obstacles(cfg)
            if not obs.any():
                free = np.ones(self.shape, dtype=bool)
            else:
                free = distance_transform_edt(~obs) * self.resolution_m > self.robot_radius_m
            free.setflags(write=False)
            self._free_cache[cfg] = free
        return self._free_cache[cfg]


# --------------------------------------------------------------------------------------------
# builders
# --------------------------------------------------------------------------------------------
def _frame(bounds: tuple[float, float, float, float], resolution_m: float, pad_m: float
           ) -> tuple[NDArray[np.float64], int, int]:
    xmin, xmax, ymin, ymax = bounds
    x0 = np.floor((xmin - pad_m) / resolution_m) * resolution_m
    y0 = np.floor((ymin - pad_m) / resolution_m) * resolution_m
    W = int(np.ceil((xmax + pad_m - x0) / resolution_m))
    H = int(np.ceil((ymax + pad_m - y0) / resolution_m))
    return np.array([x0, y0]), H, W


def _mask_polygon(grid_shape: tuple[int, int], centers: NDArray[np.float64], polygon: NDArray[np.float64],
                  origin: NDArray[np.float64], res: float) -> NDArray[np.bool_]:
    """Cells whose centre lies in ``polygon`` (tested only inside its bounding box)."""
    H, W = grid_shape
    lo = np.floor((polygon.min(axis=0) - origin) / res).astype(int) - 1
    hi = np.ceil((polygon.max(axis=0) - origin) / res).astype(int) + 1
    j0, i0 = max(lo[0], 0), max(lo[1], 0)
    j1, i1 = min(hi[0], W), min(hi[1], H)
    out = np.zeros(grid_shape, dtype=bool)
    if j1 <= j0 or i1 <= i0:
        return out
    c = centers.reshape(H, W, 2)[i0:i1, j0:j1].reshape(-1, 2)
    out[i0:i1, j0:j1] = points_in_polygon(c, polygon).reshape(i1 - i0, j1 - j0)
    if len(polygon) >= 3 and not out.any():  # thinner than a cell: mark the cell of its centroid
        cj, ci = np.floor((polygon.mean(axis=0) - origin) / res).astype(int)
        if 0 <= ci < H and 0 <= cj < W:
            out[ci, cj] = True
    return out


def _door_and_receptacle_masks(shape: tuple[int, int], centers: NDArray[np.float64], origin: NDArray[np.float64],
                               res: float, receptacles: Iterable[Receptacle], doors: Iterable[Door]
                               ) -> tuple[dict[str, NDArray[np.bool_]], dict[str, NDArray[np.bool_]]]:
    rec = {r.receptacle_id: _mask_polygon(shape, centers, box_footprint(r.box), origin, res) for r in receptacles}
    door = {d.door_id: _mask_polygon(shape, centers, box_footprint(d.box), origin, res) for d in doors}
    return door, rec


def grid_from_geometry(
    rooms: Iterable[Room],
    receptacles: Iterable[Receptacle],
    doors: Iterable[Door] = (),
    *,
    openings: Iterable[Opening] = (),
    resolution_m: float = 0.05,
    robot_radius_m: float = 0.25,
    wall_thickness_m: float = 0.10,
    pad_m: float = 0.5,
) -> OccupancyGrid:
    """Occupancy grid from the dataset geometry.

    Free space is the union of the room floor polygons; walls are the polygon outlines drawn
    ``wall_thickness_m`` thick (rooms sharing an edge are therefore separated by a wall) and
    everything outside the polygons is an obstacle; receptacle footprints (convex hull of the box
    corners seen from above) are obstacles; doorway cells (door box footprints) are cut out of the
    walls and become obstacles only when the door is closed; opening cells (doorless passages, their
    box footprints) are cut out of the walls for good. Rooms without a polygon contribute
    nothing (their space counts as unknown, i.e. blocked); if no room has a polygon, the bounding
    box of the receptacles and doors grown by 1 m is taken as free space, without walls.

    Args:
        rooms: the rooms (floor polygons, world frame, metres).
        receptacles: the receptacles (their footprints are obstacles).
        doors: the doors (their doorways are kept per door).
        openings: doorless passages (always free).
        resolution_m: cell size, metres.
        robot_radius_m: inflation radius, metres.
        wall_thickness_m: thickness of the walls drawn on the polygon outlines, metres.
        pad_m: margin around the geometry, metres.

    Raises:
        EvaluationError: on a non-positive resolution or no geometry at all.
    """
    if not resolution_m > 0:
        raise EvaluationError(f"resolution_m must be > 0, got {resolution_m}")
    rooms, receptacles, doors = list(rooms), list(receptacles), list(doors)
    polys = [np.asarray(r.floor_polygon_m, float) for r in rooms if r.floor_polygon_m is not None
             and len(r.floor_polygon_m) >= 3]
    pts = [p for p in polys]
    pts += [box_footprint(r.box) for r in receptacles] + [box_footprint(d.box) for d in doors]
    if not pts:
        raise EvaluationError("grid_from_geometry: no room polygon, receptacle or door to build a grid from")
    allp = np.concatenate(pts)
    grow = 0.0 if polys else 1.0
    bounds = (allp[:, 0].min() - grow, allp[:, 0].max() + grow, allp[:, 1].min() - grow, allp[:, 1].max() + grow)
    origin, H, W = _frame(bounds, resolution_m, pad_m + wall_thickness_m)
    grid_shape = (H, W)
    centers = (np.stack(list(np.mgrid[0:H, 0:W][::-1]), axis=-1).reshape(-1, 2) + 0.5) * resolution_m + origin
    if polys:
        inside = np.zeros(grid_shape, dtype=bool)
        wall = np.zeros(H * W, dtype=bool)
        for p in polys:
            inside |= _mask_polygon(grid_shape, centers, p, origin, resolution_m)
            for k in range(p.shape[0]):
                a, b = p[k], p[(k + 1) % p.shape[0]]
                lo = np.minimum(a, b) - wall_thickness_m
                hi = np.maximum(a, b) + wall_thickness_m
                sel = np.flatnonzero(np.all((centers >= lo) & (centers <= hi), axis=1))
                wall[sel] |= _segment_distance(centers[sel], a, b) <= wall_thickness_m / 2
        obstacle = ~inside | wall.reshape(grid_shape)
    else:
        lo = np.array([bounds[0], bounds[2]])
        hi = np.array([bounds[1], bounds[3]])
        obstacle = ~np.all((centers >= lo) & (centers <= hi), axis=1).reshape(grid_shape)
    door_cells, rec_cells = _door_and_receptacle_masks(grid_shape, centers, origin, resolution_m, receptacles, doors)
    for m in door_cells.values():
        obstacle &= ~m
    for o in openings:
        obstacle &= ~_mask_polygon(grid_shape, centers, box_footprint(o.box), origin, resolution_m)
    for m in rec_cells.values():
        obstacle |= m
    return OccupancyGrid(obstacle, origin, float(resolution_m), float(robot_radius_m), door_cells, rec_cells,
                         "geometry")


def grid_from_points(
    points_m: ArrayLike,
    *,
    receptacles: Iterable[Receptacle] = (),
    doors: Iterable[Door] = (),
    resolution_m: float = 0.05,
    robot_radius_m: float = 0.25,
    floor_band_m: tuple[float, float] = (-0.05, 0.05),
    obstacle_band_m: tuple[float, float] = (0.10, 1.60),
    min_points: int = 1,
    pad_m: float = 0.5,
) -> OccupancyGrid:
    """Occupancy grid from a fused world-frame point cloud.

    Cells with at least ``min_points`` points whose height lies in ``obstacle_band_m`` are
    obstacles; cells with floor points (height in ``floor_band_m``) and no obstacle points are
    free; cells with neither are unknown and treated as obstacles. Doorway cells (door box
    footprints) are cleared so that door leaves seen in the scans do not block them; they are
    obstacles only when the door is closed at query time. Receptacle footprints are always
    obstacles (and identify the receptacles).

    Args:
        points_m: (N, 3) world points (z up, floor at z = 0), metres.
        receptacles: the receptacles (their footprints are obstacles).
        doors: the doors (their doorways are kept per door).
        resolution_m: cell size, metres.
        robot_radius_m: inflation radius, metres.
        pad_m: margin around the points, metres.
        floor_band_m: (zmin, zmax) of floor points, metres.
        obstacle_band_m: (zmin, zmax) of obstacle points (up to the robot height), metres.
        min_points: points needed to mark a cell.
    """
    P = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    P = P[np.all(np.isfinite(P), axis=1)]
    receptacles, doors = list(receptacles), list(doors)
    extra = [box_footprint(r.box) for r in receptacles] + [box_footprint(d.box) for d in doors]
    allxy = np.concatenate([P[:, :2], *extra]) if extra else P[:, :2]
    if allxy.shape[0] == 0:
        raise EvaluationError("grid_from_points: no points")
    bounds = (allxy[:, 0].min(), allxy[:, 0].max(), allxy[:, 1].min(), allxy[:, 1].max())
    origin, H, W = _frame(bounds, resolution_m, pad_m)
    ij = np.floor((P[:, 1::-1] - origin[::-1]) / resolution_m).astype(np.int64)
    flat = ij[:, 0] * W + ij[:, 1]
    z = P[:, 2]
    floor_n = np.bincount(flat[(z >= floor_band_m[0]) & (z <= floor_band_m[1])], minlength=H * W)
    obs_n = np.bincount(flat[(z >= obstacle_band_m[0]) & (z <= obstacle_band_m[1])], minlength=H * W)
    obstacle = ~((floor_n >= min_points) & (obs_n < min_points))
    obstacle = obstacle.reshape(H, W)
    centers = (np.stack(list(np.mgrid[0:H, 0:W][::-1]), axis=-1).reshape(-1, 2) + 0.5) * resolution_m + origin
    door_cells, rec_cells = _door_and_receptacle_masks((H, W), centers, origin, resolution_m, receptacles, doors)
    for m in door_cells.values():
        obstacle &= ~m
    for m in rec_cells.values():
        obstacle |= m
    return OccupancyGrid(obstacle, origin, float(resolution_m), float(robot_radius_m), door_cells, rec_cells, "scans")


def grid_from_scans(dataset: Any, scan_ids: Sequence[str] | None = None, *, pixel_stride: int = 4,
                    frame_stride: int = 1, max_depth_m: float = 5.0, voxel_size_m: float | None = 0.05,
                    **kwargs: Any) -> OccupancyGrid:
    """Occupancy grid from the fused point clouds of ``scan_ids`` (default: every scan).

    Keyword arguments go to :func:`grid_from_points` (``receptacles`` and ``doors`` default to
    the dataset's).
    """
    ids = list(scan_ids) if scan_ids is not None else list(dataset.scan_ids)
    clouds = []
    for sid in ids:
        pcd = dataset.scan(sid).point_cloud(stride=pixel_stride, frame_stride=frame_stride, max_depth_m=max_depth_m,
                                            voxel_size_m=voxel_size_m)
        clouds.append(np.asarray(pcd.points))
    kwargs.setdefault("receptacles", list(dataset.receptacles.values()))
    kwargs.setdefault("doors", list(dataset.doors.values()) if dataset.has_table("doors") else [])
    pts = np.concatenate(clouds) if clouds else np.zeros((0, 3))
    return grid_from_points(pts, **kwargs)


def grid_from_dataset(dataset: Any, *, source: str = "geometry", **kwargs: Any) -> OccupancyGrid:
    """Occupancy grid of a dataset: ``source="geometry"`` (rooms, receptacles, doors) or ``"scans"``."""
    if source == "geometry":
        doors = list(dataset.doors.values()) if dataset.has_table("doors") else []
        openings = list(getattr(dataset, "openings", {}).values())
        return grid_from_geometry(list(dataset.rooms.values()), list(dataset.receptacles.values()), doors,
                                  openings=openings, **kwargs)
    if source == "scans":
        return grid_from_scans(dataset, **kwargs)
    raise EvaluationError(f"grid source: expected 'geometry' or 'scans', got {source!r}")
