"""Rerun's web viewer served from this machine: a ``rerun --serve-web`` process bound to one address.

The SDK's own ``serve_web_viewer`` listens on every interface (0.0.0.0) with no way to narrow it;
the ``rerun`` command's ``--bind`` sets the address of both its web server and its gRPC server,
so :class:`WebViewer` runs that command (the installed rerun-sdk's viewer binary,
:func:`rerun_command`) and the recording streams into its gRPC endpoint. The page the browser
loads from the web port reads the recording from the gRPC port named in its ``?url=`` (Rerun's web
app connects to exactly that address), so both ports are fixed and a tunnel forwards both.
"""

from __future__ import annotations

import contextlib
import os
import socket
import sys
import time
from pathlib import Path
from urllib.parse import quote

from psg_data.errors import PsgDataError
from psg_data.viewer._child import ChildServer, stop_signals

__all__ = ["WebViewer", "DEFAULT_WEB_PORT", "DEFAULT_GRPC_PORT", "DEFAULT_BIND", "url_host", "rerun_command"]

DEFAULT_WEB_PORT = 9090
"""Port of the web viewer (Rerun's default)."""
DEFAULT_GRPC_PORT = 9876
"""Port of the gRPC server the recording streams into and the page reads it from (Rerun's default)."""
DEFAULT_BIND = "127.0.0.1"
"""Only this machine: another one reaches it through an SSH tunnel (:attr:`WebViewer.ssh_tunnel`)."""
_POLL_S = 0.2
"""How often :meth:`WebViewer.wait` looks whether the server ended (seconds)."""


def _free_port(bind: str) -> int:
    with socket.socket(socket.AF_INET6 if ":" in bind else socket.AF_INET) as s:
        s.bind((bind, 0))
        return int(s.getsockname()[1])


def _check_port(bind: str, port: int, option: str) -> None:
    with socket.socket(socket.AF_INET6 if ":" in bind else socket.AF_INET) as s:
        try:
            s.bind((bind, port))
        except OSError as exc:
            raise PsgDataError(f"{option} {port}: cannot listen on {bind}:{port} ({exc.strerror}); choose another "
                               f"port with {option}") from None


def url_host(host: str) -> str:
    """``host`` as the host part of a URL (RFC 3986): an IPv6 address in brackets, anything else as it is."""
    return f"[{host.replace('%', '%25')}]" if ":" in host and not host.startswith("[") else host


def rerun_command() -> list[str]:
    """The Rerun viewer binary that ``python -m rerun`` runs, to be run directly: one process, which
    a parent-death signal reaches (``python -m rerun`` runs it as a child of its own).

    Found as rerun-sdk's ``rerun_cli/__main__.py`` finds it: ``RERUN_CLI_PATH``, on macOS the app
    bundle, else ``rerun_cli/rerun``; ``python -m rerun`` where none is there.
    """
    import importlib.util

    if os.environ.get("RERUN_CLI_PATH"):
        return [os.environ["RERUN_CLI_PATH"]]
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        here = Path(spec.origin).parent
        candidates = [here / "Rerun.app" / "Contents" / "MacOS" / "Rerun"] if sys.platform == "darwin" else []
        candidates.append(here / ("rerun.exe" if sys.platform.startswith("win") else "rerun"))
        for path in candidates:
            if path.is_file():
                return [str(path)]
    return [sys.executable, "-m", "rerun"]


