"""``psg-data view``: a dataset in the Rerun viewer, or saved as an ``.rrd`` recording."""

from __future__ import annotations

from pathlib import Path

import click

from psg_data.cli._common import Progress, dataset_path, handle_errors, quiet_option, setup_logging
from psg_data.cli._errors import ContractCommand

__all__ = ["view_cmd"]


@click.command("view", cls=ContractCommand)
@click.argument("dataset", metavar="DATASET")
@click.option("--scan", "scans", multiple=True, metavar="ID", help="Only this scan (repeatable; default: all).")
@click.option("--save", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="FILE.rrd",
              help="Write the recording to FILE.rrd instead of opening a viewer (open it later with `rerun FILE.rrd`).")
@click.option("--frame-stride", type=click.IntRange(1), default=1, show_default=True,
              help="Log every N-th frame of a scan.")
@click.option("--overwrite", is_flag=True, help="Replace an existing --save file.")
@quiet_option
@handle_errors
def view_cmd(dataset: str, scans: tuple[str, ...], save: Path | None, frame_stride: int, overwrite: bool,
             quiet: bool) -> None:
    """Look at DATASET (a directory, or ``demo`` for the built-in lab) in Rerun (needs psg-data[viewer]).

    Logs per scan the RGB and depth images, the camera trajectory and frustum, the fused point
    cloud, receptacle and door boxes coloured by state, and the label streams of objects and doors
    on one time line (see README, "Looking at a dataset").

    \b
    Examples:
      psg-data view /tmp/lab                          # opens the Rerun viewer
      psg-data view demo --save lab.rrd               # the built-in lab, saved; then: rerun lab.rrd
      psg-data view /tmp/lab --scan 2024-03-04T09 --scan 2024-03-04T11 --save two.rrd
    """
    setup_logging(quiet)
    from psg_data.errors import PsgDataError
    from psg_data.loaders import open_dataset
    from psg_data.viewer import log_dataset, recording

    ds = open_dataset(dataset_path(dataset, command="psg-data view", quiet=quiet))
    unknown = [s for s in scans if s not in set(ds.scan_ids)]
    if unknown:
        raise PsgDataError(f"--scan {unknown[0]}: no such scan in {dataset}; scans are "
                           f"{', '.join(ds.scan_ids[:5])}{', ...' if len(ds.scan_ids) > 5 else ''}")
    ids = list(dict.fromkeys(scans)) or ds.scan_ids
    with Progress("view", total=len(ids), unit="scans", quiet=quiet) as prog, \
            recording(save, overwrite=overwrite, inputs=[ds.root]) as rec:
        counts = log_dataset(rec, ds, ids, frame_stride=frame_stride, progress=prog)
    what = (f"{counts['scans']} scans, {counts['frames']} frames, {counts['points']} points, "
            f"{counts['label_streams']} label streams")
    click.echo(f"wrote {save} ({what})" if save is not None else f"sent to the Rerun viewer ({what})")
