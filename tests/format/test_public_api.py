"""Every subpackage has a curated ``__all__``: it resolves, has no duplicates, and lists every public
name the package's ``__init__`` imports (nothing is exported by accident or forgotten)."""

from __future__ import annotations

import importlib
import pkgutil
import types

import pytest

import psg_data

SUBPACKAGES = ["schemas", "loaders", "writers", "labeling", "estimators", "metrics", "synth", "navigation", "convert",
               "graph", "maps"]


@pytest.mark.parametrize("name", SUBPACKAGES)
def test_all_resolves_and_is_complete(name: str) -> None:
    pkg = importlib.import_module(f"psg_data.{name}")
    assert hasattr(pkg, "__all__"), f"psg_data.{name} has no __all__"
    for attr in pkg.__all__:
        assert hasattr(pkg, attr), f"psg_data.{name}.__all__ lists {attr!r}, which does not exist"
    assert len(set(pkg.__all__)) == len(pkg.__all__), f"psg_data.{name}.__all__ has duplicates"
    submodules = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    public = {a for a, v in vars(pkg).items()
              if not a.startswith("_") and a not in submodules and not isinstance(v, types.ModuleType)
              and a != "annotations"}
    missing = sorted(public - set(pkg.__all__))
    assert not missing, f"psg_data.{name} imports public names that __all__ does not list: {missing}"


def test_top_level_lazy_names() -> None:
    for attr in psg_data.__all__:
        assert getattr(psg_data, attr) is not None
    assert psg_data.datasets.demo is not None


KNOWN_DRIFTS = {("psg_data.estimators", "psg_data.estimators._perpetua_star")}
"""Estimator modules are being rewritten on another branch; their lists are aligned after it lands."""


def _reexports(init: str, package: str) -> dict[str, str]:
    """Names ``package/__init__.py`` imports from its own private modules: name -> module."""
    import ast

    out = {}
    for node in ast.walk(ast.parse(init)):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith(package + "._"):
            out.update({a.asname or a.name: node.module for a in node.names})
    return out


@pytest.mark.parametrize("name", SUBPACKAGES + ["loaders.raw"])
def test_module_all_lists_what_the_package_exports_from_it(name: str) -> None:
    """A name the package exports from one of its modules is in that module's ``__all__`` too."""
    from pathlib import Path

    pkg = importlib.import_module(f"psg_data.{name}")
    assert pkg.__file__ is not None
    drifts = []
    for attr, module in _reexports(Path(pkg.__file__).read_text(encoding="utf-8"), pkg.__name__).items():
        mod_all = getattr(importlib.import_module(module), "__all__", None)
        if (attr in pkg.__all__ and mod_all is not None and attr not in mod_all
                and (pkg.__name__, module) not in KNOWN_DRIFTS):
            drifts.append(f"{module}.{attr}")
    assert not drifts, f"psg_data.{name} exports names their modules' __all__ does not list: {drifts}"


DOCUMENTED = ["schemas", "loaders", "loaders.raw", "writers", "convert", "synth", "labeling", "navigation", "viewer",
              "estimators", "metrics", "evaluation", "graph", "maps"]
"""Packages whose whole public surface is documented."""


def _public_members(pkg: types.ModuleType) -> list[tuple[str, str]]:
    """(name, docstring) of every function and class a package exports, and of the public methods and
    properties of those classes; a method that overrides a documented one inherits its docstring, as
    ``inspect.getdoc`` and Sphinx do."""
    import inspect

    out: list[tuple[str, str]] = []
    for attr in pkg.__all__:
        obj = getattr(pkg, attr)
        if inspect.isclass(obj) or inspect.isfunction(obj):
            out.append((f"{pkg.__name__}.{attr}", obj.__doc__ or ""))
        if inspect.isclass(obj):
            for k, v in vars(obj).items():
                f = v.fget if isinstance(v, property) else getattr(v, "__func__", v)
                if not k.startswith("_") and (inspect.isfunction(f) or isinstance(v, property)):
                    out.append((f"{pkg.__name__}.{attr}.{k}", inspect.getdoc(getattr(obj, k)) or ""
                                if not isinstance(v, property) else f.__doc__ or ""))
    return out


@pytest.mark.parametrize("name", DOCUMENTED)
def test_public_api_is_documented(name: str) -> None:
    pkg = importlib.import_module(f"psg_data.{name}")
    missing = [label for label, doc in _public_members(pkg) if not doc.strip()]
    assert not missing, f"public names without a docstring: {missing}"


PUBLIC_SUBPACKAGES = ["datasets", "schemas", "loaders", "writers", "convert", "synth", "labeling", "estimators",
                      "metrics", "evaluation", "navigation", "viewer", "errors"]


def test_every_public_subpackage_is_an_attribute_after_import_psg_data() -> None:
    """What README's snippets do in a fresh interpreter: ``import psg_data`` then ``psg_data.evaluation....``."""
    import subprocess
    import sys

    code = ("import sys, psg_data\n"
            "light = [m for m in ('numpy', 'pandas', 'pyarrow', 'cv2', 'open3d', 'click', 'rich') if m in sys.modules]\n"
            "mods = [m for m in sys.modules if m.startswith('psg_data.')]\n"
            f"subs = {PUBLIC_SUBPACKAGES!r}\n"
            "print(light, mods)\n"
            "print([type(getattr(psg_data, s)).__name__ for s in subs])\n"
            "print(callable(psg_data.evaluation.load_results), callable(psg_data.viewer.log_dataset))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/")
    assert out.returncode == 0, out.stderr
    first, kinds, calls = out.stdout.strip().splitlines()
    assert first == "[] []"  # nothing heavy and no subpackage imported by `import psg_data` itself
    assert kinds == str(["module"] * len(PUBLIC_SUBPACKAGES))
    assert calls == "True True"


def test_dir_lists_the_public_api() -> None:
    names = dir(psg_data)
    assert set(psg_data.__all__) <= set(names) and set(PUBLIC_SUBPACKAGES) <= set(names)
    assert not {"Any", "TYPE_CHECKING", "annotations", "logging", "importlib"} & set(names)
    assert names == sorted(names)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        psg_data.nope  # noqa: B018