class WebViewer:
    """A Rerun web viewer (HTTP) and gRPC server on ``bind``, as a child process.

    A browser on another machine needs both ports forwarded under the same numbers
    (:attr:`ssh_tunnel`): the page comes from ``port``, the recording from ``grpc_port``. Used as a
    context manager, the server is stopped however the block ends, also by SIGHUP or SIGTERM
    (:mod:`psg_data.viewer._child`).

    Args:
        port: port of the web viewer (HTTP).
        grpc_port: port of the gRPC server the recording streams into and the page reads from.
        bind: the address both servers listen on (``0.0.0.0``: every interface).
        log: file that receives the server's own output.
    """

    def __init__(self, *, port: int = DEFAULT_WEB_PORT, grpc_port: int = DEFAULT_GRPC_PORT,
                 bind: str = DEFAULT_BIND, log: Path | None = None) -> None:
        self.port, self.grpc_port, self.bind, self.log = int(port), int(grpc_port), bind, log
        self._server: ChildServer | None = None
        self._exit = contextlib.ExitStack()

    @property
    def host(self) -> str:
        """The address a browser on this machine uses (every interface: the loopback address of that family)."""
        return {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(self.bind, self.bind)

    @property
    def url_host(self) -> str:
        """:attr:`host` as a URL writes it: an IPv6 address in brackets (``[::1]``)."""
        return url_host(self.host)

    @property
    def grpc_url(self) -> str:
        """What the recording connects to, and the page reads from."""
        return f"rerun+http://{self.url_host}:{self.grpc_port}/proxy"

    @property
    def url(self) -> str:
        """What to open in a browser: the viewer, connected to this server's recording."""
        return f"http://{self.url_host}:{self.port}/?url={quote(self.grpc_url, safe='')}"

    @property
    def ssh_tunnel(self) -> str:
        """The ``ssh`` command that makes :attr:`url` work on another machine: both ports, same numbers."""
        return "ssh " + " ".join(f"-L {p}:{self.url_host}:{p}" for p in (self.port, self.grpc_port)) + " HOST"

    def __enter__(self) -> WebViewer:
        """:meth:`start` with :func:`~psg_data.viewer._child.stop_signals` in force until the block ends."""
        with contextlib.ExitStack() as stack:
            stack.enter_context(stop_signals())
            stack.callback(self.stop)
            self.start()
            self._exit = stack.pop_all()
        return self

    def __exit__(self, *exc: object) -> None:
        self._exit.close()

    def start(self, timeout_s: float = 30.0) -> None:
        """Start the server and wait until both ports accept connections.

        Raises:
            PsgDataError: a port in use, or the server did not come up (its last output line is quoted).
        """
        try:
            socket.getaddrinfo(self.bind, None)
        except OSError:
            raise PsgDataError(f"--bind {self.bind}: not an address of this machine") from None
        if self.grpc_port == self.port:
            raise PsgDataError(f"--grpc-port {self.grpc_port}: the same as --port; choose two different ports")
        _check_port(self.bind, self.port, "--port")
        _check_port(self.bind, self.grpc_port, "--grpc-port")
        self._server = ChildServer([*rerun_command(), "--serve-web", "--bind", self.bind, "--port",
                                    str(self.grpc_port), "--web-viewer-port", str(self.port)], log=self.log)
        self._server.start()
        deadline = time.monotonic() + timeout_s
        while not all(self._listening(p) for p in (self.grpc_port, self.port)):
            if not self._server.running() or time.monotonic() > deadline:
                self.stop()
                raise PsgDataError(f"the Rerun web viewer did not start on {self.bind} (ports {self.port}, "
                                   f"{self.grpc_port}){self._last_line()}")
            time.sleep(0.1)

    def _listening(self, port: int) -> bool:
        with contextlib.suppress(OSError), socket.create_connection((self.host, port), timeout=0.5):
            return True
        return False

    def _last_line(self) -> str:
        if self.log is None or not self.log.is_file():
            return ""
        lines = [ln for ln in self.log.read_text(errors="replace").splitlines() if ln.strip()]
        return f": {lines[-1].strip()}" if lines else ""

    def wait(self) -> None:
        """Block until the server ends (or Ctrl-C).

        Polls every ``_POLL_S`` seconds instead of one blocking wait: the kernel may hand a Ctrl-C
        to any thread (the Rerun SDK runs a dozen), and a signal taken by another thread does not
        interrupt the main thread's blocking ``waitpid``; a sleep ends, and the KeyboardInterrupt
        is raised then.
        """
        while self._server is not None and self._server.running():
            time.sleep(_POLL_S)

    def stop(self) -> None:
        """Stop the server and whatever it started (idempotent)."""
        if self._server is not None:
            self._server.stop()
        self._server = None
