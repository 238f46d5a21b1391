"""Writing outputs without destroying anything: the one rule every command follows.

``--overwrite`` (``overwrite=True``) replaces only something psg-data wrote and only of the kind the
command writes:

* ``dataset``: a psg-dataset (``dataset.json`` of format ``psg-dataset``) in which every file is
  the manifest, ``tables/files.parquet`` or listed in it;
* ``results`` (psg-eval) and ``recordings`` (``psg-data synth --format ros1|...``): a folder whose
  marker file :data:`OUTPUT_MARKER` lists every file in it;
* an empty folder.

Never a path that is or contains an input, and never a path inside an input (whatever
``overwrite`` says). Anything else is refused with one line that says why.

Outputs are written into a staging folder beside the target (``OUT.partial``, marked as psg-data's
with :data:`PARTIAL_MARKER`), every file and folder of it is fsynced, and it is swapped into place
by renames: the old output is renamed aside (``.OUT.psg-replaced``), the new one renamed into place,
and only then is the old one removed. Nothing named ``OUT.old`` is left; after a crash in the
middle of the swap the previous output is still complete under ``.OUT.psg-replaced``.

The public library functions that write single files (``save_results``, ``write_detections``,
``save_queries``, the ``plot_*`` functions, ...) replace the files they are told to write, as
pandas and matplotlib do, but each one atomically (:func:`write_atomically`) and never inside an
input they know of.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path

from psg_data.errors import DatasetExistsError, UnsafeOutputError

__all__ = ["OUTPUT_KINDS", "OUTPUT_MARKER", "PARTIAL_MARKER", "check_output", "check_not_input", "make_staging",
           "commit_tree", "replace_file", "fsync_tree", "owned_files", "check_file_output", "FILE_SIGNATURES",
           "write_atomically"]

log = logging.getLogger(__name__)

OUTPUT_KINDS = {"dataset": "a psg-dataset", "results": "a psg-eval results folder",
                "recordings": "a folder of recordings written by psg-data synth"}
OUTPUT_MARKER = ".psg-output.json"
"""In a ``results`` or ``recordings`` folder: ``{"kind": ..., "files": [relative paths]}``."""
PARTIAL_MARKER = ".psg-partial"
"""In a staging folder ``OUT.partial``: marks it as psg-data's (it may be removed or resumed)."""
_REPLACED = ".{name}.psg-replaced"
_LIST_MAX = 3


def _resolve(p: str | os.PathLike[str]) -> Path:
    return Path(os.path.abspath(Path(p).expanduser().resolve(strict=False)))


def _within(child: Path, parent: Path) -> bool:
    return child != parent and parent in child.parents


def check_not_input(out: str | Path, inputs: Iterable[str | Path | None], *, what: str = "output") -> None:
    """Refuse an output path that is, contains or lies inside any of ``inputs`` (None entries skipped).

    Raises:
        UnsafeOutputError: naming the output and the input.
    """
    o = _resolve(out)
    for inp in inputs:
        if inp is None or str(inp) == "":
            continue
        i = _resolve(inp)
        if o == i:
            raise UnsafeOutputError(f"{out}: the {what} is the input {inp}; expected another path (psg-data never "
                                    f"writes over its inputs)")
        if _within(i, o):
            raise UnsafeOutputError(f"{out}: the {what} contains the input {inp}; expected a path outside the "
                                    f"inputs (replacing it would delete them)")
        if _within(o, i):
            raise UnsafeOutputError(f"{out}: the {what} lies inside the input {inp}; expected a path outside the "
                                    f"inputs (psg-data never writes into its inputs)")


def _files_under(root: Path) -> list[str]:
    out = []
    for dirpath, dirnames, filenames in os.walk(root):
        rel = os.path.relpath(dirpath, root)
        for n in filenames:
            out.append(n if rel == "." else f"{Path(rel).as_posix()}/{n}")
        for n in dirnames:  # links to directories are listed as entries (never followed)
            if os.path.islink(os.path.join(dirpath, n)):
                out.append(n if rel == "." else f"{Path(rel).as_posix()}/{n}")
    return sorted(out)


