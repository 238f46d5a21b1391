"""psg-eval on the real benchmarks, end to end on small files in the published layouts.

The built-in names read their pinned files; here the pins are those of the files the test writes
(``monkeypatch`` of the pin tables), served from ``$PSG_DATA_SOURCES`` as a user's offline copy is.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import pytest
from click.testing import CliRunner

import psg_data.datasets as datasets
from psg_data.cli.psg_eval_cmd import main
from tests.realdata._layout import sha256s, write_door, write_rooms


@pytest.fixture(scope="module")
def sources(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("sources")
    write_door(root, train_weeks=2, test_weeks=9, test_gap=True)
    write_rooms(root, weeks=4, names=["Bedroom", "Bathroom", "Living_Room", "Kitchen", "Outside"])
    return root


@pytest.fixture()
def pinned(sources: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    door = sha256s(sources, [f"greg_door_2016_min/{n}" for n in datasets._DOOR_SHA256])
    room = sha256s(sources, [f"aruba_location/{n}" for n in datasets._ROOM_SHA256])
    monkeypatch.setattr(datasets, "_DOOR_SHA256", door)
    monkeypatch.setattr(datasets, "_ROOM_SHA256", room)
    monkeypatch.setenv("PSG_DATA_SOURCES", str(sources))
    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "cache"))
    return sources


def run(*args: str) -> Any:
    return CliRunner().invoke(main, list(args))


def test_door_patrol_default(pinned: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    r = run("--dataset", "door-benchmark", "-e", "last_seen", "--out", str(out), "--quiet")
    assert r.exit_code == 0, r.output
    assert r.output.lstrip().startswith("door-benchmark (9 test weeks), protocol patrol: headroom")
    doc = json.loads((out / "results.json").read_text())
    assert doc["kind"] == "psg-data/state-benchmark-results" and doc["protocol"] == "patrol"
    from psg_data.evaluation import load_results

    table = load_results(out).tables[0]
    assert table.primary == "mse" and {r.method for r in table.rows} >= {"last_seen", "hindsight"}
    cmp = run("compare", str(out), "--metric", "mse")
    assert cmp.exit_code == 0 and "hindsight" in cmp.output, cmp.output
    labels = [r["label"] for r in doc["rows"]]
    for need in ("last_seen", "perpetua", "fremen", "hindsight", "mean", "hist", "always_absent",
                 "fremen:n_periods=84,max_order=5,order_rule=train_mse"):
        assert need in labels
    row = next(r for r in doc["rows"] if r["label"] == "mean")
    assert set(row["summary"]) == {"mse", "mae", "balanced_accuracy", "f1"} and len(row["per_period"]) == 9
    assert doc["headroom"]["mse"]["headroom"] > 0
    for f in ("table.txt", "summary.csv", "per_week.csv", "comparisons.csv"):
        assert (out / f).stat().st_size > 0
    img = cv2.imread(str(out / "per_week.png"))
    assert img is not None and img.std() > 5
    assert not list(pinned.rglob("*.partial")) and not (tmp_path / "cache" / "sources").exists()


def test_door_published_and_room(pinned: Path, tmp_path: Path) -> None:
    r = run("--dataset", "door-benchmark", "--protocol", "published", "-e", "fremen:max_order=5", "--out",
            str(tmp_path / "a"), "--quiet", "--no-references")
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "a" / "results.json").read_text())
    assert doc["setting"] == "predictive" and [x["label"] for x in doc["rows"]] == ["fremen:max_order=5"]
    assert 0 < doc["rows"][0]["summary"]["mse"]["mean"] < 0.25
    r = run("--dataset", "room-presence-benchmark:train_weeks=2", "-e", "fremen", "--out", str(tmp_path / "b"),
            "--quiet", "--format", "markdown")
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "b" / "results.json").read_text())
    assert "top1" in doc["metrics"] and len(doc["periods"]) == 2
    assert "| method |" in r.output


@pytest.mark.parametrize("args, expect", [
    (["--dataset", "door-benchmark:colour=red"], "setting 'colour=red'"),
    (["--dataset", "door-benchmark", "--task", "doors"], "takes --task persistence"),
    (["--dataset", "door-benchmark", "--protocol", "paper-real"], "its protocols are patrol"),
    (["--dataset", "door-benchmark", "--lab-seeds", "2"], "--lab-seeds with door-benchmark"),
    (["--dataset", "door-benchmark:patrol=9-17"], "expected START-END/STEP"),
    (["--dataset", "door-benchmark:stamps=gmt"], "door stamps 'gmt'"),
    (["--dataset", "door-benchmark", "--protocol", "published", "--labels", "noisy:0.1"], "the published protocol"),
    (["--protocol", "patrol"], "a protocol of the real benchmarks"),
])
def test_bad_options_one_line(pinned: Path, tmp_path: Path, args: list[str], expect: str) -> None:
    r = run(*args, "--out", str(tmp_path / "o"), "--quiet")
    assert r.exit_code == 1, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and expect in lines[0], r.output
    assert not (tmp_path / "o").exists()


def test_wrong_byte_in_offline_copy_is_refused(pinned: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(pinned, copy)
    p = copy / "greg_door_2016_min" / "test_all_3.txt"
    data = bytearray(p.read_bytes())
    data[-2] = ord("1") if data[-2] == ord("0") else ord("0")
    p.write_bytes(bytes(data))
    monkeypatch.setenv("PSG_DATA_SOURCES", str(copy))
    r = run("--dataset", "door-benchmark", "--out", str(tmp_path / "o"), "--quiet")
    assert r.exit_code == 1
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and "test_all_3.txt" in lines[0] and lines[0].startswith("error: ")


def test_no_network_says_where_to_get_the_files(pinned: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                                ) -> None:
    import socket

    monkeypatch.delenv("PSG_DATA_SOURCES")
    with socket.socket() as s:  # a loopback port with nothing behind it
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    real = datasets._real_sources

    def closed() -> dict[str, Any]:
        from dataclasses import replace

        return {k: replace(v, base_url=f"http://127.0.0.1:{port}/") for k, v in real().items()}
    monkeypatch.setattr(datasets, "_real_sources", closed)
    r = run("--dataset", "door-benchmark", "--out", str(tmp_path / "o"), "--quiet")
    assert r.exit_code == 1
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and "PSG_DATA_SOURCES" in lines[0] and "chronorobotics/framework2" in lines[0]
