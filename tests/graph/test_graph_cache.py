"""``psg-data graph DATASET`` caches its fit (issue 45, point 3): the key changes with every input of
the fit, a second call answers from the saved fit with the same output, a damaged cache is refitted."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

import psg_data
from psg_data.cli._graph_cache import fit_cache_key
from psg_data.cli.psg_data_cmd import main

AT = "2023-11-16 07:00"


@pytest.fixture()
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "graph-fits"


def test_the_key_changes_with_every_input_of_the_fit(graph_dataset: Path, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    ds = shutil.copytree(graph_dataset, tmp_path / "ds")
    det = tmp_path / "det.jsonl"
    det.write_text("{}\n")
    base = fit_cache_key(ds, "perpetua_star", "gt")
    assert fit_cache_key(ds, "perpetua_star", "gt") == base  # deterministic
    keys = {
        "estimator": fit_cache_key(ds, "fremen", "gt"),
        "settings": fit_cache_key(ds, "perpetua_star:gamma=0.9", "gt"),
        "labels": fit_cache_key(ds, "perpetua_star", "privileged"),
        "label seed": fit_cache_key(ds, "perpetua_star", "gt", label_seed=1),
        "detections": fit_cache_key(ds, "perpetua_star", f"detections:{det}"),
    }
    det.write_text("{}\n{}\n")
    keys["detections file"] = fit_cache_key(ds, "perpetua_star", f"detections:{det}")
    monkeypatch.setattr(psg_data, "__version__", psg_data.__version__ + ".post1")
    keys["version"] = fit_cache_key(ds, "perpetua_star", "gt")
    monkeypatch.undo()
    table = sorted((ds / "tables").glob("*.parquet"))[0]
    table.write_bytes(table.read_bytes() + b"\0")
    keys["a table file"] = fit_cache_key(ds, "perpetua_star", "gt")
    (ds / "dataset.json").write_text((ds / "dataset.json").read_text() + " ")
    keys["the manifest"] = fit_cache_key(ds, "perpetua_star", "gt")
    assert base not in keys.values()
    assert len(set(keys.values())) == len(keys), keys


def test_a_second_call_answers_from_the_cache(graph_dataset: Path, cache: Path) -> None:
    args = ["graph", str(graph_dataset), "--at", AT, "-e", "fremen", "-q"]
    first = CliRunner().invoke(main, args)
    assert first.exit_code == 0, first.output
    saved = list(cache.glob("*.json"))
    assert [p.name for p in saved] == [f"{fit_cache_key(graph_dataset, 'fremen', 'gt')}.json"]
    stamp = saved[0].stat().st_mtime_ns
    second = CliRunner().invoke(main, args)
    assert second.exit_code == 0 and second.output == first.output
    assert list(cache.glob("*.json")) == saved and saved[0].stat().st_mtime_ns == stamp  # read, not refitted
    other = CliRunner().invoke(main, ["graph", str(graph_dataset), "--at", AT, "-e", "last_seen", "-q"])
    assert other.exit_code == 0, other.output
    assert len(list(cache.glob("*.json"))) == 2  # another estimator: another fit


def test_a_damaged_cache_entry_is_refitted(graph_dataset: Path, cache: Path) -> None:
    args = ["graph", str(graph_dataset), "--at", AT, "-e", "fremen", "-q"]
    first = CliRunner().invoke(main, args)
    entry = next(cache.glob("*.json"))
    entry.write_text("{not json")
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0 and again.output == first.output
    assert entry.read_text().startswith("{") and entry.read_text() != "{not json"
