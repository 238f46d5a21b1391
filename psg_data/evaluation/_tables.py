"""The one table renderer of every task (rich), used the same way by the CLI, ``compare`` and ``table.txt``.

A cell is ``estimate ± half-width`` of its stated interval (just the estimate when there is none), or
``estimate ± standard deviation`` for a table whose ``spread`` is ``std``; every format (text, CSV,
JSON, Markdown, LaTeX) shows the same number and the line under the table says which it is;
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

from psg_data.errors import EvaluationError
from psg_data.evaluation._results import ROLES, EvalResults, ResultRow, ResultTable
from psg_data.evaluation._table_formats import plain_text

__all__ = ["render_table", "format_table", "format_results", "print_results", "format_compare", "cell_text",
           "best_marks", "ordered_rows", "format_as", "COMPARE_FORMATS", "plus_minus"]

_ARROW = {"lower": "↓", "higher": "↑"}


def plus_minus(s: Any, spread: str = "interval") -> float:
    """The number a cell shows after ``±``: the interval's half-width, or with ``spread="std"`` the
    standard deviation across the units (NaN: none).
    """
    if spread == "std":
        return float(s.std) if math.isfinite(s.std) else float("nan")
    return float(s.half_width)


def cell_text(s: Any, scale: float, digits: int, spread: str = "interval") -> str:
    """``0.185 ± 0.012`` (± per :func:`plus_minus`); ``-`` for no value."""
    if s is None or not math.isfinite(s.mean):
        return "-"
    hw = plus_minus(s, spread)
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
        label = plain_text(f"{m.label} {_ARROW.get(m.better, '')}".strip())
        if m.key in group_of:
            label = (f"{plain_text(group_of[m.key])}\n" if m.key in first else "\n") + label
        out.append(label)
    return out


def ordered_rows(rows: Sequence[ResultRow]) -> list[ResultRow]:
    """Rows in table order: ceiling, baselines, chance, then the methods (stable within a role)."""
    rank = {r: i for i, r in enumerate(ROLES)}
    return sorted(rows, key=lambda r: rank.get(r.role, len(ROLES)))


def best_marks(table: ResultTable, rows: Sequence[ResultRow]) -> list[list[bool]]:
    """Per row and metric of ``table``: whether the cell is the column's best among the non-ceiling
    rows (equal at the shown digits).
    """
    best = _best(table)
    out = []
    for r in rows:
        marks = []
        for m in table.metrics:
            s = r.values.get(m.key)
            marks.append(r.role != "ceiling" and s is not None and m.key in best
                         and abs(s.mean - best[m.key]) < 0.5 * 10 ** -m.digits / m.scale)
        out.append(marks)
    return out


def render_table(table: ResultTable, *, run: str | None = None, show_title: bool = True) -> Any:
    """A ``rich.table.Table`` of ``table`` (``run``: an extra first column, for ``compare``)."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

    t = Table(title=Text(plain_text(table.title)) if show_title else None, box=box.SIMPLE_HEAD, title_justify="left",
              show_edge=False, pad_edge=False)
    if run is not None:
        t.add_column("run")
    t.add_column("Method", no_wrap=True)
    t.add_column("ref", style="dim")
    for h in _headers(table):
        t.add_column(Text(h), justify="right", no_wrap=True)
    if table.primary is not None:
        t.add_column(Text(f"% of ceiling\n({plain_text(table.metric(table.primary).label)})"), justify="right")
    for c in table.count_columns:
        t.add_column(Text(plain_text(c)), justify="right")
    rows = ordered_rows(table.rows)
    marks = best_marks(table, rows)
    for i, r in enumerate(rows):
        cells = [] if run is None else [run]
        cells += [r.method, "" if r.role == "method" else r.role]
        for k, m in enumerate(table.metrics):
            cell = cell_text(r.values.get(m.key), m.scale, m.digits, table.spread)
            cells.append(cell + ("*" if marks[i][k] else " "))
        if table.primary is not None:
            cells.append("-" if r.pct_of_ceiling is None or not math.isfinite(r.pct_of_ceiling)
                         else f"{r.pct_of_ceiling:.0f} %")
        cells += [str(r.counts.get(c, "-")) for c in table.count_columns]
        last_ref = r.role != "method" and (i + 1 == len(rows) or rows[i + 1].role == "method")
        t.add_row(*(Text(plain_text(c)) for c in cells), end_section=last_ref)
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
    lines = [plain_text(table.title), *(ln.rstrip() for ln in text.splitlines())]
    if notes:
        lines += [plain_text(n) for n in table.notes]
    return "\n".join(lines)


