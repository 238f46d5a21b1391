"""``psg-eval --task doors`` reports its progress (query sets, then the objects), not a minute of silence."""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from tests.doors.test_door_dataset import labelled_lab  # noqa: F401 - the fixture


def test_cli_doors_reports_progress(labelled_lab: Path, tmp_path: Path) -> None:  # noqa: F811
    """Off a terminal: one final line naming the steps done (2 query sets + the object runs)."""
    from psg_data.cli.psg_eval_cmd import main

    r = CliRunner().invoke(main, ["--task", "doors", "--dataset", str(labelled_lab), "-e", "time_of_week_frequency",
                                  "--no-references", "--seeds", "2", "--queries", "20", "--no-plots",
                                  "--out", str(tmp_path / "doors")])
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("doors: query sets and objects: ")]
    assert lines and lines[-1].startswith("doors: query sets and objects: 3/3 steps, done in"), r.stderr
