"""psg_data._fetch: pinned downloads, against a loopback HTTP server written here (never the internet).

The server serves files from tmp_path, honours ``Range: bytes=N-`` (206, or 416 past the end), logs
every request, and can drop the connection after K bytes of a response, ignore Range (answer 200),
or wait before answering (to make two callers overlap).
"""

from __future__ import annotations

import hashlib
import socket
import threading
import time
import urllib.parse
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from psg_data._fetch import CHUNK_BYTES, SOURCES_ENV, RemoteFile, RemoteSource, ensure_source
from psg_data.errors import PsgDataError

DOOR = b"".join(f"{1451865600 + 60 * i}\t{(i // 37) % 2}\n".encode() for i in range(12_000))  # ~160 kB
NAMES = b"Bed_to_Toilet\nMeal_Preparation\nRelax\n"
DOOR_LOCAL, DOOR_REMOTE = "greg_door_2016_min/training_data.txt", "greg_door_2016_min/training_data.txt"
NAMES_LOCAL, NAMES_REMOTE = "aruba_location/location.names", "data/aruba/location.names"
WHERE = "GitHub example/bench at commit 0123abcd, folders greg_door_2016_min/ and data/aruba/."


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, root: Path) -> None:
        super().__init__(("127.0.0.1", 0), _Handler)
        self.root = root
        self.log: list[tuple[str, str | None, int]] = []  # (path, Range header, status)
        self.drop_after: dict[str, int] = {}  # path -> body bytes sent before the connection drops (once)
        self.ignore_range = False
        self.delay_s = 0.0

    def handle_error(self, request: object, client_address: object) -> None:
        """A client that hung up mid-body (the Ctrl-C test) is expected: no traceback on stderr."""

    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}/pinned/"


class _Handler(BaseHTTPRequestHandler):
    server: _Server

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        srv = self.server
        rel = urllib.parse.unquote(self.path.lstrip("/"))
        time.sleep(srv.delay_s)
        path = srv.root / rel
        rng = self.headers.get("Range")
        if not path.is_file():
            return self._reply(rel, rng, 404, b"not found")
        data = path.read_bytes()
        if rng is None or srv.ignore_range:
            return self._reply(rel, rng, 200, data)
        start = int(rng.removeprefix("bytes=").rstrip("-"))
        if start >= len(data):
            return self._reply(rel, rng, 416, b"", {"Content-Range": f"bytes */{len(data)}"})
        self._reply(rel, rng, 206, data[start:], {"Content-Range": f"bytes {start}-{len(data) - 1}/{len(data)}"})

    def _reply(self, rel: str, rng: str | None, status: int, body: bytes,
               headers: dict[str, str] | None = None) -> None:
        self.server.log.append((rel, rng, status))
        self.send_response(status)
        for k, v in {"Content-Length": str(len(body)), **(headers or {})}.items():
            self.send_header(k, v)
        self.end_headers()
        cut = self.server.drop_after.pop(rel, None)
        self.wfile.write(body if cut is None else body[:cut])

    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - http.server's name
        pass


@pytest.fixture(autouse=True)
def _no_proxy_no_sources(monkeypatch: pytest.MonkeyPatch) -> None:
    """Loopback requests go straight to the test server; no offline folder unless a test sets one."""
    for name in ("http_proxy", "HTTP_PROXY", "https_proxy", "HTTPS_PROXY", "all_proxy", "ALL_PROXY", SOURCES_ENV):
        monkeypatch.delenv(name, raising=False)


@pytest.fixture
def server(tmp_path: Path) -> Iterator[_Server]:
    srv = _Server(tmp_path / "served")
    _publish(srv, DOOR_REMOTE, DOOR)
    _publish(srv, NAMES_REMOTE, NAMES)
    thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True)
    thread.start()
    yield srv
    srv.shutdown()
    srv.server_close()
    thread.join()


def _publish(srv: _Server, remote: str, data: bytes) -> None:
    path = srv.root / "pinned" / remote
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)


def _source(base_url: str, *, sized: bool = True, door_size: int | None = None) -> RemoteSource:
    door = RemoteFile(DOOR_LOCAL, DOOR_REMOTE, hashlib.sha256(DOOR).hexdigest(),
                      (len(DOOR) if door_size is None else door_size) if sized else None)
    names = RemoteFile(NAMES_LOCAL, NAMES_REMOTE, hashlib.sha256(NAMES).hexdigest(), len(NAMES) if sized else None)
    return RemoteSource("door-benchmark", base_url, (door, names), WHERE)


def _closed_port_url() -> str:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return f"http://127.0.0.1:{port}/pinned/"


