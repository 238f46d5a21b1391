"""Offline semi-static object navigation (the paper's PredictiveGraphs evaluation), on
:class:`psg_data.graph.PredictiveGraph` objects (:func:`build_graph`: one per method).

- Grids and planning (re-exported from :mod:`psg_data.maps`): :func:`grid_from_geometry` (room
  polygons, walls, receptacle footprints, switchable doorways), :func:`grid_from_points` /
  :func:`grid_from_scans` (fused point clouds), :class:`OccupancyGrid` (robot-radius inflation per
  door configuration); :func:`astar` / :class:`GridPlanner` (exact 8-connected shortest paths,
  octile costs, no corner cutting, through ``scipy.sparse.csgraph``; the pure-Python
  :func:`astar_reference` is the test oracle), :func:`grid_graph` and :class:`PlanningCache` (cached
  multi-source Dijkstra fields per receptacle approach set and door configuration).
- Label sources (re-exported from :mod:`psg_data.graph`): map, door and sighting observations of
  ``gt``, ``privileged``, ``noisy:P``, ``detections:FILE`` (:func:`source_observations`,
  :class:`ObservationModel`).
- Options (:mod:`._options`): :class:`NavigationOptions` and the :data:`PROTOCOLS` ``sim`` and
  ``paper-real`` (25 queries: 10 static, 10 dynamic, 5 absent, one fixed start, adaptive).
- Queries (:mod:`._queries`): :func:`make_queries` (seeded, static / dynamic / absent), stored with
  :func:`save_queries` / :func:`load_queries`.
- Environment (:mod:`._env`): :class:`NavigationEnv` from a dataset or the synthetic lab, with the
  dense ground truth ``gt_at`` / ``doors_at``.
- Agent (:mod:`._agent`): :func:`run_episode` (MAP / top-k ranking, delta abort, two attempts,
  adaptive belief updates, door discovery).
- Harness (:mod:`._runner`): :func:`run_navigation` (a :class:`NavigationOptions`) ->
  :class:`NavigationResult` (per-query records and the paper-shaped tables, simulation or
  real-world layout), baselines 'oracle', 'last_seen_map' and 'random_receptacle', per-method door
  beliefs, a delta sweep; scoring in :mod:`psg_data.evaluation._navigation_scores`, tables and
  files in :mod:`psg_data.evaluation`.
- Simulation protocols (:mod:`._sim_benchmark`, :mod:`._sim_agent`): the paper's
  ``paper-sim-predictive`` / ``paper-sim-adaptive`` on the navigation benchmark's houses
  (:data:`SIM_PROTOCOLS`, :func:`run_sim_navigation`), the adaptive agent that looks while it walks,
  updates its filters and switches targets (:func:`run_adaptive_episode`, :class:`HouseSight`; the
  readings of the open choices: :data:`AGENT_MEMORIES`, :data:`ABSENCE_RULES`,
  :data:`LAST_MAPS`).
- Plots (:mod:`._plots`): :func:`plot_query`, :func:`plot_snapshot` (a predictive graph's snapshot on the map).
- Doors (:mod:`._doors`, :mod:`._door_dataset`): door estimators' P(open) (:func:`fit_door_filters`,
  :func:`door_open_probabilities`), door-aware episodes with replanning at closed doors
  (:func:`run_door_episode`; door rules :data:`DOOR_RULES`: the P(open) threshold, or
  :func:`expected_cost_route` re-exported from :mod:`psg_data.maps`), :func:`run_door_navigation`
  (blocked first plans, extra distance, SR, SPL per estimator vs. the all-doors-open planner), worlds from a dataset
  (:meth:`DoorWorld.from_dataset`) or the unit-test :func:`door_loop_world`, the dataset door task
  :func:`run_door_task` (with objects behind predicted-closed doors, :func:`walk_summary`) and the
  figures :func:`plot_door_query` / :func:`plot_door_example`.
"""

from __future__ import annotations

