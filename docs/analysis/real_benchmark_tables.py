"""RESULTS.md section 8's tables, rendered from the runs' results.json (nothing typed by hand).

Run: python docs/analysis/real_benchmark_tables.py RUN_DIR [RUN_DIR ...] > tables.md

Each RUN_DIR is a ``psg-eval --dataset door-benchmark|room-presence-benchmark`` output folder; its
headroom, main and per-week tables are printed as Markdown, in that order, with the command and
revision of the run (``info.command``, ``info.git_revision``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def tables(run: Path) -> str:
    """The Markdown of one run: a heading line with its command, then its tables."""
    from psg_data.evaluation._state_report import render, state_tables

    doc = json.loads((run / "results.json").read_text(encoding="utf-8"))
    info = doc.get("info", {})
    title = f"{info.get('dataset', run.name)}, protocol {doc['protocol']}"
    head = (f"`{info.get('command', '?')}` (revision {str(info.get('git_revision') or '?')[:7]}, "
            f"{info.get('created', '?')})")
    grids = state_tables(doc, title)[:3]
    return head + "\n\n" + render(grids, "markdown")


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        return 2
    print("\n\n".join(tables(Path(a)) for a in argv))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