def _snapshot(root: Path) -> dict[str, tuple[int, bytes]]:
    """Every path under root with its mtime (ns) and its bytes (b"" for folders)."""
    return {str(p.relative_to(root)): (p.stat().st_mtime_ns, p.read_bytes() if p.is_file() else b"")
            for p in sorted(root.rglob("*"))}


def _flip_byte(path: Path, at: int = 100) -> None:
    data = bytearray(path.read_bytes())
    data[at] ^= 0x01
    path.write_bytes(bytes(data))


def _door_requests(srv: _Server) -> list[tuple[str | None, int]]:
    return [(rng, status) for rel, rng, status in srv.log if rel.endswith(DOOR_REMOTE)]


# -- pins ------------------------------------------------------------------------------------------

def test_pinned_files_are_fetched_once_and_kept(server: _Server, tmp_path: Path) -> None:
    received: list[int] = []
    root = ensure_source(_source(server.url()), tmp_path / "cache", progress=received.append)
    assert root == tmp_path / "cache" / "door-benchmark"
    assert (root / DOOR_LOCAL).read_bytes() == DOOR and (root / NAMES_LOCAL).read_bytes() == NAMES
    assert sorted(rel for rel, _, _ in server.log) == sorted(["pinned/" + DOOR_REMOTE, "pinned/" + NAMES_REMOTE])
    assert sum(received) == len(DOOR) + len(NAMES)
    assert not list(root.rglob("*.partial"))
    again: list[int] = []
    assert ensure_source(_source(server.url()), tmp_path / "cache", progress=again.append) == root
    assert len(server.log) == 2 and again == []


def test_a_cached_file_that_changed_is_fetched_again(server: _Server, tmp_path: Path) -> None:
    root = ensure_source(_source(server.url()), tmp_path / "cache")
    _flip_byte(root / DOOR_LOCAL)
    ensure_source(_source(server.url()), tmp_path / "cache")
    assert (root / DOOR_LOCAL).read_bytes() == DOOR
    assert len(_door_requests(server)) == 2


# -- a wrong byte ----------------------------------------------------------------------------------

@pytest.mark.parametrize("sized", [True, False])
def test_a_wrong_byte_leaves_nothing(server: _Server, tmp_path: Path, sized: bool) -> None:
    bad = bytearray(DOOR)
    bad[70_000] ^= 0x01
    _publish(server, DOOR_REMOTE, bytes(bad))
    with pytest.raises(PsgDataError) as err:
        ensure_source(_source(server.url(), sized=sized), tmp_path / "cache")
    msg = str(err.value)
    assert "\n" not in msg
    assert server.url() + DOOR_REMOTE in msg and DOOR_LOCAL in msg
    assert hashlib.sha256(DOOR).hexdigest()[:12] in msg and hashlib.sha256(bad).hexdigest()[:12] in msg
    folder = tmp_path / "cache" / "door-benchmark" / "greg_door_2016_min"
    assert not folder.exists()  # neither the final name nor a partial file, nor the empty folder


def test_a_download_longer_than_its_pinned_size_is_stopped_early(server: _Server, tmp_path: Path) -> None:
    received: list[int] = []
    with pytest.raises(PsgDataError, match="longer than the pinned 1000 bytes"):
        ensure_source(_source(server.url(), door_size=1000), tmp_path / "cache", progress=received.append)
    assert sum(received) <= 1000 + CHUNK_BYTES < len(DOOR)
    assert not (tmp_path / "cache" / "door-benchmark" / "greg_door_2016_min").exists()


# -- interrupted downloads and resume --------------------------------------------------------------

@pytest.mark.parametrize("sized", [True, False])
def test_an_interrupted_download_keeps_the_partial_and_resumes(server: _Server, tmp_path: Path, sized: bool) -> None:
    k = 50_001
    server.drop_after["pinned/" + DOOR_REMOTE] = k
    with pytest.raises(PsgDataError) as err:
        ensure_source(_source(server.url(), sized=sized), tmp_path / "cache")
    msg = str(err.value)
    assert "\n" not in msg and f"{k} bytes kept" in msg and SOURCES_ENV in msg and DOOR_LOCAL in msg
    final = tmp_path / "cache" / "door-benchmark" / DOOR_LOCAL
    partial = final.with_name(final.name + ".partial")
    assert not final.exists() and partial.read_bytes() == DOOR[:k]
    received: list[int] = []
    root = ensure_source(_source(server.url(), sized=sized), tmp_path / "cache", progress=received.append)
    assert _door_requests(server)[-1] == (f"bytes={k}-", 206)
    assert (root / DOOR_LOCAL).read_bytes() == DOOR and not partial.exists()
    assert sum(received) == len(DOOR) - k + len(NAMES)


