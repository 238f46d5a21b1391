"""The generator model stored with a synthetic dataset: manifest fields, validation, old datasets."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from psg_data.loaders import open_dataset
from psg_data.schemas.validate import validate_dataset
from psg_data.synth import PROCESS_FILE, LabConfig, LabModel, build_lab, load_process
from psg_data.synth._process import save_process
from tests.contract import files_in, interrupt_partway


def test_manifest_names_every_parameter_and_the_model(small_dataset_path: Path, small_config: LabConfig) -> None:
    ds = open_dataset(small_dataset_path)
    extra = ds.info.extra
    assert extra["schedule_generator"] == "steps-v2" and extra["synth_version"] == "2"
    assert extra["process_file"] == PROCESS_FILE
    for k in ("routine_strength", "day_patterns", "day_persistence", "max_dwell_steps", "scan_hours", "seed"):
        assert k in extra
    assert dataclasses.replace(LabConfig.from_extra(extra), train_days=None) == small_config
    files = set(ds.table("files").column("path").to_pylist())
    assert PROCESS_FILE in files
    proc = load_process(ds)
    assert proc.parameters["routine_strength"] == small_config.routine_strength
    assert set(proc.entities) == set(ds.objects) | set(ds.doors)
    assert validate_dataset(small_dataset_path) == []


def test_validator_reports_a_broken_model(small_dataset_path: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad"
    shutil.copytree(small_dataset_path, bad)
    p = bad / PROCESS_FILE
    d = json.loads(p.read_text())
    d["entities"][0]["jump"][0][0] = [0.9] * len(d["entities"][0]["jump"][0][0])
    d["entities"][0]["routine_strength"][0][0] = 1.5
    d["entities"][1]["states"] = ["no_such_receptacle"]
    p.write_text(json.dumps(d))
    text = "\n".join(str(x) for x in validate_dataset(bad, checksums=False))
    assert f"{PROCESS_FILE}: {d['entities'][0]['entity_id']}.jump: rows must be probability distributions" in text
    assert "routine_strength: expected values in [0, 1]" in text
    assert "receptacles ['no_such_receptacle'] not in tables/receptacles.parquet" in text
    p.write_text("{not json")
    assert any("not valid JSON" in str(x) for x in validate_dataset(bad, checksums=False))
    p.unlink()
    assert any("does not exist" in str(x) for x in validate_dataset(bad, checksums=False))


def test_continuous_v1_datasets_have_no_model_and_rebuild(tmp_path: Path) -> None:
    cfg = LabConfig(seed=1, days=2, frames_per_scan=1, width=32, height=24, generator="continuous-v1")
    root = build_lab(tmp_path / "v1", cfg)
    ds = open_dataset(root)
    assert not (root / PROCESS_FILE).exists() and "process_file" not in ds.info.extra
    assert validate_dataset(root) == []
    lab = LabModel.from_dataset(ds)
    assert lab.config.generator == "continuous-v1"
    # a manifest of synth version 1 (no schedule_generator key) reads as continuous-v1
    extra = dict(ds.info.extra)
    extra.pop("schedule_generator")
    extra["synth_version"] = "1"
    old = LabConfig.from_extra(extra)
    assert old.generator == "continuous-v1"
    a, b = LabModel(old).schedule, lab.schedule
    for o in a.object_ids:
        np.testing.assert_array_equal(a.objects[o].states, b.objects[o].states)


def test_save_process_replaces_the_file_atomically(small_dataset_path: Path, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    proc = load_process(small_dataset_path)
    out = tmp_path / "model.json"
    out.write_text('{"my": "previous model"}\n', encoding="utf-8")
    interrupt_partway(monkeypatch, Path, "write_text", path_arg=0)  # Ctrl-C in the middle of the file
    with pytest.raises(KeyboardInterrupt):
        save_process(proc, out)
    assert out.read_bytes() == b'{"my": "previous model"}\n' and files_in(tmp_path) == ["model.json"]
    monkeypatch.undo()
    save_process(proc, out)
    assert load_process(out).to_json() == proc.to_json() == out.read_text(encoding="utf-8")
