"""Pinned downloads: a public source's files fetched once into the cache, each checked by SHA-256.

:func:`ensure_source` returns a folder holding every file of a :class:`RemoteSource` at its local
path, each equal to its pinned SHA-256:

- an offline copy (the ``offline_root`` argument, else the folder named by ``$PSG_DATA_SOURCES``) is
  only read: every file is hashed and the folder returned as it is;
- otherwise the files live in ``cache / source.name``. A file there is hashed on every call (the
  sources are a few MB: milliseconds; no stamp file to trust) and kept if it matches. A missing file
  is streamed to ``<file>.partial`` beside its final name while it is hashed, and renamed into
  place (``os.replace``) only once its SHA-256 matches the pin: nothing at a final name is ever
  incomplete or unverified. A mismatch deletes the partial file. An interrupted download (a
  dropped connection, a timeout, Ctrl-C) keeps the partial file, and the next call resumes it with
  an HTTP ``Range`` request (a server answering ``200`` instead of ``206`` sends the whole file again).

One process at a time fills a source's cache folder: an exclusive lock on ``cache/.<name>.lock``
(``fcntl.flock`` on POSIX, ``msvcrt.locking`` on Windows) is held for the whole call. The standard
library only (``urllib``, ``hashlib``): the user's proxy settings apply as for any ``urllib`` request.
"""

from __future__ import annotations

import contextlib
import hashlib
import http.client
import os
import re
import sys
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Protocol

from psg_data.errors import PsgDataError

__all__ = ["RemoteFile", "RemoteSource", "SOURCES_ENV", "ensure_source"]

SOURCES_ENV = "PSG_DATA_SOURCES"
"""Environment variable naming a folder that holds the sources' files at their local paths (read only)."""

CHUNK_BYTES = 1 << 16
"""Bytes read from the network (or a file being hashed) at a time."""

_SHA256 = re.compile(r"[0-9a-f]{64}\Z")


@dataclass(frozen=True)
class RemoteFile:
    """One pinned file of a :class:`RemoteSource`.

    Attributes:
        local: path relative to the source's root folder on disk, ``/``-separated
            (``"greg_door_2016_min/training_data.txt"``).
        remote: path relative to :attr:`RemoteSource.base_url`, ``/``-separated, unquoted.
        sha256: the file's SHA-256, 64 lowercase hex digits.
        size: the file's length in bytes when known; a download longer than this is refused as
            soon as it passes it, and a partial file longer than this is discarded.
    """

    local: str
    remote: str
    sha256: str
    size: int | None = None

    def __post_init__(self) -> None:
        """Refuse a pin that could name a path outside the root, or that is not a SHA-256."""
        for field, path in (("local", self.local), ("remote", self.remote)):
            if not _is_plain_relative(path):
                raise ValueError(f"RemoteFile.{field}: {path!r} must be a relative '/'-separated path without "
                                 "'..', '\\', ':' or NUL")
        if not _SHA256.match(self.sha256):
            raise ValueError(f"RemoteFile.sha256: {self.sha256!r} is not 64 lowercase hex digits")
        if self.size is not None and self.size < 0:
            raise ValueError(f"RemoteFile.size: {self.size} is negative")


@dataclass(frozen=True)
class RemoteSource:
    """A set of public files pinned by SHA-256, fetched under one base URL.

    Attributes:
        name: short name (``"door-benchmark"``), used in messages and as the cache folder's name.
        base_url: ``http(s)://`` URL ending in ``/``; each file's URL is this plus its quoted ``remote``.
        files: the pinned files (distinct local paths).
        where: one human sentence saying where the files are published (repository, commit,
            folder), printed when they cannot be fetched.
    """

    name: str
    base_url: str
    files: tuple[RemoteFile, ...]
    where: str

    def __post_init__(self) -> None:
        """Refuse a name that is not one plain folder name, a non-HTTP base URL or repeated local paths."""
        if not _is_plain_relative(self.name) or "/" in self.name or self.name.startswith("."):
            raise ValueError(f"RemoteSource.name: {self.name!r} must be a plain folder name")
        scheme = urllib.parse.urlsplit(self.base_url).scheme
        if scheme not in ("http", "https") or not self.base_url.endswith("/"):
            raise ValueError(f"RemoteSource.base_url: {self.base_url!r} must be an http(s) URL ending in '/'")
        locals_ = [f.local for f in self.files]
        if not locals_ or len(set(locals_)) != len(locals_):
            raise ValueError(f"RemoteSource.files of {self.name}: expected at least one file, each local path once")


