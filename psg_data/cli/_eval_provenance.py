"""Provenance of a psg-eval run (version, git revision, format version, command, time) for results.json."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from psg_data import __version__

__all__ = ["provenance"]


def _git_revision() -> str | None:
    here = Path(__file__).resolve().parents[2]
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def provenance(extra: dict[str, Any]) -> dict[str, Any]:
    from psg_data.schemas import FORMAT_VERSION

    return {"psg_data_version": __version__, "git_revision": _git_revision(), "format_version": FORMAT_VERSION,
            "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
            "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            **extra}
