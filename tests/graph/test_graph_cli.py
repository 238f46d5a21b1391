"""``psg-data graph``: the snapshot or a ranking as a table, a CSV and a PNG; a saved graph as input; bad input."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.graph import PredictiveGraph
from tests.graph.conftest import T0_S

AT = "2023-11-16 07:00"  # site time (UTC), after the training scans of the test dataset


@pytest.fixture(autouse=True)
def _own_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "cache"))  # the command caches its fits there


def test_ranking_table_csv_png_and_a_saved_graph(graph_dataset: Path, tmp_path: Path) -> None:
    r = CliRunner().invoke(main, ["graph", str(graph_dataset), "--at", AT, "--object", "book", "-e", "fremen",
                                  "--csv", str(tmp_path / "r.csv"), "--png", str(tmp_path / "r.png"),
                                  "--save-graph", str(tmp_path / "g.json"), "-q"])
    assert r.exit_code == 0, r.output
    g = PredictiveGraph.load(tmp_path / "g.json")
    want = g.locate("book", AT).to_pandas()
    got = pd.read_csv(tmp_path / "r.csv")
    assert got["receptacle_id"].tolist() == want["receptacle_id"].tolist()
    assert (got["p"] - want["p"]).abs().max() < 1e-12
    assert want["receptacle_id"][0] in r.output and "door1" in r.output
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"
    r2 = CliRunner().invoke(main, ["graph", str(tmp_path / "g.json"), "--at", str(T0_S + 40 * 3600), "-q"])
    assert r2.exit_code == 0, r2.output
    assert all(o in r2.output for o in ("mug", "book", "keys"))


def test_bad_input_is_one_error_line(graph_dataset: Path, tmp_path: Path) -> None:
    for args, expected in ((["--at", "soon"], "ISO 8601"), (["--at", AT, "--object", "unicorn"], "not in the graph")):
        r = CliRunner().invoke(main, ["graph", str(graph_dataset), "-e", "fremen", *args, "-q"])
        assert r.exit_code == 1 and "error:" in r.output and expected in r.output, r.output
        assert "Traceback" not in r.output
    r = CliRunner().invoke(main, ["graph", str(tmp_path / "nothing"), "--at", AT])
    assert r.exit_code == 1 and "expected a psg-dataset folder" in r.output


def test_rerun_recording_holds_the_graphs_beliefs(graph_dataset: Path, tmp_path: Path) -> None:
    import numpy as np

    from psg_data.viewer import log_graph, recording
    from tests.test_viewer import _column, _read

    g = PredictiveGraph.from_dataset(graph_dataset, "fremen")
    times = T0_S + 40 * 3600 + 1800.0 * np.arange(10)
    with recording(tmp_path / "g.rrd") as rec:
        assert log_graph(rec, g, times) == len(g.edges) + 1
    rows, batches = _read(tmp_path / "g.rrd")
    o, r = g.edges[0]
    assert rows[f"/beliefs/{o}/{r}/fremen"] == 10
    assert [v[0] for v in _column(batches[f"/beliefs/{o}/{r}/fremen"], ":scalars")] == list(
        g.edge_probabilities(times)[:, 0])
    assert rows["/beliefs/doors/door1/fremen"] == 10
    r = CliRunner().invoke(main, ["graph", str(graph_dataset), "--at", AT, "-e", "fremen", "--rerun",
                                  str(tmp_path / "c.rrd"), "-q"])
    assert r.exit_code == 0 and "belief series" in r.output, r.output
