"""A Rerun recording stream that ends up in an ``.rrd`` file or in a spawned viewer."""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from psg_data.errors import PsgDataError

__all__ = ["recording", "import_rerun"]


def import_rerun() -> Any:
    """The ``rerun`` module, or PsgDataError saying which extra to install."""
    try:
        import rerun
    except ImportError:
        raise PsgDataError("the Rerun viewer needs rerun-sdk: pip install 'psg-data[viewer]'") from None
    return rerun


@contextlib.contextmanager
def recording(save: str | Path | None = None, *, application_id: str = "psg-data",
              overwrite: bool = False, inputs: Iterable[str | Path] = ()) -> Iterator[Any]:
    """A ``rerun.RecordingStream`` for a ``with`` block.

    Args:
        save: write the recording to this ``.rrd`` file (via ``FILE.partial``, renamed when the
            block completes; nothing is left behind if it fails). None: spawn a viewer.
        application_id: Rerun application id.
        overwrite: replace an existing ``save`` file (only a Rerun recording: see
            :func:`psg_data.writers._safe_output.check_file_output`).
        inputs: paths the recording is made from (``save`` may not be or lie inside one).

    Raises:
        PsgDataError: rerun-sdk missing, or ``save`` exists and ``overwrite`` is False.
    """
    rr = import_rerun()
    rec = rr.RecordingStream(application_id)
    rec.set_log_time_enabled(False)  # only the data's own ``time`` timeline: the same data, the same timelines
    rec.set_log_tick_enabled(False)
    if save is None:
        rec.spawn()
        yield rec
        rec.flush()
        return
    from psg_data.writers._safe_output import check_file_output, replace_file

    out = Path(save)
    check_file_output(out, overwrite=overwrite, kind="rrd", inputs=inputs)  # only a recording of ours is replaced
    tmp = out.with_name(out.name + ".partial")
    rec.save(tmp)
    try:
        yield rec
        rec.flush()
        rec.disconnect()  # closes the file sink: the footer is written
        replace_file(tmp, out)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
