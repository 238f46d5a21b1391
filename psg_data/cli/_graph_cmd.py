"""``psg-data graph``: a predictive graph's snapshot at a time, or one object's ranked receptacles."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import click

from psg_data.cli._common import handle_errors, quiet_option, setup_logging
from psg_data.cli._errors import ContractCommand
from psg_data.cli._label_source import LabelSourceType

__all__ = ["graph_cmd"]

_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?")
"""``--at`` given as Unix seconds."""


def _inputs(path: str, labels: str) -> list[Path]:
    """What ``psg-data graph`` reads: PATH (the demo: the dataset cache) and a detections file."""
    p = Path(path)
    inputs = [p]
    if path == "demo" and not p.exists():
        from psg_data.datasets import cache_dir

        inputs = [cache_dir()]
    if labels.startswith("detections:"):
        inputs.append(Path(labels.split(":", 1)[1]))
    return inputs


def _check_outputs(path: str, labels: str, outputs: dict[str, tuple[Path | None, str]], overwrite: bool) -> None:
    """Every output through the safe-output rule (never an input or inside one, replaced only with
    --overwrite and only if psg-data wrote it), checked before any work.
    """
    from psg_data.writers._safe_output import check_file_output

    given = {opt: (out, kind) for opt, (out, kind) in outputs.items() if out is not None}
    png = given.get("--png")
    if png is not None and png[0].suffix.lower() != ".png":
        raise click.BadParameter(f"{png[0]}: expected a file name ending in .png", param_hint="--png")
    if "--save-graph" in given and Path(path).is_file():
        raise click.UsageError(f"--save-graph: {path} is a saved graph already (it is fitted from a dataset, "
                                "not re-saved); give a dataset folder or demo as PATH")
    seen: dict[Path, str] = {}
    for opt, (out, kind) in given.items():
        key = Path(out).expanduser().resolve()
        if key in seen:
            raise click.UsageError(f"{opt} {out}: the same file as {seen[key]}; expected one file per output")
        seen[key] = opt
        check_file_output(out, overwrite=overwrite, kind=kind, inputs=_inputs(path, labels))


def _graph(path: str, estimator: str, labels: str, save: Path | None):  # type: ignore[no-untyped-def]
    from psg_data.errors import PsgDataError
    from psg_data.graph import PredictiveGraph

    p = Path(path)
    if p.is_file():
        return PredictiveGraph.load(p)
    if path == "demo" and not p.is_dir():
        from psg_data.datasets import demo

        p = demo()
    if not p.is_dir():
        raise PsgDataError(f"{path}: expected a psg-dataset folder, 'demo' or a saved graph (.json)")
    from psg_data.cli._graph_cache import cached_fit

    g = cached_fit(p, estimator, labels)  # a second call with the same inputs loads the fit
    if save is not None:
        g.save(save)
    return g


def _refuse_fit_options_on_saved(ctx: click.Context, path: str) -> None:
    """-e / --labels choose how a dataset is fitted: on a saved graph (already fitted) they are refused."""
    from psg_data.errors import PsgDataError

    given = [f"--{n}" for n in ("estimator", "labels")
             if ctx.get_parameter_source(n) not in (None, click.core.ParameterSource.DEFAULT)]
    if given and Path(path).is_file():
        raise PsgDataError(f"{', '.join(given)}: {path} is a saved graph, fitted already (its estimator and labels "
                           "are stored in it); give a dataset PATH to fit another")


def _label_text(g: object) -> str:
    """Where the graph's observations came from: its edge count depends on it (gt, privileged, ...)."""
    info = getattr(g, "info", {}) or {}
    scans = f" in {info['train_scans']} training scans" if "train_scans" in info else ""
    return f"labels {info.get('labels', '?')} (an edge: an object seen on a receptacle{scans} under these labels)"


def _sorted_edges(cols: dict[str, list[Any]]) -> dict[str, list[Any]]:
    """The snapshot's rows by object, most probable receptacle first (stable; NaN last within an object)."""
    p = cols["p"]
    order = sorted(range(len(p)), key=lambda i: (cols["object_id"][i], p[i] != p[i], -p[i] if p[i] == p[i] else 0.0))
    return {k: [v[i] for i in order] for k, v in cols.items()}


def _print_text(g: Any, snap: Any, table: dict[str, list[Any]], object_id: str | None, when: str) -> None:
    from psg_data.cli._text_table import columns_to_text, rounded

    click.echo(f"{g!r} at {when} ({g.timezone}); {_label_text(g)}")
    if object_id is not None:
        click.echo(f"{object_id}: its receptacles ranked by P(on it at {when})")
    click.echo(columns_to_text(rounded(table, {"p": 3, "x_m": 2, "y_m": 2, "z_m": 2})))
    doors = snap.doors_to_pydict()
    if doors["door_id"]:
        between = [f"{a} and {b}" for a, b in zip(doors["room_a"], doors["room_b"])]
        click.echo("")
        click.echo(columns_to_text(rounded({"door_id": doors["door_id"], "p_open": doors["p_open"], "between": between},
                                           {"p_open": 3})))


