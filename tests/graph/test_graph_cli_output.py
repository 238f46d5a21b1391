"""What ``psg-data graph`` prints: no fit chatter unless -v, the object asked for, the label source, a door
table whose header is not mistaken for rooms; options that cannot apply are refused, before the fit.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from tests.graph.test_graph_cli import AT


@pytest.fixture(autouse=True)
def _own_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "cache"))  # the command caches its fits there


def _graph(*args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, ["graph", *args])


def test_quiet_by_default_fit_lines_with_verbose(graph_dataset: Path, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """The fit's INFO lines (settings decided, error rates) only with -v (each call in its own cache: a second
    call on the same inputs would answer from the graph-fit cache without fitting)."""
    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "a"))
    r = _graph(str(graph_dataset), "--at", AT, "-e", "fremen")
    assert r.exit_code == 0, r.output
    assert "INFO:" not in r.stderr
    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "b"))
    v = _graph(str(graph_dataset), "--at", AT, "-e", "fremen", "-v")
    assert v.exit_code == 0 and "INFO: fremen: n_periods" in v.stderr, v.output


def test_output_names_the_object_the_labels_and_the_door_rooms(graph_dataset: Path) -> None:
    r = _graph(str(graph_dataset), "--at", AT, "-e", "fremen", "--object", "book", "--labels", "gt")
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    assert "labels gt" in lines[0]
    assert lines[1].startswith("book: its receptacles ranked")
    door_header = next(ln for ln in lines if ln.lstrip().startswith("door_id"))
    assert door_header.split() == ["door_id", "p_open", "between"]
    row = next(ln for ln in lines if ln.lstrip().startswith("door1"))
    assert " and " in row


def test_estimator_or_labels_on_a_saved_graph_are_refused(graph_dataset: Path, tmp_path: Path) -> None:
    saved = tmp_path / "g.json"
    assert _graph(str(graph_dataset), "--at", AT, "-e", "fremen", "--save-graph", str(saved)).exit_code == 0
    for extra in (["-e", "perpetua"], ["--labels", "privileged"]):
        r = _graph(str(saved), "--at", AT, *extra)
        assert r.exit_code == 1 and r.stderr.startswith("error: ") and "saved graph" in r.stderr, r.output
    assert _graph(str(saved), "--at", AT).exit_code == 0


def test_existing_save_graph_is_refused_before_the_fit(graph_dataset: Path, tmp_path: Path) -> None:
    """An estimator that would fail its fit is never reached: the output path is checked first."""
    saved = tmp_path / "g.json"
    saved.write_text("{}")
    r = _graph(str(graph_dataset), "--at", AT, "-e", "no_such_estimator", "--save-graph", str(saved))
    assert r.exit_code == 1 and "exists; pass --overwrite" in r.stderr, r.output
    assert saved.read_text() == "{}"
