"""Maps the robot plans on: 2-D occupancy grids with switchable doorways and exact grid planners.

- Grids (:mod:`._grid`): :func:`grid_from_geometry` (room polygons, walls, receptacle footprints,
  switchable doorways), :func:`grid_from_points` / :func:`grid_from_scans` (fused point clouds),
  :func:`grid_from_dataset`, :class:`OccupancyGrid` (robot-radius inflation per door configuration).
- Planning (:mod:`._planner`): :func:`astar` / :class:`GridPlanner` (exact 8-connected shortest
  paths, octile costs, no corner cutting, through ``scipy.sparse.csgraph``; the pure-Python
  :func:`astar_reference` is the test oracle), :func:`grid_graph` and :class:`PlanningCache` (cached
  multi-source Dijkstra fields per receptacle approach set and door configuration).
- Door risk (:mod:`._door_risk`): :func:`expected_cost_route`, the expected-cost door rule (routes
  that weigh each door's P(open), discovered on arrival, replanned; exact under independent doors).

No estimator and no task here: :mod:`psg_data.graph` plans on these maps, :mod:`psg_data.navigation`
walks them (its public names re-export these).
"""

from psg_data.maps._door_risk import MIN_P_OPEN, DoorRoute, door_blocked_cells, expected_cost_route
from psg_data.maps._grid import (
    OccupancyGrid,
    box_footprint,
    bresenham,
    bresenham_many,
    grid_from_dataset,
    grid_from_geometry,
    grid_from_points,
    grid_from_scans,
    line_of_sight,
    points_in_polygon,
)
from psg_data.maps._planner import (
    SQRT2,
    GridPlanner,
    PathResult,
    PlanningCache,
    astar,
    astar_reference,
    grid_graph,
    octile_distance,
    path_length_m,
)

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
    "PathResult",
    "astar",
    "astar_reference",
    "GridPlanner",
    "octile_distance",
    "path_length_m",
    "grid_graph",
    "PlanningCache",
    "SQRT2",
    "DoorRoute",
    "expected_cost_route",
    "door_blocked_cells",
    "MIN_P_OPEN",
]
