"""Plotting functions build ``matplotlib.figure.Figure`` objects, return them, write a PNG only
when asked, and never touch the user's backend (no ``matplotlib.use``, no pyplot)."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from psg_data.estimators import EdgeStream
from psg_data.evaluation import evaluate_persistence, plot_beliefs, plot_metric_bars
from tests.contract import files_in, interrupt_partway

ROOT = Path(__file__).resolve().parents[2]


def test_no_backend_switch_or_pyplot_anywhere_in_the_package() -> None:
    found = []
    for p in sorted((ROOT / "psg_data").rglob("*.py")):
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "use" \
                    and isinstance(node.func.value, ast.Name) and node.func.value.id == "matplotlib":
                found.append(f"{p.name}:{node.lineno} matplotlib.use")
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            found += [f"{p.name}:{node.lineno} imports {n}" for n in names if n.startswith("matplotlib.pyplot")]
    assert found == []


def _result():  # type: ignore[no-untyped-def]
    t0, day = 1_700_000_000.0, 86_400.0
    edges = [("mug", "table"), ("book", "shelf")]
    train = [EdgeStream(e, t0 + day * np.arange(10), (np.arange(10) + k) % 2) for k, e in enumerate(edges)]
    test = [EdgeStream(e, t0 + day * (10 + np.arange(4)), (np.arange(4) + k) % 2) for k, e in enumerate(edges)]
    grid = t0 + day * 10 + 3600.0 * np.arange(96)
    gt = {e: (grid, ((grid - grid[0]) // day + k).astype(int) % 2) for k, e in enumerate(edges)}
    return evaluate_persistence(["last_seen", "always_present"], train, test, gt, keep_predictions=edges)


def test_persistence_plots_return_figures_and_leave_the_backend(tmp_path: Path, user_backend: str) -> None:
    from matplotlib.figure import Figure

    res = _result()
    fig = plot_beliefs(res.traces)
    assert isinstance(fig, Figure) and len(fig.axes) == 2 and not list(tmp_path.iterdir())
    bars = plot_metric_bars(res, tmp_path / "sub" / "bars.png")
    assert isinstance(bars, Figure) and len(bars.axes) == 3
    plot_beliefs(res.traces, tmp_path / "belief.png")
    for p in (tmp_path / "sub" / "bars.png", tmp_path / "belief.png"):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [ln.get_label() for ln in fig.axes[0].get_lines()][:2] == ["last_seen", "always_present"]


def test_belief_ticks_at_local_midnights_without_windows_and_distinct_colours() -> None:
    """An unbroken span (the benchmark: no scoring windows) gets a tick at every local midnight, not only at
    its start; more than ten rows get distinct colours."""
    import pandas as pd

    from psg_data.evaluation._persistence_plots import _colours, _tick_starts

    t0 = pd.Timestamp("2024-01-01 00:00", tz="America/Toronto").timestamp()
    t = t0 + np.arange(0, 3 * 86400, 600.0)
    assert _tick_starts(t, [], "America/Toronto") == [0, 144, 288]
    assert _tick_starts(t, [10, 20], "America/Toronto") == [0, 10, 20]
    assert len({tuple(c) for c in _colours(list(range(12)))}) == 12


def test_belief_legend_lists_only_what_is_drawn(tmp_path: Path) -> None:
    """No 'cut' entry on an unbroken time axis, no 'thin line' entry when no belief oscillates."""
    from psg_data.evaluation._persistence_types import PredictionTrace

    t = 1_700_000_000.0 + np.arange(0, 86400, 600.0)
    tr = PredictionTrace("last_seen", 0, ("mug", "table"), t, np.full(t.size, 0.2), (t < t[50]).astype(np.int64),
                         np.array([t[0]]), np.array([1], np.int8))
    fig = plot_beliefs([tr], tmp_path / "b.png")
    texts = [x.get_text() for leg in fig.legends for x in leg.get_texts()]
    assert texts and not any(x.startswith("cut:") or x.startswith("thin") for x in texts)


def test_plots_replace_the_file_atomically_in_the_format_of_its_suffix(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    from matplotlib.figure import Figure

    res = _result()
    plot_metric_bars(res, tmp_path / "poster.pdf")
    plot_beliefs(res.traces, tmp_path / "belief")  # no suffix: savefig's default format, its suffix appended
    before = (tmp_path / "poster.pdf").read_bytes()
    assert before[:5] == b"%PDF-" and (tmp_path / "belief.png").read_bytes()[:4] == b"\x89PNG"
    interrupt_partway(monkeypatch, Figure, "savefig")
    with pytest.raises(KeyboardInterrupt):
        plot_metric_bars(res, tmp_path / "poster.pdf")
    assert (tmp_path / "poster.pdf").read_bytes() == before
    assert files_in(tmp_path) == ["belief.png", "poster.pdf"]
