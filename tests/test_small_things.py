"""Small things a new user trips on: the default results folder is ignored by git; the help's examples
name scans a dataset has."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main

ROOT = Path(__file__).resolve().parents[1]


def test_default_results_folder_is_ignored_by_git(tmp_path: Path) -> None:
    """``psg-eval`` writes psg-eval-out/<timestamp>/ in the working directory: a clone ignores it."""
    repo = tmp_path / "clone"
    repo.mkdir()
    shutil.copy(ROOT / ".gitignore", repo / ".gitignore")
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    (repo / "psg-eval-out" / "20260101-000000").mkdir(parents=True)
    (repo / "psg-eval-out" / "20260101-000000" / "results.json").write_text("{}")
    r = subprocess.run(["git", "-C", str(repo), "status", "--porcelain", "--untracked-files=all"],
                       capture_output=True, text=True, check=True)
    assert "psg-eval-out" not in r.stdout and ".gitignore" in r.stdout


def test_view_help_examples_name_real_scans(tmp_path: Path) -> None:
    """Every ``--scan ID`` in ``psg-data view --help`` is a scan of the built-in lab (ids scan_DDD_HH)."""
    from psg_data.loaders import open_dataset
    from psg_data.synth import LabConfig, build_lab

    help_text = CliRunner().invoke(main, ["view", "--help"]).output
    ids = re.findall(r"--scan (\S+)", help_text)
    ids = [i for i in ids if i != "ID"]
    assert ids, help_text
    lab = build_lab(tmp_path / "lab", LabConfig(days=2, frames_per_scan=1, width=32, height=24))
    assert set(ids) <= set(open_dataset(lab).scan_ids)


def test_readme_timings_state_the_machine_and_the_load() -> None:
    """A time in the README's opening paragraph comes with the machine and its load (a number alone on a
    shared machine was off by a factor of 15)."""
    text = (ROOT / "README.md").read_text()
    opening = text.split("```", 2)[2].split("\n\n", 2)[1]
    assert "about 15 s" not in opening and "under a minute" not in opening
    for m in re.finditer(r"\d+(\.\d+)? (s|min)\b", opening):
        around = opening[max(0, m.start() - 200): m.end() + 200]
        assert "load average" in around and "core" in around, around
