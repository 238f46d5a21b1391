"""``psg-data synth`` command line."""

from __future__ import annotations

import sys
import types
from pathlib import Path

from click.testing import CliRunner

from psg_data.cli._synth_cmd import synth_cmd
from psg_data.loaders import open_dataset

ARGS = ["--days", "1", "--frames-per-scan", "2", "--resolution", "48x36"]


def test_synth_canonical_and_existing_output(tmp_path: Path) -> None:
    out = tmp_path / "lab"
    r = CliRunner().invoke(synth_cmd, [str(out), *ARGS, "--seed", "4", "--quiet"])
    assert r.exit_code == 0, r.output
    ds = open_dataset(out)
    assert len(ds.scan_ids) == 4 and ds.info.extra["seed"] == 4 and ds.info.extra["resolution"] == [48, 36]
    r = CliRunner().invoke(synth_cmd, [str(out), *ARGS])
    assert r.exit_code == 1
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "--overwrite" in lines[0]
    r = CliRunner().invoke(synth_cmd, [str(out), *ARGS, "--overwrite", "--shift", "long-weekend", "-q"])
    assert r.exit_code == 0 and open_dataset(out).info.extra["shift"] == "long-weekend"


def test_generator_and_routine_strength_options(tmp_path: Path) -> None:
    from psg_data.synth import PROCESS_FILE, load_process

    out = tmp_path / "clock"
    r = CliRunner().invoke(synth_cmd, [str(out), *ARGS, "--routine-strength", "1", "--quiet"])
    assert r.exit_code == 0, r.output
    ds = open_dataset(out)
    assert ds.info.extra["routine_strength"] == 1.0 and ds.info.extra["schedule_generator"] == "steps-v2"
    assert load_process(ds).parameters["routine_strength"] == 1.0
    old = tmp_path / "v1"
    r = CliRunner().invoke(synth_cmd, [str(old), *ARGS, "--generator", "continuous-v1", "--quiet"])
    assert r.exit_code == 0, r.output
    assert open_dataset(old).info.extra["schedule_generator"] == "continuous-v1" and not (old / PROCESS_FILE).exists()
    r = CliRunner().invoke(synth_cmd, [str(tmp_path / "x"), "--routine-strength", "1.5"])
    assert r.exit_code == 2


def test_bad_resolution_is_usage_error(tmp_path: Path) -> None:
    r = CliRunner().invoke(synth_cmd, [str(tmp_path / "x"), "--resolution", "big"])
    assert r.exit_code == 2


def test_raw_formats_go_through_export_raw(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    calls = []

    def export_raw(dataset_path: Path, out: Path, fmt: str) -> None:
        calls.append((fmt, len(open_dataset(dataset_path).scan_ids)))
        Path(out).mkdir()

    fake = types.ModuleType("psg_data.synth._raw_export")
    fake.export_raw = export_raw  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "psg_data.synth._raw_export", fake)
    r = CliRunner().invoke(synth_cmd, [str(tmp_path / "bags"), *ARGS, "--format", "ros2-mcap", "-q"])
    assert r.exit_code == 0, r.output
    assert calls == [("ros2-mcap", 4)] and (tmp_path / "bags").is_dir()


def test_lab_stats_prints_json_and_refuses_a_bad_dataset(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import json

    from click.testing import CliRunner

    from psg_data.cli.psg_data_cmd import main

    res = CliRunner().invoke(main, ["lab-stats", "--sim-weeks", "1"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["generator"] == "steps-v2" and out["visits_unseen_by_timing"] == 0.0
    bad = CliRunner().invoke(main, ["lab-stats", "--sim-weeks", "1", "--dataset", str(tmp_path)])
    assert bad.exit_code == 1 and bad.output.strip().startswith("error: ") and "Traceback" not in bad.output
