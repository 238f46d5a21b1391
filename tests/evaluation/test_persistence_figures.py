"""A run's figures drawn on the executor (one task each, PNG bytes back, the parent writes) are the
same files as drawn inline, and as the plotting functions write them themselves."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from psg_data.estimators import EdgeStream
from psg_data.evaluation import evaluate_persistence, plot_beliefs, plot_horizon, plot_metric_bars
from psg_data.evaluation._persistence_figures import figure_calls, render_png
from psg_data.evaluation._persistence_job import write_persistence_outputs
from psg_data.evaluation._report import persistence_results

ROLES = {"always_absent": ("chance", "always absent")}


def _result():  # type: ignore[no-untyped-def]
    t0, day = 1_700_000_000.0, 86_400.0
    edges = [("mug", "table"), ("book", "shelf"), ("cup", "sink")]
    train = [EdgeStream(e, t0 + day * np.arange(10), (np.arange(10) + k) % 2) for k, e in enumerate(edges)]
    test = [EdgeStream(e, t0 + day * (10 + np.arange(4)), (np.arange(4) + k) % 2) for k, e in enumerate(edges)]
    grid = t0 + day * 10 + 3600.0 * np.arange(96)
    gt = {e: (grid, ((grid - grid[0]) // (day / (k + 1))).astype(int) % 2) for k, e in enumerate(edges)}
    return evaluate_persistence(["last_seen", "always_absent", "time_of_week_frequency"], train, test, gt,
                                keep_predictions=edges)


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_figures_on_a_pool_are_the_inline_files(tmp_path: Path) -> None:
    from psg_data._executors import open_executor

    res = _result()
    info = {"task": "persistence"}
    write_persistence_outputs(res, tmp_path / "inline", info=info, roles=ROLES, timezone="UTC")
    with open_executor(2) as ex:
        write_persistence_outputs(res, tmp_path / "pool", info=info, roles=ROLES, timezone="UTC", executor=ex)
    inline, pool = _files(tmp_path / "inline"), _files(tmp_path / "pool")
    assert {"belief.png", "bars.png", "horizon.png", "results.json"} <= set(inline)
    assert inline == pool
    assert not [p for p in (tmp_path / "pool").iterdir() if p.name.startswith(".")]  # no temporary file left


def test_rendered_bytes_equal_what_the_plot_functions_write(tmp_path: Path) -> None:
    res = _result()
    results = persistence_results(res, roles=ROLES)
    calls = figure_calls(res, results, ROLES, "UTC")
    assert set(calls) == {"belief.png", "bars.png", "horizon.png"}
    # the chance row is not drawn as a belief line; the horizon figure draws it as its dashed line
    assert calls["belief.png"][1]["skip"] == ["always_absent"]
    plot_beliefs(calls["belief.png"][1]["traces"], tmp_path / "belief.png", timezone="UTC", skip=["always_absent"])
    plot_metric_bars(results, tmp_path / "bars.png")
    plot_horizon(res, tmp_path / "horizon.png", skip=["always_absent"])
    for name, (kind, kwargs) in calls.items():
        assert render_png(kind, kwargs) == (tmp_path / name).read_bytes(), name


def test_without_plots_no_figure_is_drawn(tmp_path: Path) -> None:
    res = _result()
    write_persistence_outputs(res, tmp_path, info={}, roles=ROLES, timezone="UTC", plots=False)
    assert not list(tmp_path.glob("*.png")) and (tmp_path / "results.json").is_file()
