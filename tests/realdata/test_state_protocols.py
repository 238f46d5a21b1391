"""The real benchmarks' protocols and reference rows, each against an independent computation."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.estimators import EdgeStream, get_estimator
from psg_data.evaluation._hints import EstimatorSpec
from psg_data.evaluation._state_benchmark import (
    HINDSIGHT,
    StateRunOptions,
    _locate,
    run_state_benchmark,
    state_rows,
    summarize_state_run,
)
from psg_data.evaluation._state_protocols import PatrolPlan, patrol_streams
from psg_data.loaders.raw import read_door_benchmark, read_room_presence_benchmark
from tests.realdata._layout import MONDAY, door_states, write_door, write_rooms


def _authors_fremen(t: np.ndarray, y: np.ndarray, order: int, elements: int = 84, max_period: float = 604800.0):
    """framework2's FreMEn.hs written out: absolute times, periods max/k, the ``order`` largest amplitudes."""
    g = y.mean()
    periods = max_period / np.arange(1, elements + 1)
    ang = 2 * np.pi * t[:, None] / periods[None, :]
    re = (y[:, None] * np.cos(ang)).sum(0) - g * np.cos(ang).sum(0)
    im = (y[:, None] * np.sin(ang)).sum(0) - g * np.sin(ang).sum(0)
    amp = 2 * np.sqrt(re ** 2 + im ** 2) / t.size
    ph = np.arctan2(im, re)
    top = np.argsort(-amp, kind="stable")[:order]

    def predict(tt: np.ndarray) -> np.ndarray:
        p = g + (amp[top] * np.cos(2 * np.pi * tt[:, None] / periods[top] - ph[top])).sum(1)
        return np.clip(p, 0.0, 1.0)  # their trimmer 0 1
    return predict


def test_fremen_train_mse_is_the_authors_fremen() -> None:
    rng = np.random.default_rng(3)
    t = (MONDAY + 600 * np.arange(3 * 7 * 144)).astype(np.float64)
    y = door_states(t, rng, flip=0.1).astype(np.int8)
    s = EdgeStream(("door", "open"), t, y)
    est = get_estimator("fremen", n_periods=84, max_order=5, order_rule="train_mse").fit([s], timezone="UTC")
    errs = [np.mean((_authors_fremen(t, y.astype(float), k)(t) - y) ** 2) for k in range(1, 6)]
    order = 1 + int(np.argmin(errs))
    assert est.fit_info_[("door", "open")]["order"] == order
    tt = MONDAY + 5 * 7 * 86400 + 60.0 * np.arange(7 * 1440)
    f = est.make_filter(("door", "open"))
    np.testing.assert_allclose(f.predict(tt), _authors_fremen(t, y.astype(float), order)(tt), atol=1e-9)


