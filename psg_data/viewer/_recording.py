"""A Rerun recording stream that ends up in an ``.rrd`` file, a spawned viewer or a served web viewer."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from psg_data.errors import PsgDataError

__all__ = ["recording", "import_rerun", "display_problem"]


def import_rerun() -> Any:
    """The ``rerun`` module, or PsgDataError saying which extra to install."""
    try:
        import rerun
    except ImportError:
        raise PsgDataError("the Rerun viewer needs rerun-sdk: pip install 'psg-data[viewer]'") from None
    return rerun


def display_problem() -> str | None:
    """Why a native viewer window cannot open here, or None (Linux and BSD: no X11 or Wayland
    display in the environment, as on a server, in a container or over SSH without forwarding).
    """
    if not sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return None
    if any(os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")):
        return None
    return ("no display to open the Rerun viewer on (neither DISPLAY nor WAYLAND_DISPLAY is set); save a recording "
            "with --save FILE.rrd (open it with `rerun FILE.rrd` where there is a display) or serve the web viewer "
            "with --web")


@contextlib.contextmanager
def recording(save: str | Path | None = None, *, application_id: str = "psg-data",
              overwrite: bool = False, inputs: Iterable[str | Path] = (), blueprint: Any = None,
              web: Any = None) -> Iterator[Any]:
    """A ``rerun.RecordingStream`` for a ``with`` block.

    Args:
        save: write the recording to this ``.rrd`` file (via ``FILE.partial``, renamed when the
            block completes; nothing is left behind if it fails). None: stream it to ``web``, or
            spawn a native viewer.
        application_id: Rerun application id.
        overwrite: replace an existing ``save`` file (only a Rerun recording: see
            :func:`psg_data.writers._safe_output.check_file_output`).
        inputs: paths the recording is made from (``save`` may not be or lie inside one).
        blueprint: the layout sent with the recording (``rerun.blueprint.Blueprint``; the viewer's
            default otherwise).
        web: a started :class:`~psg_data.viewer.WebViewer` to stream to (when ``save`` is None).

    Raises:
        PsgDataError: rerun-sdk missing, ``save`` exists and ``overwrite`` is False, or no display
            for a native viewer (:func:`display_problem`).
    """
    rr = import_rerun()
    rec = rr.RecordingStream(application_id)
    rec.set_log_time_enabled(False)  # only the data's own ``time`` timeline: the same data, the same timelines
    rec.set_log_tick_enabled(False)
    if save is None:
        if web is not None:
            rec.connect_grpc(web.grpc_url, default_blueprint=blueprint)
        else:
            problem = display_problem()
            if problem is not None:
                raise PsgDataError(problem)
            rec.spawn(default_blueprint=blueprint)
        yield rec
        rec.flush()
        return
    from psg_data.writers._safe_output import check_file_output, replace_file

    out = Path(save)
    check_file_output(out, overwrite=overwrite, kind="rrd", inputs=inputs)  # only a recording of ours is replaced
    tmp = out.with_name(out.name + ".partial")
    rec.save(tmp, default_blueprint=blueprint)
    try:
        yield rec
        rec.flush()
        rec.disconnect()  # closes the file sink: the footer is written
        replace_file(tmp, out)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
