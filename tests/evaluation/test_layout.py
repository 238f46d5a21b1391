"""The layout rule: psg_data.metrics holds pure metric functions and imports nothing from psg_data.evaluation."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import psg_data.metrics

METRICS_DIR = Path(psg_data.metrics.__file__).parent


def _imported_modules(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.append(node.module)
    return out


def test_metrics_source_imports_nothing_from_evaluation() -> None:
    files = sorted(METRICS_DIR.glob("*.py"))
    assert files
    for f in files:
        bad = [m for m in _imported_modules(f) if m == "psg_data.evaluation" or m.startswith("psg_data.evaluation.")]
        assert not bad, f"{f.name} imports {bad}"


def test_importing_metrics_loads_no_evaluation_module() -> None:
    code = ("import sys, psg_data.metrics, psg_data.metrics._classification, psg_data.metrics._navigation; "
            "print(','.join(m for m in sys.modules if m.startswith('psg_data.evaluation')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
