"""The three PNG figures of a persistence run, rendered side by side on the run's executor.

Rendering is most of the serial work left after the pool (matplotlib's layout and Agg drawing,
about 4 s on the demo). With an executor, each figure is one task that returns its PNG bytes
(:func:`render_png`), so the workers draw while the parent writes results.json and the CSV files;
the parent alone writes every file (atomically, :func:`~psg_data.writers._safe_output.write_atomically`),
so a remote Dask worker never needs the output folder. Without one, the figures are rendered
inline. The bytes are the same either way: the same function draws them.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from concurrent.futures import Executor, Future
from pathlib import Path
from typing import Any

from psg_data.evaluation._persistence_result import PersistenceResult

__all__ = ["figure_calls", "render_png", "submit_figures", "write_figures"]

Roles = dict[str, tuple[str, str]]
FigureCall = tuple[str, dict[str, Any]]


def figure_calls(result: PersistenceResult, results: Any, roles: Roles, timezone: str) -> dict[str, FigureCall]:
    """File name -> (figure kind, its arguments) of the run's figures: belief.png (only with traces),
    bars.png, horizon.png. Flat rows (chance, ``output=median``) are not drawn as belief lines.
    """
    flat = [n for n, (role, _) in roles.items() if role == "chance"] + \
        [n for n in result.estimators if n.endswith("output=median")]
    calls: dict[str, FigureCall] = {}
    if result.traces:
        from psg_data.evaluation._report import choose_plot_edges

        truth = {t.edge: (t.t_s, t.truth) for t in result.traces}
        keep = set(choose_plot_edges(truth, k=4))  # all traces are kept when --rerun asks for them
        calls["belief.png"] = ("belief", {"traces": [t for t in result.traces if t.edge in keep],
                                          "timezone": timezone, "skip": flat})
    calls["bars.png"] = ("bars", {"results": results})
    calls["horizon.png"] = ("horizon", {"result": result,
                                        "skip": [n for n in flat if n != "always_absent"] + ["always_absent"]})
    return calls


def render_png(kind: str, kwargs: dict[str, Any], dpi: int = 110) -> bytes:
    """One figure (``belief``, ``bars`` or ``horizon``) drawn and encoded as PNG bytes (a picklable task)."""
    from psg_data.evaluation._persistence_plots import plot_beliefs, plot_horizon, plot_metric_bars

    draw: dict[str, Callable[..., Any]] = {"belief": plot_beliefs, "bars": plot_metric_bars, "horizon": plot_horizon}
    fig = draw[kind](**kwargs)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def submit_figures(calls: dict[str, FigureCall], executor: Executor | None) -> dict[str, Future[bytes]] | None:
    """Start every figure on ``executor`` (None: nothing started; :func:`write_figures` draws them inline)."""
    if executor is None:
        return None
    return {name: executor.submit(render_png, kind, kwargs) for name, (kind, kwargs) in calls.items()}


def write_figures(calls: dict[str, FigureCall], out: Path, started: dict[str, Future[bytes]] | None = None) -> None:
    """Write each figure to ``out/NAME``: the PNG of its started task, or rendered here."""
    from psg_data.writers._safe_output import write_atomically

    for name, (kind, kwargs) in calls.items():
        png = started[name].result() if started is not None else render_png(kind, kwargs)
        write_atomically(out / name, _writer(png))


def _writer(data: bytes) -> Callable[[Path], int]:
    return lambda tmp: tmp.write_bytes(data)