def ensure_source(source: RemoteSource, cache: Path, *, offline_root: Path | None = None,
                  progress: Callable[[int], None] | None = None, timeout_s: float = 30.0) -> Path:
    """Root folder under which every ``source.files[i].local`` exists and matches its SHA-256.

    Args:
        source: the pinned files.
        cache: psg-data's cache directory; the files are kept in ``cache / source.name``.
        offline_root: a folder holding the files at their local paths, used read-only instead of the
            network (default: ``$PSG_DATA_SOURCES`` when set, else none).
        progress: called as ``progress(n)`` with the bytes received, once per chunk.
        timeout_s: seconds to wait for the connection and for each read.

    Raises:
        PsgDataError: a file of the offline folder is missing or differs from its pin; a download
            differs from its pin (it is deleted) or cannot be completed (no network, an HTTP error,
            a dropped connection: one line with the URL, the reason, ``source.where`` and how to set
            ``PSG_DATA_SOURCES``).
    """
    if offline_root is not None:
        return _check_offline(source, Path(offline_root), "offline folder")
    if os.environ.get(SOURCES_ENV):
        return _check_offline(source, Path(os.environ[SOURCES_ENV]), SOURCES_ENV)
    cache = Path(cache)
    root = cache / source.name
    root.mkdir(parents=True, exist_ok=True)
    with _lock(cache / f".{source.name}.lock"):
        try:
            for f in source.files:
                _ensure_file(source, f, root, progress, timeout_s)
        except BaseException:
            _prune_empty(root)  # a failed first download leaves no empty folders (a partial file stays)
            raise
    return root


def _prune_empty(root: Path) -> None:
    """Remove the empty folders under ``root`` and ``root`` itself if it ends up empty (``rmdir`` only
    removes an empty folder: nothing with a file in it is touched).
    """
    for d in sorted((p for p in root.rglob("*") if p.is_dir()), key=lambda p: len(p.parts), reverse=True):
        with contextlib.suppress(OSError):
            d.rmdir()
    with contextlib.suppress(OSError):
        root.rmdir()


# -- offline copies --------------------------------------------------------------------------------

def _check_offline(source: RemoteSource, root: Path, origin: str) -> Path:
    """``root`` after checking that it holds every file of ``source`` with its pinned hash (reads only)."""
    if not root.is_dir():
        raise PsgDataError(f"{root} ({origin}): not a folder; {source.name} expects one holding {_layout(source)}")
    for f in source.files:
        path = root / f.local
        if not path.is_file():
            raise PsgDataError(f"{path}: missing from {root} ({origin}); {source.name} expects {_layout(source)} "
                               f"there. {_where(source)}")
        actual = _sha256_file(path)
        if actual != f.sha256:
            raise PsgDataError(f"{path}: SHA-256 {actual[:12]}... but {source.name} pins {f.sha256[:12]}... "
                               f"({origin}); copy the file again byte for byte. {_where(source)}")
    return root


# -- the cache -------------------------------------------------------------------------------------

def _ensure_file(source: RemoteSource, f: RemoteFile, root: Path,
                 progress: Callable[[int], None] | None, timeout_s: float) -> None:
    """Make ``root / f.local`` the verified file: keep it if it matches, else download it."""
    final = root / f.local
    if final.is_file() and _sha256_file(final) == f.sha256:
        return
    if final.is_file():
        final.unlink()  # changed since it was verified: not to be used while the new copy downloads
    final.parent.mkdir(parents=True, exist_ok=True)
    partial = final.with_name(final.name + ".partial")
    url = source.base_url + urllib.parse.quote(f.remote)
    try:
        digest = _transfer(url, partial, f.size, progress, timeout_s)
    except (OSError, http.client.HTTPException) as exc:  # no network, HTTP error, timeout, dropped connection
        raise PsgDataError(_unreachable(source, f, url, exc, partial)) from None
    length = partial.stat().st_size
    if digest != f.sha256 or (f.size is not None and length != f.size):
        partial.unlink()
        raise PsgDataError(_mismatch(source, f, url, digest, length))
    os.replace(partial, final)


