"""A reader that leaves early (``| head``, quitting ``less``) costs nothing: the run's folder is complete
and the command exits quietly (psg_data.cli._errors.ReaderGoneStdout).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import psg_data
from tests.conftest import write_tiny_dataset

_ROOT = str(Path(psg_data.__file__).resolve().parents[1])


def _closed_stdout(tool: str, *args: str, cwd: Path) -> tuple[int, str]:
    """Run ``tool args`` with its stdout a pipe whose reader is gone before the first line:
    (exit code, stderr).
    """
    code = f"from psg_data.cli.{tool} import main; main()"
    env = {**os.environ, "PYTHONPATH": _ROOT}
    read, write = os.pipe()
    os.close(read)  # the reader left (head -0)
    try:
        proc = subprocess.run([sys.executable, "-c", code, *args], stdout=write, stderr=subprocess.PIPE, text=True,
                              cwd=cwd, env=env, timeout=600)
    finally:
        os.close(write)
    return proc.returncode, proc.stderr


def test_psg_eval_into_a_closed_pipe_keeps_the_whole_run(tmp_path: Path) -> None:
    """The table goes nowhere, the results folder is committed whole, exit 0, no error line."""
    rc, err = _closed_stdout("psg_eval_cmd", "--dataset", "persistence-benchmark", "-e", "always_present",
                             "--no-references", "--no-plots", "--out", "res", cwd=tmp_path)
    assert rc == 0, err
    assert "error" not in err.lower() and "Traceback" not in err
    out = tmp_path / "res"
    assert not (tmp_path / "res.partial").exists()
    data = json.loads((out / "results.json").read_text())
    assert any(r["method"] == "always_present" for t in data["tables"] for r in t["rows"])
    assert "always_present" in (out / "table.txt").read_text()


def test_psg_data_info_into_a_closed_pipe_says_nothing(tmp_path: Path) -> None:
    """``psg-data info DS | head -0``: no ``error: Broken pipe``, no exit-time flush complaint."""
    ds = write_tiny_dataset(tmp_path / "ds", scans=2, frames=1)
    rc, err = _closed_stdout("psg_data_cmd", "info", str(ds), cwd=tmp_path)
    assert (rc, err) == (0, "")


def test_closed_pipe_drops_only_stdout_and_keeps_exit_codes(tmp_path: Path) -> None:
    """A bad input still reports its one error line on stderr with exit 1 when stdout is closed."""
    rc, err = _closed_stdout("psg_data_cmd", "info", str(tmp_path / "missing"), cwd=tmp_path)
    assert rc == 1 and err.startswith("error: ") and "Broken pipe" not in err
