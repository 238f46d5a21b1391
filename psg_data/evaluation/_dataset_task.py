"""The inputs of the persistence task: from a labelled dataset, a synthetic lab or the Sec. V-A benchmark.

A :class:`PersistenceTask` bundles training / validation / test observation streams, ground truth
per edge, the site timezone and what the dataset says about how to score it (scoring windows,
scan cadence, protocol). Builders:

- :func:`persistence_task_from_dataset` (any psg-dataset):

  - **edges**: every (object, receptacle) pair in the object's valid set (the receptacles the
    ground-truth schedule ever puts it on; code -2 elsewhere);
  - **observations**: one per scan where the label source's code is 1 or 0: ``gt`` (the
    schedule), ``noisy:P[,P_F]`` (the schedule at every scan, each observation flipped present ->
    absent with P and absent -> present with P_F, deterministic by ``seed``: the paper's "noised
    ground truth", the same flips as navigation and the door task use), or a source stored in the
    dataset's ``labels`` table (``privileged``, ``detections:FILE``; written by ``psg-data label``);
  - **split**: the ``scans.split`` column when it is filled, otherwise by time: the first two
    weeks train, the third week test;
  - **ground truth**: the schedule table at the test scans (a step function between scans), or a
    denser grid: a synthetic lab knows its state at any time, and is scored every 15 min,
    clock-aligned, inside its scoring windows;
  - **scoring windows and cadence**: :func:`~psg_data.evaluation.dataset_windows`,
    :func:`~psg_data.evaluation.dataset_cadence_s`;
  - the training streams carry the training window's ground truth in ``meta['gt_t_s']`` /
    ``meta['gt_state']`` (used only by oracle switching priors and ``durations="ground_truth"``).

- :func:`persistence_task_from_lab`: the same task straight from a :class:`~psg_data.synth.LabModel`
  (no images rendered; label sources ``gt`` and ``noisy``), equal to the task of the dataset that
  ``psg-data synth`` writes for the same lab (tested). ``--lab-seeds`` uses it.
- :func:`persistence_task_from_benchmark`: one draw of the Sec. V-A benchmark, scored with the
  paper's protocol (adaptive with no horizon, plain trapezoid over the dense 60 s grid).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import EvaluationError, LabelingError
from psg_data.estimators._base import EdgeKey, EdgeStream
from psg_data.evaluation._windows import DailyWindows

__all__ = ["PersistenceTask", "persistence_task_from_dataset", "persistence_task_from_lab",
           "persistence_task_from_benchmark", "DenseGroundTruth", "DENSE_STEP_S"]

DenseGroundTruth = Callable[[int, int], tuple[NDArray[np.int64], Mapping[EdgeKey, NDArray[np.int64]]]]
"""``f(start_ns, end_ns) -> (stamps_ns, {edge: 0/1 states})``: ground truth on a grid inside a window."""

DENSE_STEP_S = 900.0
"""Grid step of a synthetic lab's dense ground truth (15 min, clock-aligned)."""

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
            them (e.g. ``schedules`` for the schedule prior, ``dataset`` / ``model`` for
            ``process_oracle``).
        windows: the dataset's scoring windows (None: unknown; the plain trapezoid is used).
        cadence_s: typical time between two scans of a day, seconds (None: not a scanned dataset).
        protocol: fixed scoring choices of the task (``weighting``, ``horizon_s``, ``name``) that
            :class:`~psg_data.evaluation.PersistenceOptions` ``"auto"`` follows.
        draw: which regenerated draw of a synthetic dataset this is (0 for a fixed dataset).
    """

    name: str
    train_streams: list[EdgeStream]
    test_streams: list[EdgeStream]
    ground_truth: dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]]
    timezone: str
    val_streams: list[EdgeStream] | None = None
    info: dict[str, Any] = field(default_factory=dict)
    estimator_hints: dict[str, Any] = field(default_factory=dict)
    windows: DailyWindows | None = None
    cadence_s: float | None = None
    protocol: dict[str, Any] = field(default_factory=dict)
    draw: int = 0

    @property
    def horizon_reason(self) -> str:
        """Why the default horizon is what it is (one line for the table)."""
        if "horizon_s" in self.protocol:
            return str(self.protocol.get("name") or "the task's protocol")
        if self.cadence_s:
            from psg_data.evaluation._windows import format_duration

            return (f"one scan interval of this dataset ({format_duration(self.cadence_s)}): a scan reveals the "
                    "state of its interval, so a shorter horizon mostly rewards repeating the last scan")
        return "no scan cadence known"


# -- label grids --------------------------------------------------------------------------------------
def _label_grid(ds: Any, gt: Any, labels: str, seed: int) -> Any:
    """The label source's codes on the ground truth's axes (module docstring)."""
    from psg_data.labeling import LabelGrid, inject_noise, parse_source

    try:
        spec = parse_source(labels)
    except LabelingError as exc:
        raise EvaluationError(str(exc)) from None
    if spec.kind == "observed":
        raise EvaluationError("labels 'observed': a door-only source (door states read from the depth images); the "
                              "persistence task scores object edges: use gt, privileged, noisy:P or detections:FILE, "
                              "or score doors with `psg-eval --task doors --labels observed`")
    if spec.kind == "gt":
        return gt
    if spec.kind == "noisy":
        return inject_noise(gt, spec.p_m, spec.p_f, seed, f"{labels} (ground truth, flipped)")
    if ds is None:
        raise EvaluationError(f"labels {labels!r}: a lab drawn without images has only its ground truth; use gt or "
                              "noisy:P, or build the dataset (psg-data synth) and label it")
    if not ds.has_table("labels"):
        raise EvaluationError(f"{ds.root}: dataset has no labels table; run `psg-data label {ds.root} --source "
                              f"{labels}` first")
    try:
        grid = LabelGrid.from_table(ds.table("labels"), spec.name)
    except LabelingError:
        have = sorted(set(ds.table("labels").column("source").to_pylist()))
        raise EvaluationError(f"{ds.root}: tables/labels.parquet has no {spec.name!r} labels (it has "
                              f"{', '.join(have) or 'none'}); run `psg-data label {ds.root} --source {labels}` first"
                              ) from None
    if grid.codes.shape != gt.codes.shape or grid.scan_ids != gt.scan_ids:
        return gt.with_codes(gt.aligned(grid), grid.source)
    return grid


def _split_masks(split: list[Any], stamps_ns: NDArray[np.int64]) -> tuple[dict[str, NDArray[np.bool_]], str]:
    s = np.array([None if x is None or (isinstance(x, float) and np.isnan(x)) else x for x in split], dtype=object)
    if all(x is not None for x in s) and (s == "test").any():
        return {k: s == k for k in ("train", "val", "test")}, "declared by scans.split"
    week = (stamps_ns - int(stamps_ns.min())) // _WEEK_NS
    return ({"train": week < 2, "val": np.zeros(stamps_ns.shape, bool), "test": week == 2},
            "by time: weeks 1-2 train, week 3 test (scans.split not filled)")


# -- the common builder -----------------------------------------------------------------------------
@dataclass
class _Grids:
    """What a task is built from: ground truth and label codes per scan, the split, scan end times."""

    gt: Any
    codes: NDArray[np.int8]
    source: str
    masks: dict[str, NDArray[np.bool_]]
    split_rule: str
    end_ns: NDArray[np.int64]


def _streams(g: _Grids, mask: NDArray[np.bool_], truth: Mapping[EdgeKey, tuple[Any, Any]] | None = None
             ) -> list[EdgeStream]:
    gt = g.gt
    t_s = gt.stamps_ns.astype(np.float64) / 1e9
    out = []
    for o, r in zip(*np.nonzero(gt.valid)):
        c = g.codes[:, o, r]
        m = mask & ((c == 0) | (c == 1))
        e = (gt.object_ids[o], gt.receptacle_ids[r])
        meta: dict[str, Any] = {"source": g.source}
        if truth is not None:  # the training ground truth (oracle switching priors)
            meta["gt_t_s"], meta["gt_state"] = truth[e]
        out.append(EdgeStream(e, t_s[m], c[m].astype(np.int8), meta))
    return out


def _window_truth(g: _Grids, split: str, edges: list[EdgeKey], dense: DenseGroundTruth | None
                  ) -> tuple[dict[EdgeKey, tuple[NDArray[np.float64], NDArray[np.int64]]], str] | None:
    """Ground truth of a split: the dense grid when given, else the schedule at the split's scans."""
    idx = np.flatnonzero(g.masks[split])
    if idx.size == 0:
        return None
    gt = g.gt
    if dense is not None:
        stamps, states = dense(int(gt.stamps_ns[idx[0]]), int(g.end_ns[idx[-1]]) + 1)
        t = np.asarray(stamps, np.float64) / 1e9
        step = float(np.median(np.diff(stamps))) / 1e9 if len(stamps) > 1 else 0.0
        return {e: (t, np.asarray(states[e], np.int64)) for e in edges}, f"dense schedule every {step:g} s"
    t = gt.stamps_ns[idx].astype(np.float64) / 1e9
    oi = {o: i for i, o in enumerate(gt.object_ids)}
    ri = {r: i for i, r in enumerate(gt.receptacle_ids)}
    return ({e: (t, gt.codes[idx, oi[e[0]], ri[e[1]]].astype(np.int64)) for e in edges},
            f"schedule table at the {split} scans")