def format_results(results: EvalResults, *, width: int | None = WIDE) -> str:
    """Plain text of every table of a run, with their notes."""
    return "\n\n".join(format_table(t, width=width) for t in results.tables)


def print_results(results: EvalResults, *, file: Any = None, fmt: str = "text") -> None:
    """Print every table and its notes to ``file`` (default stdout): ``text`` through rich (styled in a
    terminal, plain text wide enough not to wrap when redirected), or ``markdown`` / ``latex``
    (:mod:`psg_data.evaluation._table_formats`, to paste into a paper).
    """
    out = file if file is not None else sys.stdout
    if fmt != "text":
        out.write(format_as(results.tables, fmt) + "\n")
        return
    is_tty = hasattr(out, "isatty") and out.isatty()
    con = _console(out, None if is_tty else WIDE, not is_tty)
    for k, t in enumerate(results.tables):
        if k:
            con.print()
        con.print(plain_text(t.title), markup=False, style="bold" if is_tty else None, overflow="ignore", crop=False)
        con.print(render_table(t, show_title=False))
        for line in t.notes:
            con.print(plain_text(line), markup=False, style="dim" if is_tty else None, overflow="ignore", crop=False)


def format_as(tables: Sequence[ResultTable], fmt: str) -> str:
    """Tables with their notes in ``fmt``: ``text`` (as table.txt), ``markdown`` or ``latex``."""
    from psg_data.evaluation._table_formats import latex_table, markdown_table, table_grid

    if fmt == "text":
        return "\n\n".join(format_table(t) for t in tables)
    if fmt == "markdown":
        return "\n\n".join(markdown_table(table_grid(t)) for t in tables)
    if fmt == "latex":
        return "\n\n".join(latex_table(table_grid(t), label=f"tab:{t.name}") for t in tables)
    raise EvaluationError(f"format {fmt!r}: expected text, markdown or latex")


COMPARE_FORMATS = ("text", "csv", "json", "markdown", "latex")
"""What ``psg-eval compare --format`` writes."""


def format_compare(items: Sequence[tuple[str, EvalResults]], *, width: int | None = WIDE, fmt: str = "text",
                   metrics: Sequence[str] | None = None, references: bool = True) -> str:
    """``psg-eval compare``: per task and table name, every run's rows in one table.

    Args:
        items: (run name, its results) in the order to show.
        width: console width of the text form.
        fmt: one of :data:`COMPARE_FORMATS`: ``text`` (the text renderer), ``markdown`` / ``latex``
            (as ``psg-eval --format``), ``csv`` (one row per run and method: each metric's mean,
            interval ends and half-width) or ``json`` (the same, nested by table).
        metrics: only these metric columns (keys or labels); default all.
        references: keep the reference rows (ceiling, baselines, chance); False: only the methods.

    Raises:
        EvaluationError: an unknown format or metric.
    """
    from psg_data.evaluation._table_formats import select_table

    if fmt not in COMPARE_FORMATS:
        raise EvaluationError(f"format {fmt!r}: expected one of {', '.join(COMPARE_FORMATS)}")
    groups: dict[tuple[str, str], list[tuple[str, ResultTable, EvalResults]]] = {}
    for run, res in items:
        for t in res.tables:
            chosen = select_table(t, metrics=metrics, references=references)
            groups.setdefault((res.task, t.name), []).append((run, chosen, res))
    if fmt in ("csv", "json"):
        return _compare_records(groups, fmt)
    if fmt != "text":
        return "\n\n".join(_compare_paper(task, runs, fmt) for (task, _), runs in groups.items())
    return "\n\n".join(_compare_text(task, runs, width) for (task, _), runs in groups.items())


_Runs = list[tuple[str, ResultTable, EvalResults]]
_PM_MEANING = {"interval": "half-width of the stated interval", "std": "standard deviation across query sets"}
"""What ``<metric>_pm`` (the number after a cell's ±) is, per table ``spread``."""


def _interval_text(r: ResultRow, spread: str = "interval") -> str:
    iv = next((s for s in r.values.values()), None)
    if iv is None or (iv.method == "none" and spread != "std"):
        return "-"
    return "standard deviation across query sets" if spread == "std" else f"{iv.method} over {iv.n} {iv.unit}"


