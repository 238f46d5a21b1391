"""The results folder of a docs script (a run of results/manifest.json): refused before any work if it may
not be written, then ``results.json`` committed through psg-data's safe-output rule (staged beside the
folder, renamed into place). Imported by the scripts of docs/analysis and docs/figures.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any


def refuse(out: Path | None) -> str | None:
    """One error line if ``out`` may not be written (it exists, or lies in an input), else None."""
    from psg_data.errors import PsgDataError
    from psg_data.writers._safe_output import check_output

    try:
        if out is not None:
            check_output(out, overwrite=False, kind="results")
    except PsgDataError as exc:
        return f"error: {exc}"
    return None


def write(out: Path, doc: dict[str, Any] | Callable[[Path], dict[str, Any]]) -> None:
    """``out/results.json`` through the safe-output rule; ``doc`` may be a function of the staging folder that
    writes further files there (a figure) and returns the document.
    """
    from psg_data.writers._safe_output import commit_tree, make_staging

    stage = make_staging(out.with_name(out.name + ".partial"))
    body = doc(stage) if callable(doc) else doc
    (stage / "results.json").write_text(json.dumps(body, indent=1) + "\n", encoding="utf-8")
    commit_tree(stage, out, kind="results")
