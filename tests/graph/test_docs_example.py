"""README's "use the graph from your robot" example runs as written (on the demo dataset)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[2] / "README.md"


def _example() -> str:
    text = README.read_text(encoding="utf-8")
    m = re.search(r"<!-- example: use the graph from your robot.*?-->\s*```python\n(.*?)```", text, re.S)
    assert m, "README.md lost its 'use the graph from your robot' example"
    return m.group(1)


@pytest.mark.slow
def test_use_the_graph_from_your_robot(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    exec(compile(_example(), "README.md example", "exec"), {})
    out = capsys.readouterr().out
    assert "receptacle_id" in out and out.count("scan_") == 3
    from psg_data.graph import PredictiveGraph

    g = PredictiveGraph.load(tmp_path / "lab-graph.json")
    assert g.locate("hairbrush", "2025-03-21 10:00").best is not None
