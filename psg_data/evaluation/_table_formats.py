r"""Results tables as Markdown and LaTeX (booktabs), ready for a paper; and the table selection
(``--metric``, ``--no-references``) that ``psg-eval compare`` applies before any format.

The cells and marks are those of the text renderer (:mod:`psg_data.evaluation._tables`): a cell is
``estimate ± half-width`` of its stated interval; the best row of a column that is not a ceiling is
marked (bold here, ``*`` in text); grouped columns (navigation: Static / Dynamic / Absence / Overall) keep
their group above them (LaTeX: a spanning row over a ``\cmidrule``; Markdown, which has one header
row: the group named in each of its columns' headers); reference rows (ceiling, baselines, chance) come first, name
their role in the ``ref`` column and are set off by a rule (LaTeX ``\midrule``); the lines under the
table (what each column measures, the chance level, what ``±`` is) follow it (LaTeX: the ``±``
line in the caption, every line as a comment).
"""

from __future__ import annotations

import math
import re
import unicodedata
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

from psg_data.errors import EvaluationError
from psg_data.evaluation._results import ResultRow, ResultTable

__all__ = ["TABLE_FORMATS", "Grid", "table_grid", "markdown_table", "latex_table", "select_table", "grouped_header",
           "plain_text", "md_escape", "tex_escape", "tex_comment"]

TABLE_FORMATS = ("text", "markdown", "latex")
"""What ``psg-eval --format`` prints."""

_ARROW = {"lower": "↓", "higher": "↑"}


@dataclass
class Grid:
    """A table as plain cells: what the Markdown and LaTeX writers lay out.

    Attributes:
        title: the table's title.
        header: column names.
        numeric: per column, whether it is right-aligned (numbers).
        rows: per row, ``(text, best)`` per column (``best``: the column's best non-ceiling value).
        rules: indices of the rows after which a rule goes (the last reference row).
        notes: the lines under the table.
        legend: what the rules and marks mean (the LaTeX caption says it after the title).
        groups: column groups as (name, first column index, number of columns), left to right.
    """

    title: str
    header: list[str]
    numeric: list[bool]
    rows: list[list[tuple[str, bool]]]
    rules: list[int]
    notes: list[str]
    legend: str = ""
    groups: list[tuple[str, int, int]] = field(default_factory=list)


def select_table(table: ResultTable, *, metrics: Sequence[str] | None = None, references: bool = True) -> ResultTable:
    """``table`` with only the chosen metric columns (keys or labels, any case) and, without
    ``references``, only the method rows.

    Raises:
        EvaluationError: a metric the table does not have (the message lists its metrics).
    """
    keep = list(table.metrics)
    if metrics:
        by_name = {**{m.key.lower(): m for m in table.metrics}, **{m.label.lower(): m for m in table.metrics}}
        unknown = [k for k in metrics if k.lower() not in by_name]
        if unknown:
            names = ", ".join(f"{m.key} ({m.label})" for m in table.metrics)
            raise EvaluationError(f"--metric {unknown[0]}: table {table.name!r} has no such metric; its metrics: "
                                  f"{names}")
        chosen = {by_name[k.lower()].key for k in metrics}
        keep = [m for m in table.metrics if m.key in chosen]
    keys = {m.key for m in keep}
    rows = [r for r in table.rows if references or r.role == "method"]
    groups = [(g, [k for k in ks if k in keys]) for g, ks in table.groups]
    return replace(table, metrics=keep, rows=rows, groups=[(g, ks) for g, ks in groups if ks],
                   primary=table.primary if table.primary in keys and references else None)


