"""``psg-data lab-stats``: timing, persistence and time-of-week statistics of a synthetic lab, as JSON."""

from __future__ import annotations

import dataclasses
import json

import click

from psg_data.cli._common import dataset_path, handle_errors
from psg_data.cli._errors import ContractCommand

__all__ = ["lab_stats_cmd"]


@click.command("lab-stats", cls=ContractCommand)
@click.option("--generator", type=click.Choice(["steps-v2", "continuous-v1"]), default="steps-v2", show_default=True,
              help="Schedule generator of the lab (as psg-data synth --generator).")
@click.option("--routine-strength", type=click.FloatRange(0.0, 1.0), default=None,
              help="steps-v2 routine strength (default: the generator's).")
@click.option("--seed", type=int, default=0, show_default=True, help="Lab seed (as psg-data synth --seed).")
@click.option("--dataset", default=None, metavar="PATH|demo",
              help="Also report what the privileged labels of this lab dataset see (demo: the built-in lab).")
@click.option("--sim-weeks", type=click.IntRange(1), default=52, show_default=True,
              help="Simulated weeks for the time-of-week share.")
@handle_errors
def lab_stats_cmd(generator: str, routine_strength: float | None, seed: int, dataset: str | None,
                  sim_weeks: int) -> None:
    """Print the statistics of a lab configuration (definitions: psg_data/synth/stats.py) as JSON.

    \b
    Examples:
      psg-data lab-stats                                  # the built-in lab's configuration
      psg-data lab-stats --routine-strength 0 --dataset /tmp/lab_r0
    """
    from psg_data.synth._model import LabConfig
    from psg_data.synth.stats import schedule_statistics

    config = LabConfig(seed=seed, generator=generator)
    if routine_strength is not None:
        config = dataclasses.replace(config, routine_strength=routine_strength)
    out = schedule_statistics(config, sim_weeks=sim_weeks)
    if dataset:
        from psg_data.labeling import visibility_statistics

        out.update(visibility_statistics(dataset_path(dataset, command="psg-data lab-stats --dataset")))
    click.echo(json.dumps(out, indent=1))
