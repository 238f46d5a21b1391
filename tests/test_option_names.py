"""One name per idea: the renamed options work under their new names; the old spellings still work for
one release (hidden from --help, with a warning line), and giving both is a usage error.
"""

from __future__ import annotations

import io
from pathlib import Path

import pandas as pd
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.loaders import open_dataset
from tests.conftest import write_tiny_dataset
from tests.graph.conftest import graph_dataset  # noqa: F401 - the fixture
from tests.graph.test_graph_cli import AT


def test_label_seed_is_named_as_in_psg_eval(tmp_path: Path) -> None:
    """``psg-data label --label-seed`` (psg-eval's name); ``--seed`` hidden, same noise draw, a warning."""
    runs = {}
    for name, flag in (("new", "--label-seed"), ("old", "--seed")):
        ds = write_tiny_dataset(tmp_path / name, scans=3, frames=1)
        r = CliRunner().invoke(main, ["label", str(ds), "--source", "noisy:0.4", flag, "7", "-q"])
        assert r.exit_code == 0, r.output
        assert ("warning: --seed is now --label-seed" in r.stderr) == (flag == "--seed")
        runs[name] = open_dataset(ds).table("labels").to_pandas()
    pd.testing.assert_frame_equal(runs["new"], runs["old"])
    help_text = CliRunner().invoke(main, ["label", "--help"]).output
    assert "--label-seed" in help_text and "--seed " not in help_text
    ds = write_tiny_dataset(tmp_path / "both", scans=3, frames=1)
    r = CliRunner().invoke(main, ["label", str(ds), "--source", "noisy:0.4", "--seed", "1", "--label-seed", "2"])
    assert r.exit_code == 2 and "former spelling" in r.stderr


def test_convert_split_has_one_spelling_in_help() -> None:
    """``--split gap:S`` is the one spelling shown; ``--split-gap S`` is hidden."""
    help_text = CliRunner().invoke(main, ["convert", "--help"]).output
    assert "--split-gap" not in help_text and "gap:SECONDS" in help_text


def test_graph_prints_csv_like_compare(graph_dataset: Path, tmp_path: Path) -> None:  # noqa: F811
    """``graph --format csv`` prints the table as CSV on stdout (as ``psg-eval compare --format csv``);
    the former ``--csv FILE`` still writes the same table, hidden from --help.
    """
    r = CliRunner().invoke(main, ["graph", str(graph_dataset), "--at", AT, "-e", "fremen", "--object", "book",
                                  "--format", "csv", "--csv", str(tmp_path / "old.csv")])
    assert r.exit_code == 0, r.output
    printed = pd.read_csv(io.StringIO(r.stdout))
    pd.testing.assert_frame_equal(printed, pd.read_csv(tmp_path / "old.csv"))
    assert "receptacle_id" in printed.columns and len(printed) >= 1
    assert "warning: --csv FILE is now --format csv" in r.stderr
    help_text = CliRunner().invoke(main, ["graph", "--help"]).output
    assert "--format" in help_text and "--csv" not in help_text
