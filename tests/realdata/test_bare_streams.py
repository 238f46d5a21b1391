"""Scoring bare streams as a researcher does from Python (issue 42, point 6): the fixes and the README path."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import EvaluationError
from psg_data.evaluation import evaluate_persistence, evaluate_state_benchmark
from psg_data.loaders.raw import StateBenchmark, StatePeriod
from psg_data.schemas import EdgeStream
from tests.realdata._layout import MONDAY, door_states

E = ("door", "open")


def _streams(seed: int = 0) -> tuple[EdgeStream, dict]:
    rng = np.random.default_rng(seed)
    t = (MONDAY + 60 * np.arange(14 * 1440)).astype(np.float64)
    train = EdgeStream(E, t, door_states(t, rng).astype(np.int8))
    tt = t[-1] + 60.0 * np.arange(1, 7 * 1440 + 1)
    return train, {E: (tt, door_states(tt, rng))}


def test_predictive_needs_no_test_observation() -> None:
    train, gt = _streams()
    res = evaluate_persistence(["training_mean"], [train], [], gt, setting="predictive", seeds=(0,))
    assert res.ok
    t, y = gt[E]
    rate = train.y.mean()
    # the time-integrated MAE of a constant: its trapezoid mean |rate - y|
    w = np.r_[np.diff(t) / 2, 0] + np.r_[0, np.diff(t) / 2]
    assert res.edges[0].metrics["mae"] == pytest.approx(np.sum(w * np.abs(rate - y)) / w.sum(), rel=1e-12)
    with pytest.raises(EvaluationError, match="test split is empty"):
        evaluate_persistence(["training_mean"], [train], [], gt, setting="adaptive")


def test_overlapping_periods_merge_equal_repeats_and_refuse_conflicts() -> None:
    train, gt = _streams()
    t, y = gt[E]
    twice = {E: (np.r_[t, t[-1440:]], np.r_[y, y[-1440:]])}  # a repeated day, as door test weeks 4 and 5
    a = evaluate_persistence(["training_mean"], [train], [], twice, setting="predictive", seeds=(0,))
    b = evaluate_persistence(["training_mean"], [train], [], gt, setting="predictive", seeds=(0,))
    assert a.edges[0].metrics == b.edges[0].metrics
    clash = {E: (np.r_[t, t[-1:]], np.r_[y, 1 - y[-1:]])}
    with pytest.raises(EvaluationError, match="appears twice with states"):
        evaluate_persistence(["training_mean"], [train], [], clash, setting="predictive")


def test_per_period_scores_from_bare_streams() -> None:
    """The README example: your own streams as a StateBenchmark, scored per period."""
    train, gt = _streams()
    t, y = gt[E]
    half = t.size // 2
    periods = (StatePeriod("first half", {E: (t[:half], y[:half])}, "mine", half),
               StatePeriod("second half", {E: (t[half:], y[half:])}, "mine", t.size - half))
    bench = StateBenchmark("my-door", (E,), (E,), {E: (train.t_s, train.y)}, periods, "UTC")
    doc = evaluate_state_benchmark(bench, ["training_mean", "fremen"], references=False)
    rows = {r["label"]: r for r in doc["rows"]}
    assert list(rows) == ["training_mean", "fremen"]
    rate = train.y.mean()
    for k, sl in enumerate((slice(0, half), slice(half, None))):
        assert rows["training_mean"]["per_period"][k]["mse"] == pytest.approx(np.mean((rate - y[sl]) ** 2))
    m = rows["training_mean"]["summary"]["mse"]
    assert m["mean"] == pytest.approx(np.mean([p["mse"] for p in rows["training_mean"]["per_period"]]))