def table_grid(table: ResultTable, *, lead: Sequence[tuple[str, Sequence[str]]] = (),
               tail: Sequence[tuple[str, Sequence[str]]] = (), mark_best: bool = True) -> Grid:
    """The cells of ``table`` (rows in table order).

    Args:
        table: the table.
        lead: extra first text columns: (name, one value per row in table order).
        tail: extra last text columns, likewise.
        mark_best: mark each column's best non-ceiling cell.
    """
    from psg_data.evaluation._tables import best_marks, cell_text, ordered_rows

    rows = ordered_rows(table.rows)
    marks = best_marks(table, rows) if mark_best else [[False] * len(table.metrics) for _ in rows]
    header = [name for name, _ in lead] + ["Method", "ref"]
    header += [f"{m.label} {_ARROW.get(m.better, '')}".strip() for m in table.metrics]
    if table.primary is not None:
        header.append(f"% of ceiling ({table.metric(table.primary).label})")
    header += list(table.count_columns)
    numeric = [False] * (len(lead) + 2) + [True] * (len(header) - len(lead) - 2) + [False] * len(tail)
    header += [name for name, _ in tail]
    out: list[list[tuple[str, bool]]] = []
    for i, r in enumerate(rows):
        cells = [(str(values[i]), False) for _, values in lead]
        cells += [(r.method, False), ("" if r.role == "method" else r.role, False)]
        cells += [(cell_text(r.values.get(m.key), m.scale, m.digits, table.spread), marks[i][k])
                  for k, m in enumerate(table.metrics)]
        if table.primary is not None:
            cells.append(("-" if r.pct_of_ceiling is None or not math.isfinite(r.pct_of_ceiling)
                          else f"{r.pct_of_ceiling:.0f} %", False))
        cells += [(str(r.counts.get(c, "-")), False) for c in table.count_columns]
        cells += [(str(values[i]), False) for _, values in tail]
        out.append(cells)
    legend = "; ".join(p for p in (
        "reference rows (ref: ceiling, baseline, chance) above the rule" if any(r.role != "method" for r in rows)
        else "", "bold: the best row of a column that is not a ceiling" if mark_best else "") if p)
    return Grid(table.title, header, numeric, out, _rules(rows), list(table.notes), legend,
                _group_spans(table, len(lead) + 2))


def _group_spans(table: ResultTable, first: int) -> list[tuple[str, int, int]]:
    """(group, first column, width) of each run of adjacent metric columns in one group of ``table``."""
    group_of = {k: g for g, ks in table.groups for k in ks}
    spans: list[tuple[str, int, int]] = []
    for k, m in enumerate(table.metrics):
        g = group_of.get(m.key)
        if g is None:
            continue
        if spans and spans[-1][0] == g and spans[-1][1] + spans[-1][2] == first + k:
            spans[-1] = (g, spans[-1][1], spans[-1][2] + 1)
        else:
            spans.append((g, first + k, 1))
    return spans


def grouped_header(grid: Grid) -> list[str]:
    """The header with each grouped column's group before its name (``Static presence (157) SR % ↑``):
    one header row that still says which group a column belongs to.
    """
    header = list(grid.header)
    for g, start, width in grid.groups:
        for c in range(start, start + width):
            header[c] = f"{g} {header[c]}"
    return header


def _rules(rows: Sequence[ResultRow]) -> list[int]:
    return [i for i, r in enumerate(rows) if r.role != "method" and i + 1 < len(rows) and rows[i + 1].role == "method"]


# -- Markdown ------------------------------------------------------------------------------------
def _md(text: str) -> str:
    return md_escape(text)


def markdown_table(grid: Grid) -> str:
    """A GitHub / pandoc pipe table: the title in bold above it, each grouped column's group in its
    header, best cells in bold, the notes below.
    """
    lines = [f"**{_md(grid.title)}**", "", "| " + " | ".join(_md(h) for h in grouped_header(grid)) + " |",
             "|" + "|".join("---:" if n else "---" for n in grid.numeric) + "|"]
    for cells in grid.rows:
        lines.append("| " + " | ".join(f"**{_md(t)}**" if best and t else _md(t) for t, best in cells) + " |")
    if grid.notes:
        lines += ["", *(f"- {_md(n)}" for n in grid.notes)]
    return "\n".join(lines)


