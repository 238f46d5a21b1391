"""Options an attacker (or a typo) gives (docs/SECURITY.md): seed ranges bounded before any list is
built, options that do not apply refused in one line, a malformed ``--labels`` a usage error, ``view``
on a dataset without a schedule (every converted recording), ``--bind ::1`` as a valid URL."""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main as data_main
from psg_data.cli.psg_eval_cmd import main as eval_main
from psg_data.writers import DatasetWriter
from tests.contract import assert_one_error


def _eval(*args: str) -> Any:
    return CliRunner().invoke(eval_main, list(args))


@pytest.mark.parametrize("option", ["--seeds", "--lab-seeds"])
@pytest.mark.parametrize("value, said", [("0-1000000000", "at most 100 seeds"),
                                         ("0-100000000000000000000000", "a seed is at most"),
                                         ("5,0-999999999", "at most 100 seeds"), ("9" * 5000, "a seed is at most")])
def test_seed_ranges_are_bounded_with_one_message(option: str, value: str, said: str) -> None:
    tracemalloc.start()
    try:
        r = _eval(option, value, "--list-estimators")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    line = assert_one_error(r, said, code=2)
    assert len(line) < 300 and peak < 200 << 20


def test_sim_protocol_seeds_are_bounded_too() -> None:
    r = _eval("--task", "navigation", "--dataset", "navigation-benchmark", "--protocol", "paper-sim-adaptive",
              "--seeds", "0-1000000000")
    assert_one_error(r, "at most 100 seeds", code=2)


@pytest.mark.parametrize("task, protocol", [("persistence", "paper-real"), ("persistence", "sim"),
                                            ("doors", "paper-real"), ("persistence", "paper-sim-predictive")])
def test_a_navigation_protocol_on_another_task_is_refused(task: str, protocol: str, tmp_path: Path) -> None:
    r = _eval("--task", task, "--protocol", protocol, "--out", str(tmp_path / "out"), "-q")
    assert_one_error(r, f"--protocol {protocol}")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("labels", ["noisy:abc", "noisy:2", "bogus", "detections:"])
def test_malformed_labels_is_a_usage_error(labels: str, tmp_path: Path) -> None:
    assert_one_error(_eval("--labels", labels, "--out", str(tmp_path / "o"), "-q"), "--labels", code=2)
    r = CliRunner().invoke(data_main, ["graph", "demo", "--labels", labels, "--at", "2025-03-20 14:00", "-q"])
    assert_one_error(r, "--labels", code=2)


def test_view_shows_a_dataset_without_a_schedule(make_dataset: Callable[..., Path], tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A converted recording has an empty schedule table: the viewer logs its scans, with no ground truth."""
    real = DatasetWriter.set_table
    monkeypatch.setattr(DatasetWriter, "set_table",
                        lambda self, name, rows, *a, **k: None if name == "schedule" else real(self, name, rows, *a, **k))
    root = make_dataset(scans=2, frames=2)
    monkeypatch.undo()
    from psg_data.loaders import open_dataset

    assert open_dataset(root).table("schedule").num_rows == 0
    out = tmp_path / "v.rrd"
    r = CliRunner().invoke(data_main, ["view", str(root), "--save", str(out), "-q"])
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:3] == b"RRF" and "2 scans, 4 frames" in r.stdout


@pytest.mark.parametrize("bind, host", [("::1", "[::1]"), ("::", "[::1]"), ("127.0.0.1", "127.0.0.1"),
                                        ("0.0.0.0", "127.0.0.1"), ("fe80::1%eth0", "[fe80::1%25eth0]")])
def test_web_viewer_url_is_valid_for_ipv6(bind: str, host: str) -> None:
    from psg_data.viewer import WebViewer

    w = WebViewer(port=9090, bind=bind)
    w.grpc_port = 9876
    url = urlsplit(w.url)
    assert url.netloc == f"{host}:9090" and url.port == 9090
    inner = urlsplit(unquote(url.query.removeprefix("url=")))
    assert inner.netloc == f"{host}:9876" and inner.port == 9876
