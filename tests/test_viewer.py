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
import rerun  # [dev] installs psg-data[viewer]; a missing extra fails loudly
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
    """The values of the column ending with ``suffix`` in those of ``batches`` that have it."""
    out: list[Any] = []
    for b in batches:
        name = next((n for n in b.schema.names if n.endswith(suffix)), None)
        out += b.column(name).to_pylist() if name is not None else []
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
    assert len(_column(batches["/labels/gt/redmug/table"], ":scalars")) == 3  # and one static row: drawn as steps
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
    parts = _blueprint_parts(out)  # legends top left over a band above the traces: last_seen, truth, observations
    left_top = rerun.blueprint.components.Corner2D.LeftTop.value
    assert [v["PlotLegend:corner"][0][0] for k, v in parts.items() if k.endswith("/PlotLegend")] == [left_top] * 4
    assert all(v["ScalarAxis:range"][0][0][1] - 1.0 >= 3 * 0.25 for k, v in parts.items() if k.endswith("/ScalarAxis"))
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
    assert _column(batches["/labels/gt/redmug/table"], "scan") == [0, 1, 2]
    (blueprint,) = reader.blueprints()
    parts: dict[str, list] = {}  # type: ignore[type-arg]
    for chunk in reader.store(store=blueprint).stream():
        parts.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    assert _column(parts["/time_panel"], ":timeline") == [["scan"]]
    views = {p.rsplit("/", 1)[0] for p in parts if p.startswith("/view/") and p.count("/") == 3}
    plots = {p.rsplit("/", 1)[0] for p in parts if p.endswith("/ScalarAxis")}
    eye = [p for p in parts if p.endswith("/EyeControls3D")]
    # the 3D world, colour, depth, one plot per changing object edge (redmug on table and desk, the spoon
    # on the shelf) and one for the door
    assert len(eye) == 1 and len(plots) == 4 and len(views) == 7


def _blueprint_parts(path: Path) -> dict[str, dict[str, list]]:  # type: ignore[type-arg]
    """The saved recording's blueprint: entity path -> column (``Archetype:field``) -> values."""
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    (blueprint,) = reader.blueprints()
    parts: dict[str, dict[str, list]] = {}  # type: ignore[type-arg]
    for chunk in reader.store(store=blueprint).stream():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if ":" in name:
                parts.setdefault(chunk.entity_path, {}).setdefault(name, []).extend(batch.column(name).to_pylist())
    return parts


@pytest.fixture
def lab_recording(make_dataset: Callable[..., Path], tmp_path: Path) -> tuple[Path, Path]:
    """The tiny dataset (its desk lies outside the one room with a floor outline) and its recording."""
    root = make_dataset(scans=3, frames=1)
    out = tmp_path / "lab.rrd"
    assert CliRunner().invoke(main, ["view", str(root), "--save", str(out), "-q"]).exit_code == 0
    return root, out


def test_viewer_opens_paused_on_the_first_scan(lab_recording: tuple[Path, Path]) -> None:
    """The time panel is paused (Rerun then puts the cursor at the timeline's start, the first scan;
    playing or following, the default, at its end: the last scan)."""
    import rerun.blueprint as rrb

    panel = _blueprint_parts(lab_recording[1])["/time_panel"]
    assert panel["TimePanelBlueprint:timeline"] == [["scan"]]
    assert panel["TimePanelBlueprint:play_state"] == [[rrb.components.PlayState.Paused.value]]


def test_3d_view_shows_every_box_of_the_lab(lab_recording: tuple[Path, Path]) -> None:
    """Every corner of every receptacle and door box, and every room outline, projects inside the 3D
    view's opening eye: a pinhole with Rerun's vertical field of view (55 degrees, ``DEFAULT_FOV_Y``
    in the viewer's ``re_view_spatial/src/eye.rs``) on a view as wide as tall."""
    root, out = lab_recording
    ds = open_dataset(root)
    (eye,) = [v for k, v in _blueprint_parts(out).items() if k.endswith("/EyeControls3D")]
    position, target, up = (np.array(eye[f"EyeControls3D:{f}"][0][0]) for f in ("position", "look_target", "eye_up"))
    forward = (target - position) / np.linalg.norm(target - position)
    right = np.cross(forward, up) / np.linalg.norm(np.cross(forward, up))
    cam_up = np.cross(right, forward)
    points = [c for items in (ds.receptacles, ds.doors) for item in items.values() for c in item.box.corners()]
    points += [np.array([x, y, 0.0]) for room in ds.rooms.values() if room.floor_polygon_m is not None
               for x, y in room.floor_polygon_m]
    assert len(points) == 8 * 4 + 4
    half = np.tan(np.radians(55.0) / 2)
    for p in points:
        depth = (p - position) @ forward
        assert depth > 0 and abs((p - position) @ right) <= half * depth and abs((p - position) @ cam_up) <= half * depth, p


