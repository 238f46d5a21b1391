"""One error contract for every command: one ``error:`` line, exit 2 for a bad command line, exit 1 for
inputs and outputs that cannot be used, no traceback, and nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.cli.psg_eval_cmd import main as psg_eval
from tests.conftest import write_tiny_dataset
from tests.contract import assert_one_error, snapshot

USAGE = [  # (program, arguments, part of the message): the command line itself is wrong -> exit 2
    ("psg-data", ["convert"], "Missing argument 'INPUT'"),
    ("psg-data", ["convert", "a", "b", "--jobs", "0"], "expected a number of CPUs >= 1, or -1 for all"),
    ("psg-data", ["convert", "a", "b", "--jobs", "-3"], "expected a number of CPUs >= 1, or -1 for all"),
    ("psg-data", ["convert", "a", "b", "--bogus"], "No such option '--bogus'"),
    ("psg-data", ["convert", "a", "b", "--depth-scale", "x"], "'x' is not a valid float"),
    ("psg-data", ["synth"], "Missing argument 'OUT'"),
    ("psg-data", ["synth", "x", "--resolution", "big"], "expected WIDTHxHEIGHT"),
    ("psg-data", ["synth", "x", "--days", "0"], "--days"),
    ("psg-data", ["label"], "Missing argument 'DATASET'"),
    ("psg-data", ["label", "x"], "Missing option '--source'"),
    ("psg-data", ["validate"], "Missing argument 'DATASET'"),
    ("psg-data", ["info"], "Missing argument 'DATASET'"),
    ("psg-data", ["nope"], "No such command 'nope'"),
    ("psg-eval", ["--jobs", "0"], "expected a number of CPUs >= 1, or -1 for all"),
    ("psg-eval", ["--seeds", "0"], "--seeds"),
    ("psg-eval", ["--task", "bogus"], "--task"),
    ("psg-eval", ["compare"], "Missing argument 'DIRS...'"),
]


@pytest.mark.parametrize(("prog", "args", "match"), USAGE, ids=[" ".join(a) for _, a, _ in USAGE])
def test_bad_command_lines_exit_2_with_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, prog: str,
                                                args: list[str], match: str) -> None:
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(psg_data if prog == "psg-data" else psg_eval, args)
    line = assert_one_error(r, match, code=2)
    assert line.endswith("--help')")  # and says where the help is
    assert list(tmp_path.iterdir()) == []


def test_inputs_that_cannot_be_used_exit_1_with_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    ds = write_tiny_dataset(tmp_path / "lab", scans=1, frames=1)
    (tmp_path / "file.txt").write_text("x")
    cases = [
        (psg_data, ["label", "/nonexistent", "-s", "gt"], "/nonexistent: not a directory; expected a psg-dataset"),
        (psg_data, ["info", "/nonexistent"], "/nonexistent: not a directory; expected a psg-dataset"),
        (psg_data, ["info", str(tmp_path)], "dataset.json: missing manifest"),
        (psg_data, ["validate", "/nonexistent"], "/nonexistent: 1 problem(s), listed above"),
        (psg_data, ["convert", "/nonexistent", "out"], "/nonexistent: input not found"),
        (psg_data, ["convert", "file.txt", "out"], "file.txt: not a recording"),
        (psg_data, ["convert", "file.txt", "out", "--config", "missing.yaml"], "missing.yaml: config file not found"),
        (psg_data, ["synth", str(ds)], "output exists; pass --overwrite"),
        (psg_data, ["label", str(ds), "-s", "gt", "--valid", "missing.json"], "missing.json: not a readable JSON"),
        (psg_data, ["label", str(ds), "-s", "detections:missing.parquet"], "missing.parquet"),
        (psg_eval, ["--dataset", "/nonexistent"], "--dataset '/nonexistent': not a directory"),
        (psg_eval, ["compare", "/nonexistent"], "/nonexistent/results.json: missing"),
        (psg_eval, ["-e", "no_such_estimator"], "no_such_estimator"),
    ]
    before = snapshot(tmp_path)
    for cmd, args, match in cases:
        assert_one_error(CliRunner().invoke(cmd, args), match)
        assert snapshot(tmp_path) == before, args


def test_help_and_version_exit_0() -> None:
    for cmd, args in [(psg_data, ["--help"]), (psg_data, ["convert", "--help"]), (psg_data, ["--version"]),
                      (psg_eval, ["--help"]), (psg_eval, ["compare", "--help"])]:
        r = CliRunner().invoke(cmd, args)
        assert r.exit_code == 0 and r.stderr == "", (args, r.output)
    r = CliRunner().invoke(psg_data, [])
    assert r.exit_code == 2 and "Usage: " in r.stdout and "Commands:" in r.stdout
