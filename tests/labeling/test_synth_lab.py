"""Labelling the synthetic lab, checked against the renderer's own per-pixel ground truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from psg_data.labeling import (
    LabelGrid,
    VisibilityParams,
    compute_labels,
    error_rates,
    grid_streams,
    label_dataset,
    perception_labels,
    privileged_codes,
)
from psg_data.labeling._detections import Detections
from psg_data.loaders import open_dataset
from psg_data.schemas import CameraIntrinsics

SCALE = 3  # supersampling of the reference renders


def _state(ds, sid: str):  # type: ignore[no-untyped-def]
    from psg_data.synth import SceneState

    sched = [r for r in ds.table("schedule").to_pylist() if r["scan_id"] == sid]
    doors = [r for r in ds.table("door_states").to_pylist() if r["scan_id"] == sid]
    return SceneState({r["object_id"]: r["receptacle_id"] for r in sched},
                      {r["door_id"]: r["state"] == "open" for r in doors})


def _reference_visibility(ds, lab, p: VisibilityParams):  # type: ignore[no-untyped-def]
    """Per (scan, receptacle): top-face coverage and max per-frame pixels from instance-id renders."""
    rec_ids = list(ds.receptacles)
    S, R = len(ds.scan_ids), len(rec_ids)
    frac, px = np.zeros((S, R)), np.zeros((S, R))
    obj_px = np.zeros((S, len(ds.objects)))
    for s, sid in enumerate(ds.scan_ids):
        scan = ds.scan(sid)
        cam = ds.cameras[str(scan._f["camera_id"][0])]
        hi = CameraIntrinsics("hi", cam.width * SCALE, cam.height * SCALE, cam.fx * SCALE, cam.fy * SCALE,
                              (cam.cx + 0.5) * SCALE - 0.5, (cam.cy + 0.5) * SCALE - 0.5)
        rend = lab.renderer(_state(ds, sid))
        cells = {}
        for T in scan.poses:
            fr = rend.render(T, hi, noise=None)
            iid = fr.instance_ids.ravel()
            z = fr.depth_true_m.ravel().astype(float)
            v, u = np.mgrid[0:hi.height, 0:hi.width]
            pc = np.stack([(u.ravel() - hi.cx) / hi.fx * z, (v.ravel() - hi.cy) / hi.fy * z, z], 1)
            pw = pc @ T[:3, :3].T + T[:3, 3]
            nrm = fr.normals.reshape(-1, 3).astype(float)
            for k, rid in enumerate(rec_ids):
                box = ds.receptacles[rid].box
                up = box.rotation[:, 2]
                ray = pw - T[:3, 3]
                cos = np.abs(ray @ up) / np.maximum(np.linalg.norm(ray, axis=1), 1e-9)
                m = ((iid == lab.layout.instance_id(rid)) & (nrm @ up > 0.9) & (z > p.min_range_m)
                     & (z < p.max_range_m) & (cos >= p.min_cos))
                if not m.any():
                    continue
                e = box.extent_m
                local = (pw[m] - box.center_m) @ box.rotation
                nu = int(np.clip(np.ceil(e[0] / p.spacing_m - 1e-9), 2, 40))
                nv = int(np.clip(np.ceil(e[1] / p.spacing_m - 1e-9), 2, 40))
                iu = np.clip(((local[:, 0] / e[0] + 0.5) * nu).astype(int), 0, nu - 1)
                iv = np.clip(((local[:, 1] / e[1] + 0.5) * nv).astype(int), 0, nv - 1)
                cells.setdefault(k, np.zeros(nu * nv, bool))[iu * nv + iv] = True
                px[s, k] = max(px[s, k], m.sum() / SCALE**2)
            for j, oid in enumerate(ds.objects):
                obj_px[s, j] = max(obj_px[s, j], float((iid == lab.layout.instance_id(oid)).sum()) / SCALE**2)
        for k, c in cells.items():
            frac[s, k] = c.mean()
    return frac, px, obj_px


@pytest.fixture(scope="module")
def reference(lab_path: Path, lab_model):  # type: ignore[no-untyped-def]
    ds = open_dataset(lab_path)
    return _reference_visibility(ds, lab_model, VisibilityParams())


def test_privileged_agrees_with_instance_ids(lab_path: Path, reference) -> None:  # type: ignore[no-untyped-def]
    ds = open_dataset(lab_path)
    p = VisibilityParams()
    res = compute_labels(ds, "privileged", visibility_params=p)
    v = res.visibility.to_pydict()
    rec_ids = list(ds.receptacles)
    S, R = len(ds.scan_ids), len(rec_ids)
    frac = np.array(v["seen_fraction"]).reshape(S, R)
    px = np.array(v["pixels"]).reshape(S, R)
    mine = np.array(v["visible"]).reshape(S, R)
    ref_frac, ref_px, _ = reference
    ref = (ref_frac >= p.min_fraction) & (ref_px >= p.min_pixels)
    assert ref.sum() >= 0.2 * ref.size  # the lab's scans do see a good part of the receptacles
    agree = (mine == ref).mean()
    assert agree >= 0.95, f"visibility agreement {agree:.3f}"
    near = (np.abs(ref_frac - p.min_fraction) < 0.12) | (np.abs(ref_px - p.min_pixels) < 0.5 * p.min_pixels)
    assert np.all(near[mine != ref]), "disagreements away from the thresholds"
    # coverage and pixel area estimates agree where the surface was seen
    seen = ref_frac > 0.3
    assert np.median(np.abs(frac - ref_frac)[seen]) <= 0.08 + 1e-9
    assert np.median(np.abs(px - ref_px)[seen] / ref_px[seen]) < 0.2
    # codes from the independent visibility
    codes_ref = privileged_codes(res.gt, ref).codes
    valid = res.labels.codes != -2
    assert (codes_ref[valid] == res.labels.codes[valid]).mean() >= 0.95


def _perfect_detections(ds, lab, visible: np.ndarray) -> Detections:  # type: ignore[no-untyped-def]
    """Receptacle nodes for the visible receptacles and object nodes for every object on them."""
    rows = []
    rec_ids = list(ds.receptacles)
    for s, sid in enumerate(ds.scan_ids):
        st = _state(ds, sid)
        boxes = lab.layout.object_boxes(st.objects)
        for k, rid in enumerate(rec_ids):
            if not visible[s, k]:
                continue
            b = ds.receptacles[rid].box
            rows.append((sid, "x", "receptacle", b.center_m, b.center_m, b.extent_m, b.rotation))
            for o, r in st.objects.items():
                if r == rid:
                    ob = boxes[o]
                    rows.append((sid, o, "object", ob.center_m, ob.center_m, ob.extent_m, ob.rotation))
    n = len(rows)
    return Detections("perfect", np.array([r[0] for r in rows], object), np.array([r[1] for r in rows], object),
                      np.array([r[2] for r in rows], object), np.array([r[3] for r in rows]),
                      np.array([r[4] for r in rows]), np.array([r[5] for r in rows]),
                      np.array([r[6] for r in rows]), np.ones(n), np.arange(n))


def test_perfect_detections_equal_ground_truth(lab_path: Path, lab_model) -> None:  # type: ignore[no-untyped-def]
    ds = open_dataset(lab_path)
    priv = compute_labels(ds, "privileged")
    S, R = len(ds.scan_ids), len(ds.receptacles)
    visible = np.array(priv.visibility.to_pydict()["visible"]).reshape(S, R)
    grid, info = perception_labels(ds, _perfect_detections(ds, lab_model, visible))
    assert info.n_unassociated == 0 and info.matched.sum() == visible.sum()
    # observed cells equal ground truth exactly
    gt = priv.gt.codes
    obs = grid.observed
    assert obs.sum() > 50
    assert np.array_equal(grid.codes[obs], gt[obs])
    # the streams equal those of the privileged source restricted to the edge history
    hist = grid.valid
    pcodes = priv.labels.codes.copy()
    pcodes[:, ~hist] = -2
    ref = {s.edge: s for s in grid_streams(priv.labels.with_codes(pcodes, "privileged"))}
    got = grid_streams(grid)
    assert [s.edge for s in got] == list(ref)
    for s in got:
        assert np.array_equal(s.t_s, ref[s.edge].t_s) and np.array_equal(s.y, ref[s.edge].y)


def test_synth_perception_sources(lab_copy: Path) -> None:
    from psg_data.synth import write_detections

    perfect = write_detections(lab_copy, lab_copy.parent / "perfect.parquet", perfect=True)
    s = label_dataset(lab_copy, f"detections:{perfect}")
    assert s.rates is not None and s.rates.n_present > 20
    # the simulated detector sees objects it can see in any frame; the only errors left are objects
    # too small / hidden to detect while their receptacle is seen (misses), never false presences
    assert s.rates.p_f == 0.0 and s.rates.p_m < 0.25
    noisy = write_detections(lab_copy, lab_copy.parent / "noisy.parquet", seed=1)
    s2 = label_dataset(lab_copy, f"detections:{noisy}")
    assert s2.rates is not None and s2.rates.p_m >= s.rates.p_m - 0.05


def test_noisy_source_rates_on_lab(lab_copy: Path) -> None:
    p_m, p_f = 0.1, 0.1
    label_dataset(lab_copy, "privileged")
    s = label_dataset(lab_copy, f"noisy:{p_m}", seed=0)
    assert s.source == "noisy:0.1,0.1"
    ds = open_dataset(lab_copy)
    import pyarrow as pa
    import pyarrow.compute as pc

    # object rows only (the summary's rates are the objects'; the door rows are labelled too)
    t = ds.table("labels")
    t = t.filter(pc.is_in(t["object_id"], value_set=pa.array(list(ds.objects))))
    labels = LabelGrid.from_table(t, "noisy:0.1,0.1")
    priv = LabelGrid.from_table(t, "privileged")
    # relative to the privileged codes the flips are exactly the injected noise
    r = error_rates(labels, priv, confidence=0.99)
    assert r.p_m_ci[0] <= p_m <= r.p_m_ci[1] and r.p_f_ci[0] <= p_f <= r.p_f_ci[1]
    # privileged agrees with ground truth on observed cells, so the estimate against gt is the same
    assert s.rates is not None and s.rates.p_m == r.p_m and s.rates.p_f == r.p_f


def _visits_by_loop(gt: np.ndarray, codes: np.ndarray) -> tuple[int, int]:
    """(visits of moving objects, visits with a code 1 on their receptacle), scan by scan."""
    visits = seen = 0
    for o in range(gt.shape[1]):
        rec = [int(np.argmax(gt[s, o] == 1)) if (gt[s, o] == 1).any() else -1 for s in range(gt.shape[0])]
        if len(set(rec)) < 2:
            continue
        s = 0
        while s < len(rec):
            e = s
            while e + 1 < len(rec) and rec[e + 1] == rec[s]:
                e += 1
            if rec[s] >= 0:
                visits += 1
                seen += bool((codes[s:e + 1, o, rec[s]] == 1).any())
            s = e + 1
    return visits, seen


def test_visibility_statistics_count_visits_as_a_scan_by_scan_loop(lab_path: Path) -> None:
    from psg_data.labeling import compute_labels, visibility_statistics

    ds = open_dataset(lab_path)
    res = compute_labels(ds, "privileged")
    visits, seen = _visits_by_loop(res.gt.codes, res.labels.codes)
    out = visibility_statistics(ds)
    assert visits > 0 and out["visits_scanned"] == visits
    assert out["visits_seen_privileged"] == pytest.approx(seen / visits)
    assert 0.0 < out["present_scans_seen_privileged"] <= 1.0