def test_label_series_are_drawn_as_steps(lab_recording: tuple[Path, Path]) -> None:
    """Every label stream (objects and doors) is drawn holding each 0/1 value until the next
    observation (``SeriesLines`` ``StepAfter``: "hold the previous value until the next data point,
    then jump"), not as a straight line from one observation to the next."""
    import rerun as rr

    rows, batches = _read(lab_recording[1])
    series = sorted(e for e in rows if e.startswith("/labels/"))
    assert {"/labels/gt/redmug/table", "/labels/gt/doors/door1"} <= set(series)
    step = rr.components.InterpolationMode.StepAfter.value
    for entity in series:
        modes = [v for b in batches[entity] if "SeriesLines:interpolation_mode" in b.schema.names
                 for v in b.column("SeriesLines:interpolation_mode").to_pylist()]
        assert modes == [[step]], entity


def test_plot_legends_sit_over_an_empty_band_above_the_traces(lab_recording: tuple[Path, Path]) -> None:
    """0/1 traces run along the whole width at 0 and at 1: a legend in a top corner covers none of
    them only when the y axis leaves a band above 1 (here at least 0.25 per legend entry, one each)."""
    import rerun.blueprint as rrb

    parts = _blueprint_parts(lab_recording[1])
    legends = {k.rsplit("/", 1)[0]: v for k, v in parts.items() if k.endswith("/PlotLegend")}
    axes = {k.rsplit("/", 1)[0]: v for k, v in parts.items() if k.endswith("/ScalarAxis")}
    assert len(axes) == 4 and set(legends) == set(axes)
    top = {rrb.components.Corner2D.LeftTop.value, rrb.components.Corner2D.RightTop.value}
    for view, legend in legends.items():
        assert legend["PlotLegend:corner"][0][0] in top and legend["PlotLegend:visible"] == [[True]]
        low, high = axes[view]["ScalarAxis:range"][0][0]
        assert low < 0 and high - 1.0 >= 0.25


VIEW_CLI = ("import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
            "signal.signal(signal.SIGHUP, signal.SIG_DFL); from psg_data.cli.psg_data_cmd import main; main()")
"""``psg-data`` as a terminal starts it: a test run started in the background by a non-interactive
shell inherits SIGINT ignored, and so would the command (which then rightly ignores the Ctrl-C);
the earlier one-in-several "hang" of the Ctrl-C test was that (as in tests/format/test_interrupt.py).
Under ``nohup`` the run inherits SIGHUP ignored, which the command rightly keeps (the SIGHUP test
then waited 30 s for a viewer that, as asked, stayed up): the command starts with SIGHUP's default."""


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
def _web_view(root: Path, port: int, err: Path, *, grpc_port: int | None = None) -> Iterator[Any]:
    """``psg-data view ROOT --web --port PORT --grpc-port GRPC -q`` as a child process in a session
    of its own, as a terminal runs a command (stderr to ``err``); killed if still running when the
    block ends, with the Rerun server it started."""
    import signal
    import subprocess

    from psg_data.viewer._web import _free_port

    grpc_port = _free_port("127.0.0.1") if grpc_port is None else grpc_port
    with open(err, "wb") as err_file:
        proc = subprocess.Popen([sys.executable, "-X", "faulthandler", "-c", VIEW_CLI, "view", str(root), "--web",
                                 "--port", str(port), "--grpc-port", str(grpc_port), "-q"],
                                stdout=subprocess.PIPE, stderr=err_file, text=True, start_new_session=True)
    assert proc.stdout is not None
    try:
        yield proc
    finally:
        if proc.poll() is None:
            _end_with_servers(proc, signal.SIGKILL)
        proc.stdout.close()


def _read_until_served(proc: Any) -> list[str]:
    """The command's lines up to the one saying the recording was sent (the server is then up and fed)."""
    lines = [proc.stdout.readline()]
    while lines[-1] and not lines[-1].startswith("sent to the web viewer"):
        lines.append(proc.stdout.readline())
    assert lines[-1], f"the command ended early: {lines}"
    return [ln.rstrip("\n") for ln in lines]


