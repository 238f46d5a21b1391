"""Perpetua's filter and process_oracle's filter against their originals of main 8f53f6f kept in
tests/estimators/_perpetua_reference.py and _process_oracle_reference.py (issue 45: made cheap, results
unchanged): bit-equal predictions on random small inputs, interleaving updates and predictions as the
adaptive protocol does, and on every edge of the demo lab and of a navigation benchmark scene as
psg-eval runs them."""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.estimators import EdgeStream, get_estimator
from psg_data.estimators._perpetua import PerpetuaFilter
from psg_data.estimators._survival import SurvivalMixture
from tests.estimators import _perpetua_reference as ref_perpetua
from tests.estimators import _process_oracle_reference as ref_oracle
from tests.synth.test_process_exact import tiny_process
from tests.synth.test_process_mutants import _regime_process

H = 3600.0


def _replay(f: Any, hist: tuple[np.ndarray, np.ndarray], steps: list[tuple[str, Any]],
            sibling: Any = None) -> list[np.ndarray]:
    """Feed the history, then the steps (("update", (t, y)), ("predict", times), ("sibling", (t, y)): an
    update of ``sibling``, or ("copy", None): go on with deep copies of both); the predictions.
    """
    if hist[0].size:
        f.update_many(*hist)
    out = []
    for kind, arg in steps:
        if kind == "update":
            f.update(*arg)
        elif kind == "sibling":
            sibling.update(*arg)
        elif kind == "copy":  # as the navigation protocol copies an object's filters (one tracker)
            f, sibling = copy.deepcopy((f, sibling))
        else:
            out.append(np.asarray(f.predict(arg)))
    return out


def _assert_same(got: list[np.ndarray], want: list[np.ndarray], where: str) -> None:
    assert len(got) == len(want), where
    for i, (a, b) in enumerate(zip(got, want)):
        np.testing.assert_array_equal(a, b, err_msg=f"{where}: prediction call {i}")


@st.composite
def _online(draw: Callable[..., Any], t0: float, span_h: float) -> tuple[tuple[np.ndarray, np.ndarray], list[Any]]:
    """A history and an interleaved sequence of updates and predictions (times in order, queries anywhere)."""
    n_hist = draw(st.integers(0, 12))
    gaps = draw(st.lists(st.sampled_from([0.0, 0.02, 0.5, 1.0, 3.0, 20.0]), min_size=n_hist + 12,
                         max_size=n_hist + 12))
    t = t0 + np.cumsum(np.asarray(gaps) * H)
    y = np.asarray(draw(st.lists(st.integers(0, 1), min_size=t.size, max_size=t.size)), np.int8)
    steps: list[Any] = []
    for ti, yi in zip(t[n_hist:].tolist(), y[n_hist:].tolist()):
        if draw(st.booleans()):
            k = draw(st.integers(1, 4))
            q = ti + np.asarray(draw(st.lists(st.floats(-2.0, span_h), min_size=k, max_size=k))) * H
            steps.append(("predict", q))
        steps.append(("update", (ti, yi)))
    steps.append(("predict", t[-1] + np.linspace(0.0, span_h, 7) * H))
    return (t[:n_hist], y[:n_hist]), steps


def _mixture(draw: Callable[..., Any], family: str) -> SurvivalMixture:
    k = draw(st.integers(1, 3))
    w = np.asarray(draw(st.lists(st.floats(0.05, 1.0), min_size=k, max_size=k)))
    med = np.asarray(draw(st.lists(st.floats(0.3, 60.0), min_size=k, max_size=k))) * H
    if family == "lognormal":
        sig = np.asarray(draw(st.lists(st.sampled_from([0.05, 0.3, 1.0, 2.0]), min_size=k, max_size=k)))
        return SurvivalMixture("lognormal", w, np.log(med), sig)
    return SurvivalMixture("exponential", w, np.log(2.0) / med, np.ones(k))


@st.composite
def _perpetua_case(draw: Callable[..., Any]) -> tuple[Any, ...]:
    family = draw(st.sampled_from(["lognormal", "lognormal", "exponential"]))
    kw = {"p_m": draw(st.sampled_from([0.0, 0.05, 0.2])), "p_f": draw(st.sampled_from([0.0, 0.05, 0.2])),
          "delta_low": draw(st.sampled_from([0.05, 0.2, 0.45])), "delta_high": draw(st.sampled_from([0.55, 0.95])),
          "eps": draw(st.sampled_from([0.0, 0.1, 0.5])), "num_steps": draw(st.integers(0, 3))}
    return _mixture(draw, family), _mixture(draw, family), kw, draw(_online(1.7e9, 80.0)), draw(st.booleans())


@settings(max_examples=60, deadline=None)
@given(case=_perpetua_case())
def test_perpetua_filter_predicts_bit_equal_to_the_reference(case: tuple[Any, ...]) -> None:
    per, emg, kw, (hist, steps), start = case
    filters = []
    for cls in (PerpetuaFilter, ref_perpetua.PerpetuaFilter):
        f = cls(("o", "r"), per, emg, kw["p_m"], kw["p_f"], delta_low=kw["delta_low"], delta_high=kw["delta_high"],
                eps=kw["eps"], num_steps=kw["num_steps"])
        if start:
            f.start(1.7e9 - 2 * H)
        filters.append(f)
    got, want = (_replay(f, hist, steps) for f in filters)
    _assert_same(got, want, "perpetua")
    assert filters[0].get_state() == filters[1].get_state()


