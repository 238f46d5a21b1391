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
