"""The persistence-evaluation harness with toy estimators that follow the plugin Protocol."""

from __future__ import annotations

import json
import re
from typing import Any

import numpy as np
import pandas as pd
import pytest

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeFilter, EdgeStream, PersistenceEstimator
from psg_data.evaluation import TIME_METRICS, PersistenceResult, evaluate_persistence
from psg_data.metrics import (
    time_integrated_balanced_accuracy,
    time_integrated_f1,
    time_integrated_mae,
)

H = 3600.0
T0 = 1704067200.0  # 2024-01-01 00:00 UTC, a Monday


# ---------------------------------------------------------------- toy plugins


class _Filter:
    def __init__(self, mode: str, value: float) -> None:
        self.mode, self.value = mode, value
        self._last_t: float | None = None
        self._last_y: float = value

    @property
    def last_t_s(self) -> float | None:
        return self._last_t

    def update(self, t_s: float, y: int) -> None:
        self._last_t, self._last_y = float(t_s), float(y)

    def update_many(self, t_s: Any, y: Any) -> None:
        for t, v in zip(np.asarray(t_s), np.asarray(y)):
            self.update(t, v)

    def predict(self, t_s: Any) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        if self.mode == "last":
            return np.full(t.shape, self._last_y)
        if self.mode == "nan":
            out = np.full(t.shape, 0.5)
            out[t >= T0 + 7 * 24 * H + 30 * H] = np.nan
            return out
        if self.mode == "big":
            return np.full(t.shape, 1.5)
        if self.mode == "raise":
            raise RuntimeError("boom")
        return np.full(t.shape, self.value)

    def get_state(self) -> dict[str, Any]:
        return {"last_t": self._last_t, "last_y": self._last_y}


class Toy:
    """mode: 'last' (last observation), 'const' (value + 0.01 * random_state), 'nan' (NaN on edges
    whose object is 'bad' from a fixed time), 'big' (1.5 on 'bad'), 'raise' (predict raises on
    'bad'), 'fitfail' (fit raises)."""

    def __init__(self, *, mode: str = "last", value: float = 0.5, random_state: int | None = None) -> None:
        self.mode, self.value, self.random_state = mode, value, random_state

    def fit(self, streams, *, val_streams=None, timezone="UTC") -> "Toy":
        if self.mode == "fitfail":
            raise ValueError("cannot fit this")
        self.n_streams_ = len(streams)
        return self

    def make_filter(self, edge) -> _Filter:
        if self.mode in ("nan", "big", "raise"):
            return _Filter(self.mode if edge[0] == "bad" else "const", self.value)
        v = self.value + 0.01 * (self.random_state or 0) if self.mode == "const" else self.value
        return _Filter(self.mode, v)

    def filter_from_state(self, state):
        raise NotImplementedError

    def get_params(self) -> dict[str, Any]:
        return {"mode": self.mode, "value": self.value, "random_state": self.random_state}


def last_factory(random_state=None):
    return Toy(mode="last", random_state=random_state)


def const_factory(random_state=None):
    return Toy(mode="const", value=0.3, random_state=random_state)


def nan_factory(random_state=None):
    return Toy(mode="nan", random_state=random_state)


# ---------------------------------------------------------------- toy data


def make_world(seed: int = 0, edges=(("mug", "table"), ("mug", "shelf"), ("book", "table"), ("bad", "desk"))):
    """Noise-free data whose state only changes at observation times (every 3 h, on the hour).

    Train: one week from T0; test: the next week. Ground truth: hourly grid over the test week,
    the state at a grid time = the last observation at or before it.
    """
    rng = np.random.default_rng(seed)
    train, test, gt = [], [], {}
    grid = T0 + 7 * 24 * H + np.arange(0, 7 * 24) * H
    for k, e in enumerate(edges):
        obs_t = T0 + np.arange(0, 14 * 24, 3) * H + (k % 3) * H
        # blocks of random lengths so states persist for a while
        y = np.zeros(obs_t.size, dtype=np.int8)
        state, i = int(rng.integers(0, 2)), 0
        while i < y.size:
            n = int(rng.integers(2, 8))
            y[i : i + n] = state
            state, i = 1 - state, i + n
        split = T0 + 7 * 24 * H
        tr = obs_t < split
        train.append(EdgeStream(e, obs_t[tr], y[tr]))
        test.append(EdgeStream(e, obs_t[~tr], y[~tr]))
        idx = np.searchsorted(obs_t, grid, side="right") - 1
        gt[e] = (grid, y[idx])
    return train, test, gt


