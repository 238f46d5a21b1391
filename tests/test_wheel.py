"""The wheel a user installs: built from the sources (once per session), it carries ``py.typed``
(PEP 561) and the MIT LICENSE, and a downstream ``mypy`` reads its annotations (no
``import-untyped``), installed in a fresh environment outside the checkout."""

from __future__ import annotations

import shutil
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``pip wheel`` of a copy of the sources (the build never writes into the checkout)."""
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    shutil.copytree(ROOT / "psg_data", src / "psg_data", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    out = tmp_path_factory.mktemp("wheel")
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(src)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    (whl,) = out.glob("psg_data-*.whl")
    return whl


def test_wheel_carries_py_typed_and_the_license(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        dist_info = next(n.split("/")[0] for n in names if n.split("/")[0].endswith(".dist-info"))
        assert "psg_data/py.typed" in names
        licenses = [n for n in names if n.startswith(dist_info) and n.endswith("LICENSE")]
        assert licenses, sorted(n for n in names if n.startswith(dist_info))
        assert z.read(licenses[0]).decode().startswith("MIT License")
        meta = z.read(f"{dist_info}/METADATA").decode()
    assert "License-Expression: MIT" in meta and "License-File: LICENSE" in meta
    assert not [n for n in names if n.startswith(("tests/", "bench/", "examples/")) or "__pycache__" in n]


def test_downstream_mypy_reads_the_annotations(wheel: Path, tmp_path: Path) -> None:
    """mypy in a project that installed the wheel: the package's own types, not ``import-untyped``."""
    env = tmp_path / "env"
    venv.create(env, with_pip=False)
    site = next((env / "lib").glob("python3*/site-packages"))
    with zipfile.ZipFile(wheel) as z:  # what installing a pure-Python wheel does
        z.extractall(site)
    project = tmp_path / "downstream"
    project.mkdir()
    (project / "use.py").write_text(
        "import psg_data\n"
        "from psg_data.evaluation import load_results\n\n"
        "results = load_results('run')\n"
        "n: int = results.table().title\n"  # a str: mypy must say so, which it can only from our annotations
        "version: str = psg_data.__version__\n", encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "mypy", "--python-executable", str(env / "bin" / "python"),
                        "--no-incremental", "--follow-imports", "silent", "use.py"],
                       capture_output=True, text=True, cwd=project)
    out = r.stdout + r.stderr
    assert "import-untyped" not in out and "import-not-found" not in out, out
    assert 'use.py:5: error: Incompatible types in assignment (expression has type "str", variable has type "int")' \
        in out, out
    assert "Found 1 error in 1 file" in out, out
