"""Checks the loader runs on every table it reads: a malformed table is a :class:`FormatError` naming
the file, the row and the field, never a KeyError or TypeError deep inside the loader.

These are the checks reading cannot do without (``psg-data validate`` runs them all and more):
every column of the format present with a type that casts to it, no nulls where the format has
none, unique keys in the core tables, and in ``frames`` finite poses and ids that exist.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from psg_data.errors import FormatError
from psg_data.schemas._tables import TABLES, schema_for

if TYPE_CHECKING:  # pragma: no cover
    import pyarrow as pa

    from psg_data.schemas._records import CameraIntrinsics

__all__ = ["checked_table", "check_frames", "check_image_bytes", "check_image_header", "UNIQUE_KEY_TABLES"]

UNIQUE_KEY_TABLES = ("cameras", "scans", "frames", "rooms", "receptacles", "doors", "objects")
"""Tables whose primary key the loader checks (records are looked up by it)."""
_SHOW = 3


def _rows(mask: np.ndarray) -> str:
    idx = np.flatnonzero(mask)
    more = f" (and {idx.size - _SHOW} more)" if idx.size > _SHOW else ""
    return ", ".join(str(int(i)) for i in idx[:_SHOW]) + more


def checked_table(name: str, table: pa.Table, where: str, major: int) -> pa.Table:
    """``table`` with the columns of the format's table ``name`` present, typed and non-null.

    Columns whose type differs but casts safely are cast; tables outside the format pass as they are.

    Raises:
        FormatError: ``where: column: what is wrong, what was expected``.
    """
    import pyarrow as pa

    if name not in TABLES:
        return table
    for f in schema_for(name, major):
        if f.name not in table.column_names:
            raise FormatError(f"{where}: {f.name}: missing column, expected type {f.type}")
        col = table.column(f.name)
        if not col.type.equals(f.type):
            try:
                col = col.cast(f.type)
            except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError):
                raise FormatError(f"{where}: {f.name}: type {col.type}, expected {f.type}") from None
            table = table.set_column(table.schema.get_field_index(f.name), pa.field(f.name, f.type), col)
        if not f.nullable and col.null_count:
            nulls = np.asarray(col.is_null().to_numpy(zero_copy_only=False))
            raise FormatError(f"{where}: {f.name}: null value in rows {_rows(nulls)}, expected a value")
    if name in UNIQUE_KEY_TABLES and table.num_rows:
        _check_unique(table, TABLES[name].key, where)
    return table


def _check_unique(table: pa.Table, key: tuple[str, ...], where: str) -> None:
    cols = [np.asarray(table.column(k).to_numpy(zero_copy_only=False)) for k in key]
    if len(cols) == 1:
        _, first, counts = np.unique(cols[0].astype(str) if cols[0].dtype == object else cols[0],
                                     return_index=True, return_counts=True)
        dup = counts > 1
        if dup.any():
            v = cols[0][first[dup][0]]
            raise FormatError(f"{where}: {key[0]}: duplicate key {v!r} in rows {_rows(cols[0] == v)}, "
                              f"expected unique values")
        return
    import pandas as pd

    df = pd.DataFrame(dict(zip(key, cols)))
    dup = df.duplicated(keep=False).to_numpy()
    if dup.any():
        k = tuple(df.iloc[int(np.flatnonzero(dup)[0])])
        raise FormatError(f"{where}: {'+'.join(key)}: duplicate key {k!r} in rows {_rows(dup)}, expected unique "
                          f"values")


def check_frames(frames: pa.Table, scan_ids: set[str], camera_ids: set[str], where: str) -> None:
    """Rows of ``frames`` the loader would otherwise serve wrongly: non-finite or non-4x4 poses,
    frames of scans or cameras that do not exist.

    Raises:
        FormatError: naming the rows and the field.
    """
    n = frames.num_rows
    if not n:
        return
    T = np.asarray(frames.column("T_world_camera").combine_chunks().flatten().to_numpy(), dtype=np.float64)
    if T.size != 16 * n:
        raise FormatError(f"{where}: T_world_camera: {T.size} values for {n} rows, expected 16 per row (4x4)")
    bad = ~np.all(np.isfinite(T.reshape(n, 16)), axis=1)
    if bad.any():
        raise FormatError(f"{where}: T_world_camera: NaN or infinite values in rows {_rows(bad)}, expected finite "
                          f"4x4 camera-to-world poses")
    for col, valid, table in (("scan_id", scan_ids, "scans"), ("camera_id", camera_ids, "cameras")):
        v = np.asarray(frames.column(col).to_numpy(zero_copy_only=False))
        dangling = ~np.isin(v, np.asarray(sorted(valid), dtype=object)) if valid else np.ones(n, bool)
        if dangling.any():
            first = v[np.flatnonzero(dangling)[0]]
            raise FormatError(f"{where}: {col}: dangling id {first!r} in rows {_rows(dangling)}: not in "
                              f"tables/{table}.parquet")


def check_image_bytes(data: bytes, where: object, what: str) -> None:
    """A stored image is complete and undamaged (PNG chunk CRCs, JPEG segments and EOI): OpenCV
    decodes a truncated JPEG without a word, so the loader checks before it decodes.

    Raises:
        FormatError: ``where: corrupt colour/depth image (...)``.
    """
    from psg_data.schemas._image_check import DamagedImage, check_image

    try:
        check_image(data, "structure")
    except DamagedImage as exc:
        raise FormatError(f"{where}: missing or unreadable {what} image (corrupt: {exc}); psg-data validate lists "
                          f"every such image") from None


def check_image_header(data: bytes, camera: CameraIntrinsics, kind: str, where: object) -> None:
    """The header of a stored image fits its camera (size, 8-bit 3-channel colour, 16-bit
    single-channel PNG depth, at most :data:`~psg_data.schemas._image_headers.MAX_IMAGE_PIXELS`), read
    before any pixel is decoded: a decompression bomb or an image of another type is refused here.

    Raises:
        FormatError: ``where: colour/depth image header ...: what is wrong, what was expected``.
    """
    from psg_data.schemas._image_headers import header_problems, parse_image_header

    what = "colour" if kind == "color" else "depth"
    try:
        hdr = parse_image_header(data)
    except ValueError as exc:
        raise FormatError(f"{where}: missing or unreadable {what} image ({exc})") from None
    problems = header_problems(hdr, kind, camera.width, camera.height)
    if problems:
        raise FormatError(f"{where}: {what} image header does not fit camera {camera.camera_id!r}, refused before "
                          f"decoding: " + "; ".join(f"{f} {m}" for f, m in problems))
