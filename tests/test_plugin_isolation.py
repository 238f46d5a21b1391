"""Plugins isolated in every task (issue 46, family I), tried as an attacker would: a plugin package
installed through the ``psg_data.estimators`` entry-point group (tests/plugins/psg_hostile_plugin.py,
one entry point per broken rule) and run through ``psg-eval`` for --task persistence, navigation,
doors and a paper-sim protocol. Each plugin's failure is reported (exit 1, one ``error:`` line each,
results.json ``errors``), the other estimators are scored, nobody's numbers change.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.plugins.install import install_hostile_plugin

ROOT = Path(__file__).resolve().parents[1]

# what each broken rule must be reported as (a pattern found in its error message)
EXPECTED = {
    "fit_raises": r"fit raised RuntimeError: fit boom",
    "make_filter_raises": r"make_filter raised RuntimeError: make_filter boom",
    "make_filter_none": r"make_filter returned NoneType, not a filter",
    "predict_raises": r"predict raised RuntimeError: predict boom",
    "wrong_shape": r"predict returned (\d+) values for (\d+) times",
    "nan": r"(predict returned|prediction is) NaN",  # persistence: "prediction is", with the edge and time
    "out_of_range": r"(predict returned|prediction is) 1\.5 outside \[0, 1\]",
    "edits": r"raised ValueError: assignment destination is read-only",
    "exits": r"fit called sys\.exit\(0\)",
}
ATTACKS = [f"hostile_{m}" for m in EXPECTED]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return install_hostile_plugin(tmp_path_factory.mktemp("hostile-site"))


@pytest.fixture(scope="module")
def nav_ds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tests.navigation.conftest import write_nav_dataset

    return write_nav_dataset(tmp_path_factory.mktemp("navds") / "ds")


def psg_eval(site: Path, *args: str, timeout: float = 900) -> subprocess.CompletedProcess[str]:
    """``psg-eval ARGS`` in a fresh interpreter that finds the plugin through its entry points."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}
    code = "import sys; from psg_data.cli.psg_eval_cmd import main; sys.argv[0] = 'psg-eval'; main()"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, cwd=site,
                          timeout=timeout)


def run(site: Path, out: Path, *args: str) -> dict[str, Any]:
    """Exit code, stderr, results.json's errors by estimator and its main table's rows."""
    r = psg_eval(site, *args, "--no-references", "--no-plots", "-q", "--out", str(out))
    assert "Traceback" not in r.stderr, r.stderr
    res = json.loads((out / "results.json").read_text())
    errors: dict[str, list[str]] = {}
    for e in res["errors"]:
        errors.setdefault(e["estimator"], []).append(e["message"])
    main = next((t for t in res["tables"] if t["name"] == "doors"), res["tables"][0])  # doors: after the headroom
    rows = {row["method"]: row["values"] for row in main["rows"]}
    return {"rc": r.returncode, "stderr": r.stderr, "errors": errors, "rows": rows, "ok": res["ok"]}


TASKS = {
    "persistence": (["--dataset", "persistence-benchmark"], "last_seen", "mae"),
    "navigation": (["--task", "navigation", "--seeds", "1", "--queries", "12"], "last_seen", "overall_sr"),
    "doors": (["--task", "doors", "--seeds", "1", "--queries", "12"], "last_seen", "blocked_rate"),
    "paper-sim": (["--task", "navigation", "--dataset", "navigation-benchmark", "--protocol", "paper-sim-predictive",
                   "--quick"], "last_seen", "overall_sr"),
}


def _task_args(task: str, nav_ds: Path) -> list[str]:
    args = list(TASKS[task][0])
    if task in ("navigation", "doors"):
        args += ["--dataset", str(nav_ds)]
    return args


TASK_PARAMS = [t if t != "paper-sim" else pytest.param(t, marks=pytest.mark.slow) for t in TASKS]


