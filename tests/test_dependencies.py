"""pyproject.toml declares exactly what the code imports.

- every third-party module imported anywhere in ``psg_data/`` (at module level or inside a
  function) belongs to a runtime requirement, or to the optional extra of the feature that uses it;
- every runtime requirement is imported by ``psg_data/`` (``tzdata`` is read by ``zoneinfo``);
- every third-party module the tests import is a runtime, extra or ``[dev]`` requirement.
"""

from __future__ import annotations

import ast
import functools
import importlib.metadata as md
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXTRAS_USED_BY = {"viewer": ("psg_data/viewer/",), "dask": ("psg_data/_executors.py",),
                  "graph": ("psg_data/graph/_convert.py", "psg_data/labeling/_scene_graph")}
"""Where each optional extra may be imported (lazily, with an error that names the extra)."""
IMPORTED_INDIRECTLY = {"tzdata": "zoneinfo reads its time-zone files where the system has none"}


def _pyproject() -> dict:  # type: ignore[type-arg]
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        tomllib = pytest.importorskip("tomli")
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def _name(req: str) -> str:
    m = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", req)
    assert m, req
    return re.sub(r"[-_.]+", "-", m.group(1)).lower()


@functools.cache
def _imports(folder: str) -> dict[str, set[str]]:
    """Top-level module name -> files under ``ROOT / folder`` importing it (absolute imports only).

    Cached: three tests read the same trees (about 1 s each to parse)."""
    out: dict[str, set[str]] = {}
    for p in sorted((ROOT / folder).rglob("*.py")):
        for node in ast.walk(ast.parse(p.read_text(), str(p))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            for n in names:
                out.setdefault(n.split(".")[0], set()).add(p.relative_to(ROOT).as_posix())
    return out


def _third_party(imports: dict[str, set[str]]) -> dict[str, set[str]]:
    return {m: f for m, f in imports.items() if m not in sys.stdlib_module_names and m not in ("psg_data", "tests")}


@functools.cache
def _packages_distributions() -> dict[str, list[str]]:
    """Cached: each call scans every installed distribution's metadata (about 0.2 s)."""
    return md.packages_distributions()


def _distributions(module: str) -> set[str]:
    dists = _packages_distributions().get(module, [])
    assert dists, f"module {module!r} is imported but no installed distribution provides it"
    return {_name(d) for d in dists}


def _requirements() -> tuple[dict[str, str], dict[str, set[str]]]:
    project = _pyproject()["project"]
    runtime = {_name(r): r for r in project["dependencies"]}
    extras = {k: {_name(r) for r in v} for k, v in project["optional-dependencies"].items()}
    return runtime, extras


def test_every_third_party_import_of_the_package_is_declared() -> None:
    runtime, extras = _requirements()
    problems = []
    for module, files in sorted(_third_party(_imports("psg_data")).items()):
        dists = _distributions(module)
        if dists & set(runtime):
            continue
        extra = next((k for k in EXTRAS_USED_BY if dists & extras.get(k, set())), None)
        if extra is None:
            problems.append(f"{module} ({', '.join(sorted(dists))}): imported by {sorted(files)[0]}, not declared")
        elif not all(f.startswith(EXTRAS_USED_BY[extra]) for f in files):
            problems.append(f"{module}: extra [{extra}] imported outside {EXTRAS_USED_BY[extra]}: {sorted(files)}")
    assert problems == []


def test_every_runtime_requirement_is_imported_by_the_package() -> None:
    runtime, _ = _requirements()
    imported = set()
    for module in _third_party(_imports("psg_data")):
        imported |= _distributions(module)
    unused = []
    for name, req in runtime.items():
        if name in imported or name in IMPORTED_INDIRECTLY:
            continue
        try:
            md.distribution(name)
        except md.PackageNotFoundError:
            assert ";" in req, f"{req}: not installed here although it has no environment marker"
            continue  # another platform's variant (open3d vs open3d-cpu)
        unused.append(req)
    assert unused == [], "runtime requirements that psg_data never imports (move them to [dev] or an extra)"


def test_every_third_party_import_of_the_tests_is_declared() -> None:
    runtime, extras = _requirements()
    declared = set(runtime).union(*extras.values())
    missing = {m: sorted(f)[0] for m, f in _third_party(_imports("tests")).items()
               if not _distributions(m) & declared}
    assert missing == {}


def test_scikit_learn_and_mcap_are_test_only() -> None:
    runtime, extras = _requirements()
    assert {"scikit-learn", "mcap", "mcap-ros2-support"}.isdisjoint(runtime)
    assert {"scikit-learn", "mcap", "pytest", "hypothesis"} <= extras["dev"]
    assert "ruamel-yaml" in runtime and re.search(r"<\s*\d", runtime["rosbags"]), "rosbags must be bounded above"
