"""The batched interval EM (all fits of a training advanced together) against the per-problem EM of
main 9ca2d8e kept in tests/estimators/_interval_em_reference.py: same parameters to 1e-9, same
iteration counts, on random small problems and on every edge of the demo lab and of a navigation
benchmark scene (issue 45)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import psg_data.estimators._survival_training as training
from psg_data.estimators import IntervalFit, get_estimator
from psg_data.estimators._interval_em import em_intervals, fit_interval_mixtures
from tests.estimators import _interval_em_reference as ref

H = 3600.0


def _same_fit(a: IntervalFit, b: IntervalFit, where: str) -> None:
    """Equal to 1e-9 (relative above 1), the same K chosen and the same iterations run."""
    ma, mb = a.mixture, b.mixture
    assert ma.n_components == mb.n_components, where
    for x, y in ((ma.weights, mb.weights), (ma.p1, mb.p1), (ma.p2, mb.p2)):
        np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-9, err_msg=where)
    assert list(a.aic_by_k) == list(b.aic_by_k), where
    assert len(a.trace) == len(b.trace), where  # the selected run stopped at the same iteration
    np.testing.assert_allclose(a.trace, b.trace, rtol=1e-9, atol=1e-9, err_msg=where)


def _problem(draw: Callable[..., Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    n = draw(st.integers(1, 14))
    lo = np.array(draw(st.lists(st.floats(0.0, 50.0), min_size=n, max_size=n))) * H
    width = np.array(draw(st.lists(st.sampled_from([0.0, 0.01, 0.5, 2.0, 9.0, np.inf]), min_size=n, max_size=n))) * H
    w = np.array(draw(st.lists(st.sampled_from([1.0, 1.0, 0.3, 2.0]), min_size=n, max_size=n)))
    hi = lo + width
    lo[hi <= 0] = 0.0
    hi[hi <= 0] = H  # every row usable
    return lo, hi, w, draw(st.integers(1, 3))


@st.composite
def problems(draw: Callable[..., Any]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, int]]:
    return [_problem(draw) for _ in range(draw(st.integers(1, 4)))]


@settings(max_examples=25, deadline=None)
@given(probs=problems(), family=st.sampled_from(["lognormal", "lognormal", "exponential", "weibull"]),
       seed=st.integers(0, 50))
def test_batched_fits_equal_the_reference_fits_one_by_one(probs: list[Any], family: str, seed: int) -> None:
    kw: dict[str, Any] = {"family": family, "random_state": seed}
    if family == "weibull":
        kw["max_iter"] = 15  # its numerical M-step is slow; the comparison needs no convergence
    batched = fit_interval_mixtures(probs, **kw)
    for i, (lo, hi, w, k) in enumerate(probs):
        _same_fit(batched[i], ref.fit_interval_mixture(lo, hi, weights=w, max_components=k, **kw), f"problem {i}")


@pytest.mark.parametrize("family", ["lognormal", "exponential", "weibull"])
def test_em_intervals_equals_the_reference_and_stops_at_max_iter_after_the_m_step(family: str) -> None:
    rng = np.random.default_rng(3)
    lo = rng.uniform(0, 20, 30) * H
    hi = np.where(rng.random(30) < 0.2, np.inf, lo + rng.uniform(0, 5, 30) * H)
    w = rng.uniform(0.5, 2.0, 30)
    start = {"lognormal": (np.array([0.5, 0.5]), np.log([3 * H, 20 * H]), np.ones(2)),
             "exponential": (np.array([0.5, 0.5]), 1 / np.array([3 * H, 20 * H]), np.ones(2)),
             "weibull": (np.array([0.5, 0.5]), np.ones(2), np.array([3 * H, 20 * H]))}[family]
    for max_iter in (1, 3, 250):  # 1 and 3: cut short, the parameters are one M-step past the trace
        got = em_intervals(family, lo, hi, w, *start, max_iter=max_iter if family != "weibull" else min(max_iter, 6))
        want = ref.em_intervals(family, lo, hi, w, *start, max_iter=max_iter if family != "weibull" else min(max_iter, 6))
        for x, y in zip(got[:3], want[:3]):
            np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-12)
        assert len(got[3]) == len(want[3])
        np.testing.assert_allclose(got[3], want[3], rtol=1e-12)


def _reference_batch(probs: list[Any], **kw: Any) -> list[IntervalFit]:
    return [ref.fit_interval_mixture(lo, hi, weights=w, max_components=k, **kw) for lo, hi, w, k in probs]


def _fits(monkeypatch: pytest.MonkeyPatch, batch: Callable[..., list[IntervalFit]], name: str,
          data: tuple[Any, Any, str]) -> tuple[dict[Any, Any], list[IntervalFit]]:
    """The estimator's per-edge mixtures, and every IntervalFit of its training, with ``batch`` as its EM."""
    seen: list[IntervalFit] = []

    def recording(probs: list[Any], **kw: Any) -> list[IntervalFit]:
        out = batch(probs, **kw)
        seen.extend(out)
        return out

    monkeypatch.setattr(training, "fit_interval_mixtures", recording)
    est = get_estimator(name).fit(data[0], val_streams=data[1], timezone=data[2])
    monkeypatch.undo()
    return est.survivals_, seen


def _compare_trainings(monkeypatch: pytest.MonkeyPatch, data: tuple[Any, Any, str]) -> None:
    for name in ("perpetua_star", "perpetua"):
        got, got_fits = _fits(monkeypatch, fit_interval_mixtures, name, data)
        want, want_fits = _fits(monkeypatch, _reference_batch, name, data)
        assert len(got_fits) == len(want_fits) > 0
        for i, (a, b) in enumerate(zip(got_fits, want_fits)):
            _same_fit(a, b, f"{name} fit {i}")
        assert got.keys() == want.keys()
        for e in want:
            for a, b in zip(got[e], want[e]):
                assert (a.family, a.n_components) == (b.family, b.n_components), e
                for x, y in ((a.weights, b.weights), (a.p1, b.p1), (a.p2, b.p2)):
                    np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-9, err_msg=f"{name} {e}")


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    mp = pytest.MonkeyPatch()
    root = tmp_path_factory.mktemp("cache")
    mp.setenv("PSG_DATA_CACHE", str(root))
    yield root
    mp.undo()


@pytest.mark.slow
def test_every_edge_of_the_demo_lab_fits_as_the_reference(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from psg_data.datasets import demo
    from psg_data.evaluation import persistence_task_from_dataset

    task = persistence_task_from_dataset(demo(), labels="gt")  # what psg-eval scores by default
    _compare_trainings(monkeypatch, (task.train_streams, task.val_streams, task.timezone))


@pytest.mark.slow
def test_every_edge_of_a_navigation_benchmark_scene_fits_as_the_reference(
        cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from psg_data.datasets import navigation_benchmark_scenes
    from psg_data.evaluation import persistence_task_from_dataset

    scene = navigation_benchmark_scenes(scenes=1)[0]  # scene_00, house seed 0, as psg-eval builds it
    task = persistence_task_from_dataset(scene, labels="gt")
    _compare_trainings(monkeypatch, (task.train_streams, task.val_streams, task.timezone))