@pytest.fixture(scope="module", params=TASK_PARAMS)
def attacked(request: pytest.FixtureRequest, site: Path, nav_ds: Path,
             tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict[str, Any]]:
    """One run per task: every attack and one built-in, the attacks first (they run before it)."""
    task = request.param
    out = tmp_path_factory.mktemp(f"attacked-{task}") / "out"
    e_args = [a for name in (*ATTACKS, "hostile_good", TASKS[task][1]) for a in ("-e", name)]
    return task, run(site, out, *_task_args(task, nav_ds), *e_args)


@pytest.mark.parametrize("mode", list(EXPECTED))
def test_each_broken_plugin_is_reported_and_the_others_are_scored(attacked: tuple[str, dict[str, Any]],
                                                                  mode: str) -> None:
    task, r = attacked
    builtin, metric = TASKS[task][1], TASKS[task][2]
    assert r["rc"] == 1 and not r["ok"]
    msgs = r["errors"].get(f"hostile_{mode}")
    assert msgs, f"{task}: hostile_{mode} not reported; errors: {sorted(r['errors'])}"
    found = [re.search(EXPECTED[mode], m) for m in msgs]
    assert any(found), msgs
    if mode == "wrong_shape":  # the plugin's extra value, counted
        assert all(int(f.group(1)) == int(f.group(2)) + 1 for f in found if f)
    assert f"estimator 'hostile_{mode}'" in r["stderr"]  # said on the terminal too
    for name in (builtin, "hostile_good"):  # scored after every attack ran
        assert name in r["rows"] and np.isfinite(float(r["rows"][name][metric]["mean"])), (name, r["rows"].keys())
        assert name not in r["errors"]


def test_a_plugin_editing_the_training_arrays_changes_nobody_elses_score(site: Path, tmp_path: Path) -> None:
    alone = run(site, tmp_path / "alone", "--dataset", "persistence-benchmark", "-e", "last_seen")
    both = run(site, tmp_path / "both", "--dataset", "persistence-benchmark", "-e", "hostile_edits", "-e", "last_seen")
    for m in ("mae", "balanced_accuracy", "f1"):  # main: last_seen MAE 0.1059 became 0.1070
        assert both["rows"]["last_seen"][m]["mean"] == alone["rows"]["last_seen"][m]["mean"], m
    assert alone["rc"] == 0 and both["rc"] == 1
    assert any("read-only" in m for m in both["errors"]["hostile_edits"])


@pytest.mark.parametrize("task", TASK_PARAMS)
def test_a_sleeping_plugin_is_stopped_by_the_time_limit(site: Path, nav_ds: Path, tmp_path: Path, task: str) -> None:
    jobs = ["-j", "2"] if task == "persistence" else []  # the watchdog in worker processes too
    r = run(site, tmp_path / "out", *_task_args(task, nav_ds), *jobs, "--estimator-timeout", "1",
            "-e", "hostile_sleeps", "-e", TASKS[task][1])
    assert r["rc"] == 1
    assert any("took longer than the time limit of 1 s" in m for m in r["errors"]["hostile_sleeps"])
    assert TASKS[task][1] in r["rows"] and TASKS[task][1] not in r["errors"]


@pytest.mark.parametrize(("mode", "text"), [("init_raises", "__init__ raised RuntimeError: init boom"),
                                            ("params_raise", "get_params raised RuntimeError: get_params boom")])
def test_a_raising_init_or_get_params_is_one_line(site: Path, tmp_path: Path, mode: str, text: str) -> None:
    r = psg_eval(site, "--dataset", "persistence-benchmark", "-e", f"hostile_{mode}", "-e", "last_seen",
                 "--out", str(tmp_path / "o"), "-q")
    assert r.returncode == 1 and r.stderr.strip() == f"error: --estimator 'hostile_{mode}': {text}", r.stderr
    assert not (tmp_path / "o").exists()


