"""``add_tables``: add (or replace) optional tables of an existing dataset and keep it valid.

Order of operations: every new Parquet file, the new ``tables/files.parquet`` and the new
``dataset.json`` are first written to temporary files beside their targets (nothing visible
changes if any of this fails; the temporaries are removed); then each is moved into place with
``os.replace`` (atomic per file, fsynced first), tables first, then the files table, then the manifest. A crash
between the renames can leave a dataset whose checksums disagree (``psg-data validate`` reports
it; re-running the same command repairs it).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from psg_data.errors import FormatError, UnsafeOutputError
from psg_data.schemas._checksum import sha256_file
from psg_data.schemas._manifest import read_manifest
from psg_data.schemas._tables import MANIFEST_NAME, TABLES, table_path
from psg_data.writers._safe_output import replace_file

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["add_tables"]

log = logging.getLogger(__name__)

_PROTECTED = frozenset(n for n, s in TABLES.items() if s.required) | {"files"}


def _tmp(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def add_tables(root: str | Path, tables: Mapping[str, Any], *, overwrite: bool = False) -> list[Path]:
    """Write optional tables into the dataset at ``root``; update the files table and the manifest.

    Args:
        root: dataset directory.
        tables: table name -> Arrow table. Names of the label tables are cast to their schemas;
            required core tables and ``files`` cannot be written this way.
        overwrite: replace tables that already exist (otherwise that is an error). Only a table
            psg-data wrote (listed in ``tables/files.parquet``) is replaced; a file of that name it
            did not write is refused.

    Returns:
        the paths written.

    Raises:
        FormatError: a protected or badly formed name, an existing table without ``overwrite``,
            a table that does not fit its schema, or a dataset whose files table is unreadable.
        FormatError: ``root`` is not a dataset.
    """
    root = Path(root)
    info = read_manifest(root)
    _check_names(root, tables, overwrite)
    cast = {name: _cast(name, t) for name, t in tables.items()}
    files_path = root / table_path("files")
    files = _listed_files(root, files_path, cast)
    temps: list[tuple[Path, Path]] = []
    try:
        _stage_tables(root, cast, files, temps)
        _stage_files_table(files_path, files, info, temps)
        counts = dict(info.counts)
        counts.update({name: t.num_rows for name, t in cast.items()})
        info.counts = dict(sorted(counts.items()))
        mpath = root / MANIFEST_NAME
        mtmp = _tmp(mpath)
        mtmp.write_text(info.to_json(), encoding="utf-8")
        temps.append((mtmp, mpath))
    except BaseException:
        for tmp, _ in temps:
            tmp.unlink(missing_ok=True)
        raise
    for tmp, final in temps:
        replace_file(tmp, final)
    written = [final for _, final in temps[:-2]]
    log.info("added %s to %s", ", ".join(table_path(n) for n in cast), root)
    return written


def _check_names(root: Path, tables: Mapping[str, Any], overwrite: bool) -> None:
    for name in tables:
        if name in _PROTECTED:
            raise FormatError(f"add_tables: {name!r} is a core table of the format and cannot be replaced here")
        if not name or not name.replace("_", "").isalnum():
            raise FormatError(f"add_tables: table name {name!r}, expected letters, digits and underscores")
        if (root / table_path(name)).exists() and not overwrite:
            raise FormatError(f"{root / table_path(name)}: table {name!r} exists; pass --overwrite "
                                "(overwrite=True) to replace it")


def _cast(name: str, t: pa.Table) -> pa.Table:
    """A table of the format cast to its schema (its own schema metadata kept); other tables as they are."""
    import pyarrow as pa

    spec = TABLES.get(name)
    if spec is None:
        return t
    missing = [f.name for f in spec.schema if f.name not in t.column_names]
    if missing:
        raise FormatError(f"add_tables: table {name!r}: missing columns {missing}, expected {spec.schema.names}")
    try:
        meta = t.schema.metadata
        t = t.select(spec.schema.names).cast(spec.schema)
        if meta:
            t = t.replace_schema_metadata({**(spec.schema.metadata or {}), **meta})
    except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError) as exc:
        raise FormatError(f"add_tables: table {name!r} does not fit its schema: {exc}") from exc
    return t


def _listed_files(root: Path, files_path: Path, cast: Mapping[str, pa.Table]) -> dict[str, dict[str, Any]]:
    """The rows of ``files.parquet`` by path, after checking that every table to replace is one psg-data wrote."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        files = pq.read_table(files_path).to_pylist()
    except (OSError, pa.ArrowException) as exc:
        raise FormatError(f"{files_path}: unreadable ({exc}); validate the dataset first") from exc
    listed = {r["path"] for r in files}
    for name in cast:
        p = root / table_path(name)
        if (p.exists() or p.is_symlink()) and (table_path(name) not in listed or p.is_symlink()):
            raise UnsafeOutputError(f"{p}: exists but psg-data did not write it (not listed in tables/files.parquet); "
                                    f"refusing to replace it; move it away to write table {name!r}")
    return {r["path"]: r for r in files}


def _stage_tables(root: Path, cast: Mapping[str, pa.Table], entries: dict[str, dict[str, Any]],
                  temps: list[tuple[Path, Path]]) -> None:
    """Write each table beside its final path (listed in ``temps`` first, to be removed on failure);
    ``entries`` get their sizes and checksums.
    """
    import pyarrow.parquet as pq

    for name, t in cast.items():
        final = root / table_path(name)
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = _tmp(final)
        temps.append((tmp, final))
        pq.write_table(t, tmp, compression="zstd")
        entries[table_path(name)] = {"path": table_path(name), "size_bytes": tmp.stat().st_size,
                                     "sha256": sha256_file(tmp)}


def _stage_files_table(files_path: Path, entries: dict[str, dict[str, Any]], info: Any,
                       temps: list[tuple[Path, Path]]) -> None:
    """Write the new ``files.parquet`` beside it (listed in ``temps``); ``info`` gets its checksum."""
    import pyarrow.parquet as pq

    from psg_data.writers._dataset_writer import to_arrow

    ftmp = _tmp(files_path)
    temps.append((ftmp, files_path))
    pq.write_table(to_arrow("files", [entries[k] for k in sorted(entries)]), ftmp, compression="zstd")
    info.files_sha256 = sha256_file(ftmp)