def _compare_text(task: str, runs: _Runs, width: int | None) -> str:
    from rich import box
    from rich.table import Table
    from rich.text import Text

    first = runs[0][1]
    merged = ResultTable(first.name, f"[{task}] {first.title}", first.metrics, [], [], first.groups,
                         first.count_columns, first.primary)
    grid = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False)
    for c in ("run", "Method", "ref", "setting", *(_headers(merged)), "±"):
        grid.add_column(Text(c), justify="left" if c in ("run", "Method", "ref", "setting", "±") else "right",
                        no_wrap=True)
    for run, table, res in runs:
        for r in ordered_rows(table.rows):
            cells = [run, r.method, "" if r.role == "method" else r.role, str(res.config.get("setting_text", "-")),
                     *[cell_text(r.values.get(m.key), m.scale, m.digits, table.spread) for m in table.metrics],
                     _interval_text(r, table.spread)]
            grid.add_row(*(Text(plain_text(c)) for c in cells))
    buf = io.StringIO()
    _console(buf, width, True).print(grid)
    return "\n".join([plain_text(merged.title), *(ln.rstrip() for ln in buf.getvalue().rstrip("\n").splitlines())])


def _compare_paper(task: str, runs: _Runs, fmt: str) -> str:
    """One Markdown / LaTeX table of every run's rows (a rule between runs; no best marks across runs)."""
    from psg_data.evaluation._table_formats import latex_table, markdown_table, table_grid

    blocks = []
    for run, table, res in runs:
        rows = ordered_rows(table.rows)
        n = len(rows)
        setting = str(res.config.get("setting_text", "-"))
        blocks.append(table_grid(table, lead=[("run", [run] * n), ("setting", [setting] * n)],
                                 tail=[("±", [_interval_text(r, table.spread) for r in rows])], mark_best=False))
    grid = blocks[0]
    grid.title = f"[{task}] {grid.title}"
    grid.rules = []
    for b in blocks[1:]:
        if b.groups != grid.groups:
            grid.groups = []
        grid.rules.append(len(grid.rows) - 1)
        grid.rows += b.rows
    grid.notes = [n for n in grid.notes if n.startswith("±")] if len(runs) == 1 else \
        ["±: each run's own interval, named in the ± column"]
    refs = any(r.role != "method" for _, table, _ in runs for r in table.rows)
    grid.legend = "; ".join(p for p in ("reference rows named in the ref column" if refs else "",
                                        "a rule between runs" if len(runs) > 1 else "") if p)
    return markdown_table(grid) if fmt == "markdown" else latex_table(grid, label=f"tab:compare-{runs[0][1].name}")


def _compare_records(groups: dict[tuple[str, str], _Runs], fmt: str) -> str:
    tables: list[dict[str, Any]] = []
    for (task, name), runs in groups.items():
        rows: list[dict[str, Any]] = []
        for run, table, res in runs:
            for r in ordered_rows(table.rows):
                values = {m.key: {"mean": s.mean, "ci_low": s.ci_low, "ci_high": s.ci_high, "half_width": s.half_width,
                                  "n": s.n, "interval": s.method, "unit": s.unit, "pm": plus_minus(s, table.spread)}
                          for m in table.metrics if (s := r.values.get(m.key)) is not None}
                rows.append({"run": run, "method": r.method, "role": r.role,
                             "setting": res.config.get("setting_text"), "values": values,
                             "pm": _PM_MEANING[table.spread],
                             "pct_of_ceiling": r.pct_of_ceiling if table.primary is not None else None})
        group_of = {k: g for g, ks in runs[0][1].groups for k in ks}
        tables.append({"task": task, "table": name, "title": runs[0][1].title,
                       "metrics": [{**m.to_dict(), "group": group_of.get(m.key)} for m in runs[0][1].metrics],
                       "rows": rows})
    if fmt == "json":
        import json

        from psg_data.evaluation._persistence_types import clean_json

        return json.dumps(clean_json({"tables": tables}), indent=1, allow_nan=False)
    import csv

    buf = io.StringIO()
    fields: list[str] = ["task", "table", "run", "method", "role", "setting", "pm"]
    recs: list[dict[str, Any]] = []
    for t in tables:
        for row in t["rows"]:
            rec = {"task": t["task"], "table": t["table"], **{k: row[k] for k in fields[2:]}}
            for key, v in row["values"].items():
                rec.update({f"{key}{suffix}": v[part] for suffix, part in
                            (("", "mean"), ("_ci_low", "ci_low"), ("_ci_high", "ci_high"),
                             ("_half_width", "half_width"), ("_pm", "pm"))})
                rec.setdefault("interval", f"{v['interval']} over {v['n']} {v['unit']}")
            recs.append(rec)
    for rec in recs:
        fields += [k for k in rec if k not in fields]
    w = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
    w.writeheader()
    w.writerows(recs)
    return buf.getvalue().rstrip("\n")