def test_web_viewer_serves_on_localhost_until_ctrl_c(make_dataset: Callable[..., Path], tmp_path: Path) -> None:
    import signal
    import socket
    import urllib.request

    from psg_data.viewer._web import _free_port

    root = make_dataset(scans=2, frames=1)
    port, grpc_port = _free_port("127.0.0.1"), _free_port("127.0.0.1")
    err = tmp_path / "stderr.txt"
    with _web_view(root, port, err, grpc_port=grpc_port) as proc:
        url, tunnel, sent = _read_until_served(proc)
        assert url == f"web viewer: http://127.0.0.1:{port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}%2Fproxy"
        assert tunnel.startswith(f"from another machine: ssh -L {port}:127.0.0.1:{port} "
                                 f"-L {grpc_port}:127.0.0.1:{grpc_port} HOST")
        assert sent.startswith("sent to the web viewer (2 scans, 2 frames, ") and "until Ctrl-C" in sent
        with urllib.request.urlopen(url.split(": ", 1)[1], timeout=20) as page:
            assert page.status == 200 and b"<html" in page.read(4096).lower()
        proc.send_signal(signal.SIGINT)
        assert _wait_or_dump(proc, 30.0, err) == 130  # README: 130 interrupted (Ctrl-C)
        assert proc.stdout.read() == "" and err.read_text().strip().endswith("error: interrupted")
    for p in (port, grpc_port):  # the server (and the viewer binary it ran) is gone: the ports are free again
        with socket.socket() as s:
            s.bind(("127.0.0.1", p))