def test_ctrl_c_keeps_only_the_partial_and_the_next_call_resumes(server: _Server, tmp_path: Path) -> None:
    def interrupt(n: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        ensure_source(_source(server.url()), tmp_path / "cache", progress=interrupt)
    folder = tmp_path / "cache" / "door-benchmark" / "greg_door_2016_min"
    assert [p.name for p in folder.iterdir()] == ["training_data.txt.partial"]
    assert (folder / "training_data.txt.partial").read_bytes() == DOOR[:CHUNK_BYTES]
    root = ensure_source(_source(server.url()), tmp_path / "cache")
    assert _door_requests(server)[-1] == (f"bytes={CHUNK_BYTES}-", 206)
    assert (root / DOOR_LOCAL).read_bytes() == DOOR


def test_a_server_ignoring_range_still_gives_the_right_file(server: _Server, tmp_path: Path) -> None:
    server.drop_after["pinned/" + DOOR_REMOTE] = 30_000
    with pytest.raises(PsgDataError):
        ensure_source(_source(server.url()), tmp_path / "cache")
    server.ignore_range = True
    root = ensure_source(_source(server.url()), tmp_path / "cache")
    assert _door_requests(server)[-1] == ("bytes=30000-", 200)
    assert (root / DOOR_LOCAL).read_bytes() == DOOR
    assert not list(root.rglob("*.partial"))


def _plant_partial(cache: Path, data: bytes) -> Path:
    partial = cache / "door-benchmark" / (DOOR_LOCAL + ".partial")
    partial.parent.mkdir(parents=True)
    partial.write_bytes(data)
    return partial


def test_a_partial_longer_than_the_pinned_size_starts_over(server: _Server, tmp_path: Path) -> None:
    _plant_partial(tmp_path / "cache", DOOR + b"junk")
    root = ensure_source(_source(server.url()), tmp_path / "cache")
    assert _door_requests(server) == [(None, 200)]
    assert (root / DOOR_LOCAL).read_bytes() == DOOR


def test_a_416_answer_starts_over(server: _Server, tmp_path: Path) -> None:
    _plant_partial(tmp_path / "cache", DOOR + b"junk")
    root = ensure_source(_source(server.url(), sized=False), tmp_path / "cache")
    assert _door_requests(server) == [(f"bytes={len(DOOR) + 4}-", 416), (None, 200)]
    assert (root / DOOR_LOCAL).read_bytes() == DOOR


def test_a_partial_that_is_not_a_prefix_is_caught_and_deleted(server: _Server, tmp_path: Path) -> None:
    partial = _plant_partial(tmp_path / "cache", b"x" * 1000)
    with pytest.raises(PsgDataError, match="SHA-256"):
        ensure_source(_source(server.url()), tmp_path / "cache")
    assert not partial.exists() and not (tmp_path / "cache" / "door-benchmark" / DOOR_LOCAL).exists()
    root = ensure_source(_source(server.url()), tmp_path / "cache")
    assert _door_requests(server) == [("bytes=1000-", 206), (None, 200)]
    assert (root / DOOR_LOCAL).read_bytes() == DOOR


# -- offline copies --------------------------------------------------------------------------------

def _offline_copy(tmp_path: Path) -> Path:
    root = tmp_path / "realdata"
    for local, data in ((DOOR_LOCAL, DOOR), (NAMES_LOCAL, NAMES)):
        (root / local).parent.mkdir(parents=True, exist_ok=True)
        (root / local).write_bytes(data)
    return root


@pytest.mark.parametrize("via", ["argument", "environment"])
def test_an_offline_copy_is_checked_and_used_read_only(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                        via: str) -> None:
    offline = _offline_copy(tmp_path)
    before = _snapshot(offline)
    if via == "environment":
        monkeypatch.setenv(SOURCES_ENV, str(offline))
    root = ensure_source(_source(_closed_port_url()), tmp_path / "cache",
                         offline_root=offline if via == "argument" else None)
    assert root == offline and _snapshot(offline) == before
    assert not (tmp_path / "cache").exists()


@pytest.mark.parametrize("via", ["argument", "environment"])
def test_a_wrong_byte_in_an_offline_copy_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, via: str) -> None:
    offline = _offline_copy(tmp_path)
    _flip_byte(offline / DOOR_LOCAL)
    before = _snapshot(offline)
    if via == "environment":
        monkeypatch.setenv(SOURCES_ENV, str(offline))
    with pytest.raises(PsgDataError) as err:
        ensure_source(_source(_closed_port_url()), tmp_path / "cache",
                      offline_root=offline if via == "argument" else None)
    msg = str(err.value)
    assert "\n" not in msg and str(offline / DOOR_LOCAL) in msg
    assert hashlib.sha256(DOOR).hexdigest()[:12] in msg
    assert hashlib.sha256((offline / DOOR_LOCAL).read_bytes()).hexdigest()[:12] in msg
    assert _snapshot(offline) == before and not (tmp_path / "cache").exists()


