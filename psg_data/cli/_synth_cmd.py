"""``psg-data synth``: build the built-in synthetic lab."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

import click

from psg_data.cli._common import Progress, handle_errors, quiet_option, setup_logging
from psg_data.cli._errors import ContractCommand

__all__ = ["synth_cmd"]

FORMATS = ("canonical", "ros1", "ros2-sqlite3", "ros2-mcap")


def _resolution(_ctx: click.Context, _param: click.Parameter, value: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", value)
    if not m:
        raise click.BadParameter(f"expected WIDTHxHEIGHT (e.g. 160x120), got {value!r}")
    return int(m.group(1)), int(m.group(2))


@click.command("synth", cls=ContractCommand)
@click.argument("out", type=click.Path(path_type=Path))
@click.option("--format", "fmt", type=click.Choice(FORMATS), default="canonical", show_default=True,
              help="canonical psg-dataset, or raw recordings (one bag per scan) for the converter.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of layout, schedules, paths and noise.")
@click.option("--days", type=click.IntRange(1, 366), default=21, show_default=True, help="Days (4 scans a day).")
@click.option("--frames-per-scan", type=click.IntRange(1, 1000), default=8, show_default=True)
@click.option("--resolution", default="160x120", show_default=True, callback=_resolution, help="WIDTHxHEIGHT.")
@click.option("--shift", type=click.Choice(["none", "long-weekend"]), default="none", show_default=True,
              help="Distribution shift of the test days (long-weekend: Mondays and Fridays follow the weekend).")
@click.option("--generator", type=click.Choice(["steps-v2", "continuous-v1"]), default="steps-v2", show_default=True,
              help="Schedule generator: bi-hourly steps with routines (stores its exact model), or the first "
                   "continuous-time one.")
@click.option("--routine-strength", type=click.FloatRange(0.0, 1.0), default=0.8, show_default=True,
              help="steps-v2: probability that the routine sets the state at a step (0 random walk, 1 clockwork).")
@click.option("--layout", type=click.Choice(["two_routes", "chain", "corridor"]), default="corridor", show_default=True,
              help="two_routes: a door and an open passage in each inner wall (a closed door forces a detour); "
                   "chain: doors only (the former lab, where a closed door cuts a room off); corridor: doors, "
                   "and a hallway along the rooms with an opening into each (a closed door sends the robot "
                   "out through the hallway; its scans also look at the doors).")
@click.option("--overwrite", is_flag=True,
              help="Replace OUT if it is a psg-dataset psg-data wrote (by synth or convert; recordings psg-data synth "
                   "wrote with --format ros1|...) or an empty folder; anything else is refused.")
@quiet_option
@handle_errors
def synth_cmd(out: Path, fmt: str, seed: int, days: int, frames_per_scan: int, resolution: tuple[int, int],
              shift: str, generator: str, routine_strength: float, layout: str, overwrite: bool, quiet: bool) -> None:
    """Build the synthetic three-room lab (3 rooms, 2 doors, 28 receptacles, 21 objects).

    With no options it writes the default lab: 84 scans (21 days x 4 two-hour intervals from 09,
    11, 13, 15 h America/Toronto, one scan each), 8 frames each at 160x120, the first 14 days
    'train', the last 7 'test'; objects move only between intervals, and the generator's exact
    model is stored in generator/process.json.

    \b
    Examples:
      psg-data synth /tmp/lab
      psg-data synth /tmp/lab_shift --shift long-weekend --seed 3 --overwrite
      psg-data synth /tmp/small --days 2 --frames-per-scan 3 --resolution 80x60
      psg-data synth /tmp/clockwork --routine-strength 1
      psg-data synth /tmp/chain --layout chain
    """
    from psg_data.synth import LabConfig
    from psg_data.synth._model import check_memory

    setup_logging(quiet)
    config = LabConfig(seed=seed, days=days, frames_per_scan=frames_per_scan, width=resolution[0],
                       height=resolution[1], shift=None if shift == "none" else shift, generator=generator,
                       routine_strength=routine_strength, layout=layout)
    check_memory(config)
    try:
        _synth(out, fmt, config, overwrite, quiet)
    except OSError as exc:  # a full disk or a permission: name the output when the OS names no file
        if exc.filename:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(out)) from exc


def _synth(out: Path, fmt: str, config: Any, overwrite: bool, quiet: bool) -> None:
    from psg_data.synth import LabModel, build_lab
    from psg_data.writers._safe_output import check_output, commit_tree, make_staging

    kind = "dataset" if fmt == "canonical" else "recordings"
    check_output(out, overwrite=overwrite, kind=kind)
    lab = LabModel(config)
    prog = Progress("synth", total=len(lab.scans), unit="scans", quiet=quiet)
    if fmt == "canonical":
        build_lab(out, config, overwrite=overwrite, progress=prog, lab=lab)
        prog.close()
        click.echo(f"wrote {out} ({len(lab.scans)} scans)")
        return
    from psg_data.synth._raw_export import export_raw  # written by the raw-export helper

    stage = make_staging(out.with_name(out.name + ".partial"))  # beside OUT: the final move is a rename
    try:
        build_lab(stage / out.name, config, progress=prog, lab=lab)  # the lab's name: OUT's, not a staging one
        prog.close()
        export_raw(stage / out.name, stage / "recordings", fmt)
        commit_tree(stage / "recordings", out, kind="recordings")
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    click.echo(f"wrote {out} ({fmt}, {len(lab.scans)} scans)")