def _row(res: PersistenceResult, est: str, obj: str, rec: str, seed: int = 0):
    (r,) = [r for r in res.edges if r.estimator == est and r.edge == (obj, rec) and r.seed == seed]
    return r


# ---------------------------------------------------------------- tests


def test_toy_plugins_follow_the_protocol():
    est = Toy()
    assert isinstance(est, PersistenceEstimator)
    assert isinstance(est.make_filter(("a", "b")), EdgeFilter)


def test_last_observation_is_perfect_in_adaptive_but_not_in_predictive():
    train, test, gt = make_world()
    ests = {"last": last_factory}
    ada = evaluate_persistence(ests, train, test, gt, setting="adaptive")
    pre = evaluate_persistence(ests, train, test, gt, setting="predictive")
    assert ada.ok and pre.ok
    for r in ada.edges:
        assert r.status == "ok"
        assert r.metrics["mae"] == 0.0 and r.metrics["sample_mae"] == 0.0
        assert r.metrics["f1"] == pytest.approx(1.0, abs=1e-7)
        assert r.metrics["balanced_accuracy"] == pytest.approx(1.0, abs=1e-7)
        assert r.n_points == 7 * 24  # observation times fall on grid times
    assert ada.summary["last"]["mae"].mean == 0.0
    assert pre.summary["last"]["mae"].mean > 0.2
    assert pre.summary["last"]["balanced_accuracy"].mean <= 0.5 + 1e-9  # constant prediction
    # predictive = constant last training observation, scored by hand with the metric functions
    for s, (e, (t, y)) in zip(train, gt.items()):
        b = np.full(t.size, float(s.y[-1]))
        r = _row(pre, "last", *e)
        assert r.metrics["mae"] == pytest.approx(time_integrated_mae(t, y, b))
        assert r.metrics["balanced_accuracy"] == pytest.approx(time_integrated_balanced_accuracy(t, y, b))
        assert r.metrics["f1"] == pytest.approx(time_integrated_f1(t, y, b))
        assert r.n_train_obs == len(s) and r.n_test_obs == 56


def test_adaptive_predicts_before_applying_a_later_observation():
    # one edge; truth flips at the observation at 10 s, but an eval time at 9 s must not see it
    train = [EdgeStream(("o", "r"), [0.0], [1])]
    test = [EdgeStream(("o", "r"), [10.0], [0])]
    gt = {("o", "r"): (np.array([5.0, 9.0, 10.0, 12.0]), np.array([1, 1, 0, 0]))}
    res = evaluate_persistence({"last": last_factory}, train, test, gt, setting="adaptive", eval_times="grid")
    assert _row(res, "last", "o", "r").metrics["mae"] == 0.0
    # had the filter seen the observation at 10 s before predicting at 9 s, |1 - 0| on [9, 10]
    res_p = evaluate_persistence({"last": last_factory}, train, test, gt, setting="predictive", eval_times="grid")
    assert _row(res_p, "last", "o", "r").metrics["mae"] == pytest.approx((0.5 * 1 + 1 * 2) / 7)