def test_a_missing_offline_file_is_named(tmp_path: Path) -> None:
    offline = _offline_copy(tmp_path)
    (offline / NAMES_LOCAL).unlink()
    with pytest.raises(PsgDataError, match=f"{offline / NAMES_LOCAL}: missing"):
        ensure_source(_source(_closed_port_url()), tmp_path / "cache", offline_root=offline)


def test_the_argument_wins_over_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(SOURCES_ENV, str(tmp_path / "nowhere"))
    offline = _offline_copy(tmp_path)
    assert ensure_source(_source(_closed_port_url()), tmp_path / "cache", offline_root=offline) == offline
    with pytest.raises(PsgDataError, match="nowhere"):
        ensure_source(_source(_closed_port_url()), tmp_path / "cache")


# -- no network ------------------------------------------------------------------------------------

def _silent_port_url() -> tuple[socket.socket, str]:
    """A listening socket that never answers (the connection is queued, nothing is sent)."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(4)
    return s, f"http://127.0.0.1:{s.getsockname()[1]}/pinned/"


@pytest.mark.parametrize("kind", ["refused", "timeout", "http 404"])
def test_no_network_is_one_line_saying_where_to_get_the_files(server: _Server, tmp_path: Path, kind: str) -> None:
    silent = None
    if kind == "refused":
        url = _closed_port_url()
    elif kind == "timeout":
        silent, url = _silent_port_url()
    else:
        url = server.url().replace("/pinned/", "/moved/")
    try:
        with pytest.raises(PsgDataError) as err:
            ensure_source(_source(url), tmp_path / "cache", timeout_s=0.5)
    finally:
        if silent is not None:
            silent.close()
    msg = str(err.value)
    assert "\n" not in msg and url + DOOR_REMOTE in msg and DOOR_LOCAL in msg
    assert WHERE.rstrip(".") in msg and f"{SOURCES_ENV}=DIR" in msg
    assert "greg_door_2016_min/training_data.txt, aruba_location/location.names" in msg
    assert {"refused": "refused", "timeout": "timed out", "http 404": "HTTP 404"}[kind] in msg
    assert not (tmp_path / "cache" / "door-benchmark").exists()  # nothing left: no file, no empty folder


# -- two callers at once ---------------------------------------------------------------------------

def test_two_callers_at_once_fetch_each_file_once(server: _Server, tmp_path: Path) -> None:
    server.delay_s = 0.2  # both callers are inside ensure_source while the first download runs
    barrier = threading.Barrier(2)
    results: list[Path | BaseException] = []

    def call() -> None:
        barrier.wait()
        try:
            results.append(ensure_source(_source(server.url()), tmp_path / "cache"))
        except BaseException as exc:  # noqa: BLE001 - reported by the assertion below
            results.append(exc)

    threads = [threading.Thread(target=call) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    root = tmp_path / "cache" / "door-benchmark"
    assert results == [root, root]
    assert len(server.log) == 2  # one request per file
    assert (root / DOOR_LOCAL).read_bytes() == DOOR and (root / NAMES_LOCAL).read_bytes() == NAMES


# -- pins are checked when written -----------------------------------------------------------------

@pytest.mark.parametrize("local", ["../escape.txt", "/abs.txt", "a//b", "c:/x", "a\\b", ""])
def test_a_pin_naming_a_path_outside_the_root_is_refused(local: str) -> None:
    with pytest.raises(ValueError, match="RemoteFile.local"):
        RemoteFile(local, "x.txt", "0" * 64)


def test_a_pin_that_is_not_a_sha256_is_refused() -> None:
    with pytest.raises(ValueError, match="RemoteFile.sha256"):
        RemoteFile("a.txt", "a.txt", "ABC" + "0" * 61)
    with pytest.raises(ValueError, match="base_url"):
        RemoteSource("s", "file:///etc/", (RemoteFile("a.txt", "a.txt", "0" * 64),), WHERE)
    with pytest.raises(ValueError, match="name"):
        RemoteSource("../s", "https://example.org/", (RemoteFile("a.txt", "a.txt", "0" * 64),), WHERE)
