"""``psg-data view`` and ``psg-eval --rerun``: the saved recordings, read back with Rerun's own
reader (``rerun.chunk.RrdReader``), hold the expected entities and row counts."""

from __future__ import annotations

import contextlib
import sys
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun  # noqa: F401  - [dev] installs psg-data[viewer]; a missing extra fails loudly
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.loaders import open_dataset


def _read(path: Path) -> tuple[Counter, dict]:  # type: ignore[type-arg]
    from rerun.chunk import RrdReader

    rows: Counter[str] = Counter()
    batches: dict[str, list] = {}  # type: ignore[type-arg]
    for chunk in RrdReader(str(path)).store().stream():
        rows[chunk.entity_path] += chunk.num_rows
        batches.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return rows, batches


def _column(batches: list, suffix: str) -> list:  # type: ignore[type-arg]
    out = []
    for b in batches:
        name = next(n for n in b.schema.names if n.endswith(suffix))
        out += b.column(name).to_pylist()
    return out


def test_view_saves_a_recording_with_every_scan(make_dataset: Callable[..., Path], tmp_path: Path) -> None:
    root = make_dataset(scans=3, frames=4)
    out = tmp_path / "lab.rrd"
    r = CliRunner().invoke(main, ["view", str(root), "--save", str(out), "-q"])
    assert r.exit_code == 0, r.output
    assert r.stdout.strip().startswith(f"wrote {out} (3 scans, 12 frames, ")
    rows, batches = _read(out)
    for entity, n in {"/world/camera": 12, "/world/camera/rgb": 12, "/world/camera/depth": 12,
                      "/world/receptacles": 3, "/world/doors": 3, "/world/points": 3, "/world/trajectory": 3}.items():
        assert rows[entity] == n, entity
    # doors coloured by state: the fixture's door1 is open in scans 0 and 2, closed in scan 1
    colours = _column(batches["/world/doors"], ":colors")
    assert len({tuple(c) for c in colours}) == 2 and colours[0] == colours[2] != colours[1]
    # label streams: the schedule's present edges and the door, one row per scan
    assert rows["/labels/gt/redmug/table"] == 3 and rows["/labels/gt/doors/door1"] == 3
    assert _column(batches["/labels/gt/doors/door1"], ":scalars") == [[1.0], [0.0], [1.0]]
    ds = open_dataset(root)
    assert _column(batches["/world/camera/depth"], ":meter")[0] == [pytest.approx(1 / ds.cameras["d435"].depth_scale_m)]
    assert not (tmp_path / "lab.rrd.partial").exists()


def test_view_selects_scans_and_refuses_to_overwrite(make_dataset: Callable[..., Path], tmp_path: Path) -> None:
    root = make_dataset(scans=3, frames=2)
    out = tmp_path / "one.rrd"
    r = CliRunner().invoke(main, ["view", str(root), "--scan", "scan_001", "--save", str(out), "-q"])
    assert r.exit_code == 0, r.output
    rows, _ = _read(out)
    assert rows["/world/camera/rgb"] == 2 and rows["/world/receptacles"] == 1
    r = CliRunner().invoke(main, ["view", str(root), "--save", str(out), "-q"])
    assert r.exit_code == 1 and "output exists; pass --overwrite" in r.stderr
    r = CliRunner().invoke(main, ["view", str(root), "--scan", "nope", "--save", str(tmp_path / "x.rrd"), "-q"])
    assert r.exit_code == 1 and r.stderr.startswith("error: --scan nope: no such scan")


