"""The error contract as test helpers: one ``error:`` line, the exit code, and a file system left as it was."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any


def snapshot(root: Path) -> dict[str, tuple[str, int, str]]:
    """Every entry under ``root``: relative path -> (kind, size, sha256 of the content) (dirs and links too)."""
    out: dict[str, tuple[str, int, str]] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for n in dirnames:
            p = Path(dirpath, n)
            out[str(p.relative_to(root))] = ("link" if p.is_symlink() else "dir", 0, "")
        for n in filenames:
            p = Path(dirpath, n)
            if p.is_symlink():
                out[str(p.relative_to(root))] = ("link", 0, os.readlink(p))
            else:
                data = p.read_bytes()
                out[str(p.relative_to(root))] = ("file", len(data), hashlib.sha256(data).hexdigest())
    return out


def assert_one_error(result: Any, match: str | None = None, code: int = 1) -> str:
    """A CliRunner result ended with exit ``code`` and exactly one stderr line ``error: ...`` (no traceback).

    Returns the error line.
    """
    stderr = result.stderr
    assert result.exit_code == code, (result.exit_code, result.stdout, stderr, result.exception)
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in stderr and "Traceback" not in result.stdout
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    if match is not None:
        assert match in lines[0], lines[0]
    return lines[0]


def interrupt_partway(monkeypatch: Any, owner: Any, name: str, *, path_arg: int = 1, only: str = "") -> None:
    """Make the writer ``owner.name`` stop like a Ctrl-C in the middle of a file: it writes its output
    (argument ``path_arg``, a path), cuts it to half its size and raises KeyboardInterrupt.

    With ``only``, just the calls whose path's name contains it are interrupted (the others write as usual).
    """
    original = getattr(owner, name)

    def cut(*args: Any, **kwargs: Any) -> Any:
        path = Path(args[path_arg])
        if only not in path.name:
            return original(*args, **kwargs)
        original(*args, **kwargs)
        os.truncate(path, path.stat().st_size // 2)
        raise KeyboardInterrupt

    monkeypatch.setattr(owner, name, cut)


def files_in(folder: Path) -> list[str]:
    """Names of the entries in ``folder`` (sorted; temporary files of an atomic write would show here)."""
    return sorted(p.name for p in folder.iterdir())