@click.command("graph", cls=ContractCommand)
@click.argument("path", metavar="PATH")
@click.option("--at", "at", required=True, metavar="TIME",
              help="Time: 'YYYY-MM-DD HH:MM' in site time, ISO 8601 with an offset, or Unix seconds.")
@click.option("--object", "object_id", default=None, metavar="NAME", help="Rank this object's receptacles instead.")
@click.option("-e", "--estimator", default="perpetua_star", show_default=True, metavar="NAME",
              help="Estimator fitted on the training scans (a dataset PATH only).")
@click.option("--labels", type=LabelSourceType(), default="gt", show_default=True, metavar="SOURCE",
              help="Label source of the observations: gt, privileged, noisy:P, detections:FILE.")
@click.option("--top", type=click.IntRange(1), default=None, help="Rows of the ranking (default: all).")
@click.option("--format", "table_format", type=click.Choice(["text", "csv"]), default="text", show_default=True,
              help="How the table is printed: text, or csv (the ranking or snapshot only; as psg-eval compare "
                   "--format csv; redirect it to a file).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path), default=None, hidden=True,
              help="Former spelling of --format csv > FILE (kept for one release).")
@click.option("--png", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also draw it on the map (rooms, receptacles coloured by P, doors by P(open)).")
@click.option("--rerun", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="FILE.rrd",
              help="Also save the beliefs of every edge and door over the week around --at as a Rerun recording "
                   "(needs psg-data[viewer]).")
@click.option("--save-graph", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="FILE.json",
              help="Save the fitted graph (load it later by giving FILE.json as PATH).")
@click.option("--overwrite", is_flag=True,
              help="Replace existing output files (--png, --rerun, --save-graph), only ones psg-data wrote.")
@quiet_option
@click.option("--verbose", "-v", is_flag=True, help="Also print the fit's INFO lines (settings decided, error rates).")
@click.pass_context
@handle_errors
def graph_cmd(ctx: click.Context, path: str, at: str, object_id: str | None, estimator: str, labels: str,
              top: int | None, table_format: str, csv_path: Path | None, png: Path | None, rerun: Path | None,
              save_graph: Path | None, overwrite: bool, quiet: bool, verbose: bool) -> None:
    """Where things are predicted at a time: the predictive graph of PATH (a dataset, demo, or a
    graph saved with --save-graph) as a table; with --object the object's receptacles ranked.

    \b
    Examples:
      psg-data graph demo --at "2025-03-20 14:00"                      # every edge and door
      psg-data graph demo --at "2025-03-20 14:00" --object hairbrush --png brush.png
      psg-data graph /data/lab --labels privileged --save-graph lab.json --at "2025-03-20 14:00"
      psg-data graph lab.json --at 2025-03-21T09:30+01:00 --object redmug --top 3
    """
    setup_logging(quiet=quiet or not verbose, verbose=verbose and not quiet)
    _refuse_fit_options_on_saved(ctx, path)
    _check_outputs(path, labels, {"--csv": (csv_path, "graph-csv"), "--png": (png, "png"), "--rerun": (rerun, "rrd"),
                                  "--save-graph": (save_graph, "graph")}, overwrite)
    g = _graph(path, estimator, labels, save_graph)
    t = float(at) if _NUMBER.fullmatch(at.strip()) else at  # bounded by the graph (years 1 to 9999)
    snap = g.at(t)
    if object_id is not None:
        table = g.locate(object_id, t, top=top).to_pydict()
    else:
        table = _sorted_edges(snap.to_pydict())
    import datetime as dt
    from zoneinfo import ZoneInfo

    when = dt.datetime.fromtimestamp(snap.t_s, ZoneInfo(g.timezone)).isoformat(timespec="minutes")
    from psg_data.cli._text_table import columns_to_csv

    if table_format == "csv":
        click.echo(columns_to_csv(table), nl=False)
    else:
        _print_text(g, snap, table, object_id, when)
    if csv_path is not None:
        from psg_data.writers._safe_output import write_atomically

        click.echo("warning: --csv FILE is now --format csv > FILE; the old spelling goes in the next release",
                   err=True)
        write_atomically(csv_path, lambda tmp: Path(tmp).write_text(columns_to_csv(table), encoding="utf-8"),
                         inputs=_inputs(path, labels))
    if png is not None:
        from psg_data.navigation._plots import plot_snapshot

        plot_snapshot(snap, png, object_id=object_id)
    if rerun is not None:
        import numpy as np

        from psg_data.viewer import log_graph, recording

        with recording(rerun, overwrite=overwrite, inputs=[*_inputs(path, labels), g.info.get("dataset")]) as rec:
            n = log_graph(rec, g, snap.t_s + np.arange(-3.5 * 86400, 3.5 * 86400 + 1, 1800.0))
        click.echo(f"wrote {rerun} ({n} belief series, a week around {when} every 30 min)",
                   err=table_format == "csv")  # stdout: only the CSV