def test_beliefs_recording_holds_every_estimator_and_edge(tmp_path: Path) -> None:
    from psg_data.estimators import EdgeStream
    from psg_data.evaluation import evaluate_persistence
    from psg_data.viewer import log_beliefs, recording

    t0, day = 1_700_000_000.0, 86_400.0
    edges = [("mug", "table"), ("book", "shelf"), ("cup", "desk")]
    train = [EdgeStream(e, t0 + day * np.arange(10), (np.arange(10) + k) % 2) for k, e in enumerate(edges)]
    test = [EdgeStream(e, t0 + day * (10 + np.arange(4)), (np.arange(4) + k) % 2) for k, e in enumerate(edges)]
    grid = t0 + day * 10 + 3600.0 * np.arange(96)
    gt = {e: (grid, ((grid - grid[0]) // day + k).astype(int) % 2) for k, e in enumerate(edges)}
    res = evaluate_persistence(["last_seen", "fremen"], train, test, gt, seeds=(0, 1), keep_predictions=edges)
    out = tmp_path / "beliefs.rrd"
    with recording(out) as rec:
        assert log_beliefs(rec, res.traces) == 3
    rows, batches = _read(out)
    tr = next(t for t in res.traces if t.seed == 0 and t.estimator == "fremen" and t.edge == ("mug", "table"))
    assert rows["/beliefs/mug/table/fremen"] == len(tr.t_s)
    assert [v[0] for v in _column(batches["/beliefs/mug/table/fremen"], ":scalars")] == pytest.approx(tr.belief)
    assert {e for e in rows if e.startswith("/beliefs/")} == {
        f"/beliefs/{o}/{r}/{k}" for o, r in edges for k in ("last_seen", "fremen", "ground_truth", "observations")}


def test_psg_eval_rerun_records_every_scored_edge(tmp_path: Path) -> None:
    from psg_data.cli.psg_eval_cmd import main as eval_main

    out = tmp_path / "b.rrd"
    r = CliRunner().invoke(eval_main, ["--dataset", "persistence-benchmark", "--seeds", "1", "-e", "last_seen",
                                       "--no-references", "--no-plots", "--rerun", str(out),
                                       "--out", str(tmp_path / "res"), "-q"])
    assert r.exit_code == 0, r.output
    rows, _ = _read(out)
    import json

    n_edges = json.loads((tmp_path / "res" / "results.json").read_text())["config"]["n_edges"]
    assert len({e for e in rows if e.endswith("/last_seen")}) == n_edges
    assert len({e for e in rows if e.endswith("/ground_truth")}) == n_edges
    from rerun.chunk import RrdReader

    reader = RrdReader(str(out))
    (blueprint,) = reader.blueprints()  # one panel per edge whose truth changes most
    assert len({c.entity_path for c in reader.store(store=blueprint).stream() if c.entity_path.endswith("/ScalarAxis")}
               ) == 4
    r = CliRunner().invoke(eval_main, ["--task", "doors", "--rerun", str(tmp_path / "d.rrd"), "-q"])
    assert r.exit_code == 1 and "--rerun: beliefs are recorded for --task persistence" in r.stderr


def test_without_a_display_view_fails_at_once_in_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    """A server, a container, SSH: no window can open; the hint names --save and --web, before any work."""
    from tests.contract import assert_one_error

    for var in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr("sys.platform", "linux")
    line = assert_one_error(CliRunner().invoke(main, ["view", "/nonexistent"]), "no display to open the Rerun viewer")
    assert "--save FILE.rrd" in line and "--web" in line  # and the dataset was not even opened


def test_without_a_display_the_command_ends_in_one_line() -> None:
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")}
    r = subprocess.run([sys.executable, "-c", "from psg_data.cli.psg_data_cmd import main; main()", "view", "demo"],
                       capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 1 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("error: no display") and "--web" in r.stderr


def test_recording_carries_a_blueprint_and_a_scan_timeline(make_dataset: Callable[..., Path], tmp_path: Path) -> None:
    from rerun.chunk import RrdReader

    root = make_dataset(scans=3, frames=2)
    out = tmp_path / "lab.rrd"
    assert CliRunner().invoke(main, ["view", str(root), "--save", str(out), "-q"]).exit_code == 0
    reader = RrdReader(str(out))
    timelines: dict[str, set[str]] = {}
    for chunk in reader.store().stream():
        timelines.setdefault(chunk.entity_path, set()).update(chunk.timeline_names)
    for entity in ("/world/camera", "/world/points", "/world/receptacles", "/labels/gt/redmug/table",
                   "/labels/gt/doors/door1"):
        assert {"time", "scan"} <= timelines[entity], entity
    rows, batches = _read(out)
    scan_col = next(n for n in batches["/labels/gt/redmug/table"][0].schema.names if n == "scan")
    assert batches["/labels/gt/redmug/table"][0].column(scan_col).to_pylist() == [0, 1, 2]
    (blueprint,) = reader.blueprints()
    parts: dict[str, list] = {}  # type: ignore[type-arg]
    for chunk in reader.store(store=blueprint).stream():
        parts.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    panel = parts["/time_panel"][0]
    assert panel.column(next(n for n in panel.schema.names if n.endswith(":timeline"))).to_pylist() == [["scan"]]
    views = {p.rsplit("/", 1)[0] for p in parts if p.startswith("/view/") and p.count("/") == 3}
    plots = {p.rsplit("/", 1)[0] for p in parts if p.endswith("/ScalarAxis")}
    eye = [p for p in parts if p.endswith("/EyeControls3D")]
    # the 3D world, colour, depth, one plot per changing object edge (redmug on table and desk, the spoon
    # on the shelf) and one for the door
    assert len(eye) == 1 and len(plots) == 4 and len(views) == 7


VIEW_CLI = ("import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
            "from psg_data.cli.psg_data_cmd import main; main()")
"""``psg-data`` as a terminal starts it: a test run started in the background by a non-interactive
shell inherits SIGINT ignored, and so would the command (which then rightly ignores the Ctrl-C);
the earlier one-in-several "hang" of the Ctrl-C test was that (as in tests/format/test_interrupt.py)."""


def _wait_or_dump(proc: Any, timeout_s: float, stderr_path: Path) -> int:
    """``proc.wait``; if it does not end in time, its Python stacks (``-X faulthandler``, SIGABRT)
    are the failure message, so a hang names where it hangs."""
    import signal
    import subprocess

    try:
        return int(proc.wait(timeout=timeout_s))
    except subprocess.TimeoutExpired:
        masks = _signal_masks(proc.pid)
        _end_with_servers(proc, signal.SIGABRT)
        pytest.fail(f"did not exit within {timeout_s} s; signal masks (thread: blocked ignored caught):\n{masks}\n"
                    f"its stacks:\n{stderr_path.read_text(errors='replace')}")


def _end_with_servers(proc: Any, sig: int) -> None:
    """End ``proc`` with ``sig`` and kill the Rerun server it started (in a session of its own, so
    not reached through ``proc``; its pid is known only while ``proc`` lives)."""
    import os
    import signal

    servers = _children(proc.pid)
    proc.send_signal(sig)
    proc.wait(timeout=10)
    for pid in servers:
        with contextlib.suppress(OSError):
            os.killpg(pid, signal.SIGKILL)


def _children(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux's /proc; empty elsewhere)."""
    out: list[int] = []
    with contextlib.suppress(OSError):
        for tid in Path(f"/proc/{pid}/task").iterdir():
            out += [int(c) for c in (tid / "children").read_text().split()]
    return out


def _signal_masks(pid: int) -> str:
    """Each thread's blocked / ignored / caught signal masks from /proc (Linux; empty elsewhere)."""
    lines = []
    with contextlib.suppress(OSError):
        for tid in sorted(Path(f"/proc/{pid}/task").iterdir()):
            f = dict(ln.split(":\t", 1) for ln in (tid / "status").read_text().splitlines() if ":\t" in ln)
            lines.append(f"{tid.name} {f.get('Name', '?').strip()}: {f.get('SigBlk', '?').strip()} "
                         f"{f.get('SigIgn', '?').strip()} {f.get('SigCgt', '?').strip()}")
    return "\n".join(lines)


@contextlib.contextmanager
def _web_view(root: Path, port: int, err: Path) -> Iterator[Any]:
    """``psg-data view ROOT --web --port PORT -q`` as a child process (stderr to ``err``); killed if
    still running when the block ends, with the Rerun server it started."""
    import signal
    import subprocess

    with open(err, "wb") as err_file:
        proc = subprocess.Popen([sys.executable, "-X", "faulthandler", "-c", VIEW_CLI, "view", str(root), "--web",
                                 "--port", str(port), "-q"], stdout=subprocess.PIPE, stderr=err_file, text=True)
    assert proc.stdout is not None
    try:
        yield proc
    finally:
        if proc.poll() is None:
            _end_with_servers(proc, signal.SIGKILL)
        proc.stdout.close()


def test_web_viewer_serves_on_localhost_until_ctrl_c(make_dataset: Callable[..., Path], tmp_path: Path) -> None:
    import signal
    import socket
    import urllib.request

    from psg_data.viewer._web import _free_port

    root = make_dataset(scans=2, frames=1)
    port = _free_port("127.0.0.1")
    err = tmp_path / "stderr.txt"
    with _web_view(root, port, err) as proc:
        url = proc.stdout.readline().strip()
        assert url.startswith(f"web viewer: http://127.0.0.1:{port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A")
        sent = proc.stdout.readline()
        assert sent.startswith("sent to the web viewer (2 scans, 2 frames, ") and "until Ctrl-C" in sent
        with urllib.request.urlopen(url.split(": ", 1)[1], timeout=20) as page:
            assert page.status == 200 and b"<html" in page.read(4096).lower()
        proc.send_signal(signal.SIGINT)
        assert _wait_or_dump(proc, 30.0, err) == 0
        assert proc.stdout.read().strip() == "stopped"
    with socket.socket() as s:  # the server (and the viewer binary it ran) is gone: the port is free again
        s.bind(("127.0.0.1", port))


def _tgkill(pid: int, tid: int, sig: int) -> None:
    """Send ``sig`` to one thread ``tid`` of process ``pid`` (Linux's tgkill(2), in glibc >= 2.30 and musl)."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    assert libc.tgkill(pid, tid, sig) == 0, f"tgkill failed: errno {ctypes.get_errno()}"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="threads picked through /proc and tgkill(2)")
def test_web_viewer_stops_when_ctrl_c_reaches_another_thread(make_dataset: Callable[..., Path],
                                                             tmp_path: Path) -> None:
    """The kernel may hand a process's SIGINT to any of its threads; one taken by a Rerun SDK thread
    must stop the viewer too (a blocking ``waitpid`` in the main thread never returned)."""
    import os
    import signal

    from psg_data.viewer._web import _free_port

    root = make_dataset(scans=1, frames=1)
    port = _free_port("127.0.0.1")
    err = tmp_path / "stderr.txt"
    with _web_view(root, port, err) as proc:
        assert proc.stdout.readline().startswith("web viewer: ")
        assert proc.stdout.readline().startswith("sent to the web viewer")
        others = sorted(int(t) for t in os.listdir(f"/proc/{proc.pid}/task") if int(t) != proc.pid)
        assert others, "the viewer process runs no thread besides its main one"
        _tgkill(proc.pid, others[-1], signal.SIGINT)
        assert _wait_or_dump(proc, 20.0, err) == 0
        assert proc.stdout.read().strip() == "stopped"


def test_web_viewer_port_in_use_is_one_line(make_dataset: Callable[..., Path]) -> None:
    import socket

    from tests.contract import assert_one_error

    root = make_dataset(scans=1, frames=1)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        line = assert_one_error(CliRunner().invoke(main, ["view", str(root), "--web", "--port", str(port), "-q"]))
    assert f"--port {port}: cannot listen on 127.0.0.1:{port}" in line