def _task(name: str, g: _Grids, dense: DenseGroundTruth | None, timezone: str, info: dict[str, Any]
          ) -> PersistenceTask:
    gt = g.gt
    if not g.masks["test"].any():
        raise EvaluationError(f"{info.get('dataset', name)}: the test split is empty (no scan in the test window); "
                              "fill scans.split or provide three weeks of scans")
    edges = [(gt.object_ids[o], gt.receptacle_ids[r]) for o, r in zip(*np.nonzero(gt.valid))]
    if not edges:
        raise EvaluationError(f"{info.get('dataset', name)}: no edges (the schedule never places an object on a "
                              "receptacle)")
    test_truth = _window_truth(g, "test", edges, dense)
    assert test_truth is not None
    train_truth = _window_truth(g, "train", edges, dense)
    if train_truth is not None and dense is not None:  # oracle priors get 0/1 int8 states
        train_truth = ({e: (t, y.astype(np.int8)) for e, (t, y) in train_truth[0].items()}, train_truth[1])
    elif train_truth is not None:
        train_truth = ({e: (t, (y == 1).astype(np.int8)) for e, (t, y) in train_truth[0].items()}, train_truth[1])
    val = _streams(g, g.masks["val"]) if g.masks["val"].any() else None
    kind = test_truth[1] + (" over the test window" if dense is not None else "")
    return PersistenceTask(
        name=name, train_streams=_streams(g, g.masks["train"], train_truth[0] if train_truth else None),
        test_streams=_streams(g, g.masks["test"]), ground_truth=test_truth[0], timezone=timezone, val_streams=val,
        info={**info, "labels": g.source, "split": g.split_rule, "ground_truth": kind, "edges": len(edges),
              "scans": {k: int(v.sum()) for k, v in g.masks.items()}})