def _transfer(url: str, partial: Path, size: int | None, progress: Callable[[int], None] | None,
              timeout_s: float) -> str:
    """Complete ``partial`` from ``url`` (resuming what it holds) and return its SHA-256 (hex).

    Raises OSError / HTTPException on network failures (the partial file kept with what arrived).
    """
    start = partial.stat().st_size if partial.is_file() else 0
    if size is not None and start > size:
        start = 0  # longer than the file: not a prefix of it
    if size is not None and start == size and start > 0:
        return _sha256_file(partial)  # complete, interrupted before its check
    response, start = _open(url, start, timeout_s)
    with response:
        hasher = hashlib.sha256()
        if start:
            _hash_into(hasher, partial)
        expected = _expected_bytes(response, start, size)
        with open(partial, "ab" if start else "wb") as out:
            total = start + _stream(response, out, hasher, progress, None if size is None else size - start)
    if size is not None and total > size:
        return hasher.hexdigest()  # the caller deletes it (size mismatch)
    if expected is not None and total < expected:
        raise ConnectionError(f"connection closed after {total} of {expected} bytes")
    return hasher.hexdigest()


def _open(url: str, start: int, timeout_s: float) -> tuple[http.client.HTTPResponse, int]:
    """The response for ``url`` from byte ``start`` on, and the offset it really starts at (``start`` or 0).

    ``206`` with the asked ``Content-Range`` resumes; ``200`` restarts from 0; ``416`` (the partial
    file is not shorter than the file) or a ``206`` from another offset asks again for the whole file.
    """
    headers = {"Range": f"bytes={start}-"} if start else {}
    try:
        response = urllib.request.urlopen(urllib.request.Request(url, headers=headers), timeout=timeout_s)
    except urllib.error.HTTPError as exc:
        exc.close()  # its body is not read
        if exc.code != 416 or not start:
            raise
        return _open(url, 0, timeout_s)
    content_range = response.headers.get("Content-Range", "")
    if response.status == 206 and _range_start(content_range) != start:
        response.close()
        if not start:
            raise http.client.HTTPException(f"206 with Content-Range {content_range!r} for the whole file")
        return _open(url, 0, timeout_s)
    return response, start if response.status == 206 else 0


def _range_start(content_range: str) -> int | None:
    """First byte of a ``Content-Range: bytes N-M/T`` header, or None."""
    m = re.match(r"\s*bytes\s+(\d+)-", content_range)
    return int(m.group(1)) if m else None


def _expected_bytes(response: http.client.HTTPResponse, start: int, size: int | None) -> int | None:
    """The file's length the transfer must reach (bytes): the pin, else the server's Content-Length."""
    if size is not None:
        return size
    length = response.headers.get("Content-Length")
    return start + int(length) if length and length.isdigit() else None


class _Hasher(Protocol):
    def update(self, data: bytes, /) -> None: ...  # noqa: D102

    def hexdigest(self) -> str: ...  # noqa: D102


def _stream(response: IO[bytes], out: IO[bytes], hasher: _Hasher, progress: Callable[[int], None] | None,
            limit: int | None) -> int:
    """Copy ``response`` into ``out`` through ``hasher``; bytes copied (stops past ``limit`` bytes)."""
    got = 0
    while limit is None or got <= limit:
        chunk = response.read(CHUNK_BYTES)
        if not chunk:
            break
        out.write(chunk)
        hasher.update(chunk)
        got += len(chunk)
        if progress is not None:
            progress(len(chunk))
    return got


