"""A dataset converted from ``psg-data synth --format ros1`` recordings is the lab again: named by the
user's folder (not the staging folder ``canonical``), scored on the lab's hours, its label source stated.
"""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.cli.psg_eval_cmd import main as psg_eval
from psg_data.loaders import open_dataset


def test_converted_synth_recordings_keep_name_and_hours(tmp_path: Path) -> None:
    """Convert -> info names ``recs``; psg-eval scores 09:00-17:00 like the built-in lab and says ``labels gt``."""
    recs, lab = tmp_path / "recs", tmp_path / "lab"
    r = CliRunner().invoke(psg_data, ["synth", str(recs), "--format", "ros1", "--days", "4", "--frames-per-scan", "1",
                                      "--resolution", "32x24", "-q"])
    assert r.exit_code == 0, r.output
    assert json.loads((recs / "site.json").read_text())["operating_hours"] == "09:00-17:00"
    r = CliRunner().invoke(psg_data, ["convert", str(recs), str(lab), "-q"])
    assert r.exit_code == 0, r.output
    ds = open_dataset(lab)
    assert ds.info.name == "recs"
    info = CliRunner().invoke(psg_data, ["info", str(lab)])
    assert "canonical" not in info.output and "recs" in info.output
    out = tmp_path / "res"
    r = CliRunner().invoke(psg_eval, ["--dataset", str(lab), "-e", "last_seen", "--no-references", "--no-plots",
                                      "--out", str(out), "-q"])
    assert r.exit_code == 0, r.output
    res = json.loads((out / "results.json").read_text())
    assert res["config"]["windows"]["text"].startswith("09:00-17:00")
    assert res["config"]["windows"]["source"] == "the dataset's operating hours"
    notes = res["tables"][0]["notes"]
    assert any("labels gt" in n for n in notes), notes
    assert "canonical" not in res["tables"][0]["title"]


def test_bad_operating_hours_in_a_site_file_is_one_line(tmp_path: Path) -> None:
    """A site file's operating_hours that is not local hour ranges is refused, naming the file and field."""
    import pytest

    from psg_data.errors import ConversionError
    from psg_data.loaders.raw._side import read_side_files

    (tmp_path / "site.json").write_text(json.dumps({"name": "x", "timezone": "UTC", "operating_hours": "9 to 5"}))
    with pytest.raises(ConversionError, match=r"site.json: operating_hours: expected local hour ranges"):
        read_side_files(tmp_path)
    (tmp_path / "site.json").write_text(json.dumps({"name": "x", "timezone": "UTC", "operating_hours": "9-12,13-17"}))
    assert read_side_files(tmp_path).operating_hours == "9-12,13-17"
