"""``psg-data graph``: a predictive graph's snapshot at a time, or one object's ranked receptacles."""

from __future__ import annotations

from pathlib import Path

import click

from psg_data.cli._common import handle_errors, quiet_option, setup_logging
from psg_data.cli._errors import ContractCommand

__all__ = ["graph_cmd"]


def _graph(path: str, estimator: str, labels: str, save: Path | None, overwrite: bool):  # type: ignore[no-untyped-def]
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
        if save.exists() and not overwrite:
            raise PsgDataError(f"{save}: exists; pass --overwrite to replace it")
        g.save(save)
    return g


@click.command("graph", cls=ContractCommand)
@click.argument("path", metavar="PATH")
@click.option("--at", "at", required=True, metavar="TIME",
              help="Time: 'YYYY-MM-DD HH:MM' in site time, ISO 8601 with an offset, or Unix seconds.")
@click.option("--object", "object_id", default=None, metavar="NAME", help="Rank this object's receptacles instead.")
@click.option("-e", "--estimator", default="perpetua_star", show_default=True, metavar="NAME",
              help="Estimator fitted on the training scans (a dataset PATH only).")
@click.option("--labels", default="gt", show_default=True, metavar="SOURCE",
              help="Label source of the observations: gt, privileged, noisy:P, detections:FILE.")
@click.option("--top", type=click.IntRange(1), default=None, help="Rows of the ranking (default: all).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the table as CSV.")
@click.option("--png", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also draw it on the map (rooms, receptacles coloured by P, doors by P(open)).")
@click.option("--rerun", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="FILE.rrd",
              help="Also save the beliefs of every edge and door over the week around --at as a Rerun recording "
                   "(needs psg-data[viewer]).")
@click.option("--save-graph", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="FILE.json",
              help="Save the fitted graph (load it later by giving FILE.json as PATH).")
@click.option("--overwrite", is_flag=True, help="Replace an existing --save-graph file.")
@quiet_option
@handle_errors
def graph_cmd(path: str, at: str, object_id: str | None, estimator: str, labels: str, top: int | None,
              csv_path: Path | None, png: Path | None, rerun: Path | None, save_graph: Path | None, overwrite: bool,
              quiet: bool) -> None:
    """Where things are predicted at a time: the predictive graph of PATH (a dataset, demo, or a
    graph saved with --save-graph) as a table; with --object the object's receptacles ranked.

    \b
    Examples:
      psg-data graph demo --at "2025-03-20 14:00"                      # every edge and door
      psg-data graph demo --at "2025-03-20 14:00" --object hairbrush --png brush.png
      psg-data graph /data/lab --labels privileged --save-graph lab.json --at "2025-03-20 14:00"
      psg-data graph lab.json --at 2025-03-21T09:30+01:00 --object redmug --top 3
    """
    setup_logging(quiet)
    g = _graph(path, estimator, labels, save_graph, overwrite)
    t = float(at) if at.replace(".", "", 1).isdigit() else at
    snap = g.at(t)
    if object_id is not None:
        table = g.locate(object_id, t, top=top).to_pandas()
    else:
        table = snap.to_pandas().sort_values(["object_id", "p"], ascending=[True, False], kind="stable")
    import datetime as dt
    from zoneinfo import ZoneInfo

    when = dt.datetime.fromtimestamp(snap.t_s, ZoneInfo(g.timezone)).isoformat(timespec="minutes")
    click.echo(f"{g!r} at {when} ({g.timezone})")
    click.echo(table.round({"p": 3, "x_m": 2, "y_m": 2, "z_m": 2}).to_string(index=False))
    doors = snap.doors_to_pandas()[["door_id", "p_open", "room_a", "room_b"]]
    if len(doors):
        click.echo(doors.round({"p_open": 3}).to_string(index=False))
    if csv_path is not None:
        from psg_data.writers._safe_output import write_atomically

        write_atomically(csv_path, lambda tmp: table.to_csv(tmp, index=False))
    if png is not None:
        from psg_data.navigation._plots import plot_snapshot

        plot_snapshot(snap, png, object_id=object_id)
    if rerun is not None:
        import numpy as np

        from psg_data.viewer import log_graph, recording

        with recording(rerun, overwrite=overwrite, inputs=[g.info.get("dataset")]) as rec:
            n = log_graph(rec, g, snap.t_s + np.arange(-3.5 * 86400, 3.5 * 86400 + 1, 1800.0))
        click.echo(f"wrote {rerun} ({n} belief series, a week around {when} every 30 min)")
