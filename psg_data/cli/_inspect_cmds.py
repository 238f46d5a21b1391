"""``psg-data validate`` and ``psg-data info``."""

from __future__ import annotations

import sys

import click

from psg_data.cli._common import DATASET_HELP, EXIT_PROBLEMS, dataset_path, handle_errors
from psg_data.cli._errors import ContractCommand

__all__ = ["validate_cmd", "info_cmd"]


@click.command("validate", cls=ContractCommand, epilog=DATASET_HELP)
@click.argument("dataset", metavar="DATASET")
@click.option("--no-checksums", is_flag=True, help="Check file sizes only, not SHA-256 checksums (faster).")
@click.option("--quick", is_flag=True,
              help="Check image headers only (default: every image checked whole and decoded).")
@handle_errors
def validate_cmd(dataset: str, no_checksums: bool, quick: bool) -> None:
    """Check DATASET: manifest, schemas, ids, value ranges, images and checksums.

    Every image is checked whole (PNG chunk CRCs and data, JPEG headers and EOI) and decoded
    strictly (a JPEG decoder warning such as "Corrupt JPEG data" is a problem), and its size and
    sample format compared with its camera; --quick reads image headers only.

    Prints one line per problem (file[:row]: field: what is wrong, what was expected) and exits 1,
    or prints OK and exits 0.

    \b
    Examples:
      psg-data validate /tmp/lab
      psg-data validate demo --quick
    """
    from psg_data.schemas.validate import validate_dataset

    path = dataset_path(dataset, command="psg-data validate")

    problems = validate_dataset(path, checksums=not no_checksums, decode=not quick)
    if problems:
        for p in problems:
            click.echo(str(p))
        click.echo(f"error: {path}: {len(problems)} problem(s), listed above", err=True)
        sys.exit(EXIT_PROBLEMS)
    click.echo("OK")


def _fmt_bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} GB"  # pragma: no cover


@click.command("info", cls=ContractCommand, epilog=DATASET_HELP)
@click.argument("dataset", metavar="DATASET")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@handle_errors
def info_cmd(dataset: str, as_json: bool) -> None:
    """Summarise DATASET: scans, frames, time span, rooms, receptacles, objects, doors, size.

    \b
    Examples:
      psg-data info /tmp/lab
      psg-data info demo --json
    """
    import json

    from psg_data.loaders import open_dataset
    from psg_data.loaders._summary import summarize

    summary = summarize(open_dataset(dataset_path(dataset, command="psg-data info")))
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    s = summary
    click.echo(f"dataset      {s['name']}  ({s['format']} {s['format_version']}, colour {s['color_encoding']})")
    click.echo(f"path         {s['path']}")
    click.echo(f"scans        {s['scans']}  (splits: {', '.join(f'{k} {v}' for k, v in s['splits'].items()) or '-'})")
    click.echo(f"frames       {s['frames']}  ({s['frames_per_scan_min']}-{s['frames_per_scan_max']} per scan)")
    click.echo(f"time span    {s['start_local']} .. {s['end_local']}  ({s['timezone']}, {s['span_days']:.1f} days)")
    click.echo(f"cameras      {', '.join(s['cameras'])}")
    click.echo(f"rooms        {s['rooms']}")
    per_room = ", ".join(f"{k}: {v}" for k, v in s["receptacles_per_room"].items())
    click.echo(f"receptacles  {s['receptacles']}  ({per_room})")
    states = ", ".join(f"{k} {v}" for k, v in s["door_states"].items())
    click.echo(f"doors        {s['doors']}  (states: {states})")
    click.echo(f"objects      {s['objects']}")
    click.echo(f"schedule     {s['schedule_rows']} rows ({s['schedule_absent']} absent)")
    if s["extra_tables"]:
        click.echo(f"other tables {', '.join(s['extra_tables'])}")
    click.echo(f"size         {_fmt_bytes(s['size_bytes'])} in {s['files']} files")