def _dataset_listing(root: Path) -> set[str] | str:
    """Files a psg-dataset at ``root`` says it holds, or why it cannot be recognised as one."""
    manifest = root / "dataset.json"
    try:
        fmt = json.loads(manifest.read_text(encoding="utf-8")).get("format")
    except (OSError, UnicodeDecodeError, ValueError, AttributeError):
        return "is not a psg-dataset (no readable dataset.json)"
    if fmt != "psg-dataset":
        return "is not a psg-dataset (dataset.json is of another format)"
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq

        listed = set(pq.read_table(root / "tables" / "files.parquet", columns=["path"]).column("path").to_pylist())
    except (OSError, KeyError, pa.ArrowException):
        return "is a psg-dataset whose tables/files.parquet is unreadable, so which files psg-data wrote is unknown"
    return listed | {"dataset.json", "tables/files.parquet"}


def _marker(root: Path) -> dict | None:
    try:
        marker = json.loads((root / OUTPUT_MARKER).read_text(encoding="utf-8"))
        return marker if isinstance(marker, dict) and isinstance(marker.get("files"), list) else None
    except (OSError, UnicodeDecodeError, ValueError):
        return None


def owned_files(root: str | Path, kind: str) -> set[str] | str:
    """Relative paths psg-data wrote into the output ``root`` of ``kind``, or why it is not such an output."""
    root = Path(root)
    marker = _marker(root)
    if kind == "dataset":
        if marker is not None and not (root / "dataset.json").exists():
            return f"is {OUTPUT_KINDS.get(marker.get('kind'), 'another kind of output')}"  # type: ignore[arg-type]
        return _dataset_listing(root)
    if marker is None:
        if (root / "dataset.json").is_file():
            return "is a psg-dataset"
        return f"is not {OUTPUT_KINDS[kind]} (no {OUTPUT_MARKER})"
    if marker.get("kind") != kind:
        return f"is {OUTPUT_KINDS.get(marker.get('kind'), 'another kind of output')}"  # type: ignore[arg-type]
    return {str(f) for f in marker["files"]} | {OUTPUT_MARKER}


def _foreign(root: Path, kind: str) -> str | None:
    """Why replacing ``root`` could destroy something psg-data did not write (None: it may be replaced)."""
    if root.is_symlink():
        return "is a symbolic link"
    if not root.is_dir():
        return "is a file" if root.is_file() else "is not a folder"
    present = [f for f in _files_under(root) if f != PARTIAL_MARKER]  # left by a crash right after a swap
    if not present:
        return None
    owned = owned_files(root, kind)
    if isinstance(owned, str):
        return owned if owned.startswith("is a") else f"{owned} and holds {_some(present)}"
    strays = [f for f in present if f not in owned]
    if strays:
        return f"holds files psg-data did not write ({_some(strays)})"
    return None


def _some(names: list[str]) -> str:
    more = f" and {len(names) - _LIST_MAX} more" if len(names) > _LIST_MAX else ""
    return ", ".join(names[:_LIST_MAX]) + more


def check_output(out: str | Path, *, overwrite: bool, kind: str = "dataset",
                 inputs: Iterable[str | Path | None] = ()) -> None:
    """Check that writing ``kind`` to ``out`` can destroy nothing (see the module docstring).

    Raises:
        UnsafeOutputError: ``out`` (or its staging folder) is, contains or lies inside an input, or
            ``overwrite`` is set but ``out`` is not something of ``kind`` that psg-data wrote.
        DatasetExistsError: ``out`` exists and ``overwrite`` is False.
    """
    if kind not in OUTPUT_KINDS:
        raise ValueError(f"kind: expected one of {', '.join(OUTPUT_KINDS)}, got {kind!r}")
    out = Path(out)
    inputs = list(inputs)
    check_not_input(out, inputs)
    check_not_input(out.with_name(out.name + ".partial"), inputs, what="staging folder")
    if not out.exists() and not out.is_symlink():
        return
    if not overwrite:
        raise DatasetExistsError(f"{out}: output exists; pass --overwrite to replace it")
    reason = _foreign(out, kind)
    if reason is not None:
        raise UnsafeOutputError(f"{out}: {reason}; --overwrite replaces only {OUTPUT_KINDS[kind]} or an empty "
                                f"folder; choose another output path (or move it away yourself)")