def _stat(pid: int) -> tuple[str, int, int]:
    """State, parent and process group of ``pid`` from /proc/PID/stat (Linux)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return fields[0], int(fields[1]), int(fields[2])


def _processes() -> dict[int, tuple[str, int, int]]:
    """Every live process: pid -> (state, parent, process group)."""
    out = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                out[int(d.name)] = _stat(int(d.name))
    return out


def _descendants(pid: int) -> set[int]:
    procs = _processes()
    found: set[int] = set()
    todo = [pid]
    while todo:
        parent = todo.pop()
        kids = {p for p, (_, ppid, _) in procs.items() if ppid == parent} - found
        found |= kids
        todo += kids
    return found


def _left_in(groups: set[int], pids: set[int], wait_s: float = 15.0) -> list[str]:
    """The processes (not zombies) still in ``groups`` or among ``pids`` once they had ``wait_s``
    seconds to end (each as its /proc cmdline); all of them are then killed, so that a failing test
    leaves nothing behind."""
    import os
    import signal
    import time

    deadline = time.monotonic() + wait_s
    while True:
        left = {p for p, (state, _, pgid) in _processes().items() if state != "Z" and (pgid in groups or p in pids)}
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    names = []
    for pid in sorted(left):
        with contextlib.suppress(OSError):
            names.append(f"{pid}: {Path(f'/proc/{pid}/cmdline').read_bytes().replace(bytes(1), b' ').decode()[:120]}")
            os.kill(pid, signal.SIGKILL)
    return names


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="processes found through /proc")
@pytest.mark.parametrize("sig, code", [("SIGHUP", 129), ("SIGTERM", 143), ("SIGINT", 130)])
def test_web_viewer_leaves_no_process_when_stopped_by_a_signal(make_dataset: Callable[..., Path], tmp_path: Path,
                                                               sig: str, code: int) -> None:
    """A dropped SSH session or closed terminal (SIGHUP to the command's process group), ``kill``
    (SIGTERM) and Ctrl-C (SIGINT to the group): the command ends with 128 + the signal's number and
    no process of its own or of the Rerun server's process group survives; both ports are free."""
    import os
    import signal
    import socket

    from psg_data.viewer._web import _free_port

    root = make_dataset(scans=1, frames=1)
    port, grpc_port = _free_port("127.0.0.1"), _free_port("127.0.0.1")
    err = tmp_path / "stderr.txt"
    with _web_view(root, port, err, grpc_port=grpc_port) as proc:
        _read_until_served(proc)
        pids = _descendants(proc.pid)
        groups = {proc.pid} | {_stat(p)[2] for p in pids}
        assert len(groups) >= 2, "the Rerun server runs in a process group of its own"
        number = getattr(signal, sig)
        if sig == "SIGTERM":
            os.kill(proc.pid, number)
        else:
            os.killpg(proc.pid, number)  # what the terminal does: its (foreground) process group
        exit_code = _wait_or_dump(proc, 30.0, err)
        assert _left_in(groups, pids) == []
        assert exit_code == code
    for p in (port, grpc_port):
        with socket.socket() as s:
            s.bind(("127.0.0.1", p))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal: Linux's prctl")
def test_web_viewer_server_dies_with_a_killed_command(make_dataset: Callable[..., Path], tmp_path: Path) -> None:
    """SIGKILL (nothing of psg-data runs any more): the kernel ends the server (PR_SET_PDEATHSIG)."""
    import os
    import signal

    from psg_data.viewer._web import _free_port

    root = make_dataset(scans=1, frames=1)
    err = tmp_path / "stderr.txt"
    with _web_view(root, _free_port("127.0.0.1"), err) as proc:
        _read_until_served(proc)
        pids = _descendants(proc.pid)
        groups = {_stat(p)[2] for p in pids}
        assert pids
        os.kill(proc.pid, signal.SIGKILL)
        assert proc.wait(timeout=30) == -signal.SIGKILL
        assert _left_in(groups, pids) == []


@contextlib.contextmanager
def _relay(listen: tuple[str, int], target: tuple[str, int]) -> Iterator[None]:
    """What ``ssh -L PORT:HOST:PORT`` does, without ssh: every connection to ``listen`` is piped to ``target``."""
    import socket
    import threading

    def pump(src: socket.socket, dst: socket.socket) -> None:
        with contextlib.suppress(OSError):
            while data := src.recv(65536):
                dst.sendall(data)
        with contextlib.suppress(OSError):
            dst.shutdown(socket.SHUT_WR)

    def serve(server: socket.socket) -> None:
        with contextlib.suppress(OSError):
            while True:
                near, _ = server.accept()
                far = socket.create_connection(target, timeout=30)
                for a, b in ((near, far), (far, near)):
                    threading.Thread(target=pump, args=(a, b), daemon=True).start()

    with socket.socket() as server:
        server.bind(listen)
        server.listen()
        threading.Thread(target=serve, args=(server,), daemon=True).start()
        yield


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="127.0.0.2: a loopback address of its own on Linux")
def test_web_viewer_page_and_data_reach_a_browser_through_the_printed_tunnel(make_dataset: Callable[..., Path],
                                                                             tmp_path: Path) -> None:
    """A browser on another machine, through the tunnel the command prints: ``ssh -L`` is mimicked
    by one relay per forwarded port, listening on 127.0.0.2 (the "other machine's" localhost, where
    the server, bound to 127.0.0.1, cannot be reached) under the same port numbers. Through them the
    printed URL's page loads, and the data endpoint its ``?url=`` names answers the request Rerun's
    web app makes (gRPC-web ``ReadMessages``) with this recording (its application id).
    """
    import re
    import socket
    import urllib.request
    from urllib.parse import parse_qs, urlsplit

    from psg_data.viewer._web import _free_port

    root = make_dataset(scans=1, frames=1)
    with _web_view(root, _free_port("127.0.0.1"), tmp_path / "stderr.txt") as proc:
        lines = _read_until_served(proc)
        url = lines[0].removeprefix("web viewer: ").replace("127.0.0.1", "127.0.0.2")  # as the other machine sees it
        forwards = re.findall(r"-L (\d+):([^: ]+):(\d+)", next((ln for ln in lines if "ssh " in ln), ""))
        data = urlsplit(parse_qs(urlsplit(url).query)["url"][0])
        assert data.hostname == "127.0.0.2" and data.port is not None
        with pytest.raises(OSError):  # without the tunnel the data port is out of reach
            socket.create_connection(("127.0.0.2", data.port), timeout=5).close()
        with contextlib.ExitStack() as tunnel:
            for near, host, far in forwards:
                tunnel.enter_context(_relay(("127.0.0.2", int(near)), (host, int(far))))
            with urllib.request.urlopen(url, timeout=20) as page:
                assert page.status == 200 and b"<html" in page.read(4096).lower()
            request = urllib.request.Request(
                f"http://127.0.0.2:{data.port}/rerun.sdk_comms.v1alpha1.MessageProxyService/ReadMessages",
                data=bytes(5), headers={"content-type": "application/grpc-web+proto", "x-grpc-web": "1"})
            with urllib.request.urlopen(request, timeout=20) as reply:  # empty request: one frame, flag 0, length 0
                assert reply.headers["content-type"].startswith("application/grpc-web")
                head = reply.read(5)
                first = reply.read(int.from_bytes(head[1:5], "big"))
        assert head[0] == 0 and b"psg-data" in first  # a data frame of the recording (application id)


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
        assert _read_until_served(proc)[0].startswith("web viewer: ")
        others = sorted(int(t) for t in os.listdir(f"/proc/{proc.pid}/task") if int(t) != proc.pid)
        assert others, "the viewer process runs no thread besides its main one"
        _tgkill(proc.pid, others[-1], signal.SIGINT)
        assert _wait_or_dump(proc, 20.0, err) == 130
        assert err.read_text().strip().endswith("error: interrupted")


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
    with socket.socket() as s:  # the data port too, named by its own option
        s.bind(("127.0.0.1", 0))
        s.listen()
        taken = s.getsockname()[1]
        line = assert_one_error(CliRunner().invoke(main, ["view", str(root), "--web", "--port", str(port),
                                                          "--grpc-port", str(taken), "-q"]))
    assert f"--grpc-port {taken}: cannot listen on 127.0.0.1:{taken}" in line and "choose another port" in line
    line = assert_one_error(CliRunner().invoke(main, ["view", str(root), "--web", "--port", str(port),
                                                      "--grpc-port", str(port), "-q"]))
    assert line == f"error: --grpc-port {port}: the same as --port; choose two different ports"