# -- helpers ---------------------------------------------------------------------------------------

def _sha256_file(path: Path) -> str:
    """SHA-256 of a file's bytes (hex)."""
    hasher = hashlib.sha256()
    _hash_into(hasher, path)
    return hasher.hexdigest()


def _hash_into(hasher: _Hasher, path: Path) -> None:
    """Feed a file's bytes into ``hasher``, :data:`CHUNK_BYTES` at a time."""
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(CHUNK_BYTES), b""):
            hasher.update(chunk)


def _is_plain_relative(path: str) -> bool:
    """A non-empty relative ``/``-separated path with no ``..`` component, backslash, colon or NUL."""
    parts = path.split("/")
    return (bool(path) and not path.startswith("/") and not any(c in path for c in "\\:\0")
            and ".." not in parts and "" not in parts)


def _layout(source: RemoteSource) -> str:
    """The source's local paths, grouped by folder: ``dir/{a.txt, b.txt}, other/c.txt``."""
    groups: dict[str, list[str]] = {}
    for f in source.files:
        folder, _, name = f.local.rpartition("/")
        groups.setdefault(folder, []).append(name)
    parts = []
    for folder, names in groups.items():
        listed = names[0] if len(names) == 1 else "{" + ", ".join(names) + "}"
        parts.append(f"{folder}/{listed}" if folder else listed)
    return ", ".join(parts)


def _where(source: RemoteSource) -> str:
    """Where to get the files and how to point psg-data at a copy (one sentence pair)."""
    return (f"The files are published in {source.where.rstrip('.')}; to use a copy, set {SOURCES_ENV}=DIR, "
            f"a folder holding {_layout(source)}")


def _mismatch(source: RemoteSource, f: RemoteFile, url: str, digest: str, length: int) -> str:
    """One line: the download of ``f`` from ``url`` does not fit its pin (hash, or length in bytes)."""
    if f.size is not None and length != f.size:
        what = f"longer than the pinned {f.size} bytes (stopped at {length})"
    else:
        what = f"SHA-256 {digest[:12]}... does not match the pin {f.sha256[:12]}..."
    return (f"{url}: {what} ({f.local} of {source.name}); the download was deleted (the file changed at the "
            f"source or was damaged on the way). {_where(source)}")


def _unreachable(source: RemoteSource, f: RemoteFile, url: str, exc: BaseException, partial: Path) -> str:
    """One line: which file could not be fetched from where and why, then where to get it."""
    if isinstance(exc, urllib.error.HTTPError):
        reason = f"HTTP {exc.code} {exc.reason}"
    elif isinstance(exc, urllib.error.URLError):
        reason = str(exc.reason)
    else:
        reason = str(exc) or type(exc).__name__
    kept = partial.stat().st_size if partial.is_file() else 0
    resume = f" ({kept} bytes kept in {partial}; the next run resumes)" if kept else ""
    return f"cannot fetch {f.local} of {source.name} from {url}: {reason}{resume}. {_where(source)}"


@contextlib.contextmanager
def _lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on the file ``path`` (created) against other processes."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+b") as fh:
        _acquire(fh)
        try:
            yield
        finally:
            _release(fh)


def _acquire(fh: IO[bytes]) -> None:
    """Block until this open file holds the exclusive lock."""
    if sys.platform == "win32":  # pragma: no cover - Windows
        import msvcrt

        fh.seek(0)
        while True:
            try:
                msvcrt.locking(fh.fileno(), msvcrt.LK_LOCK, 1)  # retries for 10 s, then raises
                return
            except OSError:
                continue
    else:
        import fcntl

        fcntl.flock(fh, fcntl.LOCK_EX)


def _release(fh: IO[bytes]) -> None:
    """Release the lock taken by :func:`_acquire`."""
    if sys.platform == "win32":  # pragma: no cover - Windows
        import msvcrt

        fh.seek(0)
        msvcrt.locking(fh.fileno(), msvcrt.LK_UNLCK, 1)
    else:
        import fcntl

        fcntl.flock(fh, fcntl.LOCK_UN)
