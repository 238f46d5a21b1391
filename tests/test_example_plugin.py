"""Plugins: examples/plugin installs as a package of its own, passes check_estimator and is scored by
psg-eval through its entry point; check_estimator names every missing or wrong member; an
undeclared plugin setting with a bad value fails once, before any work, in one line."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.errors import EstimatorError
from psg_data.estimators import BaseEstimator, BaseFilter, check_estimator, register_estimator
from tests.contract import assert_one_error

ROOT = Path(__file__).resolve().parents[1]


def _tree(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if "__pycache__" not in p.parts)


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """examples/plugin installed (pip, as a user would) into a folder of its own."""
    site = tmp_path_factory.mktemp("plugin-site")
    src = ROOT / "examples" / "plugin"
    before = _tree(src)
    copy = tmp_path_factory.mktemp("plugin-src") / "plugin"  # a build may write build/, *.egg-info beside its source
    shutil.copytree(src, copy, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(copy)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert _tree(src) == before  # the repository's examples/plugin/ is left as it was
    assert list(site.glob("psg_example_plugin-0.1.0.dist-info/entry_points.txt"))
    return site


def _python(site: Path, code: str, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, cwd=site)


def test_installed_example_plugin_passes_check_and_is_scored(plugin_site: Path, tmp_path: Path) -> None:
    r = _python(plugin_site, "from psg_data.estimators import check_estimator, get_estimator, list_estimators\n"
                             "assert 'example_decay' in list_estimators()\n"
                             "print(sorted(set(check_estimator(get_estimator('example_decay')).values())))")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "['ok']"
    out = tmp_path / "res"
    r = _python(plugin_site, "import sys; from psg_data.cli.psg_eval_cmd import main; sys.argv[0] = 'psg-eval'; "
                             "main()", "--dataset", "persistence-benchmark", "-e", "example_decay",
                "-e", "example_decay:half_life_h=48", "-e", "last_seen", "--no-references", "--out", str(out),
                "--no-plots", "-q")
    assert r.returncode == 0, r.stderr
    rows = {row["method"]: row["values"] for row in json.loads((out / "results.json").read_text())["tables"][0]["rows"]}
    assert set(rows) == {"example_decay", "example_decay:half_life_h=48", "last_seen"}
    assert rows["example_decay"]["mae"]["mean"] != rows["example_decay:half_life_h=48"]["mae"]["mean"]
    r = _python(plugin_site, "import sys; from psg_data.cli.psg_eval_cmd import main; main()",
                "-e", "example_decay:half_life_h=-1")
    assert r.returncode == 1 and r.stderr.strip().startswith("error: ") and "half_life_h must be a number > 0" in \
        r.stderr and len(r.stderr.strip().splitlines()) == 1


class _Filter(BaseFilter):
    def _update_many(self, t: np.ndarray, y: np.ndarray) -> None:
        pass

    def _predict(self, t: np.ndarray) -> np.ndarray:
        return np.full(t.shape, 0.5)

    def get_state(self) -> dict:  # type: ignore[type-arg]
        return {"estimator": "half", "edge": list(self.edge), "last_t_s": self._last_t}


class _Half(BaseEstimator):
    name = "half"

    def __init__(self, *, level: float = 0.5) -> None:
        self.level = level

    def fit(self, streams, *, val_streams=None, timezone="UTC"):  # type: ignore[no-untyped-def]
        float(self.level)  # an undeclared setting, used as a number
        self.fitted_ = True
        return self

    def make_filter(self, edge):  # type: ignore[no-untyped-def]
        self._check_fitted()
        return _Filter(edge)

    def filter_from_state(self, state):  # type: ignore[no-untyped-def]
        f = _Filter(self._check_state(state))
        f._last_t = state["last_t_s"]
        return f


def test_base_classes_make_a_conforming_plugin() -> None:
    assert set(check_estimator(_Half()).values()) == {"ok"}


def test_check_estimator_names_every_missing_member() -> None:
    class NoParams:
        def fit(self, streams, **kw):  # type: ignore[no-untyped-def]
            return self

    with pytest.raises(EstimatorError) as err:
        check_estimator(NoParams())  # type: ignore[arg-type]
    msg = str(err.value)
    assert msg.startswith("check_estimator(NoParams): members: missing or not callable: ")
    assert "make_filter(), filter_from_state(), get_params()" in msg

    class BadFilter(_Half):
        def make_filter(self, edge):  # type: ignore[no-untyped-def]
            self._check_fitted()
            return object()

    with pytest.raises(EstimatorError, match=r"filter_members: the filter \(object\) misses update\(\), "
                                             r"update_many\(\), predict\(\), get_state\(\), last_t_s"):
        check_estimator(BadFilter())

    class NoClone(_Half):
        def get_params(self, deep: bool = True) -> dict:  # type: ignore[type-arg]
            return {"level": self.level, "extra": 1}

    with pytest.raises(EstimatorError, match=r"get_params: type\(est\)\(\*\*est.get_params\(\)\) fails"):
        check_estimator(NoClone())

    class Crashes(_Half):
        def fit(self, streams, *, val_streams=None, timezone="UTC"):  # type: ignore[no-untyped-def]
            raise KeyError("boom")

    with pytest.raises(EstimatorError, match=r"check_estimator\(Crashes\): fit_returns_self: raised KeyError"):
        check_estimator(Crashes())


def test_undeclared_setting_with_a_bad_value_fails_once_up_front(tmp_path: Path) -> None:
    from psg_data.cli.psg_eval_cmd import main

    register_estimator("half_for_test", _Half, overwrite=True)
    r = CliRunner().invoke(main, ["--dataset", "persistence-benchmark", "-e", "half_for_test:level=abc",
                                  "--no-references", "--out", str(tmp_path / "o"), "--no-plots", "-q"])
    line = assert_one_error(r, "--estimator 'half_for_test:level=abc': setting level is not declared by half_for_test")
    assert "ValueError: could not convert string to float: 'abc'" in line
    assert not (tmp_path / "o").exists()
    r = CliRunner().invoke(main, ["--dataset", "persistence-benchmark", "-e", "half_for_test:level=0.2",
                                  "--no-references", "--out", str(tmp_path / "ok"), "--no-plots", "-q"])
    assert r.exit_code == 0, r.output
