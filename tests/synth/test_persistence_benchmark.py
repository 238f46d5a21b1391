"""The Sec. V-A persistence benchmark: layout, determinism, the long-weekend shift, paper ordering."""

from __future__ import annotations

import numpy as np
import pytest

from psg_data.errors import PsgDataError
from psg_data.estimators import get_estimator
from psg_data.estimators._fremen import wall_seconds
from psg_data.synth.persistence_benchmark import make_persistence_benchmark


def _local_weekday(t: np.ndarray, tz: str) -> np.ndarray:
    days = np.floor(wall_seconds(t, tz) / 86400).astype(np.int64)
    return (days + 3) % 7  # 0 = Monday


def test_layout_and_determinism() -> None:
    a = make_persistence_benchmark(seed=3)
    b = make_persistence_benchmark(seed=3)
    c = make_persistence_benchmark(seed=4)
    assert len(a.train_streams) == len(a.test_streams) == len(a.val_streams) == 8
    for s, t in zip(a.train_streams, b.train_streams):
        np.testing.assert_array_equal(s.t_s, t.t_s)
        np.testing.assert_array_equal(s.y, t.y)
    assert not np.array_equal(a.train_streams[0].t_s, c.train_streams[0].t_s)
    # val week, four training weeks, test week, in this order
    assert a.train_start_s - a.start_s == pytest.approx(7 * 86400)
    assert a.test_start_s - a.train_start_s == pytest.approx(28 * 86400)
    for s in a.train_streams:
        assert s.t_s.min() >= a.train_start_s and s.t_s.max() < a.test_start_s
    for s in a.val_streams:
        assert s.t_s.max() < a.train_start_s
    gaps = np.diff(a.train_streams[0].t_s)
    assert gaps.min() >= 600 - 1e-6 and np.median(gaps) < 1800 and gaps.max() > 2 * 3600  # cadence + gaps
    # noise rates close to P_M = P_F = 0.1
    errs, n = 0, 0
    for s in a.train_streams:
        gt_t, gt_x = a.train_truth[s.edge]
        x = gt_x[np.searchsorted(gt_t, s.t_s, side="right") - 1]
        errs += int(np.sum(x != s.y))
        n += s.y.size
    assert errs / n == pytest.approx(0.1, abs=0.02)
    static = [e for e in a.edges if a.train_truth[e][1].min() == 1]
    assert len(static) == 4


def test_shift_changes_exactly_monday_and_friday() -> None:
    shifted = make_persistence_benchmark(seed=1, shift="long-weekend")
    normal = make_persistence_benchmark(seed=1, shift=None)
    changed_days: set[int] = set()
    for e in shifted.edges:
        t, xs = shifted.test_truth[e]
        _, xn = normal.test_truth[e]
        diff = xs != xn
        changed_days |= set(_local_weekday(t[diff], shifted.timezone).tolist())
        np.testing.assert_array_equal(shifted.train_truth[e][1], normal.train_truth[e][1])
    assert changed_days == {0, 4}
    for a, b in zip(shifted.test_streams, normal.test_streams):
        np.testing.assert_array_equal(a.t_s, b.t_s)  # same observation times
    # the shifted Monday equals the (shifted) Saturday pattern for the laptop (absent all weekend day)
    t, x = shifted.test_truth[("laptop", "desk")]
    wd = _local_weekday(t, shifted.timezone)
    assert x[wd == 0].max() == 0 and x[wd == 4].max() == 0 and x[wd == 2].max() == 1
    with pytest.raises(PsgDataError, match="shift"):
        make_persistence_benchmark(shift="holiday")


def _mae(gt_t: np.ndarray, gt_x: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Reference MAE: trapezoid integral of |x - b| over the truth grid / span (b thresholded at 0.5)."""
    err = np.abs(gt_x - (b >= 0.5))
    span = gt_t[-1] - gt_t[0]
    return float(np.sum(0.5 * (err[1:] + err[:-1]) * np.diff(gt_t)) / span), float(span)


def _score(name: str, bench, **settings) -> float:
    est = get_estimator(name, **settings).fit(bench.train_streams, val_streams=bench.val_streams,
                                              timezone=bench.timezone)
    total = weight = 0.0
    for tr, te in zip(bench.train_streams, bench.test_streams):
        f = est.make_filter(tr.edge)
        f.update_many(tr.t_s, tr.y)
        gt_t, gt_x = bench.test_truth[tr.edge]
        b = np.empty(gt_t.size)
        stop = np.searchsorted(gt_t, te.t_s, side="left")
        prev = 0
        for j, ti, yi in zip(stop, te.t_s, te.y):  # adaptive: predict up to each observation, then update
            if j > prev:
                b[prev:j] = f.predict(gt_t[prev:j])
                prev = j
            f.update(float(ti), int(yi))
        b[prev:] = f.predict(gt_t[prev:])
        m, w = _mae(gt_t, gt_x, b)
        total += m * w
        weight += w
    return total / weight


@pytest.mark.slow
def test_perpetua_star_beats_perpetua_and_fremen() -> None:
    bench = make_persistence_benchmark(seed=0)
    star = _score("perpetua_star", bench)
    perp = _score("perpetua", bench)
    frem = _score("fremen", bench)
    assert star < perp and star < frem
