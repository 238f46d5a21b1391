"""``psg-data view``: a dataset in the Rerun viewer (native or web), or saved as an ``.rrd`` recording."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, NamedTuple

import click

from psg_data.cli._common import DATASET_HELP, Progress, dataset_path, handle_errors, quiet_option, setup_logging
from psg_data.cli._errors import ContractCommand

__all__ = ["view_cmd"]


@click.command("view", cls=ContractCommand, epilog=DATASET_HELP)
@click.argument("dataset", metavar="DATASET")
@click.option("--scan", "scans", multiple=True, metavar="ID", help="Only this scan (repeatable; default: all).")
@click.option("--save", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="FILE.rrd",
              help="Write the recording to FILE.rrd instead of opening a viewer (open it later with: rerun FILE.rrd).")
@click.option("--web", is_flag=True,
              help="Serve Rerun's web viewer from this machine and print its URL (for servers, containers, SSH); "
                   "runs until Ctrl-C.")
@click.option("--port", type=click.IntRange(1, 65535), default=9090, show_default=True,
              help="--web: port of the web viewer.")
@click.option("--grpc-port", type=click.IntRange(1, 65535), default=9876, show_default=True,
              help="--web: port the viewer page reads the recording from (forward it too).")
@click.option("--bind", default="127.0.0.1", show_default=True, metavar="ADDR",
              help="--web: address to listen on (0.0.0.0: every interface; the default is reached from another "
                   "machine through an SSH tunnel of both ports: "
                   "ssh -L 9090:127.0.0.1:9090 -L 9876:127.0.0.1:9876 HOST).")
@click.option("--frame-stride", type=click.IntRange(1), default=1, show_default=True,
              help="Log every N-th frame of a scan.")
@click.option("--overwrite", is_flag=True, help="Replace an existing --save file.")
@quiet_option
@handle_errors
def view_cmd(dataset: str, scans: tuple[str, ...], save: Path | None, web: bool, port: int, grpc_port: int,
             bind: str, frame_stride: int, overwrite: bool, quiet: bool) -> None:
    """Look at DATASET in Rerun (needs psg-data[viewer]): a viewer window, --web, or --save FILE.rrd.

    Logs per scan the RGB and depth images, the camera trajectory and frustum, the fused point
    cloud, receptacle and door boxes coloured by state, and the label streams of objects and doors,
    on two timelines: time (UTC) and scan (step scan by scan). The layout shows the 3D world, the
    current scan's images and the edges whose state changes most (see README, "Looking at a
    dataset"). Without a display (a server, a container, SSH) use --web or --save.

    \b
    Examples:
      psg-data view /tmp/lab                          # opens the Rerun viewer
      psg-data view demo --web                        # the built-in lab in the browser: open the printed URL
      psg-data view demo --save lab.rrd               # saved; then: rerun lab.rrd
      psg-data view demo --scan scan_000_09 --scan scan_000_11 --save two.rrd   # two scans of the built-in lab
    """
    setup_logging(quiet)
    from psg_data.errors import PsgDataError
    from psg_data.viewer._recording import display_problem, import_rerun

    if save is not None and web:
        raise click.UsageError("--save and --web: choose one (a file, or the web viewer)")
    problem = display_problem() if save is None and not web else None
    if problem is not None:  # before anything slow: this is what a server or a container sees first
        raise PsgDataError(problem)
    import_rerun()  # says which extra to install before any work is done
    from psg_data.loaders import open_dataset

    ds = open_dataset(dataset_path(dataset, command="psg-data view", quiet=quiet))
    unknown = [s for s in scans if s not in set(ds.scan_ids)]
    if unknown:
        raise PsgDataError(f"--scan {unknown[0]}: no such scan in {dataset}; scans are "
                           f"{', '.join(ds.scan_ids[:5])}{', ...' if len(ds.scan_ids) > 5 else ''}")
    ids = list(dict.fromkeys(scans)) or ds.scan_ids
    if web:
        _serve(ds, ids, WebOptions(port, grpc_port, bind), frame_stride, quiet)
        return
    counts = _log(ds, ids, save, None, frame_stride, overwrite, quiet)
    what = _what(counts)
    click.echo(f"wrote {save} ({what})" if save is not None else f"sent to the Rerun viewer ({what})")


def _log(ds: Any, ids: list[str], save: Path | None, web: Any, frame_stride: int, overwrite: bool,
         quiet: bool) -> dict[str, int]:
    from psg_data.viewer import dataset_blueprint, log_dataset, recording

    with Progress("view", total=len(ids), unit="scans", quiet=quiet) as prog, \
            recording(save, overwrite=overwrite, inputs=[ds.root], blueprint=dataset_blueprint(ds),
                      web=web) as rec:
        return log_dataset(rec, ds, ids, frame_stride=frame_stride, progress=prog)


def _what(counts: dict[str, int]) -> str:
    return (f"{counts['scans']} scans, {counts['frames']} frames, {counts['points']} points, "
            f"{counts['label_streams']} label streams")


class WebOptions(NamedTuple):
    """Where ``--web`` serves."""

    port: int
    grpc_port: int
    bind: str


def _serve(ds: Any, ids: list[str], where: WebOptions, frame_stride: int, quiet: bool) -> None:
    """Start the web viewer, stream the recording into it, print the URL and serve until Ctrl-C.

    Ctrl-C ends the command as every interrupted one (exit 130); SIGHUP (the terminal or the SSH
    session is gone) and SIGTERM end it with 128 + the signal's number, silently; the server goes
    with it in every case (``psg_data/viewer/_child.py``).
    """
    import tempfile

    from psg_data.viewer import WebViewer
    from psg_data.viewer._child import Stopped

    try:
        with tempfile.TemporaryDirectory(prefix="psg-view-") as tmp, \
                WebViewer(port=where.port, grpc_port=where.grpc_port, bind=where.bind,
                          log=Path(tmp) / "rerun.log") as server:
            click.echo(f"web viewer: {server.url}")
            click.echo(f"from another machine: {server.ssh_tunnel}, then open the URL there (the page comes "
                       f"from port {server.port}, its data from port {server.grpc_port})")
            counts = _log(ds, ids, None, server, frame_stride, False, quiet)
            click.echo(f"sent to the web viewer ({_what(counts)}); serving until Ctrl-C")
            server.wait()
    except Stopped as exc:
        sys.exit(128 + exc.signum)
