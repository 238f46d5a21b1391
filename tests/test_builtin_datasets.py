"""Built-in dataset names (``psg_data.datasets.BUILTIN``) in every command that takes a dataset: a
name that is a dataset directory (``demo``) is built on first use and read like a path; one that is
not (``persistence-benchmark``) is refused in one line naming the commands that take it."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import CliRunner

from psg_data import datasets
from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.cli.psg_eval_cmd import main as psg_eval
from tests.contract import assert_one_error

DATASET_COMMANDS = [["info"], ["validate", "--quick"], ["label", "-s", "gt"], ["view", "--save", "{tmp}/v.rrd"]]
"""Every psg-data command whose argument is a dataset, with the options that make it run here."""


@pytest.fixture
def tiny_builtin(make_dataset: Callable[..., Path], monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """``demo`` replaced by a builder of a tiny dataset (the table mechanism, without the 15 s lab)."""
    built = {"calls": 0}

    def build(*, progress: Callable[..., object] | None = None) -> Path:
        built["calls"] += 1
        root = make_dataset("cached-demo", scans=2, frames=2)
        for _ in range(2):
            if progress is not None:
                progress(1)
        return root

    entry = datasets.BUILTIN["demo"]
    monkeypatch.setitem(datasets.BUILTIN, "demo", datasets.BuiltinDataset("demo", entry.description, build,
                                                                          entry.accepted_by, scans=2))
    return built


@pytest.mark.parametrize("args", DATASET_COMMANDS, ids=lambda a: a[0])
def test_every_dataset_command_takes_demo(args: list[str], tiny_builtin: dict[str, int], tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # no directory called demo here
    cmd = [args[0], "demo", *(a.format(tmp=tmp_path) for a in args[1:]), *(["-q"] if args[0] in ("label", "view")
                                                                          else [])]
    r = CliRunner().invoke(psg_data, cmd)
    assert r.exit_code == 0, (r.output, r.exception)
    assert tiny_builtin["calls"] == 1
    assert "not a directory" not in r.output


def test_lab_stats_dataset_takes_demo(tiny_builtin: dict[str, int], monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[object] = []
    from psg_data import labeling

    monkeypatch.setattr(labeling, "visibility_statistics", lambda p: seen.append(p) or {"privileged": {}})
    r = CliRunner().invoke(psg_data, ["lab-stats", "--dataset", "demo", "--sim-weeks", "1"])
    assert r.exit_code == 0, r.output
    assert tiny_builtin["calls"] == 1 and Path(str(seen[0])).name == "cached-demo"
    assert "privileged" in json.loads(r.stdout)


@pytest.mark.parametrize("args", DATASET_COMMANDS, ids=lambda a: a[0])
def test_a_builtin_that_is_no_directory_is_refused_in_one_line(args: list[str], tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    cmd = [args[0], "persistence-benchmark", *(a.format(tmp=tmp_path) for a in args[1:])]
    line = assert_one_error(CliRunner().invoke(psg_data, cmd), "persistence-benchmark: the paper's Sec. V-A")
    assert f"psg-data {args[0]} reads a dataset directory (a path, or demo)" in line
    assert "read by psg-eval --dataset persistence-benchmark" in line
    assert list(tmp_path.iterdir()) == []


def test_a_directory_named_like_a_builtin_wins(make_dataset: Callable[..., Path], tiny_builtin: dict[str, int],
                                               tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    make_dataset("demo", scans=3, frames=1)
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(psg_data, ["info", "demo", "--json"])
    assert r.exit_code == 0 and json.loads(r.stdout)["scans"] == 3 and tiny_builtin["calls"] == 0


def test_psg_eval_resolves_names_through_the_same_table(tiny_builtin: dict[str, int]) -> None:
    from psg_data.cli._eval_inputs import resolve_dataset

    choice = resolve_dataset("demo", quiet=True)
    assert choice.kind == "dataset" and choice.path is not None and choice.path.name == "cached-demo"
    assert resolve_dataset("persistence-benchmark", quiet=True).kind == "benchmark"
    line = assert_one_error(CliRunner().invoke(psg_eval, ["--dataset", "nope", "--no-plots"]), "--dataset 'nope'")
    assert "one of 'demo', 'persistence-benchmark'" in line


def test_info_on_the_real_demo_lab() -> None:
    """The real built-in lab (built once into the cache, as the psg-eval tests use it)."""
    r = CliRunner().invoke(psg_data, ["info", "demo", "--json"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    # the three lab rooms and the corridor (a room without receptacles, the default layout)
    assert (s["scans"], s["rooms"], s["doors"], s["objects"], s["receptacles"]) == (84, 4, 2, 21, 28)
