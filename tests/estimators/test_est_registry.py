"""Registry, entry-point plugins, conformance check of every built-in, public surface."""

from __future__ import annotations

import importlib
import json
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import psg_data.estimators as E
from psg_data.errors import EstimatorError, NotFittedError
from psg_data.estimators import check_estimator, get_estimator, list_estimators, register_estimator

BUILTINS = ["always_absent", "always_present", "fremen", "last_seen", "perpetua", "perpetua_star", "perpetua_star_oracle",
            "perpetua_star_schedule", "persistence_filter", "time_of_week_frequency"]


def _settings(name: str) -> dict:
    if name == "perpetua_star_schedule":
        return {"schedules": {"obj_a/rec_1": "Schedule: ['Mon: 08:00 - Mon: 18:00', 'Tue: 08:00 - Tue: 18:00']",
                              ("obj_b", "rec_2"): ["Sun: 19:00 - Mon: 01:00"]}}
    if name == "fremen":
        return {"n_periods": 200}
    return {}


def test_builtins_listed() -> None:
    assert set(BUILTINS) <= set(list_estimators())


@pytest.mark.parametrize("name", BUILTINS)
def test_check_estimator_passes_for_builtin(name: str) -> None:
    report = check_estimator(get_estimator(name, **_settings(name)))
    assert set(report.values()) == {"ok"} and "state_roundtrip" in report


def test_unknown_name_lists_valid_names() -> None:
    with pytest.raises(EstimatorError, match=r"unknown estimator 'nope'; valid names: .*perpetua_star"):
        get_estimator("nope")
    with pytest.raises(EstimatorError, match="invalid settings"):
        get_estimator("perpetua_star", bogus=1)


def test_not_fitted_and_bad_settings() -> None:
    with pytest.raises(NotFittedError, match="not fitted"):
        get_estimator("perpetua_star").make_filter(("a", "b"))
    streams = E.conformance_streams(days=3)
    with pytest.raises(EstimatorError, match="prior must be one of"):
        get_estimator("perpetua_star", prior="llm").fit(streams)
    with pytest.raises(EstimatorError, match="needs schedules"):
        get_estimator("perpetua_star_schedule").fit(streams)
    with pytest.raises(EstimatorError, match="oracle"):
        get_estimator("perpetua_star_oracle").fit([E.EdgeStream(s.edge, s.t_s, s.y) for s in streams])


def test_register_estimator() -> None:
    register_estimator("test_always_present_copy", lambda **kw: E.AlwaysPresentEstimator(**kw), overwrite=True)
    assert "test_always_present_copy" in list_estimators()
    est = get_estimator("test_always_present_copy")
    check_estimator(est)
    with pytest.raises(EstimatorError, match="already registered"):
        register_estimator("perpetua", lambda: None)


def test_entry_point_plugin_is_listed_and_scored(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pkg = tmp_path / "tiny_psg_plugin"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(textwrap.dedent('''
        import numpy as np

        class HalfFilter:
            def __init__(self, edge):
                self.edge, self._last = edge, None
            @property
            def last_t_s(self):
                return self._last
            def update(self, t_s, y):
                self.update_many([t_s], [y])
            def update_many(self, t_s, y):
                from psg_data.errors import EstimatorError
                t = np.asarray(t_s, dtype=float)
                if t.size and ((self._last is not None and t[0] < self._last) or np.any(np.diff(t) < 0)):
                    raise EstimatorError("time went backwards")
                if t.size:
                    self._last = float(t[-1])
            def predict(self, t_s):
                return np.full(np.shape(t_s), 0.5)
            def get_state(self):
                return {"edge": list(self.edge), "last": self._last}

        class HalfEstimator:
            def __init__(self, *, level=0.5):
                self.level = level
            def get_params(self):
                return {"level": self.level}
            def fit(self, streams, *, val_streams=None, timezone="UTC"):
                self.fitted_ = True
                return self
            def make_filter(self, edge):
                from psg_data.errors import NotFittedError
                if not getattr(self, "fitted_", False):
                    raise NotFittedError("not fitted")
                return HalfFilter(edge)
            def filter_from_state(self, state):
                f = HalfFilter(tuple(state["edge"]))
                f._last = state["last"]
                return f
    '''))
    dist = tmp_path / "tiny_psg_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: tiny-psg-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[psg_data.estimators]\nhalf = tiny_psg_plugin:HalfEstimator\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.invalidate_caches()
    assert "half" in list_estimators()
    assert "tiny_psg_plugin" not in sys.modules  # listed without importing the plugin
    est = get_estimator("half", level=0.5)
    assert type(est).__name__ == "HalfEstimator"
    assert set(check_estimator(est).values()) == {"ok"}
    streams = E.conformance_streams(days=2)
    est.fit(streams)
    f = est.make_filter(streams[0].edge)
    f.update_many(streams[0].t_s, streams[0].y)
    gt_x = streams[0].meta["gt_state"].astype(float)
    mae = np.mean(np.abs(gt_x - f.predict(streams[0].meta["gt_t_s"])))
    assert mae == pytest.approx(0.5)
    # scored by psg-eval like a built-in, with no change to psg_data
    from click.testing import CliRunner

    from psg_data.cli.psg_eval_cmd import main as psg_eval

    out = tmp_path / "res"
    res = CliRunner().invoke(psg_eval, ["--dataset", "persistence-benchmark", "-e", "half", "--no-references",
                                        "--seeds", "1", "--out", str(out), "--quiet", "--no-plots"])
    assert res.exit_code == 0, res.output + str(res.exception)
    assert "half" in res.output
    rows = json.loads((out / "results.json").read_text())["tables"][0]["rows"]
    assert [r["method"] for r in rows] == ["half"]
    assert rows[0]["values"]["mae"]["mean"] == pytest.approx(0.5)  # a constant 0.5 is 0.5 away from any 0/1 truth


def test_check_estimator_catches_broken_estimators() -> None:
    class Raw(E.LastSeenEstimator):
        def make_filter(self, edge):
            f = super().make_filter(edge)
            f.predict = lambda t: np.full(np.shape(t), 1.5)  # bypasses the clipping
            return f

    with pytest.raises(EstimatorError, match="range"):
        check_estimator(Raw())


def test_public_all_is_complete() -> None:
    for n in E.__all__:
        assert hasattr(E, n), n
    for n in ("EdgeStream", "EdgeFilter", "PersistenceEstimator", "get_estimator", "list_estimators",
              "register_estimator", "check_estimator", "receptacle_belief", "map_receptacle", "render_llm_prompt",
              "parse_llm_schedule"):
        assert n in E.__all__


def test_fit_depends_on_seed_is_declared() -> None:
    # estimators whose fit draws random restarts say so; the others repeat the same fit for any seed
    assert get_estimator("perpetua_star").fit_depends_on_seed and get_estimator("perpetua").fit_depends_on_seed
    for name in ("last_seen", "always_absent", "always_present", "fremen", "time_of_week_frequency",
                 "persistence_filter", "process_oracle"):
        assert not get_estimator(name).fit_depends_on_seed, name


def test_always_absent_predicts_zero() -> None:
    import numpy as np

    from psg_data.estimators import EdgeStream

    est = get_estimator("always_absent").fit([EdgeStream(("o", "r"), np.array([0.0, 1.0]), np.array([1, 1], np.int8))])
    f = est.make_filter(("o", "r"))
    f.update(2.0, 1)
    assert f.predict(np.array([3.0, 4.0])).tolist() == [0.0, 0.0]
