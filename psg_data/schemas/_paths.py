"""Path containment: every path a dataset names stays inside the dataset (docs/SECURITY.md).

A dataset is untrusted input. Its tables name files (``frames.color_path``, ``files.path``, the
manifest's ``extra.process_file``) and its directory may hold symbolic links; one rule decides
whether such a path may be opened: it is relative, has no ``..`` component (slash or backslash as
separator, so a Windows-style path is caught on every OS), and with every symbolic link followed it
resolves to a location strictly inside the dataset root. The loader raises a
:class:`~psg_data.errors.FormatError` through :func:`inside_dataset`; ``psg-data validate``
reports :func:`path_problem` as one line.
"""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path, PureWindowsPath

from psg_data.errors import FormatError

__all__ = ["path_problem", "inside_dataset", "real_root", "open_inside"]

_SEP = re.compile(r"[/\\]")
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_LINK_ERRNOS = (errno.ELOOP, errno.EMLINK)  # O_NOFOLLOW on a symbolic link: Linux, macOS / FreeBSD


def real_root(root: str | Path) -> str:
    """The dataset root with every symbolic link resolved (the containment reference)."""
    return os.path.realpath(root)


def path_problem(root: str, rel: object, *, resolve: bool = True) -> str | None:
    """What makes ``rel`` unsafe to open in the dataset at ``root`` (None: safe).

    Args:
        root: the dataset root as :func:`real_root` gives it.
        rel: a path read from the dataset (a table cell, a manifest value).
        resolve: also follow symbolic links (``False``: the lexical rule only, for a raw recording's
            folder, whose owner may link its image folders to another disk).

    Returns:
        ``"is absolute"``, ``"has a '..' component"``, ``"resolves outside the dataset (to ...)"``,
        ... or None when ``rel`` names a location inside ``root``.
    """
    if not isinstance(rel, str) or not rel:
        return f"is {rel!r}, expected a non-empty string"
    if "\x00" in rel:
        return "contains a NUL character"
    if rel.startswith(("/", "\\")) or PureWindowsPath(rel).drive:
        return "is absolute"
    if ".." in _SEP.split(rel):
        return "has a '..' component"
    if not resolve:
        return None
    real = os.path.realpath(os.path.join(root, rel))
    if not real.startswith(root.rstrip(os.sep) + os.sep):
        return f"resolves outside the dataset (to {real}; a symbolic link?)"
    return None


def inside_dataset(root: str, rel: object, where: str) -> str:
    """``rel`` resolved inside the dataset ``root`` (:func:`real_root`), ready to open.

    Args:
        root: the dataset root as :func:`real_root` gives it.
        rel: the path read from the dataset.
        where: what named it, e.g. ``tables/frames.parquet:12: color_path``.

    Raises:
        FormatError: ``where: path 'REL' is absolute|has a '..' component|resolves outside the
            dataset; expected a relative path inside the dataset``.
    """
    problem = path_problem(root, rel)
    if problem is not None:
        raise FormatError(_message(root, rel, problem, where))
    return os.path.join(root, str(rel))


def open_inside(root: str, rel: str, where: str, flags: int, known_dirs: set[str]) -> int:
    """``os.open`` of ``rel`` in the dataset ``root`` under the rule of :func:`path_problem`, at the
    cost of one ``open`` per file: the lexical rule on ``rel``, its directory resolved once
    (remembered in the caller's ``known_dirs``) and the file itself opened with ``O_NOFOLLOW``,
    resolved only when it is a symbolic link (every time where the system has no ``O_NOFOLLOW``).

    Raises:
        FormatError: as :func:`inside_dataset` when ``rel`` leaves the dataset.
        OSError: the file cannot be opened.
    """
    problem = path_problem(root, rel, resolve=False)
    parent = os.path.dirname(rel)
    if problem is None and parent and parent not in known_dirs:
        problem = path_problem(root, parent)
        if problem is None:
            known_dirs.add(parent)
    path = os.path.join(root, rel)
    if problem is None and _NOFOLLOW:
        try:
            return os.open(path, flags | _NOFOLLOW)
        except OSError as exc:
            if exc.errno not in _LINK_ERRNOS:
                raise
    if problem is None:
        problem = path_problem(root, rel)  # a symbolic link: where does it lead?
    if problem is not None:
        raise FormatError(_message(root, rel, problem, where))
    return os.open(path, flags)


def _message(root: str, rel: object, problem: str, where: str) -> str:
    return f"{where}: path {rel!r} {problem}; expected a relative path inside the dataset {root}"