def test_observation_times_off_grid_are_scored_against_the_step_ground_truth():
    train = [EdgeStream(("o", "r"), [0.0], [1])]
    test = [EdgeStream(("o", "r"), [4.0], [1])]
    gt = {("o", "r"): (np.array([2.0, 6.0]), np.array([1, 0]))}
    res = evaluate_persistence({"c": const_factory}, train, test, gt, eval_times="observations+grid")
    r = _row(res, "c", "o", "r")
    # times 2, 4, 6 with truth 1, 1, 0 and belief 0.3: |err| 0.7, 0.7, 0.3 -> (1.4 + 1.0) / 4
    assert r.n_points == 3 and r.span_s == 4.0
    assert r.metrics["mae"] == pytest.approx(2.4 / 4)
    assert r.metrics["sample_mae"] == pytest.approx(1.7 / 3)
    res_g = evaluate_persistence({"c": const_factory}, train, test, gt, eval_times="grid")
    assert _row(res_g, "c", "o", "r").n_points == 2


def test_nan_plugin_is_reported_with_edge_and_time_while_others_complete():
    train, test, gt = make_world()
    res = evaluate_persistence({"nanny": nan_factory, "last": last_factory}, train, test, gt, setting="adaptive",
                               seeds=(0,))
    assert not res.ok
    (issue,) = res.errors
    t_bad = T0 + 7 * 24 * H + 30 * H
    assert (issue.estimator, issue.object_id, issue.receptacle_id, issue.stage) == ("nanny", "bad", "desk", "prediction")
    assert issue.t_s == t_bad
    assert "'bad'" in issue.message and "NaN" in issue.message and repr(t_bad) in issue.message
    assert _row(res, "nanny", "bad", "desk").status == "error"
    assert all(r.status == "ok" for r in res.edges if not (r.estimator == "nanny" and r.object_id == "bad"))
    assert res.summary["last"]["mae"].mean == 0.0
    # the failed edge is left out of the aggregate, which stays finite
    assert np.isfinite(res.summary["nanny"]["mae"].mean)
    assert res.seed_scores()["nanny"][0]["n_edges_error"] == 1
    json.dumps(res.to_dict(), allow_nan=False)


@pytest.mark.parametrize(
    ("mode", "stage", "match"),
    [("big", "prediction", r"1\.5 outside \[0, 1\]"), ("raise", "predict", "RuntimeError: boom"),
     ("fitfail", "fit", "fit raised ValueError: cannot fit this")],
)
def test_other_plugin_failures_are_recorded(mode, stage, match):
    train, test, gt = make_world()
    res = evaluate_persistence({mode: lambda random_state=None: Toy(mode=mode, random_state=random_state),
                                "last": last_factory}, train, test, gt, seeds=(0,))
    assert not res.ok
    assert {e.stage for e in res.errors} == {stage}
    assert all(e.estimator == mode for e in res.errors)
    assert any(re.search(match, e.message) for e in res.errors)
    n_err = sum(r.status == "error" for r in res.edges)
    assert n_err == (4 if mode == "fitfail" else 1)
    assert all(r.status == "ok" for r in res.edges if r.estimator == "last")


def test_empty_test_split_and_bad_settings_raise():
    train, test, gt = make_world()
    empty = [EdgeStream(s.edge, s.t_s[:0], s.y[:0]) for s in test]
    with pytest.raises(EvaluationError, match="test split is empty: 4 test streams with 0 observations"):
        evaluate_persistence({"last": last_factory}, train, empty, gt)
    with pytest.raises(EvaluationError, match="test split is empty: 0 test streams"):
        evaluate_persistence({"last": last_factory}, train, [], gt)
    with pytest.raises(EvaluationError, match="ground truth is empty"):
        evaluate_persistence({"last": last_factory}, train, test, {})
    with pytest.raises(EvaluationError, match="setting must be"):
        evaluate_persistence({"last": last_factory}, train, test, gt, setting="online")  # type: ignore[arg-type]
    with pytest.raises(EvaluationError, match="unknown timezone 'Mars/Olympus'"):
        evaluate_persistence({"last": last_factory}, train, test, gt, timezone="Mars/Olympus")
    with pytest.raises(EvaluationError, match="no estimator given"):
        evaluate_persistence({}, train, test, gt)
    with pytest.raises(EvaluationError, match="seeds is empty"):
        evaluate_persistence({"last": last_factory}, train, test, gt, seeds=())
    with pytest.raises(EvaluationError, match=r"ground_truth \('o', 'r'\): y_true\[0\] = 3"):
        evaluate_persistence({"last": last_factory}, train, test, {("o", "r"): ([0.0, 1.0], [3, 1])})


