"""The one table renderer of every task (rich), used the same way by the CLI, ``compare`` and ``table.txt``.

A cell is ``estimate ± half-width`` of its stated interval (just the estimate when there is none);
``*`` marks the best row of a column among the rows that are not a ceiling; reference rows
(ceiling, baselines, chance) come first, above a rule; the lines under the table say what every
column measures, the chance level, where the ceiling stands and what ``±`` is.
"""

from __future__ import annotations

import io
import math
import sys
from collections.abc import Sequence
from typing import Any

from psg_data.evaluation._results import ROLES, EvalResults, ResultRow, ResultTable

__all__ = ["render_table", "format_table", "format_results", "print_results", "format_compare", "cell_text"]

_ARROW = {"lower": "↓", "higher": "↑"}


def cell_text(s: Any, scale: float, digits: int) -> str:
    """``0.185 ± 0.012``; ``-`` for no value."""
    if s is None or not math.isfinite(s.mean):
        return "-"
    hw = s.half_width
    v = f"{scale * s.mean:.{digits}f}"
    return v if not math.isfinite(hw) else f"{v} ± {scale * hw:.{digits}f}"


def _best(table: ResultTable) -> dict[str, float]:
    best: dict[str, float] = {}
    for m in table.metrics:
        vals = [r.values[m.key].mean for r in table.rows if r.role != "ceiling" and m.key in r.values
                and math.isfinite(r.values[m.key].mean)]
        if vals:
            best[m.key] = min(vals) if m.better == "lower" else max(vals)
    return best


def _headers(table: ResultTable) -> list[str]:
    group_of = {k: g for g, ks in table.groups for k in ks}
    first = {ks[0] for _, ks in table.groups if ks}
    out = []
    for m in table.metrics:
        label = f"{m.label} {_ARROW.get(m.better, '')}".strip()
        if m.key in group_of:
            label = (f"{group_of[m.key]}\n" if m.key in first else "\n") + label
        out.append(label)
    return out


def _ordered(rows: Sequence[ResultRow]) -> list[ResultRow]:
    rank = {r: i for i, r in enumerate(ROLES)}
    return sorted(rows, key=lambda r: rank.get(r.role, len(ROLES)))


def render_table(table: ResultTable, *, run: str | None = None, show_title: bool = True) -> Any:
    """A ``rich.table.Table`` of ``table`` (``run``: an extra first column, for ``compare``)."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

    t = Table(title=Text(table.title) if show_title else None, box=box.SIMPLE_HEAD, title_justify="left",
              show_edge=False, pad_edge=False)
    if run is not None:
        t.add_column("run")
    t.add_column("Method", no_wrap=True)
    t.add_column("ref", style="dim")
    for h in _headers(table):
        t.add_column(Text(h), justify="right", no_wrap=True)
    if table.primary is not None:
        t.add_column(f"% of ceiling\n({table.metric(table.primary).label})", justify="right")
    for c in table.count_columns:
        t.add_column(c, justify="right")
    best = _best(table)
    rows = _ordered(table.rows)
    for i, r in enumerate(rows):
        cells = [] if run is None else [run]
        cells += [r.method, "" if r.role == "method" else r.role]
        for m in table.metrics:
            s = r.values.get(m.key)
            text = cell_text(s, m.scale, m.digits)
            mark = (r.role != "ceiling" and s is not None and m.key in best
                    and abs(s.mean - best[m.key]) < 0.5 * 10 ** -m.digits / m.scale)
            cells.append(text + ("*" if mark else " "))
        if table.primary is not None:
            cells.append("-" if r.pct_of_ceiling is None or not math.isfinite(r.pct_of_ceiling)
                         else f"{r.pct_of_ceiling:.0f} %")
        cells += [str(r.counts.get(c, "-")) for c in table.count_columns]
        last_ref = r.role != "method" and (i + 1 == len(rows) or rows[i + 1].role == "method")
        t.add_row(*(Text(c) for c in cells), end_section=last_ref)
    return t


def _console(file: Any, width: int | None, plain: bool) -> Any:
    from rich.console import Console

    return Console(file=file, width=width, no_color=plain, color_system=None if plain else "auto",
                   force_terminal=False if plain else None, soft_wrap=False, highlight=False, emoji=False)


WIDE = 1000
"""Console width of plain-text renders: tables take their natural width and never wrap."""


def format_table(table: ResultTable, *, width: int | None = WIDE, notes: bool = True) -> str:
    """Plain text of one table (and its notes): what ``table.txt`` holds."""
    buf = io.StringIO()
    con = _console(buf, width, True)
    con.print(render_table(table, show_title=False))
    text = buf.getvalue().rstrip("\n")
    lines = [table.title, *(ln.rstrip() for ln in text.splitlines())]
    if notes:
        lines += table.notes
    return "\n".join(lines)


def format_results(results: EvalResults, *, width: int | None = WIDE) -> str:
    """Plain text of every table of a run, with their notes."""
    return "\n\n".join(format_table(t, width=width) for t in results.tables)


def print_results(results: EvalResults, *, file: Any = None) -> None:
    """Print every table and its notes to ``file`` (default stdout) through rich: styled in a
    terminal, plain text (wide enough not to wrap) when redirected.
    """
    out = file if file is not None else sys.stdout
    is_tty = hasattr(out, "isatty") and out.isatty()
    con = _console(out, None if is_tty else WIDE, not is_tty)
    for k, t in enumerate(results.tables):
        if k:
            con.print()
        con.print(t.title, markup=False, style="bold" if is_tty else None, overflow="ignore", crop=False)
        con.print(render_table(t, show_title=False))
        for line in t.notes:
            con.print(line, markup=False, style="dim" if is_tty else None, overflow="ignore", crop=False)


def format_compare(items: Sequence[tuple[str, EvalResults]], *, width: int | None = WIDE) -> str:
    """``psg-eval compare``: per task and table name, every run's rows in one table (same renderer)."""
    by_key: dict[tuple[str, str], list[tuple[str, ResultTable, EvalResults]]] = {}
    for run, res in items:
        for t in res.tables:
            by_key.setdefault((res.task, t.name), []).append((run, t, res))
    blocks = []
    for (task, name), runs in by_key.items():
        first = runs[0][1]
        merged = ResultTable(name, f"[{task}] {first.title}", first.metrics, [], [], first.groups, first.count_columns,
                             first.primary)
        buf = io.StringIO()
        con = _console(buf, width, True)
        from rich import box
        from rich.table import Table
        from rich.text import Text

        grid = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False)
        for c in ("run", "Method", "ref", "setting", *(_headers(merged)), "±"):
            grid.add_column(Text(c), justify="left" if c in ("run", "Method", "ref", "setting", "±") else "right",
                         no_wrap=True)
        for run, table, res in runs:
            for r in _ordered(table.rows):
                iv = next((s for s in r.values.values()), None)
                what = f"{iv.method} over {iv.n} {iv.unit}" if iv is not None and iv.method != "none" else "-"
                cells = [run, r.method, "" if r.role == "method" else r.role, str(res.config.get("setting_text", "-")),
                         *[cell_text(r.values.get(m.key), m.scale, m.digits) for m in table.metrics], what]
                grid.add_row(*(Text(c) for c in cells))
        con.print(grid)
        blocks.append("\n".join([merged.title, *(ln.rstrip() for ln in buf.getvalue().rstrip("\n").splitlines())]))
    return "\n\n".join(blocks)