def _lab_dense(lab: Any, windows: DailyWindows, step_s: float = DENSE_STEP_S) -> DenseGroundTruth:
    """Dense ground truth of a synthetic lab, every ``step_s`` aligned with the clock, inside ``windows``
    (both ends included, so that a state changing at a step start changes on a grid point).
    """
    step_ns = int(round(step_s * 1e9))

    def dense(start_ns: int, end_ns: int) -> tuple[NDArray[np.int64], dict[EdgeKey, NDArray[np.int64]]]:
        d = lab.schedule.dense(step_s, start_ns - start_ns % step_ns, end_ns)
        t = d.stamps_ns.astype(np.float64) / 1e9
        keep = windows.contains(t) | windows.contains(t - 1e-3)  # the window's end point too
        objs = d.objects[keep]
        states = {}
        for j, o in enumerate(d.object_ids):
            for i, r in enumerate(d.receptacle_ids):
                states[(o, r)] = (objs[:, j] == i).astype(np.int64)
        return d.stamps_ns[keep], states

    return dense


# -- public builders -----------------------------------------------------------------------------------
def persistence_task_from_dataset(dataset: Any, *, labels: str = "gt",
                                  dense_ground_truth: DenseGroundTruth | str | None = "auto",
                                  seed: int = 0) -> PersistenceTask:
    """Build a :class:`PersistenceTask` from a psg-dataset (see the module docstring).

    Args:
        dataset: a :class:`~psg_data.loaders.Dataset` or its path.
        labels: ``gt``, ``noisy:P[,P_F]`` (computed from the schedule) or a source stored in the
            ``labels`` table (``privileged``, ``detections:FILE``).
        dense_ground_truth: ``"auto"`` (a synthetic lab's dense schedule, else the scans), None
            (the schedule at the test scans) or a :data:`DenseGroundTruth` function.
        seed: seed of the ``noisy`` flips.

    Raises:
        EvaluationError: no labels of that source (the message says which ``psg-data label`` to
            run), no test scans, or no edges.
    """
    from psg_data.evaluation._hints import dataset_hints
    from psg_data.evaluation._windows import dataset_cadence_s, dataset_windows
    from psg_data.labeling import ground_truth
    from psg_data.loaders import open_dataset

    ds = dataset if hasattr(dataset, "table") else open_dataset(dataset)
    try:
        gt = ground_truth(ds)
    except LabelingError as exc:
        raise EvaluationError(f"{ds.root}: cannot derive ground truth ({exc})") from None
    grid = _label_grid(ds, gt, labels, seed)
    scans = ds.df("scans").set_index("scan_id")
    masks, rule = _split_masks(scans["split"].reindex(gt.scan_ids).tolist(), gt.stamps_ns)
    end_ns = scans["end_stamp_ns"].reindex(gt.scan_ids).to_numpy(np.int64)
    windows = dataset_windows(ds)
    dense = dense_ground_truth
    if dense == "auto":
        dense = None
        if ds.info.extra.get("generator") == "psg_data.synth":
            from psg_data.synth import LabModel

            dense = _lab_dense(LabModel.from_dataset(ds), windows)
    g = _Grids(gt, grid.codes, grid.source, masks, rule, end_ns)
    task = _task(ds.info.name, g, dense, ds.info.timezone,  # type: ignore[arg-type]
                 {"dataset": str(ds.root), "format_version": ds.info.format_version, "labels_spec": labels,
                  "label_seed": int(seed)})
    task.windows, task.cadence_s, task.estimator_hints = windows, dataset_cadence_s(ds), dataset_hints(ds)
    return task