@st.composite
def _oracle_case(draw: Callable[..., Any]) -> tuple[Any, ...]:
    seed = draw(st.integers(0, 30))
    proc = _regime_process(seed, start_day=draw(st.integers(0, 2))) if draw(st.booleans()) else tiny_process(seed)
    proc.days = 6
    ent = proc.entities["obj"]
    t0 = proc.clock.step_start_s(2 * proc.n_slots) + 60.0  # the training data end a day later
    labels = [s for s in ent.states if s is not None]
    train = []
    for lab in labels:  # the siblings' training observations: one per step for a day and a half
        tt = np.array([proc.clock.step_start_s(i) + 60.0 for i in range(3 * proc.n_slots)])
        train.append(EdgeStream(("obj", lab), tt, np.asarray(draw(st.lists(st.integers(0, 1), min_size=tt.size,
                                                                              max_size=tt.size)), np.int8)))
    noise = draw(st.sampled_from([0.0, 0.1]))
    hist, steps = draw(_online(t0, 30.0))
    share = draw(st.booleans())
    if share:  # a sibling reports observations, often earlier than the filter's last update
        last, mixed = (float(hist[0][-1]) + 1800.0 if hist[0].size else -np.inf), []  # after its history
        for kind, arg in steps:
            if kind == "update" and draw(st.booleans()):
                last = max(last, arg[0] - draw(st.sampled_from([0.0, 0.5, 3.0, 12.0])) * H)
                mixed.append(("sibling", (last, draw(st.integers(0, 1)))))
            mixed.append((kind, arg))
            if draw(st.integers(0, 4)) == 0:
                mixed.append(("copy", None))
        steps = mixed
    return (proc, train, draw(st.sampled_from(labels)), (hist, steps), noise, share,
            draw(st.sampled_from(["probability", "median"])))


@settings(max_examples=80, deadline=None)
@given(case=_oracle_case())
def test_process_oracle_filter_predicts_bit_equal_to_the_reference(case: tuple[Any, ...]) -> None:
    proc, train, label, (hist, steps), noise, share, output = case
    kw = {"process": proc.to_dict(), "p_m": max(noise, 0.05), "p_f": max(noise, 0.05), "share_updates": share,
          "output": output}
    new = get_estimator("process_oracle", **kw).fit(train)
    old = get_estimator("process_oracle", **kw).fit(train)  # its own tracker
    sibling = next(s.edge for s in train if s.edge[1] != label) if len(train) > 1 else None
    got, want = [], []
    for make, out in ((new.make_filter, got), (lambda e: ref_oracle.reference_filter(old, e), want)):
        sib = make(sibling) if sibling is not None else None
        if share and sib is not None and hist[0].size:  # the sibling's history goes to the tracker too
            sib.update_many(hist[0] + 1800.0, 1 - hist[1])
        out.extend(_replay(make(("obj", label)), hist, [x for x in steps if sib is not None or x[0] != "sibling"],
                           sib))
    _assert_same(got, want, "process_oracle")


# -- every edge of the demo lab and of a navigation benchmark scene, as psg-eval runs them -----------------


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    mp = pytest.MonkeyPatch()
    root = tmp_path_factory.mktemp("cache")
    mp.setenv("PSG_DATA_CACHE", str(root))
    yield root
    mp.undo()


def _compare_dataset(path: Path, settings_: dict[str, Any]) -> None:
    """Every ground-truth edge through the adaptive protocol's loop (psg-eval's defaults) and with every
    evaluation time in one call (predictive), new filter against the reference."""
    from psg_data.evaluation import PersistenceOptions, persistence_task_from_dataset
    from psg_data.evaluation._edge_run import ScoreConfig, _predictions, _Progress
    from psg_data.evaluation._persistence_task import _edge_jobs

    task = persistence_task_from_dataset(path, labels="gt")
    opts = PersistenceOptions().resolve(task)
    jobs = _edge_jobs(task, opts, set())
    assert len(jobs) > 10
    cases = [("perpetua", {}, ref_perpetua.reference_filter)] + [
        ("process_oracle", {"dataset": str(path), **s}, ref_oracle.reference_filter) for s in settings_["oracle"]]
    for name, kw, reference in cases:
        fits = [get_estimator(name, **kw).fit(task.train_streams, val_streams=task.val_streams,
                                               timezone=task.timezone) for _ in range(2)]
        for setting in ("adaptive", "predictive"):
            cfg = ScoreConfig(setting, float(opts.horizon), 0.5, opts.convention, opts.sample_convention,
                              tuple(opts.codes))
            for job in jobs:
                got = []
                for f in (fits[0].make_filter(job.edge), reference(fits[1], job.edge)):
                    if job.hist_t.size:
                        f.update_many(job.hist_t, job.hist_y)
                    got.append(_predictions(f, job, cfg, _Progress())[0])
                np.testing.assert_array_equal(got[0], got[1], err_msg=f"{name} {kw} {setting} {job.edge}")


@pytest.mark.slow
def test_every_edge_of_the_demo_lab_predicts_as_the_reference(cache: Path) -> None:
    from psg_data.datasets import demo

    _compare_dataset(demo(), {"oracle": [{}, {"output": "median"}]})


@pytest.mark.slow
def test_every_edge_of_a_navigation_benchmark_scene_predicts_as_the_reference(cache: Path) -> None:
    from psg_data.datasets import navigation_benchmark_scenes

    scene = navigation_benchmark_scenes(scenes=1)[0]  # scene_00, house seed 0, as psg-eval builds it
    _compare_dataset(scene, {"oracle": [{}, {"model": "train"}]})
