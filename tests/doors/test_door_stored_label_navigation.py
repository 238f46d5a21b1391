"""Navigation from stored labels (privileged, detections) of a rendered synthetic lab (the door tests' lab)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.labeling import LabelGrid, error_rates, ground_truth, label_dataset
from psg_data.loaders import open_dataset
from psg_data.navigation import NavigationEnv, NavigationOptions, run_navigation


@pytest.fixture(scope="module")
def labelled(tmp_path_factory, door_lab_path, door_lab_model):  # type: ignore[no-untyped-def]
    from psg_data.synth import write_detections

    root = tmp_path_factory.mktemp("navlab") / "lab"
    shutil.copytree(door_lab_path, root)
    det = write_detections(door_lab_model, root.parent / "dets.parquet", seed=1, miss_rate=0.3,
                           false_positive_rate=0.2)
    label_dataset(root, "privileged")
    label_dataset(root, f"detections:{det}")
    return root, det


def _train_ids(ds) -> list[str]:  # type: ignore[no-untyped-def]
    sc = ds.df("scans")
    return sc.loc[sc.split == "train", "scan_id"].tolist()


def test_privileged_map_is_the_truth_where_seen(labelled) -> None:  # type: ignore[no-untyped-def]
    root, _ = labelled
    gt_env = NavigationEnv.from_dataset(root)
    pr_env = NavigationEnv.from_dataset(root, labels="privileged")
    truth = {(s.edge, t): y for s in gt_env.map_streams for t, y in zip(s.t_s, s.y)}
    n = 0
    for s in pr_env.map_streams:
        for t, y in zip(s.t_s, s.y):
            assert truth[(s.edge, t)] == y  # privileged observations are exact ...
            n += 1
    assert 0 < n < len(truth)  # ... but only where the scan saw the receptacle
    assert pr_env.observation.exact
    assert set(pr_env.edges) <= set(gt_env.edges)
    # door streams of the source: the door rows stored under 'privileged' (only scans that saw the door)
    assert sum(len(s) for s in pr_env.door_streams) <= sum(len(s) for s in gt_env.door_streams)


def test_detections_sightings_have_the_measured_error_rates(labelled) -> None:  # type: ignore[no-untyped-def]
    root, det = labelled
    ds = open_dataset(root)
    source = f"detections:{det}"
    env = NavigationEnv.from_dataset(ds, labels=source, label_seed=2)
    # independent measurement: stored detection labels against the schedule on the train scans
    grid = LabelGrid.from_table(ds.table("labels"), f"detections:{det.name}")
    keep = [k for k, s in enumerate(grid.scan_ids) if s in set(_train_ids(ds))]
    sub = LabelGrid([grid.scan_ids[k] for k in keep], grid.object_ids, grid.receptacle_ids, grid.stamps_ns[keep],
                    grid.codes[keep], grid.source)
    rates = error_rates(sub, ground_truth(ds))
    assert rates.p_m > 0.05 and rates.p_f > 0.0
    assert env.observation.p_miss == pytest.approx(rates.p_m) and env.observation.p_false == pytest.approx(rates.p_f)
    assert env.extra["labels"]["doors"]["from"].startswith("read from the depth")  # detections carry no doors
    opts = NavigationOptions.preset("sim", labels=source, label_seed=2, seeds=(0,), n_queries=30, setting="adaptive",
                                    door_belief="predicted")
    res = run_navigation(ds, ["oracle", "time_of_week_frequency"], opts)
    assert res.config["labels"] == source and res.config["sightings"]["p_miss"] == pytest.approx(rates.p_m)
    assert np.isfinite(res.summary["overall_sr_mean"]).all()
