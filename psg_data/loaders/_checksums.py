"""The loader's checksum checks: ``tables/files.parquet`` against the manifest, and every file it
reads whole (tables, the generator model, images of the ``files`` layout) against ``files.parquet``.

Checksums detect accidents (bit rot, a truncated copy, a file edited by hand), not attacks: whoever
can edit a dataset can rewrite its checksums too (docs/SECURITY.md). A file whose content does not
fit its recorded size or SHA-256 is refused with a :class:`~psg_data.errors.FormatError` naming
the file, the field and what was expected. A file is hashed from the bytes that are parsed or
decoded, once per process. A scan archive (``tar`` layout) is hashed only when the dataset is opened
with ``verify_archives=True``: by default reading one frame stays two ``pread`` calls and a damaged
frame does not make its scan's other frames unreadable; ``validate`` checks archives.
"""

from __future__ import annotations

import hashlib
import os
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from psg_data.errors import FormatError
from psg_data.schemas._paths import inside_dataset
from psg_data.schemas._tables import table_path

if TYPE_CHECKING:  # pragma: no cover
    import pyarrow as pa

__all__ = ["FileChecksums"]

FILES_REL = table_path("files")


class FileChecksums:
    """What ``files.parquet`` records of each file of one dataset (read and checked on first use).

    Args:
        root: the dataset directory.
        real: the dataset root with links resolved (:func:`~psg_data.schemas._paths.real_root`).
        files_sha256: the manifest's SHA-256 of ``files.parquet`` ("" when the manifest has none).
    """

    def __init__(self, root: Path, real: str, files_sha256: str) -> None:
        self.root, self.real, self.files_sha256 = root, real, files_sha256
        self._listed: dict[str, tuple[int, str]] | None = None
        self._table: pa.Table | None = None
        self._verified: set[str] = set()
        self._lock = threading.Lock()

    def files_table(self) -> pa.Table | None:
        """``files.parquet`` as read (checked against the manifest), or None if the dataset has none."""
        self._load()
        return self._table

    def expected(self, rel: str) -> tuple[int, str] | None:
        """(size in bytes, hex SHA-256) recorded for ``rel``, or None if ``files.parquet`` does not list it."""
        return self._load().get(rel)

    def read_listed(self, rel: str, where: str, *, check: bool = True) -> bytes:
        """The bytes of the dataset file ``rel`` (inside the dataset), checked against ``files.parquet``
        (``check=False``: not yet; the caller checks its content first, then calls :meth:`check_bytes`).

        Raises:
            FormatError: ``rel`` leaves the dataset, is unreadable, or does not fit its record.
        """
        path = Path(inside_dataset(self.real, rel, where))
        want = self.expected(rel)
        try:
            with open(path, "rb") as fh:
                data = fh.read() if want is None else fh.read(want[0] + 1)
        except OSError as exc:
            raise FormatError(f"{self.root / rel}: unreadable ({exc.strerror or type(exc).__name__})") from None
        if check:
            self.check_bytes(rel, data)
        return data

    def check_bytes(self, rel: str, data: bytes) -> None:
        """Raise :class:`FormatError` unless ``data`` (the whole file ``rel``) fits its record."""
        want = self.expected(rel)
        if want is None or rel in self._verified:
            return
        self._compare(rel, len(data), hashlib.sha256(data).hexdigest(), want)

    def check_fd(self, rel: str, fd: int, size: int) -> None:
        """Like :meth:`check_bytes` for the open file ``fd`` of ``size`` bytes (read with ``pread``
        in 1 MiB blocks; the caller holds any lock the descriptor needs).
        """
        want = self.expected(rel)
        if want is None or rel in self._verified:
            return
        if size != want[0]:
            self._compare(rel, size, "", want)
        h = hashlib.sha256()
        for offset in range(0, size, 1 << 20):
            n = min(1 << 20, size - offset)
            if hasattr(os, "pread"):
                h.update(os.pread(fd, n, offset))
            else:  # pragma: no cover - Windows
                os.lseek(fd, offset, os.SEEK_SET)
                h.update(os.read(fd, n))
        self._compare(rel, size, h.hexdigest(), want)

    def _compare(self, rel: str, size: int, digest: str, want: tuple[int, str]) -> None:
        if size != want[0]:
            raise FormatError(f"{self.root / rel}: size_bytes: file has {size} bytes, {FILES_REL} says "
                              f"{want[0]} (truncated or changed after writing)")
        if digest != want[1]:
            raise FormatError(f"{self.root / rel}: sha256: checksum {digest[:12]}... does not match {FILES_REL} "
                              f"{want[1][:12]}...; the file was changed after writing")
        with self._lock:
            self._verified.add(rel)

    def _load(self) -> dict[str, tuple[int, str]]:
        if self._listed is not None:
            return self._listed
        with self._lock:
            if self._listed is None:
                self._table, self._listed = self._read_files_table()
        return self._listed

    def _read_files_table(self) -> tuple[pa.Table | None, dict[str, tuple[int, str]]]:
        import pyarrow as pa
        import pyarrow.parquet as pq

        path = self.root / FILES_REL
        if not path.is_file():
            return None, {}
        inside_dataset(self.real, FILES_REL, f"{self.root}: table 'files'")
        data = path.read_bytes()
        if self.files_sha256:
            digest = hashlib.sha256(data).hexdigest()
            if digest != self.files_sha256:
                raise FormatError(f"{path}: sha256: checksum {digest[:12]}... does not match dataset.json "
                                  f"files_sha256 {self.files_sha256[:12]}...; the file was changed after writing")
        try:
            table = pq.read_table(pa.BufferReader(data))
            cols = table.to_pydict()
            listed = {str(p): (int(n), str(s)) for p, n, s in zip(cols["path"], cols["size_bytes"], cols["sha256"])}
        except (KeyError, TypeError, ValueError, pa.ArrowException) as exc:
            raise FormatError(f"{path}: unreadable files table ({exc}); expected columns path, size_bytes, "
                              "sha256") from None
        return table, listed

