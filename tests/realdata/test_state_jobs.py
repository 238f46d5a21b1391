"""The state benchmark's jobs (a fit per row and seed, then one job per scored edge) give one process's results,
whatever order they complete in.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from psg_data.evaluation._hints import EstimatorSpec
from psg_data.evaluation._state_benchmark import StateRun, StateRunOptions, _Tasks, run_state_benchmark, state_rows
from psg_data.loaders.raw import read_door_benchmark, read_room_presence_benchmark
from tests.realdata._layout import write_door, write_rooms


def _rows(specs: tuple[str | EstimatorSpec, ...]):
    """The user's rows and the reference rows (Perpetua and Perpetua*, slow on minute rows, left out)."""
    specs_ = [s if isinstance(s, EstimatorSpec) else EstimatorSpec.of(s) for s in specs]
    return [r for r in state_rows(specs_) if r.label not in ("perpetua", "perpetua_star")]


def _doc(run: StateRun) -> str:
    """Everything a run reports, as text (NaN compares equal to NaN)."""
    return json.dumps({"values": run.values, "errors": run.errors, "fits": run.fits, "periods": run.periods})


def _bench(kind: str, root: Path):
    if kind == "rooms":
        return read_room_presence_benchmark(write_rooms(root, weeks=4), train_weeks=2)
    return read_door_benchmark(write_door(root, train_weeks=2, test_weeks=3))


@pytest.mark.parametrize(("kind", "protocol"), [("door", "published"), ("rooms", "patrol")])
def test_out_of_order_completion_assembles_as_inline(tmp_path: Path, kind: str, protocol: str) -> None:
    """Tasks completed in a shuffled order (edges of a later row before an earlier row's) give the inline run."""
    b = _bench(kind, tmp_path)
    rows = _rows(("fremen", "persistence_filter"))
    opts = StateRunOptions(protocol=protocol, seeds=(0, 1))
    inline = run_state_benchmark(b, rows, opts)
    assert not inline.errors and len(inline.values) == len(rows)
    rng = np.random.default_rng(3)
    for _ in range(2):
        tasks = _Tasks(b, rows, opts)
        todo = tasks.first()
        order = []
        while todo:
            key = todo.pop(int(rng.integers(len(todo))))
            fn, args = tasks.call(key)
            order.append(key)
            todo += tasks.done(key, fn(*args))[0]
        assert order != sorted(order, key=lambda k: (k[1], k[0] != "fit"))  # really out of the rows' order
        values, errors, fits = tasks.assemble()
        assert list(values) == [r.label for r in rows]
        shuffled = StateRun(values, inline.periods, errors, fits, opts, inline.info)
        assert _doc(shuffled) == _doc(inline)


def test_pool_equals_inline_and_reports_rows(tmp_path: Path) -> None:
    """Two worker processes give the inline run's values, problems and fits; progress counts finished rows."""
    from psg_data._pool import process_pool

    b = _bench("rooms", tmp_path)
    rows = _rows((EstimatorSpec.of("fremen", max_order=3), "persistence_filter"))
    opts = StateRunOptions(protocol="patrol")
    inline = run_state_benchmark(b, rows, opts)
    assert not inline.errors and "fremen:max_order=3" in inline.values  # a row with settings, fitted
    seen: list[tuple[int, int]] = []
    with process_pool(2) as pool:
        pooled = run_state_benchmark(b, rows, opts, executor=pool, progress=lambda d, n: seen.append((d, n)))
    assert _doc(pooled) == _doc(inline)
    assert seen == [(k, len(rows)) for k in range(1, len(rows) + 1)]


def test_one_job_per_edge_equals_one_filter_per_period(tmp_path: Path) -> None:
    """A row's per-period MSE from the edge jobs equals filters built per period from the fitted estimator."""
    from psg_data.estimators import get_estimator
    from psg_data.evaluation._edge_run import run_edge
    from psg_data.evaluation._state_protocols import edge_jobs, score_config

    b = _bench("door", tmp_path)
    run = run_state_benchmark(b, _rows(("persistence_filter",))[:1], StateRunOptions(protocol="published"))
    train = b.train_streams()
    est = get_estimator("persistence_filter").fit(train, timezone=b.timezone)
    hist = {s.edge: s for s in train}
    for k, p in enumerate(b.periods):
        sq = []
        for job in edge_jobs(p.truth, b.scored, hist, {}, k, b.timezone):
            _, _, issues, trace = run_edge("persistence_filter", 0, est, job, score_config("predictive", 7200.0))
            assert not issues and trace is not None
            sq.append(((trace.belief - trace.truth) ** 2)[trace.truth >= 0])
        assert run.values["persistence_filter"][k]["mse"] == pytest.approx(np.mean(np.concatenate(sq)), rel=1e-12)