# -- LaTeX ---------------------------------------------------------------------------------------
_TEX_CHARS = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_", "{": r"\{",
              "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}", "<": r"\textless{}",
              ">": r"\textgreater{}", "±": r"\ensuremath{\pm}", "↓": r"\ensuremath{\downarrow}",
              "↑": r"\ensuremath{\uparrow}", "≥": r"\ensuremath{\geq}", "≤": r"\ensuremath{\leq}",
              "×": r"\ensuremath{\times}", "→": r"\ensuremath{\rightarrow}", "−": "-", "–": "--", "—": "---",
              "·": r"\ensuremath{\cdot}", "°": r"\ensuremath{^\circ}", "≈": r"\ensuremath{\approx}",
              "Δ": r"\ensuremath{\Delta}", "δ": r"\ensuremath{\delta}", "γ": r"\ensuremath{\gamma}",
              "α": r"\ensuremath{\alpha}", "µ": r"\ensuremath{\mu}", "σ": r"\ensuremath{\sigma}"}


def tex_escape(text: str) -> str:
    """``text`` as LaTeX that pdflatex sets without extra packages (other non-ASCII letters lose their accents);
    every character TeX treats specially is escaped and line breaks and control characters are
    neutralised first (:func:`plain_text`), so no text of a results file is ever live LaTeX.
    """
    out = []
    for ch in plain_text(text):
        if ch in _TEX_CHARS:
            out.append(_TEX_CHARS[ch])
        elif ord(ch) < 128:
            out.append(ch)
        else:
            out.append(unicodedata.normalize("NFKD", ch).encode("ascii", "ignore").decode() or "?")
    return "".join(out)


def _tex_cell(text: str, best: bool) -> str:
    value, pm, half = text.partition(" ± ")
    v = tex_escape(value)
    v = rf"\textbf{{{v}}}" if best and value not in ("", "-") else v
    return rf"{v} $\pm$ {tex_escape(half)}" if pm else v


def _tex_group_rows(grid: Grid) -> list[str]:
    r"""The group row (``\multicolumn`` over each group's columns) and its ``\cmidrule`` s; none without groups."""
    if not grid.groups:
        return []
    cells: list[str] = []
    col = 0
    for g, start, width in grid.groups:
        cells += [""] * (start - col)
        cells.append(rf"\multicolumn{{{width}}}{{c}}{{{tex_escape(g)}}}")
        col = start + width
    cells += [""] * (len(grid.header) - col)
    rules = " ".join(rf"\cmidrule(lr){{{start + 1}-{start + width}}}" for _, start, width in grid.groups)
    return [" & ".join(cells) + r" \\", rules]


def latex_table(grid: Grid, *, label: str | None = None) -> str:
    r"""A ``table`` float with a booktabs ``tabular`` (``\usepackage{booktabs}``), the rows and
    rules of the text table, best cells in bold; the caption names the title, the marks and ``±``.
    """
    pm = next((n for n in grid.notes if n.startswith("±")), "")
    said = "; ".join(p for p in (grid.legend, pm) if p)
    caption = tex_escape(grid.title + (f". {said[:1].upper()}{said[1:]}" if said else "") + ".")
    spec = "".join("r" if n else "l" for n in grid.numeric)
    lines = ["% psg-eval table; needs \\usepackage{booktabs}", *(f"% {tex_comment(n)}" for n in grid.notes),
             r"\begin{table}[t]", r"\centering", r"\small", rf"\caption{{{caption}}}"]
    if label:
        lines.append(rf"\label{{{tex_escape(label)}}}")
    lines += [rf"\begin{{tabular}}{{{spec}}}", r"\toprule", *_tex_group_rows(grid),
              " & ".join(tex_escape(h) for h in grid.header) + r" \\", r"\midrule"]
    for i, cells in enumerate(grid.rows):
        lines.append(" & ".join(_tex_cell(t, b) if grid.numeric[k] else tex_escape(t)
                                for k, (t, b) in enumerate(cells)) + r" \\")
        if i in grid.rules:
            lines.append(r"\midrule")
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines)



# -- escaping per output format (every text of a results file is untrusted, docs/SECURITY.md) -----
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069]")
_BREAKS = "\t\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"


def _visible(m: re.Match[str]) -> str:
    ch = m.group()
    if ch in _BREAKS:
        return " "
    return f"\\x{ord(ch):02x}" if ord(ch) < 256 else f"\\u{ord(ch):04x}"


def plain_text(text: str) -> str:
    r"""``text`` on one line with nothing a terminal acts on: line breaks and tabs become spaces, every
    other control character (the ESC of escape sequences, bidirectional overrides) shows as
    ``\xNN`` / ``\uNNNN``. The text renderer and both paper formats apply it first.
    """
    return _CONTROL.sub(_visible, str(text))


_MD_CHARS = {"\\": "\\\\", "`": "\\`", "*": "\\*", "_": "\\_", "|": "\\|", "~": "\\~", "<": "&lt;", ">": "&gt;",
             "&": "&amp;"}


def md_escape(text: str) -> str:
    """``text`` as literal Markdown (GitHub, pandoc): on one line, no emphasis, code, link, table cell
    break or HTML (``<`` ``>`` ``&`` as entities).
    """
    return "".join(_MD_CHARS.get(ch, ch) for ch in plain_text(text)).replace("](", "]\\(")  # no inline link


def tex_comment(text: str) -> str:
    """``text`` for a LaTeX ``%`` comment line: on one line (a line break would end the comment)."""
    return plain_text(text)
