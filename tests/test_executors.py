"""The executor seam: convert and the persistence harness give the same bytes on a Dask cluster
(LocalCluster, reached by its tcp:// address and as ``scheduler="local"``) as in the local pool."""

from __future__ import annotations

import json
from pathlib import Path

import distributed  # [dev] installs psg-data[dask]; a missing extra fails loudly
import numpy as np
import pytest
from click.testing import CliRunner

from psg_data._executors import check_scheduler, open_executor
from psg_data.convert import convert
from psg_data.errors import PsgDataError
from psg_data.estimators import EdgeStream
from psg_data.evaluation import evaluate_persistence
from psg_data.synth._raw_export import export_raw
from tests.convert.conftest import dataset_bytes, make_dataset


@pytest.fixture(scope="module")
def cluster():  # type: ignore[no-untyped-def]
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=40) as c:
        yield c


def _sweep_inputs():  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(3)
    t0, hour = 1_700_000_000.0, 3600.0
    edges = [(f"obj{i}", f"rec{j}") for i in range(3) for j in range(2)]
    train, test, gt = [], [], {}
    for e in edges:
        t = t0 + hour * np.sort(rng.uniform(0, 24 * 14, 40))
        train.append(EdgeStream(e, t, rng.integers(0, 2, t.size)))
        tt = t0 + hour * np.sort(rng.uniform(24 * 14, 24 * 21, 12))
        test.append(EdgeStream(e, tt, rng.integers(0, 2, tt.size)))
        grid = t0 + hour * np.arange(24 * 14, 24 * 21, 0.5)
        gt[e] = (grid, rng.integers(0, 2, grid.size))
    return train, test, gt


def test_a_small_sweep_on_dask_equals_the_local_pool(cluster) -> None:  # type: ignore[no-untyped-def]
    train, test, gt = _sweep_inputs()
    estimators = ["fremen", "time_of_week_frequency", "persistence_filter"]
    kw = dict(seeds=(0, 1), keep_predictions=[next(iter(gt))])
    local = evaluate_persistence(estimators, train, test, gt, jobs=2, **kw)
    with open_executor(2, cluster.scheduler_address) as ex:
        assert type(ex).__module__.startswith("distributed")
        on_dask = evaluate_persistence(estimators, train, test, gt, jobs=2, executor=ex, **kw)
    a, b = (json.dumps(r.to_dict(), sort_keys=True) for r in (local, on_dask))
    # none of the three fits depends on the seed: each is fitted once, whatever seeds says
    assert local.ok and len(local.edges) == 3 * 6 and all(v == [0] for v in local.config["estimator_seeds"].values())
    assert a == b
    assert [t.belief.tobytes() for t in local.traces] == [t.belief.tobytes() for t in on_dask.traces]


def test_a_small_conversion_on_dask_equals_the_local_pool(tmp_path: Path, cluster) -> None:  # type: ignore[no-untyped-def]
    raw = export_raw(make_dataset(tmp_path / "canon", n_scans=3, n_frames=3), tmp_path / "raw", "ros1",
                     images="compressed")
    pool = Path(convert(raw, tmp_path / "pool", jobs=2).output)
    remote = Path(convert(raw, tmp_path / "remote", jobs=2, scheduler=cluster.scheduler_address).output)
    local = Path(convert(raw, tmp_path / "local", jobs=2, scheduler="local").output)
    a = dataset_bytes(pool)
    assert sum(k.endswith(".tar") for k in a) == 3
    assert a == dataset_bytes(remote) == dataset_bytes(local)


def test_scheduler_values_are_checked() -> None:
    assert check_scheduler(None) is None and check_scheduler("local") == "local"
    assert check_scheduler("tcp://10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    with pytest.raises(PsgDataError, match="expected 'local' or a Dask scheduler address"):
        check_scheduler("10.0.0.5")


def test_cli_rejects_a_bad_scheduler_in_one_line(tmp_path: Path) -> None:
    from psg_data.cli.psg_eval_cmd import main

    r = CliRunner().invoke(main, ["--scheduler", "nowhere", "--out", str(tmp_path / "o"), "-q"])
    assert r.exit_code == 1 and r.stderr.strip().splitlines() == [
        "error: --scheduler 'nowhere': expected 'local' or a Dask scheduler address such as tcp://10.0.0.5:8786"]
    assert not (tmp_path / "o").exists()
