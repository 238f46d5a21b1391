"""``process_oracle:output=median`` scored from ``process_oracle``'s predictions (one filter per edge)
gives exactly what running the median row on its own gives: inline and on a pool, every edge
result, breakdown row, trace and issue; which rows derive, and which never do."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import pytest

from psg_data.estimators import EdgeStream, get_estimator
from psg_data.evaluation import evaluate_persistence
from psg_data.evaluation._derived_rows import derived_rows
from psg_data.evaluation._persistence_task import RegistryFactory
from psg_data.schemas._generator_model import StepProcess
from psg_data.synth._process import sample_entity
from tests.synth.test_process_exact import tiny_process

P = 0.15


def _data(proc: StepProcess, days: int = 24, train_days: int = 16) -> tuple[list[EdgeStream], ...]:
    ent = proc.entities["obj"]
    n = days * proc.n_slots
    path = sample_entity(proc, ent, n, np.random.default_rng(3))
    t = np.array([proc.clock.step_start_s(i) + 180.0 for i in range(n)])
    rng = np.random.default_rng(4)
    seen = rng.random(n) < 0.5  # observed at half of the steps
    cut = train_days * proc.n_slots
    train, test, truth = [], [], []
    for j, label in enumerate(ent.states):
        if label is None:
            continue
        x = (path.states == j).astype(np.int8)
        y = np.where(rng.random(n) < P, 1 - x, x).astype(np.int8)
        tr, te = seen & (np.arange(n) < cut), seen & (np.arange(n) >= cut)
        train.append(EdgeStream(("obj", label), t[tr], y[tr]))
        test.append(EdgeStream(("obj", label), t[te], y[te]))
        truth.append((("obj", label), t[cut:] + 600.0, x[cut:]))
    return train, test, truth


@pytest.fixture(scope="module")
def proc() -> StepProcess:
    p = tiny_process(7, K=2, S=4)
    p.days = 30
    return p


def _settings(proc: StepProcess, **extra: Any) -> tuple[tuple[str, Any], ...]:
    return tuple({"process": proc.to_dict(), "p_m": P, "p_f": P, **extra}.items())


def _median_alone(*, random_state: int, settings: tuple[tuple[str, Any], ...]) -> Any:
    """The median row built by a plain factory: never derived, so it runs its own filters."""
    return get_estimator("process_oracle", **dict(settings))


def _run(proc: StepProcess, derived: bool, jobs: int) -> Any:
    train, test, truth = _data(proc)
    base = RegistryFactory("process_oracle", _settings(proc))
    med_settings = _settings(proc, output="median")
    median = RegistryFactory("process_oracle", med_settings) if derived else \
        functools.partial(_median_alone, settings=med_settings)
    gt = {e: (t, y) for e, t, y in truth}
    return evaluate_persistence({"oracle": base, "oracle:median": median, "last_seen": "last_seen"}, train, test,
                                gt, jobs=jobs, keep_predictions=list(gt))


def _same_results(a: Any, b: Any) -> None:
    assert a.to_frame().equals(b.to_frame())
    assert a.breakdown_rows == b.breakdown_rows
    assert [(t.estimator, t.edge) for t in a.traces] == [(t.estimator, t.edge) for t in b.traces]
    for ta, tb in zip(a.traces, b.traces):
        np.testing.assert_array_equal(ta.belief, tb.belief)
    assert [e.message for e in a.errors] == [e.message for e in b.errors]
    assert a.config["estimator_params"] == b.config["estimator_params"]


@pytest.mark.parametrize("jobs", [1, 2])
def test_the_median_row_scored_from_the_probability_row_equals_running_it(proc: StepProcess, jobs: int) -> None:
    derived, alone = _run(proc, True, jobs), _run(proc, False, jobs)
    assert derived.config["derived_rows"] == {"oracle:median": "oracle"}
    assert "derived_rows" not in alone.config
    _same_results(derived, alone)
    med = [t for t in derived.traces if t.estimator == "oracle:median"]
    assert med and all(set(np.unique(t.belief)) <= {0.0, 1.0} for t in med)
    assert any(np.unique(t.belief).size == 2 for t in med)  # the median is not constant: the test can tell
    assert derived.ok and len(derived.edges) == 3 * 3


def test_a_failing_base_fit_is_an_error_of_both_rows(proc: StepProcess) -> None:
    train, test, truth = _data(proc)
    gt = {e: (t, y) for e, t, y in truth}
    rows = {"oracle": RegistryFactory("process_oracle", (("dataset", "/nonexistent/lab"),)),
            "oracle:median": RegistryFactory("process_oracle", (("dataset", "/nonexistent/lab"), ("output", "median")))}
    res = evaluate_persistence(rows, train, test, gt)
    assert res.config["derived_rows"] == {"oracle:median": "oracle"}
    fits = [e for e in res.errors if e.stage == "fit"]
    assert [e.estimator for e in fits] == ["oracle", "oracle:median"]
    assert fits[1].message.startswith("estimator 'oracle:median' seed 0: ")
    assert fits[0].message.split(": ", 1)[1] == fits[1].message.split(": ", 1)[1]
    assert {e.status for e in res.edges} == {"error"}


def test_which_rows_derive() -> None:
    seeds = {"a": (0,), "b": (0,), "c": (0,), "d": (0, 1)}
    base = ("process_oracle", {"dataset": "x", "p_m": 0.1})
    med = ("process_oracle", {"dataset": "x", "p_m": 0.1, "output": "median"})
    assert {k: v.base for k, v in derived_rows({"a": base, "b": med}, seeds).items()} == {"b": "a"}
    assert derived_rows({"b": med}, seeds) == {}  # no probability row to derive from
    assert derived_rows({"a": ("process_oracle", {"dataset": "x", "p_m": 0.2}), "b": med}, seeds) == {}
    assert derived_rows({"a": ("process_oracle", {"dataset": "y", "p_m": 0.1}), "b": med}, seeds) == {}
    assert derived_rows({"d": base, "b": med}, seeds) == {}  # other seeds
    assert derived_rows({"a": med, "b": med}, seeds) == {}  # a median row is no base
    assert derived_rows({"a": ("last_seen", {}), "b": ("last_seen", {})}, seeds) == {}
    assert derived_rows({"a": base, "b": ("no_such_estimator", {"output": "median"})}, seeds) == {}
    row = derived_rows({"a": base, "b": med}, seeds)["b"]
    np.testing.assert_array_equal(row.fn(np.array([0.0, 0.4999, 0.5, 1.0])), [0.0, 0.0, 1.0, 1.0])
    assert row.params["output"] == "median"


def test_a_class_outside_psg_data_declaring_a_derived_output_is_not_trusted(monkeypatch: pytest.MonkeyPatch) -> None:
    from psg_data.estimators._process_oracle import ProcessOracleEstimator

    rows = {"a": ("process_oracle", {"dataset": "x"}), "b": ("process_oracle", {"dataset": "x", "output": "median"})}
    seeds = {"a": (0,), "b": (0,)}
    assert set(derived_rows(rows, seeds)) == {"b"}
    monkeypatch.setattr(ProcessOracleEstimator, "__module__", "someone_elses_plugin")
    assert derived_rows(rows, seeds) == {}