def test_hist_and_mean_brute_force() -> None:
    rng = np.random.default_rng(1)
    t = (MONDAY + 60 * np.sort(rng.choice(14 * 1440, 3000, replace=False))).astype(np.float64)
    y = door_states(t, rng, flip=0.2).astype(np.int8)
    s = EdgeStream(("d", "open"), t, y)
    mean = get_estimator("training_mean").fit([s]).make_filter(("d", "open"))
    assert mean.predict(np.array([t[0] + 1e5]))[0] == pytest.approx(y.mean())
    best = None
    for nb in (3, 4, 6, 12, 24):
        b = ((t % 86400) // (86400 / nb)).astype(int)
        means = [y[b == i].mean() if np.any(b == i) else 0.0 for i in range(nb)]
        err = np.mean([(means[bi] - yi) ** 2 for bi, yi in zip(b, y)])
        if best is None or err < best[0]:
            best = (err, nb, means)
    hist = get_estimator("time_of_day_histogram").fit([s])
    q = MONDAY + 86400 * 30 + np.arange(0, 86400, 1800.0)
    expect = [best[2][int((x % 86400) // (86400 / best[1]))] for x in q]
    np.testing.assert_allclose(hist.make_filter(("d", "open")).predict(q), expect, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 6), st.integers(1, 40))
def test_locate_brute_force(seed: int, k: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    b = rng.random((n, k)).round(1)  # ties on purpose: the listed order breaks them
    true = rng.integers(0, k, n)
    y = np.zeros((n, k), np.int64)
    y[np.arange(n), true] = 1

    class Tr:
        def __init__(self, bel: np.ndarray, tr: np.ndarray) -> None:
            self.belief, self.truth = bel, tr
    top1, top3 = _locate([Tr(b[:, j], y[:, j]) for j in range(k)])
    ranks = [sorted(range(k), key=lambda j: (-b[i, j], j)).index(true[i]) for i in range(n)]
    assert top1 == pytest.approx(np.mean([r < 1 for r in ranks]))
    assert top3 == pytest.approx(np.mean([r < 3 for r in ranks]))


def test_patrol_flips_and_door_complement() -> None:
    t = MONDAY + 60.0 * np.arange(40 * 1440)
    y = (((t % 86400) // 3600).astype(int) % 2).astype(np.int64)  # odd hours present
    plan = PatrolPlan(8, 18, 1, p_m=0.2, p_f=0.1, seed=5)
    rows = {("d", "open"): (t, y), ("d", "closed"): (t, 1 - y)}
    s_open, s_closed = patrol_streams(rows, plan, "UTC", complement=True)
    np.testing.assert_array_equal(s_closed.y, 1 - s_open.y)
    truth = y[np.searchsorted(t, s_open.t_s)]
    assert len(s_open) == 40 * 11
    assert np.mean(s_open.y[truth == 1] == 0) == pytest.approx(0.2, abs=0.06)
    assert np.mean(s_open.y[truth == 0] == 1) == pytest.approx(0.1, abs=0.05)
    again = patrol_streams(rows, plan, "UTC", complement=True)[0]
    np.testing.assert_array_equal(again.y, s_open.y)


def test_patrol_plan_parse() -> None:
    p = PatrolPlan.parse("8-18/30min")
    assert p.hours[0] == 8 and p.hours[-1] == 18 and p.hours.size == 21
    for bad in ("9-17", "17-9/2h", "9-17/0h", "9-25/1h"):
        with pytest.raises(Exception, match="patrol"):
            PatrolPlan.parse(bad)


def _run(bench, protocol: str, specs=()):
    """The reference rows (Perpetua, slow on minute rows and checked elsewhere, left out)."""
    rows = [r for r in state_rows([EstimatorSpec.of(s) for s in specs]) if r.label != "perpetua"]
    opts = StateRunOptions(protocol=protocol)
    run = run_state_benchmark(bench, rows, opts)
    return run, rows, summarize_state_run(run, rows, one_hot=bench.one_hot)


def test_published_door_protocol_mse_and_hindsight(tmp_path: Path) -> None:
    write_door(tmp_path, train_weeks=2, test_weeks=2)
    b = read_door_benchmark(tmp_path)
    run, rows, s = _run(b, "published")
    assert not run.errors
    # mean: the training base rate; its MSE per week is mean((rate - y)^2) over the week's rows
    rate = b.train[("door", "open")][1].mean()
    for k, p in enumerate(b.periods):
        y = p.truth[("door", "open")][1]
        assert run.values["mean"][k]["mse"] == pytest.approx(np.mean((rate - y[y >= 0]) ** 2), rel=1e-12)
        assert run.values["always_absent"][k]["mse"] == pytest.approx(np.mean(y[y >= 0]), rel=1e-12)
    # hindsight: time_of_week_frequency fitted on the scored week itself
    p = b.periods[1]
    t, y = p.truth[("door", "open")]
    tow = get_estimator("time_of_week_frequency").fit([EdgeStream(("door", "open"), t, y.astype(np.int8))])
    pred = tow.make_filter(("door", "open")).predict(t)
    assert run.values[HINDSIGHT][1]["mse"] == pytest.approx(np.mean((pred - y) ** 2), rel=1e-12)
    h = s["headroom"]["mse"]
    base = {r.label: s["summary"][r.label]["mse"]["mean"] for r in rows if r.role == "baseline"}
    assert h["best_baseline_value"] == min(base.values())
    assert h["headroom"] == pytest.approx(min(base.values()) - s["summary"][HINDSIGHT]["mse"]["mean"])
    m = np.array([v["mse"] for v in run.values["mean"]])
    assert s["summary"]["mean"]["mse"]["half_width"] == pytest.approx(
        12.706204736 * np.std(m, ddof=1) / math.sqrt(2), rel=1e-6)  # t(0.975, 1 dof)


def test_paired_comparison_is_the_paired_t(tmp_path: Path) -> None:
    write_door(tmp_path, train_weeks=2, test_weeks=3)
    run, rows, s = _run(read_door_benchmark(tmp_path), "published")
    c = next(c for c in s["comparisons"] if {c["a"], c["b"]} == {"mean", "hist"})
    d = np.array([v["mse"] for v in run.values[c["a"]]]) - np.array([v["mse"] for v in run.values[c["b"]]])
    assert c["t"] == pytest.approx(d.mean() / (d.std(ddof=1) / math.sqrt(d.size)), rel=1e-9)


def test_patrol_protocol_adapts_and_scores_patrol_hours(tmp_path: Path) -> None:
    write_door(tmp_path, train_weeks=2, test_weeks=2)
    b = read_door_benchmark(tmp_path)
    from psg_data.evaluation._windows import DailyWindows

    win = DailyWindows(((9.0, 17.0),), "UTC")
    opts = StateRunOptions(protocol="patrol", windows=win)
    rows = state_rows([], references=True)
    rows = [r for r in rows if r.label in ("last_seen", "always_absent")]
    run = run_state_benchmark(b, rows, opts)
    t, y = b.periods[0].truth[("door", "open")]
    inside = win.contains(t) & (y >= 0)
    assert run.values["always_absent"][0]["mse"] == pytest.approx(np.mean(y[inside]), rel=1e-12)
    # last_seen at t holds the last patrol observation at or before t - 2 h (the horizon)
    plan = PatrolPlan()
    s = patrol_streams({("door", "open"): (t, y)}, plan, "UTC", salt=1)[0]
    hist = patrol_streams(b.train, plan, "UTC", complement=True)[0]
    ot, oy = np.r_[hist.t_s, s.t_s], np.r_[hist.y, s.y]
    last = np.array([oy[ot <= x - 7200][-1] for x in t[inside]], float)
    assert run.values["last_seen"][0]["mse"] == pytest.approx(np.mean((last - y[inside]) ** 2), rel=1e-12)


def test_room_presence_locate(tmp_path: Path) -> None:
    write_rooms(tmp_path, weeks=4)
    b = read_room_presence_benchmark(tmp_path, train_weeks=2)
    run, rows, s = _run(b, "published")
    assert "top1" in s["metrics"] and not run.errors
    # hindsight ranks the usual room first almost always; always_absent's ties fall back to the listed order
    assert s["summary"][HINDSIGHT]["top1"]["mean"] > 0.9
    first_room = np.mean([np.mean(p.truth[b.edges[0]][1] == 1) for p in b.periods])
    assert s["summary"]["always_absent"]["top1"]["mean"] == pytest.approx(first_room)


def test_history_applied_once_equals_per_period(tmp_path: Path) -> None:
    """Filters built once with the history and copied per period score as filters built per period do."""
    from psg_data.evaluation._edge_run import run_edge
    from psg_data.evaluation._state_protocols import edge_jobs, score_config

    write_door(tmp_path, train_weeks=2, test_weeks=2)
    b = read_door_benchmark(tmp_path)
    rows = [r for r in state_rows([EstimatorSpec.of("perpetua")], references=False)]
    run = run_state_benchmark(b, rows, StateRunOptions(protocol="patrol", seeds=(0,)))
    plan = PatrolPlan()
    train = patrol_streams(b.train, plan, "UTC", complement=True)
    est = get_estimator("perpetua", random_state=0).fit(train, timezone="UTC")
    for k, p in enumerate(b.periods):
        test = {s.edge: s for s in patrol_streams(p.truth, plan, "UTC", complement=True, salt=k + 1)}
        job = edge_jobs(p.truth, b.scored, {s.edge: s for s in train}, test, k, "UTC")[0]
        res, _, issues, trace = run_edge("perpetua", 0, est, job, score_config("adaptive", 7200.0))
        assert not issues
        valid = trace.truth >= 0
        assert run.values["perpetua"][k]["mse"] == pytest.approx(
            np.mean((trace.belief[valid] - trace.truth[valid]) ** 2), rel=1e-12)
        assert run.values["perpetua"][k]["balanced_accuracy"] == pytest.approx(res.metrics["balanced_accuracy"])
