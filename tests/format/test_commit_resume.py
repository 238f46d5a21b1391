"""A commit that fails at any step leaves a state the same command resumes (issue 28, D1).

``commit_tree`` swaps the new output in by renames; a failure is injected at each of its steps (and,
where the file system allows it, made real with ``chattr +i``). After each, the error is one line,
the previous output is intact (in place or set aside), and rerunning the same command succeeds
with nothing left beside the output.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.schemas.validate import validate_dataset
from psg_data.writers import _safe_output
from psg_data.writers._safe_output import PARTIAL_MARKER
from tests.contract import assert_one_error

STEPS = ["fsync", "set_aside", "swap", "swap_and_restore", "unmark", "remove_old"]


def _inject(monkeypatch: pytest.MonkeyPatch, out: Path, step: str) -> None:
    """Make step ``step`` of the next commit to ``out`` fail with an OSError (once)."""
    real_replace, real_rmtree, real_unlink = os.replace, shutil.rmtree, Path.unlink
    aside = out.with_name(f".{out.name}.psg-replaced")
    fired: dict[str, bool] = {}

    def fail(what: str) -> None:
        fired[what] = True
        raise PermissionError(1, "Operation not permitted (injected)", str(out))

    def replace(src: Any, dst: Any, *a: Any, **k: Any) -> Any:
        s, d = Path(src), Path(dst)
        if step == "set_aside" and s == out and d == aside and not fired.get(step):
            fail(step)
        if step in ("swap", "swap_and_restore") and d == out and s.name.endswith(".partial") and not fired.get("swap"):
            fail("swap")
        if step == "swap_and_restore" and s == aside and d == out and not fired.get("restore"):
            fail("restore")
        return real_replace(src, dst, *a, **k)

    def rmtree(path: Any, *a: Any, **k: Any) -> Any:
        if step == "remove_old" and Path(path) == aside and not fired.get(step):
            fail(step)
        return real_rmtree(path, *a, **k)

    def unlink(self: Path, *a: Any, **k: Any) -> Any:
        if step == "unmark" and self == out / PARTIAL_MARKER and not fired.get(step):
            fail(step)
        return real_unlink(self, *a, **k)

    def fsync_tree(root: Any) -> None:
        if step == "fsync" and not fired.get(step):
            fail(step)

    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setattr(shutil, "rmtree", rmtree)
    monkeypatch.setattr(Path, "unlink", unlink)
    if step == "fsync":
        monkeypatch.setattr(_safe_output, "fsync_tree", fsync_tree)


def _assert_clean(out: Path) -> None:
    assert validate_dataset(out, checksums=True) == []
    beside = sorted(p.name for p in out.parent.iterdir() if p.name.startswith((out.name, f".{out.name}")))
    assert beside == [out.name], beside
    assert not (out / PARTIAL_MARKER).exists()


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tests.convert.conftest import write_bag

    return write_bag(tmp_path_factory.mktemp("rec") / "run.bag", n=3)


@pytest.mark.parametrize("step", STEPS)
def test_convert_overwrite_resumes_after_a_failed_commit(tmp_path: Path, recording: Path, step: str,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "ds"
    args = ["convert", str(recording), str(out), "--quiet"]
    assert CliRunner().invoke(psg_data, args).exit_code == 0
    with monkeypatch.context() as m:
        _inject(m, out, step)
        r = CliRunner().invoke(psg_data, [*args, "--overwrite"])
    if step in ("unmark", "remove_old"):  # the new output is in place; the last clean-up failed
        assert_one_error(r, "rerun the same command")
    else:
        assert_one_error(r, "rerun the same command to resume")
        assert (out / "dataset.json").is_file() or out.with_name(f".{out.name}.psg-replaced").is_dir()
        assert (out.with_name("ds.partial") / PARTIAL_MARKER).is_file()
    r = CliRunner().invoke(psg_data, [*args, "--overwrite"])
    assert r.exit_code == 0, r.output
    _assert_clean(out)


@pytest.mark.parametrize("step", ["set_aside", "swap", "unmark"])
def test_synth_overwrite_reruns_after_a_failed_commit(tmp_path: Path, step: str,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "lab"
    args = ["synth", str(out), "--days", "1", "--frames-per-scan", "1", "--resolution", "32x24", "--quiet"]
    assert CliRunner().invoke(psg_data, args).exit_code == 0
    with monkeypatch.context() as m:
        _inject(m, out, step)
        r = CliRunner().invoke(psg_data, [*args, "--overwrite"])
    assert_one_error(r)
    r = CliRunner().invoke(psg_data, [*args, "--overwrite"])
    assert r.exit_code == 0, r.output
    _assert_clean(out)


def test_immutable_output_then_rerun(tmp_path: Path, recording: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The reported case: ``chattr +i ds`` (made real where the file system and user allow it, else
    the same EPERM injected at the rename), ``--overwrite`` fails, ``chattr -i ds``, rerun succeeds."""
    out = tmp_path / "ds"
    args = ["convert", str(recording), str(out), "--quiet"]
    assert CliRunner().invoke(psg_data, args).exit_code == 0
    real = shutil.which("chattr") is not None and subprocess.run(["chattr", "+i", str(out)],
                                                                 capture_output=True).returncode == 0
    try:
        with monkeypatch.context() as m:
            if not real:
                _inject(m, out, "set_aside")
            r = CliRunner().invoke(psg_data, [*args, "--overwrite"])
    finally:
        if real:
            subprocess.run(["chattr", "-i", str(out)], check=True)
    assert_one_error(r, "Operation not permitted")
    r = CliRunner().invoke(psg_data, [*args, "--overwrite"])
    assert r.exit_code == 0, r.output
    _assert_clean(out)
