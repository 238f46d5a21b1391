"""``psg-eval compare``: earlier runs side by side, one table per task (read with the results schema's loader)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import click

__all__ = ["compare_runs"]


def compare_runs(dirs: tuple[Path, ...], *, fmt: str = "text", metrics: Sequence[str] = (),
                 references: bool = True) -> None:
    """Tabulate earlier psg-eval runs side by side (each DIR/results.json, :func:`psg_data.evaluation.load_results`).

    Persistence, navigation and door runs may be mixed: each task (and table) gets its own table;
    ``fmt``, ``metrics`` and ``references`` as :func:`psg_data.evaluation.format_compare` takes them.
    """
    from psg_data.evaluation import format_compare, load_results

    items = [(d.name, load_results(d)) for d in dirs]
    click.echo(format_compare(items, fmt=fmt, metrics=list(metrics) or None, references=references))
