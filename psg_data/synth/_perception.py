"""A simulated perception source: per-scan detections as a scene-graph builder would emit them.

Only what the renderer shows is detected: an object or receptacle is *visible* in a scan when at
least ``min_pixels`` pixels of one frame's instance-id image belong to it (so very small or far
objects are missed the way a real detector misses them). Errors, all seeded:

* miss: each visible object is dropped with probability ``miss_rate`` (receptacles with
  ``receptacle_miss_rate``);
* false positive: on each visible receptacle, with probability ``false_positive_rate``, a spurious
  object detection (a random object that is not on it) appears on its top surface;
* confusion: a kept object detection takes the label of a similar object
  (:data:`~psg_data.synth._catalog.CONFUSABLE`, e.g. redbowl/redplate) with probability
  ``confusion_rate`` (objects without a look-alike keep their label);
* noise: Gaussian centroid noise of ``centroid_noise_m`` per axis, box size noise of 10 % (log-normal)
  and yaw noise of 5 deg; scores ~ Beta(8, 2) for true detections, Beta(2, 3) for false ones.

``detections.parquet`` layout (one row per detection):

==============  ===================  =========================================================
column          type                 meaning
==============  ===================  =========================================================
scan_id         string               scan
label           string               detected class: object name, or receptacle category
kind            string               'object' or 'receptacle'
centroid_m      list<double>[3]      centroid of the detection's points, world frame, metres
box_center_m    list<double>[3]      oriented box centre, world frame, metres
box_extent_m    list<double>[3]      box side lengths, metres
box_rotation    list<double>[9]      row-major world-from-box rotation
score           double               detector confidence in [0, 1]
frame_index     int32                frame with the most pixels of the instance
pixels          int32                pixels of the instance in that frame (0 for false positives)
gt_id           string (nullable)    true object_id / receptacle_id; null for false positives
==============  ===================  =========================================================
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from psg_data._geometry import yaw_rotation
from psg_data.schemas._records import CameraIntrinsics
from psg_data.synth._catalog import CONFUSABLE
from psg_data.synth._layout import OBJECT_ID0, RECEPTACLE_ID0
from psg_data.synth._model import LabModel
from psg_data.synth._render import SceneState

__all__ = ["write_detections", "detect", "DETECTIONS_SCHEMA", "visible_instances"]

log = logging.getLogger(__name__)

_V3, _M3 = pa.list_(pa.float64(), 3), pa.list_(pa.float64(), 9)
DETECTIONS_SCHEMA = pa.schema([
    pa.field("scan_id", pa.string(), nullable=False),
    pa.field("label", pa.string(), nullable=False),
    pa.field("kind", pa.string(), nullable=False),
    pa.field("centroid_m", _V3, nullable=False),
    pa.field("box_center_m", _V3, nullable=False),
    pa.field("box_extent_m", _V3, nullable=False),
    pa.field("box_rotation", _M3, nullable=False),
    pa.field("score", pa.float64(), nullable=False),
    pa.field("frame_index", pa.int32(), nullable=False),
    pa.field("pixels", pa.int32(), nullable=False),
    pa.field("gt_id", pa.string(), nullable=True),
])
"""Arrow schema of ``detections.parquet``."""


def _scans(source: Any) -> tuple[LabModel, Iterator[tuple[int, str, SceneState, np.ndarray, CameraIntrinsics]]]:
    if isinstance(source, LabModel):
        lab = source

        def it_lab() -> Iterator[tuple[int, str, SceneState, np.ndarray, CameraIntrinsics]]:
            for p in lab.scans:
                yield p.index, p.scan_id, p.state, p.poses, lab.camera
        return lab, it_lab()
    if isinstance(source, (str, Path)):
        from psg_data.loaders import open_dataset

        source = open_dataset(source)
    ds = source
    lab = LabModel.from_dataset(ds)
    sched = ds.table("schedule").to_pylist()
    doors = ds.table("door_states").to_pylist()

    def it_ds() -> Iterator[tuple[int, str, SceneState, np.ndarray, CameraIntrinsics]]:
        for k, sid in enumerate(ds.scan_ids):
            st = SceneState({r["object_id"]: r["receptacle_id"] for r in sched if r["scan_id"] == sid},
                            {r["door_id"]: r["state"] == "open" for r in doors if r["scan_id"] == sid})
            scan = ds.scan(sid)
            cam = ds.cameras[str(scan.camera_ids[0])] if len(scan) else lab.camera
            yield k, sid, st, scan.poses, cam
    return lab, it_ds()


def visible_instances(lab: LabModel, state: SceneState, poses: np.ndarray, camera: CameraIntrinsics,
                      min_pixels: int = 4) -> dict[int, tuple[int, int]]:
    """Instances seen in a scan: ``instance_id -> (best frame index, pixels in that frame)``.

    An instance is visible if some frame has at least ``min_pixels`` pixels of it.
    """
    rend = lab.renderer(state)
    best: dict[int, tuple[int, int]] = {}
    for i, T in enumerate(poses):
        fr = rend.render(T, camera, noise=None)
        ids, counts = np.unique(fr.instance_ids, return_counts=True)
        for iid, n in zip(ids.tolist(), counts.tolist()):
            if n >= min_pixels and n > best.get(iid, (-1, -1))[1]:
                best[iid] = (i, n)
    return best


def detect(source: Any, *, seed: int = 0, miss_rate: float = 0.1, false_positive_rate: float = 0.05,
           centroid_noise_m: float = 0.03, confusion_rate: float = 0.05, perfect: bool = False,
           receptacle_miss_rate: float = 0.0, min_pixels: int = 4) -> pa.Table:
    """Simulated detections of every scan as an Arrow table (:data:`DETECTIONS_SCHEMA`).

    Args:
        source: a :class:`LabModel`, or a synthetic dataset (opened :class:`Dataset` or its path).
        seed: seed of the perception errors.
        miss_rate: probability of missing a visible object.
        false_positive_rate: probability of a spurious object detection per visible receptacle.
        centroid_noise_m: std of the centroid noise per axis, metres.
        confusion_rate: probability that a detected object takes a look-alike's label.
        perfect: no errors, no noise: exactly the visible ground truth with score 1.
        receptacle_miss_rate: probability of missing a visible receptacle.
        min_pixels: pixels an instance needs in one frame to count as visible.
    """
    lab, scans = _scans(source)
    L = lab.layout
    rows: list[dict[str, Any]] = []
    for k, sid, state, poses, cam in scans:
        rng = np.random.default_rng([int(seed), 601, k])
        vis = visible_instances(lab, state, poses, cam, min_pixels)
        oboxes = L.object_boxes(state.objects)
        for iid in sorted(vis):
            fi, npx = vis[iid]
            if RECEPTACLE_ID0 <= iid < OBJECT_ID0 and iid - RECEPTACLE_ID0 < len(L.receptacles):
                rec = L.receptacles[iid - RECEPTACLE_ID0]
                if not perfect and rng.random() < receptacle_miss_rate:
                    continue
                rows.append(_row(sid, rec.category or "receptacle", "receptacle", rec.box.center_m, rec.box.extent_m,
                                 rec.box.rotation, fi, npx, rec.receptacle_id, rng, perfect, centroid_noise_m, True))
                if not perfect and rng.random() < false_positive_rate:
                    on = {o for o, r in state.objects.items() if r == rec.receptacle_id}
                    names = [o.name for o in L.objects if o.name not in on]
                    o = L.objects[[x.name for x in L.objects].index(names[int(rng.integers(len(names)))])]
                    R = np.asarray(rec.box.rotation)
                    e = np.asarray(rec.box.extent_m)
                    loc = np.array([*(rng.uniform(-0.4, 0.4, 2) * e[:2]), e[2] / 2 + o.size_m[2] / 2])
                    rows.append(_row(sid, o.name, "object", R @ loc + np.asarray(rec.box.center_m),
                                     np.asarray(o.size_m), R, fi, 0, None, rng, perfect, centroid_noise_m, False))
            elif iid >= OBJECT_ID0 and iid - OBJECT_ID0 < len(L.objects):
                o = L.objects[iid - OBJECT_ID0]
                if not perfect and rng.random() < miss_rate:
                    continue
                label = o.name
                if not perfect and o.name in CONFUSABLE and rng.random() < confusion_rate:
                    alts = CONFUSABLE[o.name]
                    label = alts[int(rng.integers(len(alts)))]
                b = oboxes[o.name]
                rows.append(_row(sid, label, "object", b.center_m, b.extent_m, b.rotation, fi, npx, o.name, rng,
                                 perfect, centroid_noise_m, True))
    return pa.Table.from_pylist(rows, schema=DETECTIONS_SCHEMA)


def _row(scan_id: str, label: str, kind: str, center: Any, extent: Any, rotation: Any, frame_index: int,
         pixels: int, gt_id: str | None, rng: np.random.Generator, perfect: bool, sigma: float, true: bool
         ) -> dict[str, Any]:
    c = np.asarray(center, float)
    e = np.asarray(extent, float)
    R = np.asarray(rotation, float)
    score = 1.0
    if not perfect:
        c = c + rng.normal(0.0, sigma, 3)
        e = e * np.exp(rng.normal(0.0, 0.1, 3))
        R = yaw_rotation(rng.normal(0.0, np.deg2rad(5.0))) @ R
        score = float(rng.beta(8, 2) if true else rng.beta(2, 3))
    return {"scan_id": scan_id, "label": label, "kind": kind, "centroid_m": c.tolist(), "box_center_m": c.tolist(),
            "box_extent_m": e.tolist(), "box_rotation": R.reshape(9).tolist(), "score": score,
            "frame_index": int(frame_index), "pixels": int(pixels), "gt_id": gt_id}


def write_detections(dataset_or_lab: Any, path: str | Path, *, seed: int = 0, miss_rate: float = 0.1,
                     false_positive_rate: float = 0.05, centroid_noise_m: float = 0.03, confusion_rate: float = 0.05,
                     perfect: bool = False, receptacle_miss_rate: float = 0.0, min_pixels: int = 4) -> Path:
    """Write :func:`detect`'s detections to ``path`` (``detections.parquet``, layout in the module doc).

    Replaces the file at ``path`` atomically (an interrupted call leaves the previous one as it
    was); never inside the input dataset.

    Raises:
        UnsafeOutputError: ``path`` is, contains or lies inside the input dataset (checked before
            anything is computed).
    """
    import pyarrow.parquet as pq

    from psg_data.writers._safe_output import check_not_input, write_atomically

    path = Path(path)
    inputs = [dataset_or_lab if isinstance(dataset_or_lab, (str, Path)) else getattr(dataset_or_lab, "root", None)]
    check_not_input(path, inputs)
    table = detect(dataset_or_lab, seed=seed, miss_rate=miss_rate, false_positive_rate=false_positive_rate,
                   centroid_noise_m=centroid_noise_m, confusion_rate=confusion_rate, perfect=perfect,
                   receptacle_miss_rate=receptacle_miss_rate, min_pixels=min_pixels)
    write_atomically(path, lambda tmp: pq.write_table(table, tmp, compression="zstd"), inputs=inputs)
    log.info("wrote %d detections to %s", table.num_rows, path)
    return path