from psg_data.graph._sources import ObservationModel, SourceObservations, grid_map_streams, source_observations
from psg_data.maps._door_risk import DoorRoute, expected_cost_route
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
from psg_data.navigation._agent import OUTCOMES, SETTINGS, AgentConfig, Episode, episode_record, run_episode
from psg_data.navigation._baselines import (
    LastSeenFilter,
    OracleFilter,
    RandomFilter,
    last_seen_filters,
    oracle_filters,
    random_filters,
)
from psg_data.navigation._door_dataset import (
    DOOR_MODE_LABELS,
    DoorTaskOptions,
    DoorTaskResult,
    door_world_from_dataset,
    run_door_task,
    walk_summary,
)
from psg_data.navigation._doors import (
    DOOR_BASELINES,
    DOOR_RULES,
    DoorEpisode,
    DoorNavigationResult,
    DoorQuery,
    DoorWorld,
    door_loop_world,
    door_open_probabilities,
    fit_door_filters,
    make_door_queries,
    plot_door_query,
    run_door_episode,
    run_door_navigation,
)
from psg_data.navigation._env import WEEK_S, DatasetTimeline, NavigationEnv, streams_from_states
from psg_data.navigation._options import DOOR_BELIEFS, PROTOCOLS, START_MODES, NavigationOptions
from psg_data.navigation._plots import pick_door_example, plot_door_example, plot_query, plot_snapshot
from psg_data.navigation._queries import (
    CATEGORIES,
    Query,
    load_queries,
    make_queries,
    queries_from_frame,
    queries_to_frame,
    save_queries,
    start_cells,
)
from psg_data.navigation._runner import (
    ABSENT_RULES,
    METRICS,
    NavigationResult,
    build_filters,
    build_graph,
    door_belief_from_filters,
    run_navigation,
    score_records,
)
from psg_data.navigation._sim_agent import ABSENCE_RULES, AGENT_MEMORIES, HouseSight, run_adaptive_episode
from psg_data.navigation._sim_benchmark import (
    LAST_MAPS,
    SIM_PROTOCOLS,
    SimProtocol,
    method_filters,
    run_sim_navigation,
    run_sim_scene,
    scene_settings,
    scene_split_ids,
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
    "NavigationEnv",
    "DatasetTimeline",
    "streams_from_states",
    "NavigationOptions",
    "PROTOCOLS",
    "DOOR_BELIEFS",
    "START_MODES",
    "ObservationModel",
    "SourceObservations",
    "source_observations",
    "grid_map_streams",
    "WEEK_S",
    "Query",
    "CATEGORIES",
    "make_queries",
    "start_cells",
    "queries_to_frame",
    "queries_from_frame",
    "save_queries",
    "load_queries",
    "LastSeenFilter",
    "OracleFilter",
    "last_seen_filters",
    "oracle_filters",
    "RandomFilter",
    "random_filters",
    "AgentConfig",
    "Episode",
    "run_episode",
    "episode_record",
    "SETTINGS",
    "OUTCOMES",
    "NavigationResult",
    "run_navigation",
    "build_filters",
    "build_graph",
    "score_records",
    "door_belief_from_filters",
    "METRICS",
    "ABSENT_RULES",
    "plot_query",
    "plot_snapshot",
    "pick_door_example",
    "plot_door_example",
    "DOOR_BASELINES",
    "DOOR_RULES",
    "DoorRoute",
    "expected_cost_route",
    "DoorWorld",
    "DoorQuery",
    "DoorEpisode",
    "DoorNavigationResult",
    "fit_door_filters",
    "door_open_probabilities",
    "run_door_episode",
    "make_door_queries",
    "run_door_navigation",
    "door_loop_world",
    "door_world_from_dataset",
    "DoorTaskOptions",
    "DoorTaskResult",
    "run_door_task",
    "walk_summary",
    "DOOR_MODE_LABELS",
    "plot_door_query",
    "SimProtocol",
    "SIM_PROTOCOLS",
    "run_sim_scene",
    "run_sim_navigation",
    "method_filters",
    "scene_settings",
    "scene_split_ids",
    "HouseSight",
    "ABSENCE_RULES",
    "AGENT_MEMORIES",
    "LAST_MAPS",
    "run_adaptive_episode",
]
