"""Looking at datasets and estimator beliefs in Rerun (``rerun-sdk``, extra ``psg-data[viewer]``).

- :func:`log_dataset`: per scan the RGB and depth images, the camera trajectory and frustum, the
  fused point cloud, receptacle and door boxes coloured by state, and the label streams of
  objects and doors, on one ``time`` timeline (UTC). ``psg-data view DATASET``.
- :func:`log_beliefs`: estimator beliefs over time per scored edge, beside the ground truth and
  the test observations. ``psg-eval ... --rerun FILE.rrd``.
- :func:`recording`: a recording that is saved to an ``.rrd`` file (atomically), shown in a
  spawned viewer, or streamed to a :class:`WebViewer` (Rerun's web viewer served from this
  machine, bound to 127.0.0.1 by default); :func:`display_problem` says why no native viewer can
  open here (no display).
- :func:`log_graph`: a predictive graph's beliefs per edge and door over a range of times, on the
  same entity paths. ``psg-data graph PATH --at T --rerun FILE.rrd``.
- :func:`dataset_blueprint`, :func:`beliefs_blueprint`: the layouts sent with the recordings.

README.md ("Looking at a dataset") lists the entities a recording holds.
"""

from psg_data.viewer._beliefs import log_beliefs, log_graph
from psg_data.viewer._blueprint import beliefs_blueprint, dataset_blueprint
from psg_data.viewer._dataset_log import SCAN_TIMELINE, TIMELINE, log_dataset
from psg_data.viewer._recording import display_problem, recording
from psg_data.viewer._web import WebViewer

__all__ = ["TIMELINE", "SCAN_TIMELINE", "log_dataset", "log_beliefs", "log_graph", "recording", "display_problem",
           "dataset_blueprint", "beliefs_blueprint", "WebViewer"]
