"""Turning a labelled dataset into the inputs of :func:`evaluate_persistence`.

A :class:`PersistenceTask` bundles training / validation / test observation streams, ground truth
per edge and the site timezone. :func:`persistence_task_from_dataset` builds it from a psg-dataset:

- **edges**: every (object, receptacle) pair in the object's valid set (the receptacles the
  ground-truth schedule ever puts it on; code -2 elsewhere);
- **observations**: the chosen label source, one observation per scan where the code is 1 or 0
  (``gt`` is computed on the fly from the schedule table; other sources are read from the
  dataset's ``labels`` table, written by ``psg-data label``);
- **split**: the ``scans.split`` column when it is filled (``train`` / ``val`` / ``test``),
  otherwise by time: the first two weeks train, the third week test;
- **ground truth**: the schedule table at the test scans (a step function between scans), or a
  denser grid given by ``dense_ground_truth`` (the synthetic lab knows its schedule at any time).
  The training streams carry the training window's ground truth the same way in
  ``meta['gt_t_s']`` / ``meta['gt_state']`` (used only by oracle switching priors and by
  ``durations="ground_truth"``), so ``perpetua_star_oracle`` runs on any dataset with a schedule.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError, LabelingError
from psg_data.estimators._base import EdgeKey, EdgeStream

__all__ = ["PersistenceTask", "persistence_task_from_dataset", "DenseGroundTruth"]

DenseGroundTruth = Callable[[int, int], tuple[NDArray[np.int64], Mapping[EdgeKey, NDArray[np.int64]]]]
"""``f(start_ns, end_ns) -> (stamps_ns, {edge: 0/1 states})``: ground truth on a grid inside a window."""

_WEEK_NS = 7 * 86400 * 10**9


@dataclass
class PersistenceTask:
    """Inputs of one persistence evaluation.

    Attributes:
        name: dataset or benchmark name.
        train_streams: observations before the test window, one stream per edge.
        test_streams: observations inside the test window (used online in the adaptive setting).
        ground_truth: edge -> (t_s, states) on the test window (1 present, 0 absent).
        timezone: IANA site timezone.
        val_streams: held-out observations for model selection (FreMEn order), or None.
        info: provenance (label source, split rule, counts) stored in results.json.
        estimator_hints: settings an estimator may use if it has them and the user did not set
            them (e.g. ``schedules`` for the schedule prior on the benchmark).
    """

    name: str
    train_streams: list[EdgeStream]
    test_streams: list[EdgeStream]
    ground_truth: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]]
    timezone: str
    val_streams: list[EdgeStream] | None = None
    info: dict[str, Any] = field(default_factory=dict)
    estimator_hints: dict[str, Any] = field(default_factory=dict)


def _split_masks(ds: Any, stamps_ns: NDArray[np.int64], scan_ids: list[str]) -> tuple[dict[str, NDArray[np.bool_]], str]:
    scans = ds.df("scans").set_index("scan_id")
    split = scans["split"].reindex(scan_ids)
    if split.notna().all() and (split == "test").any():
        s = split.to_numpy()
        return {k: s == k for k in ("train", "val", "test")}, "declared by scans.split"
    t0 = int(stamps_ns.min())
    week = (stamps_ns - t0) // _WEEK_NS
    return ({"train": week < 2, "val": np.zeros(stamps_ns.shape, bool), "test": week == 2},
            "by time: weeks 1-2 train, week 3 test (scans.split not filled)")


def persistence_task_from_dataset(
    dataset: Any,
    *,
    labels: str = "gt",
    dense_ground_truth: DenseGroundTruth | None = None,
    seed: int = 0,
) -> PersistenceTask:
    """Build a :class:`PersistenceTask` from a psg-dataset (see the module docstring).

    Args:
        dataset: a :class:`~psg_data.loaders.Dataset` or its path.
        labels: ``gt`` (computed from the schedule) or a source stored in the ``labels`` table
            (``privileged``, ``noisy:0.1``, ``detections:FILE``).
        dense_ground_truth: optional ground truth on a grid denser than the scans.
        seed: seed of on-the-fly label sources.

    Raises:
        EvaluationError: no labels of that source (the message says which ``psg-data label`` to
            run), no test scans, or no edges.
    """
    from psg_data.labeling import LabelGrid, compute_labels, ground_truth, parse_source
    from psg_data.loaders import open_dataset

    ds = dataset if hasattr(dataset, "table") else open_dataset(dataset)
    try:
        gt = ground_truth(ds)
    except LabelingError as exc:
        raise EvaluationError(f"{ds.root}: cannot derive ground truth ({exc})") from None
    try:
        spec = parse_source(labels)
    except LabelingError as exc:
        raise EvaluationError(str(exc)) from None
    if spec.kind == "observed":
        raise EvaluationError("labels 'observed': a door-only source (door states read from the depth images); the "
                              "persistence task scores object edges: use gt, privileged, noisy:P or detections:FILE, "
                              "or score doors with `psg-eval --task doors --labels observed`")
    if spec.kind == "gt":
        grid = compute_labels(ds, "gt", seed=seed).labels
    else:
        if not ds.has_table("labels"):
            raise EvaluationError(
                f"{ds.root}: dataset has no labels table; run `psg-data label {ds.root} --source {labels}` first")
        try:
            grid = LabelGrid.from_table(ds.table("labels"), spec.name)
        except LabelingError:
            have = sorted(set(ds.table("labels").column("source").to_pylist()))
            raise EvaluationError(
                f"{ds.root}: tables/labels.parquet has no {spec.name!r} labels (it has {', '.join(have) or 'none'}); "
                f"run `psg-data label {ds.root} --source {labels}` first") from None
    codes = gt.aligned(grid) if grid.codes.shape != gt.codes.shape or grid.scan_ids != gt.scan_ids else grid.codes
    masks, split_rule = _split_masks(ds, gt.stamps_ns, gt.scan_ids)
    if not masks["test"].any():
        raise EvaluationError(f"{ds.root}: the test split is empty (no scan in the test window); "
                              "fill scans.split or provide three weeks of scans")
    t_s = gt.stamps_ns.astype(np.float64) / 1e9
    valid = gt.valid
    edges = [(gt.object_ids[o], gt.receptacle_ids[r]) for o, r in zip(*np.nonzero(valid))]
    if not edges:
        raise EvaluationError(f"{ds.root}: no edges (the schedule never places an object on a receptacle)")

    def streams(mask: NDArray[np.bool_], truth: Mapping[EdgeKey, tuple[Any, Any]] | None = None) -> list[EdgeStream]:
        out = []
        for o, r in zip(*np.nonzero(valid)):
            c = codes[:, o, r]
            m = mask & ((c == 0) | (c == 1))
            e = (gt.object_ids[o], gt.receptacle_ids[r])
            meta: dict[str, Any] = {"source": grid.source}
            if truth is not None:  # the training ground truth (oracle switching priors)
                meta["gt_t_s"], meta["gt_state"] = truth[e]
            out.append(EdgeStream(e, t_s[m], c[m].astype(np.int8), meta))
        return out

    test_idx = np.flatnonzero(masks["test"])
    truth: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]] = {}
    gt_kind = "schedule table at the test scans"
    if dense_ground_truth is not None:
        scans = ds.df("scans").set_index("scan_id")
        start = int(gt.stamps_ns[test_idx[0]])
        end = int(scans.loc[gt.scan_ids[test_idx[-1]], "end_stamp_ns"]) + 1
        stamps, states = dense_ground_truth(start, end)
        for e in edges:
            truth[e] = (np.asarray(stamps, np.float64) / 1e9, np.asarray(states[e], np.int64))
        step = float(np.median(np.diff(stamps))) / 1e9 if len(stamps) > 1 else 0.0
        gt_kind = f"dense schedule every {step:g} s over the test window"
    else:
        for o, r in zip(*np.nonzero(valid)):
            truth[(gt.object_ids[o], gt.receptacle_ids[r])] = (t_s[test_idx], gt.codes[test_idx, o, r].astype(np.int64))
    val = streams(masks["val"]) if masks["val"].any() else None
    train_truth = _train_truth(ds, gt, masks["train"], edges, dense_ground_truth)
    return PersistenceTask(
        name=ds.info.name,
        train_streams=streams(masks["train"], train_truth),
        test_streams=streams(masks["test"]),
        ground_truth=truth,
        timezone=ds.info.timezone,
        val_streams=val,
        info={"dataset": str(ds.root), "format_version": ds.info.format_version, "labels": grid.source,
              "split": split_rule, "ground_truth": gt_kind, "edges": len(edges),
              "scans": {k: int(v.sum()) for k, v in masks.items()}},
    )


def _train_truth(ds: Any, gt: Any, train: NDArray[np.bool_], edges: list[EdgeKey],
                 dense: DenseGroundTruth | None) -> dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int8]]] | None:
    """Ground truth over the training window per edge: the dense grid when given, else the schedule
    at the training scans (a step function). None when there is no training scan."""
    idx = np.flatnonzero(train)
    if idx.size == 0:
        return None
    if dense is not None:
        scans = ds.df("scans").set_index("scan_id")
        start = int(gt.stamps_ns[idx[0]])
        end = int(scans.loc[gt.scan_ids[idx[-1]], "end_stamp_ns"]) + 1
        stamps, states = dense(start, end)
        t = np.asarray(stamps, np.float64) / 1e9
        return {e: (t, np.asarray(states[e], np.int8)) for e in edges}
    t = gt.stamps_ns[idx].astype(np.float64) / 1e9
    oi = {o: i for i, o in enumerate(gt.object_ids)}
    ri = {r: i for i, r in enumerate(gt.receptacle_ids)}
    return {e: (t, (gt.codes[idx, oi[e[0]], ri[e[1]]] == 1).astype(np.int8)) for e in edges}
