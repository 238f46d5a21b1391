"""PredictiveGraphs as a library object: a time-varying scene graph that other projects query and update.

The paper's system is a 3D scene graph "whose nodes represent objects and edges function as
Perpetua* filters encoding spatio-semantic relationships". :class:`PredictiveGraph` is that graph:

- :meth:`PredictiveGraph.from_dataset` (a psg-dataset, a label source, an estimator: any registry
  name or a plugin instance; the door estimator settable) or :meth:`PredictiveGraph.fit` (a
  :class:`SceneLayout` and :class:`~psg_data.estimators.EdgeStream` observations) fits one filter
  per object-receptacle edge and one P(open) filter per door;
- ``g.at(t)`` -> :class:`Snapshot` (every edge's P(object on receptacle), every door's P(open);
  ``to_pandas``, ``to_networkx``, ``to_spark_dsg``); ``g.edge_probabilities(times)`` for many times;
- ``g.locate(object, t, top=k)`` -> :class:`Ranking` (receptacles, probabilities, positions);
- ``g.update(observations)``: label-table rows or ``(t, object, receptacle, present)`` tuples, no refit;
- ``g.plan(start_xy, object, t, delta=0.2)`` -> :class:`Plan` (the navigation agent's ranked targets,
  predicted doors and path on the map: :func:`ranked_candidates`, :func:`doors_believed_open`);
- ``g.save(path)`` / :meth:`PredictiveGraph.load` (one versioned JSON file, filters' state);
- ``psg-data graph PATH --at "2025-03-20 14:00" [--object NAME]`` on the command line.

Times are Unix seconds (UTC), zone-aware datetimes, or ISO strings in site time (:func:`to_seconds`).
The navigation and door tasks (:mod:`psg_data.navigation`) run on these objects: filters fitted by
:func:`fit_edge_filters` / :func:`fit_door_filters`, beliefs from :meth:`PredictiveGraph.object_probabilities`
and :meth:`~PredictiveGraph.door_probabilities`, targets by :func:`ranked_candidates`. Label sources
(:func:`source_observations`) and the scan timeline (:class:`DatasetTimeline`) live here too.
"""

from psg_data.graph._convert import snapshot_to_networkx, snapshot_to_spark_dsg
from psg_data.graph._fit import (
    door_open_probabilities,
    fit_door_filters,
    fit_edge_filters,
    fresh_estimator,
    resolve_estimator,
)
from psg_data.graph._graph import PredictiveGraph
from psg_data.graph._layout import SceneLayout
from psg_data.graph._plan import Plan, ranked_candidates
from psg_data.graph._snapshot import Ranking, Snapshot, doors_believed_open
from psg_data.graph._sources import ObservationModel, SourceObservations, grid_map_streams, source_observations
from psg_data.graph._store import GRAPH_FORMAT, GRAPH_VERSION, load_graph, save_graph
from psg_data.graph._timeline import DatasetTimeline
from psg_data.graph._times import to_seconds

__all__ = [
    "PredictiveGraph",
    "SceneLayout",
    "Snapshot",
    "Ranking",
    "Plan",
    "ranked_candidates",
    "doors_believed_open",
    "fit_edge_filters",
    "fit_door_filters",
    "door_open_probabilities",
    "resolve_estimator",
    "fresh_estimator",
    "snapshot_to_networkx",
    "snapshot_to_spark_dsg",
    "save_graph",
    "load_graph",
    "GRAPH_FORMAT",
    "GRAPH_VERSION",
    "to_seconds",
    "source_observations",
    "SourceObservations",
    "ObservationModel",
    "grid_map_streams",
    "DatasetTimeline",
]
