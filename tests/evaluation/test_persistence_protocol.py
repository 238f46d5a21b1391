"""The persistence protocol's new settings: forecast horizon, scoring windows, seeds per estimator, lab draws."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import EvaluationError
from psg_data.estimators._base import EdgeStream
from psg_data.evaluation import (
    EstimatorSpec,
    PersistenceOptions,
    PersistenceTask,
    evaluate_persistence,
    persistence_task_from_benchmark,
    persistence_task_from_dataset,
    persistence_task_from_lab,
    run_persistence_task,
)
from psg_data.evaluation._persistence_job import run_lab_draws
from psg_data.synth import LabConfig, build_lab

H = 3600.0
T0 = 1704067200.0  # Monday 2024-01-01 00:00 UTC
SMALL = LabConfig(seed=5, days=4, train_days=3, frames_per_scan=1, width=40, height=30)


def _streams() -> tuple[list[EdgeStream], list[EdgeStream], dict]:
    """One edge observed every 3 h; its state flips at every observation (so a stale belief is wrong)."""
    obs = T0 + np.arange(0, 48, 3) * H
    y = (np.arange(obs.size) % 2).astype(np.int8)
    split = T0 + 24 * H
    tr, te = obs < split, obs >= split
    grid = T0 + 24 * H + np.arange(0, 24) * H
    gt = y[np.searchsorted(obs, grid, side="right") - 1]
    return [EdgeStream(("o", "r"), obs[tr], y[tr])], [EdgeStream(("o", "r"), obs[te], y[te])], {("o", "r"): (grid, gt)}


@pytest.mark.parametrize("h", [0.0, 3 * H, 5 * H])
def test_a_prediction_uses_exactly_the_observations_up_to_t_minus_the_horizon(h: float) -> None:
    train, test, gt = _streams()
    res = evaluate_persistence(["last_seen"], train, test, gt, horizon=h, eval_times="grid", keep_predictions=[("o", "r")])
    (tr,) = res.traces
    obs_t = np.concatenate([train[0].t_s, test[0].t_s])
    obs_y = np.concatenate([train[0].y, test[0].y])
    for t, b in zip(tr.t_s, tr.belief):
        usable = obs_t[(obs_t <= t - h) | (obs_t < test[0].t_s[0])]  # the history is always applied
        want = float(obs_y[np.flatnonzero(obs_t == usable.max())[0]])
        assert b == want, (t, h)
    assert res.config["horizon"] == h


def test_horizon_breakdown_bins_follow_the_horizon() -> None:
    train, test, gt = _streams()
    res = evaluate_persistence(["last_seen"], train, test, gt, horizon="3h", eval_times="grid", seeds=(0,))
    keys = {r.key for r in res.breakdown_rows if r.by == "horizon"}
    assert keys == {"2-12 h"}  # every prediction is 3-5 h after the observation it used
    res0 = evaluate_persistence(["last_seen"], train, test, gt, horizon=0, eval_times="grid", seeds=(0,))
    assert {r.key for r in res0.breakdown_rows if r.by == "horizon"} == {"< 2 h", "2-12 h"}
    pred = evaluate_persistence(["last_seen"], train, test, gt, setting="predictive", eval_times="grid", seeds=(0,))
    assert {r.key for r in pred.breakdown_rows if r.by == "horizon"} == {"2-12 h", "12-48 h"}


def test_options_resolve_from_the_task() -> None:
    train, test, gt = _streams()
    bare = PersistenceTask("t", train, test, gt, "UTC")
    r = PersistenceOptions().resolve(bare)
    assert (r.horizon, r.weighting, r.windows, r.setting) == (0.0, "reference", "none", "adaptive")
    bench = PersistenceOptions().resolve(persistence_task_from_benchmark(0))
    assert (bench.horizon, bench.weighting) == (0.0, "reference")  # the paper's protocol
    w = PersistenceOptions(windows="9-17").resolve(bare)
    assert w.weighting == "windows" and w.windows.hours == ((9.0, 17.0),)
    with pytest.raises(EvaluationError, match="needs scoring windows"):
        PersistenceOptions(weighting="windows").resolve(bare)
    with pytest.raises(EvaluationError, match="horizon"):
        PersistenceOptions(horizon="soon")
    with pytest.raises(EvaluationError, match="unknown settings"):
        PersistenceOptions().replace(horizn=2)


@pytest.fixture(scope="module")
def small_lab(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    return build_lab(tmp_path_factory.mktemp("proto") / "lab", SMALL)


def test_the_lab_task_without_images_equals_the_dataset_task(small_lab) -> None:  # type: ignore[no-untyped-def]
    a = persistence_task_from_dataset(small_lab)
    b = persistence_task_from_lab(SMALL)
    assert set(a.ground_truth) == set(b.ground_truth)
    for e, (t, y) in a.ground_truth.items():
        np.testing.assert_array_equal(t, b.ground_truth[e][0])
        np.testing.assert_array_equal(y, b.ground_truth[e][1])
    for sa, sb in ((a.train_streams, b.train_streams), (a.test_streams, b.test_streams)):
        by = {s.edge: s for s in sb}
        for s in sa:
            np.testing.assert_array_equal(s.t_s, by[s.edge].t_s)
            np.testing.assert_array_equal(s.y, by[s.edge].y)
    assert a.windows == b.windows and a.windows.hours == ((9.0, 17.0),) and a.cadence_s == b.cadence_s == 2 * H
    # the dense truth lies inside the scoring windows (both ends included) and nights get no weight
    t = next(iter(a.ground_truth.values()))[0]
    assert (a.windows.contains(t) | a.windows.contains(t - 1e-3)).all()


def test_noisy_labels_flip_the_ground_truth_as_navigation_does(small_lab) -> None:  # type: ignore[no-untyped-def]
    from psg_data.loaders import open_dataset
    from psg_data.navigation import source_observations

    task = persistence_task_from_dataset(small_lab, labels="noisy:0.3")
    ds = open_dataset(small_lab)
    map_ids = ds.df("scans").query("split == 'train'")["scan_id"].tolist()
    nav = {s.edge: s for s in source_observations(ds, "noisy:0.3", map_ids).object_streams}
    exact = {s.edge: s for s in persistence_task_from_dataset(small_lab).train_streams}
    flipped = 0
    for s in task.train_streams:  # one observation per scan and edge, the same flips in both tasks
        np.testing.assert_array_equal(s.t_s, exact[s.edge].t_s)
        flipped += int(np.sum(s.y != exact[s.edge].y))
        if s.edge in nav:
            np.testing.assert_array_equal(s.y, nav[s.edge].y)
    assert flipped > 0


def test_seeds_auto_fits_seed_dependent_estimators_three_times(small_lab) -> None:  # type: ignore[no-untyped-def]
    task = persistence_task_from_dataset(small_lab)
    res = run_persistence_task(["last_seen", "perpetua"], task)
    assert res.config["estimator_seeds"] == {"last_seen": [0], "perpetua": [0, 1, 2]}
    s = res.summary["perpetua"]["balanced_accuracy"]
    assert s.unit == "objects" and s.method in ("bootstrap", "jackknife-t")


def test_lab_draws_through_the_executor_give_a_t_interval() -> None:
    from psg_data._executors import open_executor

    specs = [EstimatorSpec.of("last_seen"), EstimatorSpec.of("always_absent")]
    inline, _ = run_lab_draws("lab", [0, 1], "gt", specs, PersistenceOptions())
    with open_executor(2) as ex:
        pooled, first = run_lab_draws("lab", [0, 1], "gt", specs, PersistenceOptions(), executor=ex)
    s = pooled.summary["last_seen"]["balanced_accuracy"]
    assert (s.method, s.unit, s.n) == ("t", "lab draws", 2)
    assert pooled.to_frame().equals(inline.to_frame())
    per_draw = [pooled.summary_frame()]  # two labs, two different layouts: their estimates differ
    assert per_draw and pooled.config["draws"] == [0, 1] and first.draw == 0 and first.name == "lab seed 0"