def test_estimator_timeout_option_is_checked_and_documented() -> None:
    from click.testing import CliRunner

    from psg_data.cli.psg_eval_cmd import ESTIMATOR_TIMEOUT_S, main
    from psg_data.estimators._guard import DEFAULT_TIMEOUT_S

    assert ESTIMATOR_TIMEOUT_S == DEFAULT_TIMEOUT_S == 600.0
    r = CliRunner().invoke(main, ["--estimator-timeout", "-1"])
    assert r.exit_code == 2 and "--estimator-timeout" in r.output
    help_text = CliRunner().invoke(main, ["--help"]).output
    assert "--estimator-timeout" in help_text and "600" in help_text
    for doc in ("README.md", "docs/SECURITY.md"):
        text = (ROOT / doc).read_text()
        assert "--estimator-timeout" in text and "600 s" in text, doc


# -- the mechanism, in process ---------------------------------------------------------------------
def test_guarded_call_reports_exit_and_lets_ctrl_c_through() -> None:
    from psg_data.estimators._guard import PluginError, guarded_call

    with pytest.raises(PluginError, match=r"^fit called sys.exit\(3\)$"):
        guarded_call("p", "fit", sys.exit, 3)

    def interrupted() -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        guarded_call("p", "fit", interrupted)


def test_built_ins_are_not_wrapped_and_keep_their_repair() -> None:
    import psg_data.estimators as est_pkg
    from psg_data.estimators import BaseFilter, get_estimator, list_estimators
    from psg_data.estimators._guard import GuardedEstimator, isolate

    for name in [n for n in list_estimators() if not n.startswith("hostile_")]:
        e = get_estimator(name)
        assert isolate(e, name) is e, name
    assert est_pkg.LastSeenEstimator.__module__.startswith("psg_data.")

    def subclasses(c: type) -> list[type]:
        return [c, *[s for k in c.__subclasses__() for s in subclasses(k)]]

    built_in = [c for c in subclasses(BaseFilter)[1:] if c.__module__.startswith("psg_data.")]
    assert built_in and all(c._repairs_predictions for c in built_in)

    class Raw(BaseFilter):  # a plugin's filter: its NaN and 1.5 come out as they are, for the guard to report
        def _update_many(self, t: np.ndarray, y: np.ndarray) -> None:
            pass

        def _predict(self, t: np.ndarray) -> np.ndarray:
            return np.array([np.nan, 1.5])[: t.size]

        def get_state(self) -> dict[str, Any]:
            return {}

    out = Raw(("o", "r")).predict([1.0, 2.0])
    assert np.isnan(out[0]) and out[1] == 1.5
    assert isinstance(isolate(type("P", (), {"make_filter": None, "get_params": None})()), GuardedEstimator)


def test_built_ins_never_write_into_the_arrays_they_are_handed() -> None:
    """Read-only training streams, observations and query times: every built-in that can fit with its
    defaults runs on them (so no built-in relies on editing what it is given)."""
    from psg_data.estimators import EdgeStream, conformance_streams, get_estimator, list_estimators
    from psg_data.errors import EstimatorError

    def frozen(a: np.ndarray) -> np.ndarray:
        b = np.array(a)
        b.setflags(write=False)
        return b

    streams = []
    for s in conformance_streams(days=3):
        s = EdgeStream(s.edge, s.t_s, s.y)
        s.t_s.setflags(write=False)
        s.y.setflags(write=False)
        streams.append(s)
    ran = []
    for name in [n for n in list_estimators() if not n.startswith("hostile_")]:
        est = get_estimator(name)
        try:
            est.fit(streams, val_streams=streams, timezone="UTC")
        except EstimatorError as exc:  # needs a setting (a model, a schedule) the defaults do not give
            assert "read-only" not in str(exc), name
            continue
        for s in streams:
            f = est.make_filter(s.edge)
            f.update_many(frozen(s.t_s[:-1]), frozen(s.y[:-1]))
            f.update(float(s.t_s[-1]), int(s.y[-1]))
            p = f.predict(frozen(s.t_s[-1] + np.array([0.0, 3600.0, 86400.0])))
            assert np.all((p >= 0) & (p <= 1)), name
        ran.append(name)
    assert {"perpetua_star", "perpetua", "fremen", "last_seen", "time_of_week_frequency"} <= set(ran), ran