FILE_SIGNATURES: dict[str, tuple[bytes | tuple[bytes, ...], str]] = {
    "rrd": (b"RRF", "a Rerun recording (.rrd)"),
    "png": (b"\x89PNG\r\n\x1a\n", "a PNG image"),
    "graph": (b'{"format": "psg-predictive-graph"', "a predictive graph saved by psg-data (.json)"),
    "graph-csv": ((b"object_id,receptacle_id,", b"rank,receptacle_id,"), "a table written by psg-data graph --csv"),
}
"""Single-file outputs: kind -> (leading bytes of every file of that kind psg-data writes (or a tuple of
such starts), what it is)."""


def check_file_output(out: str | Path, *, overwrite: bool, kind: str, inputs: Iterable[str | Path | None] = ()) -> None:
    """The rule for a single-file output (``psg-data view --save``, ``psg-eval --rerun``, ``psg-data graph
    --csv / --png / --rerun / --save-graph``): never an input or inside one; ``overwrite`` replaces only
    a file of that kind (its signature), and ``OUT.partial``, the file written first, must not exist.

    Raises:
        UnsafeOutputError, DatasetExistsError: as :func:`check_output`.
    """
    out = Path(out)
    magic, what = FILE_SIGNATURES[kind]
    magics = magic if isinstance(magic, tuple) else (magic,)
    inputs = list(inputs)
    check_not_input(out, inputs)
    partial = out.with_name(out.name + ".partial")
    if partial.exists() or partial.is_symlink():
        raise UnsafeOutputError(f"{partial}: exists; expected no such path beside the output (move it away)")
    if not out.exists() and not out.is_symlink():
        return
    if not overwrite:
        raise DatasetExistsError(f"{out}: output exists; pass --overwrite to replace it")
    if out.is_symlink() or not out.is_file():
        raise UnsafeOutputError(f"{out}: is not a file; --overwrite replaces only {what}")
    with open(out, "rb") as fh:
        head = fh.read(max(len(m) for m in magics))
    if not any(head.startswith(m) for m in magics):
        raise UnsafeOutputError(f"{out}: is not {what} (it starts with {head[:8].hex() or 'nothing'}); --overwrite "
                                f"replaces only {what}; choose another path (or move it away yourself)")


def make_staging(path: str | Path, *, resume: bool = False) -> Path:
    """Create the staging folder ``path`` (``OUT.partial``) marked as psg-data's.

    An existing one is kept with ``resume`` and removed otherwise, but only if it carries the
    marker; a folder of that name psg-data did not create is refused.

    Raises:
        UnsafeOutputError: ``path`` exists without :data:`PARTIAL_MARKER`.
    """
    path = Path(path)
    if path.exists() or path.is_symlink():
        if path.is_symlink() or not (path / PARTIAL_MARKER).is_file():
            raise UnsafeOutputError(f"{path}: exists and was not created by psg-data (no {PARTIAL_MARKER}); "
                                    f"expected no such path beside the output (move it away)")
        if not resume:
            shutil.rmtree(path)
    path.mkdir(parents=True, exist_ok=True)
    (path / PARTIAL_MARKER).touch()
    return path


def _fsync_path(path: str, directory: bool) -> None:
    flags = os.O_RDONLY | getattr(os, "O_BINARY", 0)
    if directory:
        if os.name == "nt":  # directories cannot be opened for fsync there
            return
        flags |= getattr(os, "O_DIRECTORY", 0)
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_tree(root: str | Path) -> None:
    """Fsync every regular file and folder under ``root`` (so a rename publishes complete data)."""
    for dirpath, _, filenames in os.walk(root):
        for n in filenames:
            p = os.path.join(dirpath, n)
            if not os.path.islink(p):
                _fsync_path(p, directory=False)
        _fsync_path(dirpath, directory=True)


def _write_marker(tree: Path, kind: str) -> None:
    from psg_data import __version__

    files = [f for f in _files_under(tree) if f not in (OUTPUT_MARKER, PARTIAL_MARKER)]
    (tree / OUTPUT_MARKER).write_text(json.dumps({"kind": kind, "written_by": f"psg-data {__version__}",
                                                  "files": files}, indent=1) + "\n", encoding="utf-8")


