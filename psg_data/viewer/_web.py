"""Rerun's web viewer served from this machine: a ``rerun --serve-web`` process bound to one address.

The SDK's own ``serve_web_viewer`` listens on every interface (0.0.0.0) with no way to narrow it;
the ``rerun`` command's ``--bind`` sets the address of both its web server and its gRPC server,
so :class:`WebViewer` runs that command (from the installed rerun-sdk: ``python -m rerun``) and the
recording streams into its gRPC endpoint.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import quote

from psg_data.errors import PsgDataError

__all__ = ["WebViewer", "DEFAULT_WEB_PORT", "DEFAULT_BIND", "url_host"]

DEFAULT_WEB_PORT = 9090
"""Port of the web viewer (Rerun's default)."""
DEFAULT_BIND = "127.0.0.1"
"""Only this machine: another one reaches it through an SSH tunnel (``ssh -L 9090:127.0.0.1:9090``)."""
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


class WebViewer:
    """A Rerun web viewer (HTTP) and gRPC server on ``bind``, as a child process.

    Args:
        port: port of the web viewer (HTTP).
        bind: the address both servers listen on (``0.0.0.0``: every interface).
        log: file that receives the server's own output.
    """

    def __init__(self, *, port: int = DEFAULT_WEB_PORT, bind: str = DEFAULT_BIND, log: Path | None = None) -> None:
        self.port, self.bind, self.log = int(port), bind, log
        self.grpc_port = 0
        self._proc: subprocess.Popen[bytes] | None = None

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
        """What the recording connects to."""
        return f"rerun+http://{self.url_host}:{self.grpc_port}/proxy"

    @property
    def url(self) -> str:
        """What to open in a browser: the viewer, connected to this server's recording."""
        return f"http://{self.url_host}:{self.port}/?url={quote(self.grpc_url, safe='')}"

    def start(self, timeout_s: float = 30.0) -> None:
        """Start the server and wait until both ports accept connections.

        Raises:
            PsgDataError: a port in use, or the server did not come up (its last output line is quoted).
        """
        try:
            socket.getaddrinfo(self.bind, None)
        except OSError:
            raise PsgDataError(f"--bind {self.bind}: not an address of this machine") from None
        _check_port(self.bind, self.port, "--port")
        self.grpc_port = _free_port(self.bind)
        with open(self.log, "wb") if self.log is not None else contextlib.nullcontext(subprocess.DEVNULL) as out:
            self._proc = subprocess.Popen([sys.executable, "-m", "rerun", "--serve-web", "--bind", self.bind,
                                           "--port", str(self.grpc_port), "--web-viewer-port", str(self.port)],
                                          stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                          start_new_session=os.name == "posix")  # python -m rerun runs a child
        deadline = time.monotonic() + timeout_s
        while not all(self._listening(p) for p in (self.grpc_port, self.port)):
            if self._proc.poll() is not None or time.monotonic() > deadline:
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
        while self._proc is not None and self._proc.poll() is None:
            time.sleep(_POLL_S)

    def stop(self) -> None:
        """Stop the server (idempotent)."""
        if self._proc is not None:
            self._signal(signal.SIGTERM)
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._signal(signal.SIGKILL if os.name == "posix" else signal.SIGTERM)
                self._proc.wait()
        self._proc = None

    def _signal(self, sig: int) -> None:
        """``sig`` to the server and the viewer binary it started (its process group on POSIX)."""
        assert self._proc is not None
        with contextlib.suppress(ProcessLookupError, PermissionError):
            if os.name == "posix":
                os.killpg(self._proc.pid, sig)
            else:  # pragma: no cover - Windows
                self._proc.send_signal(sig)
