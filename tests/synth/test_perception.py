"""Simulated detections: perfect mode equals visible ground truth; error rates match the settings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.stats import binomtest

from psg_data.synth import (
    CONFUSABLE,
    DETECTIONS_SCHEMA,
    OBJECT_ID0,
    RECEPTACLE_ID0,
    LabConfig,
    LabModel,
    detect,
    rerender_frame,
    write_detections,
)


def _visible_from_dataset(ds, lab: LabModel, min_pixels: int = 4) -> set[tuple[str, str]]:  # type: ignore[no-untyped-def]
    """(scan_id, gt id) seen with >= min_pixels in some frame, from re-rendered stored frames."""
    inst = lab.layout.instances
    out = set()
    for sid in ds.scan_ids:
        for i in range(len(ds.scan(sid))):
            ids, n = np.unique(rerender_frame(ds, sid, i, noise=False, lab=lab).instance_ids, return_counts=True)
            out |= {(sid, inst[int(k)].key) for k, c in zip(ids, n) if c >= min_pixels and k >= RECEPTACLE_ID0}
    return out


def test_perfect_detections_equal_visible_ground_truth(small_dataset, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    lab = LabModel.from_dataset(small_dataset)
    path = write_detections(small_dataset, tmp_path / "detections.parquet", seed=0, perfect=True)
    t = pq.read_table(path)
    assert t.schema.equals(DETECTIONS_SCHEMA)
    rows = t.to_pylist()
    got = {(r["scan_id"], r["gt_id"]) for r in rows}
    assert got == _visible_from_dataset(small_dataset, lab)
    assert len(got) == len(rows)
    sched = {(r["scan_id"], r["object_id"]): r["receptacle_id"] for r in small_dataset.table("schedule").to_pylist()}
    recs = small_dataset.receptacles
    for r in rows:
        assert r["score"] == 1.0
        if r["kind"] == "object":
            assert r["label"] == r["gt_id"]
            rec = recs[sched[(r["scan_id"], r["gt_id"])]]  # the object lies on its scheduled receptacle's top
            top = rec.box.center_m[2] + rec.box.extent_m[2] / 2
            assert r["centroid_m"][2] > top
            assert rec.box.contains(np.array([[*r["centroid_m"][:2], top - 0.01]]))[0]
        else:
            rec = recs[r["gt_id"]]
            assert r["label"] == rec.category
            np.testing.assert_allclose(r["box_center_m"], rec.box.center_m)
    # the lab-model path gives the same detections as the dataset path
    assert detect(lab, perfect=True).equals(t)


def test_error_rates_close_to_configured() -> None:
    lab = LabModel(LabConfig(seed=1, days=4, frames_per_scan=5, width=120, height=90))
    perfect = detect(lab, perfect=True, min_pixels=2).to_pylist()
    n_obj = sum(r["kind"] == "object" for r in perfect)
    n_rec = sum(r["kind"] == "receptacle" for r in perfect)
    n_conf = sum(r["kind"] == "object" and r["gt_id"] in CONFUSABLE for r in perfect)
    miss, fp, conf, sigma = 0.3, 0.2, 0.25, 0.05
    rows = detect(lab, seed=9, miss_rate=miss, false_positive_rate=fp, confusion_rate=conf,
                  centroid_noise_m=sigma, min_pixels=2).to_pylist()
    true_obj = [r for r in rows if r["kind"] == "object" and r["gt_id"] is not None]
    fps = [r for r in rows if r["gt_id"] is None]
    assert {(r["scan_id"], r["gt_id"]) for r in rows if r["gt_id"]} <= {(r["scan_id"], r["gt_id"]) for r in perfect}
    assert n_obj > 80 and n_rec > 100
    assert binomtest(n_obj - len(true_obj), n_obj, miss).pvalue > 1e-3
    assert binomtest(len(fps), n_rec, fp).pvalue > 1e-3
    confused = sum(r["label"] != r["gt_id"] for r in true_obj)
    kept_conf = sum(r["gt_id"] in CONFUSABLE for r in true_obj)
    assert kept_conf > 0.5 * n_conf
    assert binomtest(confused, kept_conf, conf).pvalue > 1e-3
    for r in true_obj:
        if r["label"] != r["gt_id"]:
            assert r["label"] in CONFUSABLE[r["gt_id"]]
    # centroid noise: per-axis std close to sigma (chi-square, 3 axes per detection)
    truth = {(r["scan_id"], r["gt_id"]): np.asarray(r["centroid_m"]) for r in perfect}
    err = np.array([np.asarray(r["centroid_m"]) - truth[(r["scan_id"], r["gt_id"])] for r in true_obj])
    assert np.std(err) == pytest.approx(sigma, rel=0.15)
    assert all(0.0 <= r["score"] <= 1.0 for r in rows)
    # false positives sit on a visible receptacle and name an object absent from it
    assert len(fps) > 0 and all(r["pixels"] == 0 for r in fps)


def test_detections_seeded() -> None:
    lab = LabModel(LabConfig(seed=2, days=1, frames_per_scan=2, width=48, height=36))
    a = detect(lab, seed=4, miss_rate=0.2, false_positive_rate=0.2)
    assert a.equals(detect(lab, seed=4, miss_rate=0.2, false_positive_rate=0.2))
    assert not a.equals(detect(lab, seed=5, miss_rate=0.2, false_positive_rate=0.2))
    assert OBJECT_ID0 > RECEPTACLE_ID0


def test_write_detections_never_writes_into_its_input(small_dataset_path: Path, tmp_path: Path) -> None:
    import shutil

    from psg_data.errors import UnsafeOutputError
    from psg_data.loaders import open_dataset
    from tests.contract import snapshot

    lab = tmp_path / "lab"
    shutil.copytree(small_dataset_path, lab)  # a copy: a failing test must not damage the shared dataset
    before = snapshot(lab)
    for source in (lab, str(lab), open_dataset(lab)):
        for path, msg in ((lab / "tables" / "objects.parquet", "lies inside the input"), (lab, "is the input"),
                          (tmp_path, "contains the input")):
            with pytest.raises(UnsafeOutputError, match=msg) as err:
                write_detections(source, path)
            assert str(path) in str(err.value)
    assert snapshot(lab) == before


def test_write_detections_replaces_the_file_atomically(small_dataset_path: Path, small_lab: LabModel, tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    from tests.contract import files_in, interrupt_partway

    out = tmp_path / "detections.parquet"
    write_detections(small_lab, out)  # a LabModel: no input folder
    good = out.read_bytes()
    interrupt_partway(monkeypatch, pq, "write_table")  # Ctrl-C in the middle of the file
    with pytest.raises(KeyboardInterrupt):
        write_detections(small_dataset_path, out, seed=1)
    assert out.read_bytes() == good and files_in(tmp_path) == ["detections.parquet"]