def commit_tree(tree: str | Path, out: str | Path, *, kind: str = "dataset") -> Path:
    """Publish the complete output ``tree`` at ``out``: fsync, swap by renames, old output removed last.

    ``out`` is checked again (see :func:`check_output`, with overwrite) right before the swap, so a
    file added to it meanwhile is never deleted. ``tree`` keeps its :data:`PARTIAL_MARKER` until it
    is in place (then the marker is removed from ``out``), so whichever step fails, ``tree`` is
    still a staging folder a rerun may remove or resume, the previous output is either in place or
    complete under ``.OUT.psg-replaced`` (put back or removed by the next commit), and a marker
    left in ``out`` by a crash right after the swap is psg-data's own (see :func:`check_output`).
    Outputs other than datasets get their :data:`OUTPUT_MARKER`.

    Raises:
        UnsafeOutputError: ``out`` became something psg-data may not replace.
        OSError: a step failed (see above for what it leaves).
    """
    tree, out = Path(tree), Path(out)
    if kind != "dataset":
        _write_marker(tree, kind)
    fsync_tree(tree)
    parent = out.parent
    parent.mkdir(parents=True, exist_ok=True)
    aside = out.with_name(_REPLACED.format(name=out.name))
    if not out.exists() and not out.is_symlink():
        os.replace(tree, out)
    else:
        reason = _foreign(out, kind)
        if reason is not None:
            raise UnsafeOutputError(f"{out}: {reason} (changed while writing); refusing to replace it")
        _remove_stale(aside, kind)
        os.replace(out, aside)
        try:
            os.replace(tree, out)
        except BaseException:
            os.replace(aside, out)  # put the previous output back
            raise
    (out / PARTIAL_MARKER).unlink(missing_ok=True)
    _fsync_path(str(out), directory=True)
    _fsync_path(str(parent), directory=True)
    if aside.is_dir() and _foreign(aside, kind) is None:  # the previous output (or one an earlier swap left)
        shutil.rmtree(aside)
    return out


def _remove_stale(aside: Path, kind: str) -> None:
    """Remove ``.OUT.psg-replaced`` (a previous output set aside by a swap), if psg-data's."""
    if not aside.exists() and not aside.is_symlink():
        return
    stale = _foreign(aside, kind)
    if stale is not None:
        raise UnsafeOutputError(f"{aside}: {stale}; expected nothing of that name beside the output (move it away)")
    shutil.rmtree(aside)


def replace_file(tmp: str | Path, final: str | Path) -> None:
    """Move the complete file ``tmp`` over ``final`` atomically (fsynced before, folder fsynced after)."""
    _fsync_path(str(tmp), directory=False)
    os.replace(tmp, final)
    _fsync_path(str(Path(final).parent), directory=True)


_TEMP = ".{name}.psg-tmp-{pid}"
_TEMP_TRIES = 100


def _claim_temp(final: Path) -> Path:
    """Create an empty temporary file beside ``final`` that no one else has (never reuses an existing one)."""
    base = _TEMP.format(name=final.name, pid=os.getpid())
    for k in range(_TEMP_TRIES):
        tmp = final.with_name(base if k == 0 else f"{base}-{k}")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666))
        except FileExistsError:
            continue
        return tmp
    raise UnsafeOutputError(f"{final.with_name(base)}: exists (and {_TEMP_TRIES - 1} numbered variants); expected "
                            f"no such files beside the output (move them away)")


def write_atomically(path: str | Path, write: Callable[[Path], object], *,
                     inputs: Iterable[str | Path | None] = ()) -> Path:
    """Replace the file ``path`` atomically by what ``write`` writes: complete or not at all.

    ``write(tmp)`` writes the whole file to ``tmp``, a temporary file psg-data creates beside
    ``path`` (``.NAME.psg-tmp-PID``; an existing file of that name is left alone and another name
    is chosen). The temporary file is fsynced and renamed over ``path`` (:func:`replace_file`); if
    ``write`` raises (or is interrupted), it is removed and the previous file at ``path`` is left
    exactly as it was. A symbolic link at ``path`` is replaced, its target left alone. Missing
    parent folders are created.

    Args:
        path: the file to write (replaced if it exists).
        write: called once with the temporary path; writes the complete file there.
        inputs: paths ``path`` must not be, contain or lie inside (see :func:`check_not_input`).

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        UnsafeOutputError: ``path`` is, contains or lies inside an input (nothing is written), or no
            free temporary name was found.
    """
    final = Path(path)
    check_not_input(final, list(inputs))
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = _claim_temp(final)
    try:
        write(tmp)
        replace_file(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return final