def lab_ground_truth(lab: Any) -> Any:
    """The ground-truth :class:`~psg_data.labeling.LabelGrid` of a :class:`~psg_data.synth.LabModel`
    (what :func:`psg_data.labeling.ground_truth` gives on the dataset ``psg-data synth`` writes).
    """
    from psg_data.labeling import LabelGrid
    from psg_data.schemas._tables import CODE_ABSENT, CODE_INVALID, CODE_PRESENT

    L, plans = lab.layout, lab.scans
    objs = [o.name for o in L.objects]
    recs = [r.receptacle_id for r in L.receptacles]
    ri = {r: i for i, r in enumerate(recs)}
    present = np.zeros((len(plans), len(objs), len(recs)), bool)
    for s, p in enumerate(plans):
        for j, o in enumerate(objs):
            r = p.state.objects.get(o)
            if r is not None:
                present[s, j, ri[r]] = True
    codes = np.where(present, CODE_PRESENT, CODE_ABSENT).astype(np.int8)
    codes[:, ~present.any(axis=0)] = CODE_INVALID
    starts = np.array([p.start_ns for p in plans], np.int64)
    return LabelGrid([p.scan_id for p in plans], objs, recs, starts, codes, "gt")


def persistence_task_from_lab(lab: Any, *, labels: str = "gt", seed: int = 0) -> PersistenceTask:
    """The persistence task of a synthetic lab without rendering it (module docstring).

    Args:
        lab: a :class:`~psg_data.synth.LabModel` or a :class:`~psg_data.synth.LabConfig`.
        labels: ``gt`` or ``noisy:P[,P_F]``.
        seed: seed of the ``noisy`` flips.
    """
    from psg_data.evaluation._windows import DailyWindows, _synth_hours
    from psg_data.synth import LabModel
    from psg_data.synth._process import llm_schedules

    if not hasattr(lab, "schedule"):
        lab = LabModel(lab)
    cfg = lab.config
    gt = lab_ground_truth(lab)
    grid = _label_grid(None, gt, labels, seed)
    plans = lab.scans
    masks, rule = _split_masks([p.split for p in plans], gt.stamps_ns)
    end_ns = np.array([int(p.stamps_ns.max()) for p in plans], np.int64)
    extra = cfg.to_extra()
    hours = _synth_hours(extra)
    assert hours is not None
    windows = DailyWindows((hours,), cfg.timezone, source="the lab's scan steps")
    g = _Grids(gt, grid.codes, grid.source, masks, rule, end_ns)
    task = _task(f"lab seed {cfg.seed}", g, _lab_dense(lab, windows), cfg.timezone,
                 {"dataset": f"synthetic lab, seed {cfg.seed} (no images)", "lab_seed": cfg.seed,
                  "kind": "the built-in lab", "labels_spec": labels, "label_seed": int(seed)})
    step = sorted(cfg.scan_hours)
    task.windows, task.cadence_s = windows, float(np.median(np.diff(step)) * 3600.0) if len(step) > 1 else 86400.0
    proc = getattr(lab.schedule, "process", None)
    if proc is not None:
        task.estimator_hints = {"process": json.loads(proc.to_json()),
                                "schedules": {f"{o}/{r}": v for (o, r), v in llm_schedules(proc).items()}}
    task.draw = int(cfg.seed)
    return task