def test_privileged_codes_in_ground_truth_are_excluded():
    train = [EdgeStream(("o", "r"), [0.0], [1])]
    test = [EdgeStream(("o", "r"), [1.0], [1])]
    gt = {("o", "r"): (np.array([0.0, 1.0, 2.0, 3.0]), np.array([1, 1, -1, 0]))}
    res = evaluate_persistence({"c": const_factory}, train, test, gt, eval_times="grid")
    r = _row(res, "c", "o", "r")
    assert r.n_points == 3 and r.span_s == 1.0  # only [0, 1] has two valid end points
    assert r.metrics["mae"] == pytest.approx(0.7)
    assert r.metrics["sample_mae"] == pytest.approx((0.7 + 0.7 + 0.3) / 3)


def test_seeds_give_mean_and_std_and_breakdowns():
    train, test, gt = make_world()
    seeds = (0, 1, 2)
    res = evaluate_persistence({"c": const_factory}, train, test, gt, seeds=seeds, timezone="Europe/Zurich")
    frame = res.to_frame()
    assert len(frame) == 3 * 4
    per_seed = []
    for s in seeds:
        f = frame[frame.seed == s]
        per_seed.append(np.average(f["mae"], weights=f["span_s"]))
    summ = res.summary["c"]["mae"]
    assert (summ.n, summ.method, summ.unit) == (3, "jackknife-t", "objects")  # 3 objects (< 10: no bootstrap)
    assert summ.mean == pytest.approx(np.mean(per_seed))
    assert summ.std == pytest.approx(np.std(per_seed, ddof=1))
    assert summ.std > 0  # the toy prediction depends on random_state
    assert summ.ci_low <= summ.mean <= summ.ci_high
    # per object: span-weighted over that object's edges, then mean over seeds
    by_obj = res.breakdown("object")
    mug = by_obj[(by_obj.object == "mug") & (by_obj.metric == "mae")].iloc[0]
    exp = [np.average(f["mae"], weights=f["span_s"]) for _, f in frame[frame.object_id == "mug"].groupby("seed")]
    assert mug["mean"] == pytest.approx(np.mean(exp)) and mug["n"] == 1 and mug["std"] > 0
    by_rec = res.breakdown("receptacle")
    assert set(by_rec.receptacle) == {"table", "shelf", "desk"}
    # weekday rows split each edge's span over the 7 local days
    wf = res.weekday_frame()
    assert set(wf.weekday_name) == {"Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun"}
    sums = wf.groupby(["seed", "object_id", "receptacle_id"])["span_s"].sum()
    spans = frame.set_index(["seed", "object_id", "receptacle_id"])["span_s"]
    pd.testing.assert_series_equal(sums.sort_index(), spans.sort_index(), check_names=False)
    assert len(res.breakdown("weekday")) == 7 * len(TIME_METRICS) * 2
    sf = res.summary_frame()
    assert set(sf.columns) == {"estimator", "metric", "mean", "std", "ci_low", "ci_high", "n", "method", "unit"}
    json.dumps(res.to_dict(), allow_nan=False)


def test_weekday_uses_the_local_timezone():
    # 2024-01-07 22:00 UTC is Sunday 23:00 in Zurich; 23:30 UTC is Monday 00:30 there
    t = np.array([1704664800.0, 1704670200.0])
    train = [EdgeStream(("o", "r"), [t[0] - 10], [1])]
    test = [EdgeStream(("o", "r"), [t[0]], [1])]
    gt = {("o", "r"): (t, np.array([1, 1]))}
    res = evaluate_persistence({"c": const_factory}, train, test, gt, timezone="Europe/Zurich", seeds=(0,))
    assert sorted(r.weekday for r in res.weekdays) == [0, 6]
    res_utc = evaluate_persistence({"c": const_factory}, train, test, gt, timezone="UTC", seeds=(0,))
    assert sorted(r.weekday for r in res_utc.weekdays) == [6]


