"""Looking at datasets and estimator beliefs in Rerun (``rerun-sdk``, extra ``psg-data[viewer]``).

- :func:`log_dataset`: per scan the RGB and depth images, the camera trajectory and frustum, the
  fused point cloud, receptacle and door boxes coloured by state, and the label streams of
  objects and doors, on one ``time`` timeline (UTC). ``psg-data view DATASET``.
- :func:`log_beliefs`: estimator beliefs over time per scored edge, beside the ground truth and
  the test observations. ``psg-eval ... --rerun FILE.rrd``.
- :func:`log_graph`: a predictive graph's beliefs per edge and door over a range of times, on the
  same entity paths. ``psg-data graph PATH --at T --rerun FILE.rrd``.
- :func:`recording`: a recording that is saved to an ``.rrd`` file (atomically) or shown in a
  spawned viewer.

README.md ("Looking at a dataset") lists the entities a recording holds.
"""

from psg_data.viewer._beliefs import log_beliefs, log_graph
from psg_data.viewer._dataset_log import TIMELINE, log_dataset
from psg_data.viewer._recording import recording

__all__ = ["TIMELINE", "log_dataset", "log_beliefs", "log_graph", "recording"]
