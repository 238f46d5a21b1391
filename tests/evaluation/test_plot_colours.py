"""One colour per method in every figure of a run: beliefs (some rows skipped), bars (every row, the
reference rows first) and horizons agree.
"""

from __future__ import annotations

import numpy as np
from matplotlib.colors import to_rgba

from psg_data.estimators import EdgeStream
from psg_data.evaluation import evaluate_persistence, plot_beliefs, plot_metric_bars
from psg_data.evaluation._persistence_plots import plot_horizon


def _result():  # type: ignore[no-untyped-def]
    t0, day = 1_700_000_000.0, 86_400.0
    edges = [("mug", "table"), ("book", "shelf")]
    train = [EdgeStream(e, t0 + day * np.arange(10), (np.arange(10) + k) % 2) for k, e in enumerate(edges)]
    test = [EdgeStream(e, t0 + day * (10 + np.arange(4)), (np.arange(4) + k) % 2) for k, e in enumerate(edges)]
    grid = t0 + day * 10 + 3600.0 * np.arange(96)
    gt = {e: (grid, ((grid - grid[0]) // day + k).astype(int) % 2) for k, e in enumerate(edges)}
    return evaluate_persistence(["always_present", "last_seen", "time_of_week_frequency"], train, test, gt,
                                keep_predictions=edges)


def test_a_method_has_one_colour_in_every_figure() -> None:
    """The belief figure skips a flat row (as psg-eval does): the other rows keep the bars' colours."""
    res = _result()
    beliefs = plot_beliefs(res.traces, skip=["always_present"])
    line_colour = {ln.get_label(): to_rgba(ln.get_color()) for ln in beliefs.axes[0].get_lines()}
    bars = plot_metric_bars(res)
    ax = bars.axes[0]
    names = [t.get_text() for t in ax.get_xticklabels()]
    bar_colour = {n: to_rgba(p.get_facecolor()) for n, p in zip(names, ax.patches)}
    horizon = plot_horizon(res)
    hz_colour = {c.get_label(): to_rgba(c.lines[0].get_color()) for c in horizon.axes[0].containers}
    shared = ["last_seen", "time_of_week_frequency"]
    for n in shared:
        assert line_colour[n] == bar_colour[n] == hz_colour[n], n
    assert bar_colour["always_present"] not in {bar_colour[n] for n in shared}