def test_progress_is_reported():
    train, test, gt = make_world()
    calls = []
    evaluate_persistence({"c": const_factory, "last": last_factory}, train, test, gt, seeds=(0, 1),
                         progress=lambda d, n: calls.append((d, n)))
    assert calls[-1] == (16, 16)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


def test_jobs_2_equals_jobs_1():
    train, test, gt = make_world()
    ests = {"c": const_factory, "last": last_factory, "nanny": nan_factory}
    kw = dict(setting="adaptive", seeds=(0, 1), timezone="Europe/Zurich")
    calls = []
    r1 = evaluate_persistence(ests, train, test, gt, jobs=1, **kw)
    r2 = evaluate_persistence(ests, train, test, gt, jobs=2, progress=lambda d, n: calls.append(d), **kw)
    pd.testing.assert_frame_equal(r1.to_frame(), r2.to_frame())
    pd.testing.assert_frame_equal(r1.weekday_frame(), r2.weekday_frame())
    assert r1.errors == r2.errors
    assert r1.to_dict() == r2.to_dict()
    assert calls[-1] == 3 * 2 * 4


def test_unpicklable_factory_with_jobs_2_is_a_clear_error():
    train, test, gt = make_world()
    with pytest.raises(EvaluationError, match="use jobs=1"):
        evaluate_persistence({"l": lambda random_state=None: Toy(random_state=random_state)}, train, test, gt, jobs=2)


class _NoSeedToy(Toy):
    def __init__(self, *, value: float = 0.25) -> None:
        super().__init__(mode="const", value=value)

    def get_params(self) -> dict[str, Any]:
        return {"value": self.value}


def test_registry_names_pass_random_state_only_when_accepted(monkeypatch):
    import psg_data.estimators as registry

    made = []

    def fake_get_estimator(name, **settings):
        made.append((name, settings))
        return Toy(mode="const", value=0.3, **settings) if name == "seeded" else _NoSeedToy(**settings)

    monkeypatch.setattr(registry, "get_estimator", fake_get_estimator, raising=False)
    train, test, gt = make_world()
    res = evaluate_persistence(["seeded", "plain"], train, test, gt, seeds=(0, 3))
    assert res.ok
    assert ("seeded", {"random_state": 3}) in made
    assert all(s == {} for n, s in made if n == "plain")
    assert _row(res, "seeded", "mug", "table", seed=3).metrics["sample_mae"] != _row(res, "seeded", "mug", "table", seed=0).metrics["sample_mae"]
    # a fit that does not depend on the seed is made once, whatever the seeds
    assert res.config["estimator_seeds"] == {"seeded": [0, 3], "plain": [0]}
    assert res.summary["plain"]["mae"].std == 0.0 and res.summary["seeded"]["mae"].std > 0
    assert res.config["estimator_params"]["plain"] == {"value": 0.25}


def test_chance_note_states_only_a_measured_balanced_accuracy():
    """Without the always_absent row the table's B-Acc chance is unknown (it depends on the edges that
    hold one state only) and is not printed; with it, its measured value is."""
    from psg_data.evaluation._report import persistence_results

    train, test, gt = make_world()
    without = persistence_results(evaluate_persistence(["last_seen"], train, test, gt)).table()
    note = next(n for n in without.notes if n.startswith("B-Acc"))
    assert "chance" not in note
    res = evaluate_persistence(["last_seen", "always_absent"], train, test, gt)
    note = next(n for n in persistence_results(res).table().notes if n.startswith("B-Acc"))
    assert f"chance: always_absent {res.summary['always_absent']['balanced_accuracy'].mean:.3f}" in note