def persistence_task_from_benchmark(seed: int = 0, **kwargs: Any) -> PersistenceTask:
    """One draw of the Sec. V-A benchmark (:func:`psg_data.synth.make_persistence_benchmark`) with the paper's
    protocol: adaptive, no forecast horizon, the plain trapezoid over the dense 60 s grid.
    """
    from psg_data.estimators import PAPER_SETTINGS
    from psg_data.synth import make_persistence_benchmark

    bm = make_persistence_benchmark(seed=seed, **kwargs)
    return PersistenceTask(
        name="persistence-benchmark", train_streams=bm.train_streams, test_streams=bm.test_streams,
        ground_truth={k: (t, y.astype(np.int64)) for k, (t, y) in bm.test_truth.items()}, timezone=bm.timezone,
        val_streams=bm.val_streams,
        info={"dataset": "persistence-benchmark", "seed": seed, "p_m": bm.p_m, "p_f": bm.p_f, "shift": bm.shift,
              "edges": len(bm.edges), "ground_truth": "dense 60 s grid over the test week",
              "split": "week 0 validation, weeks 1-4 train, week 5 test", "labels": "benchmark observations",
              "kind": "the persistence benchmark"},
        # the paper's Sec. V-A settings (gamma per observation, alpha0 per minute, 1000 FreMEn periods)
        # for every estimator that leaves them to the data's cadence
        estimator_hints={"schedules": bm.schedules, **PAPER_SETTINGS},
        protocol={"weighting": "reference", "horizon_s": 0.0,
                  "name": "the paper's Sec. V-A protocol (adaptive, plain trapezoid over the 60 s grid)"},
        draw=int(seed))
