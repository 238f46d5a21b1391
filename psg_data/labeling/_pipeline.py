"""The labelling pipeline: a label source -> label grid -> label tables and edge streams.

Sources (``source`` strings, also the ``--source`` of ``psg-data label``):

* ``gt``: ground truth from the schedule (1 / 0 on valid pairs, -2 elsewhere; no visibility).
* ``privileged``: ground truth filtered by what the scan saw (visibility from the depth images).
* ``noisy:P`` or ``noisy:P_M,P_F``: privileged codes with observed codes flipped (present -> absent
  with P_M, absent -> present with P_F), seeded.
* ``detections:FILE``: the perception path from a detections file (Parquet or JSON), or from
  ConceptGraphs / Spark-DSG / HOV-SG scene graphs (a file or a folder of per-scan sessions;
  :mod:`psg_data.labeling._scene_graphs`).
* ``observed``: door states read from the depth images only (no object rows; see
  :mod:`psg_data.labeling._doors`).

Doors (datasets with a ``doors`` table): a door is a semi-static "object" whose "receptacles" are
its states, so ``gt``, ``privileged``, ``noisy`` and ``observed`` also produce door-state rows
(``object_id`` = door_id, ``receptacle_id`` = 'open' / 'closed', same codes) in the same source,
and the ``visibility`` table gets rows of kind 'door'. ``gt`` needs the ``door_states`` table;
``privileged`` / ``noisy`` use the door visibility; ``observed`` reads the state from the depth.
Pass ``doors=False`` to leave doors out. :func:`load_label_streams` / :func:`label_streams`
return object streams by default, door streams with ``doors="only"`` and both with ``doors=True``.

The ``labels`` table can hold several sources side by side (its ``source`` column); labelling with
a source already in the table needs ``overwrite``. The ``visibility`` table is computed once and
reused by later runs (recomputed with ``overwrite``).
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import LabelingError
from psg_data.labeling._association import AssociationParams, PerceptionInfo, perception_labels
from psg_data.labeling._codes import ErrorRates, LabelGrid, error_rates, ground_truth, inject_noise, privileged_codes
from psg_data.labeling._doors import (
    DoorObservations,
    DoorParams,
    door_label_grid,
    door_visibility_from_table,
    is_door_row,
    observe_doors,
)
from psg_data.labeling._scene_graphs import read_any_detections
from psg_data.labeling._visibility import VisibilityParams, compute_visibility, visibility_matrix
from psg_data.schemas._records import Box
from psg_data.schemas._streams import EdgeStream
from psg_data.schemas._tables import CODE_ABSENT, CODE_PRESENT, TABLES

__all__ = ["SourceSpec", "parse_source", "LabelResult", "LabelSummary", "compute_labels", "label_dataset",
           "label_streams", "load_label_streams", "grid_streams", "summarize"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SourceSpec:
    """A parsed label source.

    Attributes:
        kind: ``gt``, ``privileged``, ``noisy`` or ``detections``.
        p_m, p_f: noise rates (``noisy``).
        path: detections file (``detections``).
    """

    kind: str
    p_m: float = 0.0
    p_f: float = 0.0
    path: str | None = None

    @property
    def name(self) -> str:
        """Value of the ``source`` column."""
        if self.kind == "noisy":
            return f"noisy:{self.p_m:g},{self.p_f:g}"
        if self.kind == "detections":
            return f"detections:{Path(self.path or '').name}"
        return self.kind


def parse_source(source: str) -> SourceSpec:
    """Parse ``gt``, ``privileged``, ``noisy:P[,P_F]`` or ``detections:FILE``.

    Raises:
        LabelingError: anything else.
    """
    s = str(source).strip()
    if s in ("gt", "privileged", "observed"):
        return SourceSpec(s)
    if s.startswith("noisy:"):
        parts = s[len("noisy:"):].split(",")
        try:
            vals = [float(x) for x in parts]
        except ValueError as exc:
            raise LabelingError(f"source {s!r}: expected noisy:P or noisy:P_M,P_F with probabilities in "
                                f"[0, 1]") from exc
        if len(vals) not in (1, 2) or not all(np.isfinite(v) and 0 <= v <= 1 for v in vals):
            raise LabelingError(f"source {s!r}: expected noisy:P or noisy:P_M,P_F with probabilities in [0, 1]")
        return SourceSpec("noisy", vals[0], vals[-1])
    if s.startswith("detections:") and len(s) > len("detections:"):
        return SourceSpec("detections", path=s[len("detections:"):])
    raise LabelingError(f"source {s!r}: expected gt, privileged, noisy:P[,P_F], observed or detections:FILE")


@dataclass
class LabelResult:
    """Output of :func:`compute_labels`.

    Attributes:
        labels: the source's label grid.
        gt: ground truth (None if the dataset has no schedule).
        visibility: visibility table (None if the source did not need it).
        perception: diagnostics of the perception path.
        timings: seconds per stage.
        visibility_reused: the visibility table came from the dataset (unchanged).
        doors: door-state label grid of the source (None without doors or with ``doors=False``).
        door_gt: door ground truth (None without a door_states table).
        door_observations: door observations when they were computed.
        door_visibility: visibility rows of kind 'door' computed in this run and not yet in
            ``visibility`` (:func:`label_dataset` appends them to the stored table).
    """

    labels: LabelGrid
    gt: LabelGrid | None
    visibility: Any = None
    perception: PerceptionInfo | None = None
    timings: dict[str, float] = field(default_factory=dict)
    visibility_reused: bool = False
    doors: LabelGrid | None = None
    door_gt: LabelGrid | None = None
    door_observations: DoorObservations | None = None
    door_visibility: Any = None


def _open(dataset: Any) -> Any:
    from psg_data.loaders import Dataset, open_dataset

    return dataset if isinstance(dataset, Dataset) else open_dataset(dataset)


def compute_labels(dataset: Any, source: str | SourceSpec, *, seed: int = 0,
                   visibility_params: VisibilityParams | None = None,
                   association: AssociationParams | None = None,
                   valid: Mapping[str, Sequence[str]] | None = None,
                   object_boxes: Mapping[str, Mapping[str, Box]] | None = None,
                   visibility: Any = None, reuse_visibility: bool = True,
                   progress: Callable[..., Any] | None = None, doors: bool = True,
                   door_params: DoorParams | None = None, detections_format: str = "auto") -> LabelResult:
    """Compute the label grid of one source (nothing is written).

    Args:
        dataset: a :class:`~psg_data.loaders.Dataset` or its path.
        source: source string or :class:`SourceSpec` (module docstring).
        seed: seed of the noise (``noisy``).
        visibility_params: visibility thresholds.
        association: matching and association settings (``detections``).
        valid: object_id -> valid receptacle ids (default: the schedule's support).
        object_boxes: ``scan_id -> {object_id: Box}`` to test object visibility directly.
        visibility: a precomputed visibility table to use.
        reuse_visibility: use the dataset's ``visibility`` table if it exists (and no
            ``object_boxes`` are given).
        progress: called as ``progress(1)`` per scan of the visibility pass.
        doors: also label the doors (datasets with a doors table; module docstring).
        door_params: thresholds of the door observation.
        detections_format: ``auto`` (recognised from the content), ``table``, ``conceptgraphs``,
            ``spark-dsg`` or ``hovsg`` (:mod:`psg_data.labeling._scene_graphs`).
    """
    ds = _open(dataset)
    spec = parse_source(source) if isinstance(source, str) else source
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    gt = None
    has_schedule = ds.has_table("schedule") and ds.table("schedule").num_rows > 0
    has_doors = ds.has_table("doors") and ds.table("doors").num_rows > 0
    if spec.kind == "observed" and not has_doors:
        raise LabelingError(f"source 'observed': {ds.root}/tables/doors.parquet has no doors to observe")
    if spec.kind in ("gt", "privileged", "noisy") or has_schedule:
        gt = ground_truth(ds, valid)
    timings["ground_truth"] = time.perf_counter() - t0
    assoc = association or AssociationParams()
    need_vis = (spec.kind in ("privileged", "noisy", "observed")
                or (spec.kind == "detections" and assoc.observed != "matched"))
    reused = False
    if need_vis and visibility is None:
        if reuse_visibility and object_boxes is None and ds.has_table("visibility"):
            visibility = ds.table("visibility")
            reused = True
            log.info("using the existing tables/visibility.parquet (pass overwrite to recompute it)")
        else:
            visibility = compute_visibility(ds, visibility_params, object_boxes=object_boxes, progress=progress,
                                            timings=timings)
    scan_ids, rec_ids, obj_ids = list(ds.scan_ids), list(ds.receptacles), list(ds.objects)
    rec_vis = visibility_matrix(visibility, scan_ids, rec_ids, "receptacle") if visibility is not None else None
    t1 = time.perf_counter()
    perception = None
    if spec.kind == "gt":
        assert gt is not None
        labels = gt
    elif spec.kind == "observed":  # doors only: an object grid without objects
        labels = LabelGrid(scan_ids, [], rec_ids, np.array([ds.scan(s).start_stamp_ns for s in scan_ids], np.int64),
                           np.zeros((len(scan_ids), 0, len(rec_ids)), np.int8), "observed")
    elif spec.kind in ("privileged", "noisy"):
        assert gt is not None and rec_vis is not None
        obj_vis = None
        if object_boxes is not None:
            obj_vis = visibility_matrix(visibility, scan_ids, obj_ids, "object")
        labels = privileged_codes(gt, rec_vis, obj_vis)
        labels.meta = {"object_visibility": "boxes" if object_boxes is not None else "receptacle"}
        if spec.kind == "noisy":
            labels = inject_noise(labels, spec.p_m, spec.p_f, seed, spec.name)
    else:
        t_read = time.perf_counter()
        det = read_any_detections(ds, spec.path or "", detections_format, min_score=assoc.min_score)
        timings["detections.read"] = time.perf_counter() - t_read
        t1 = time.perf_counter()
        labels, perception = perception_labels(ds, det, assoc, receptacle_visible=rec_vis, source=spec.name)
        labels.meta["file"] = str(spec.path)
    timings["codes"] = time.perf_counter() - t1
    res = LabelResult(labels, gt, visibility, perception, timings, reused)
    if doors and has_doors and spec.kind != "detections":
        _label_doors(ds, spec, res, seed, door_params)
    return res


def _label_doors(ds: Any, spec: SourceSpec, res: LabelResult, seed: int, params: DoorParams | None) -> None:
    """Fill ``res.doors`` / ``res.door_gt`` (and door rows of ``res.visibility``) for ``spec``."""
    t0 = time.perf_counter()
    has_states = ds.has_table("door_states") and ds.table("door_states").num_rows > 0
    if spec.kind in ("gt", "privileged", "noisy") and not has_states:
        log.warning("%s/tables/door_states.parquet: missing or empty; no door labels for source %s", ds.root, spec.name)
        return
    if has_states:
        res.door_gt = door_label_grid(ds, "gt")
    if spec.kind == "gt":
        res.doors = res.door_gt
        return
    stored = (door_visibility_from_table(res.visibility, list(ds.scan_ids), list(ds.doors))
              if res.visibility is not None else None)
    vis, obs = stored, None
    if stored is None or spec.kind == "observed":
        obs = observe_doors(ds, params)
        res.door_observations = obs
        vis = obs.visible
        if stored is None:  # the visibility table gets the door rows
            res.door_visibility = obs.visibility_table()
    if spec.kind == "observed":
        res.doors = door_label_grid(ds, "observed", observations=obs)
    else:
        res.doors = door_label_grid(ds, spec.kind, source=spec.name, visible=vis, p_m=spec.p_m, p_f=spec.p_f,
                                    seed=seed)
    res.timings["doors"] = time.perf_counter() - t0


# -- streams -------------------------------------------------------------------------------------
def grid_streams(grid: LabelGrid) -> list[EdgeStream]:
    """One :class:`EdgeStream` per edge (pair with any code other than -2), sorted by (object, receptacle).

    Observations are the scans with code 1 (y = 1) or 0 (y = 0) at ``t_s`` = the scan's stamp in
    seconds; codes -1 and -2 are dropped. Edges without observations give empty streams.
    """
    t_s = grid.stamps_ns.astype(np.float64) / 1e9
    order = np.argsort(grid.stamps_ns, kind="stable")
    out = []
    valid = grid.valid
    for o, r in sorted(zip(*np.nonzero(valid)), key=lambda x: (grid.object_ids[x[0]], grid.receptacle_ids[x[1]])):
        c = grid.codes[order, o, r]
        m = (c == CODE_PRESENT) | (c == CODE_ABSENT)
        out.append(EdgeStream((grid.object_ids[o], grid.receptacle_ids[r]), t_s[order][m], c[m].astype(np.int8),
                              {"source": grid.source, "n_missing": int((~m).sum())}))
    return out


_DOOR_OPTIONS = (False, True, "only")


def _check_doors_option(doors: Any) -> None:
    if not any(doors is o or (isinstance(o, str) and doors == o) for o in _DOOR_OPTIONS):
        raise LabelingError(f"doors={doors!r}: expected False (objects), True (objects and doors) or 'only'")


def label_streams(dataset: Any, source: str = "privileged", *, doors: bool | str = False,
                  **kwargs: Any) -> list[EdgeStream]:
    """Edge streams of a label source computed on the fly (nothing written; see :func:`compute_labels`).

    Args:
        dataset: a dataset or its path.
        source: label source.
        doors: False: object edges; True: object then door edges; ``"only"``: door edges
            ``(door_id, 'open')`` and ``(door_id, 'closed')``.
        **kwargs: passed to :func:`compute_labels`.
    """
    _check_doors_option(doors)
    res = compute_labels(dataset, source, doors=doors is not False, **kwargs)
    out = [] if doors == "only" else grid_streams(res.labels)
    if doors is not False and res.doors is not None:
        out += grid_streams(res.doors)
    return out


def load_label_streams(dataset: Any, source: str | None = None, *, doors: bool | str = False) -> list[EdgeStream]:
    """Edge streams from the dataset's ``labels`` table.

    Args:
        dataset: a :class:`~psg_data.loaders.Dataset` or its path.
        source: the ``source`` value to read; may be omitted when the table holds one source.
        doors: False: object edges only (door-state rows are left out); True: object then door
            edges; ``"only"``: door edges ``(door_id, 'open')`` and ``(door_id, 'closed')``.

    Raises:
        LabelingError: no labels table, or ``source`` missing / ambiguous.
    """
    _check_doors_option(doors)
    ds = _open(dataset)
    if not ds.has_table("labels"):
        raise LabelingError(f"{ds.root}/tables/labels.parquet: missing; run `psg-data label {ds.root} --source ...` "
                            "first")
    t = ds.table("labels")
    sources = sorted(set(t.column("source").to_pylist()))
    if source is None:
        if len(sources) != 1:
            raise LabelingError(f"{ds.root}/tables/labels.parquet: holds sources {sources}; choose one with source=")
        source = sources[0]
    import pyarrow.compute as pc

    t = t.filter(pc.equal(t.column("source"), source))
    if t.num_rows == 0:
        raise LabelingError(f"labels: no rows of source {source!r}; sources present: {sources or 'none'}")
    door_ids = set(ds.doors) if ds.has_table("doors") else set()
    is_door = is_door_row(t.column("object_id").to_pylist(), t.column("receptacle_id").to_pylist(), door_ids)
    out: list[EdgeStream] = []
    obj_rows = t.filter(_pa_mask(~is_door))
    if doors != "only" and obj_rows.num_rows:
        out += grid_streams(LabelGrid.from_table(obj_rows, source))
    door_rows = t.filter(_pa_mask(is_door))
    if doors is not False and door_rows.num_rows:
        out += grid_streams(LabelGrid.from_table(door_rows, source))
    return out


def _pa_mask(mask: Any) -> Any:
    import pyarrow as pa

    return pa.array(np.asarray(mask, bool), pa.bool_())


# -- summary -------------------------------------------------------------------------------------
@dataclass
class LabelSummary:
    """What a labelling run produced.

    Attributes:
        source: source name.
        n_edges: edges (pairs with a code other than -2).
        obs_per_edge: (mean, min, max) observations (codes 1/0) per edge.
        codes: count of each code over all cells.
        rates: P_M / P_F against ground truth (None without a schedule).
        timings: seconds per stage.
        written: paths written.
        extra: source-specific numbers.
        edge_kind: ``"object"``, or ``"door"`` for the door-only source ``observed`` (its edges,
            observations and codes are then the door-state edges').
    """

    source: str
    n_edges: int
    obs_per_edge: tuple[float, int, int]
    codes: dict[int, int]
    rates: ErrorRates | None
    timings: dict[str, float] = field(default_factory=dict)
    written: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    edge_kind: str = "object"

    def lines(self) -> list[str]:
        """The summary as readable lines (what ``psg-data label`` prints)."""
        m, lo, hi = self.obs_per_edge
        c = self.codes
        kind = "door-state " if self.edge_kind == "door" else ""
        out = [f"source {self.source}: {self.n_edges} {kind}edges, observations per {kind}edge mean {m:.1f} "
               f"(min {lo}, max {hi})",
               f"codes: 1 (present) {c.get(1, 0)}, 0 (absent) {c.get(0, 0)}, -1 (not observed) {c.get(-1, 0)}, "
               f"-2 (invalid) {c.get(-2, 0)}"]
        if self.rates is not None:
            out.append(f"vs ground truth: {self.rates}")
        elif self.source == "observed":
            out.append("objects: none (observed is a door-only source)")
        elif self.source != "gt":
            out.append("vs ground truth: no schedule")
        out += [f"{k}: {v}" for k, v in self.extra.items()]
        if self.timings:
            out.append("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in self.timings.items()))
        return out


def summarize(res: LabelResult) -> LabelSummary:
    """Summary of a :class:`LabelResult` (door-only sources are summarised by their door edges)."""
    g = res.labels
    edge_kind = "object"
    if not g.object_ids and res.doors is not None:
        g, edge_kind = res.doors, "door"
    valid = g.valid
    n_obs = g.observed.sum(axis=0)[valid]
    rates = error_rates(g, res.gt) if res.gt is not None and g.source not in ("gt", "observed") else None
    extra: dict[str, Any] = {}
    if res.visibility is not None:
        d = res.visibility.to_pydict()
        vis = [v for k, v in zip(d["kind"], d["visible"]) if k == "receptacle"]
        extra["receptacles visible"] = f"{sum(vis)} of {len(vis)} (scan, receptacle) pairs" + (
            " (reused tables/visibility.parquet)" if res.visibility_reused else "")
    if res.doors is not None:
        dg = res.doors
        obs = dg.codes[:, :, 0] >= 0
        line = f"{int(obs.sum())} of {obs.size} (scan, door) pairs observed"
        if res.door_gt is not None and dg.source != "gt":
            ref = res.door_gt.aligned(dg)[:, :, 0]
            both = obs & (ref >= 0)
            agree = int((dg.codes[:, :, 0] == ref)[both].sum())
            line += f", state agrees with door_states in {agree} of {int(both.sum())}"
        extra["doors"] = line
    if res.perception is not None:
        p = res.perception
        extra["perception"] = (f"{int(p.matched.sum())} receptacle matches (mean IoU {p.mean_iou:.2f}), "
                               f"{p.n_unmatched_nodes} unmatched receptacle nodes, {p.n_unassociated} unassociated and "
                               f"{p.n_unknown_labels} unknown-label object detections")
    return LabelSummary(g.source, int(valid.sum()),
                        (float(n_obs.mean()) if n_obs.size else 0.0, int(n_obs.min()) if n_obs.size else 0,
                         int(n_obs.max()) if n_obs.size else 0),
                        g.code_counts(), rates, dict(res.timings), extra=extra, edge_kind=edge_kind)


def label_dataset(root: str | Path, source: str, *, seed: int = 0, overwrite: bool = False,
                  progress: Callable[..., Any] | None = None, **kwargs: Any) -> LabelSummary:
    """Label the dataset at ``root`` with ``source`` and store ``labels`` (and ``visibility``) in it.

    The rows of ``source`` are added to ``tables/labels.parquet`` (other sources are kept); a
    source already present is replaced only with ``overwrite``. ``tables/visibility.parquet`` is
    written when computed (an existing one is reused unless ``overwrite``). All checks run before
    anything is written; see :func:`~psg_data.writers.add_tables` for how the dataset stays valid.

    Args:
        root: dataset directory.
        source: label source (module docstring).
        seed: noise seed.
        overwrite: replace this source's labels and recompute the visibility table.
        progress: called per scan of the visibility pass.
        **kwargs: passed to :func:`compute_labels`.

    Raises:
        LabelingError: bad source, bad detections, existing labels of this source without ``overwrite``.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    from psg_data.writers._add_tables import add_tables

    ds = _open(root)
    spec = parse_source(source)
    old = ds.table("labels") if ds.has_table("labels") else None
    if old is not None and not overwrite:
        if spec.name in set(old.column("source").to_pylist()):
            raise LabelingError(f"{ds.root}/tables/labels.parquet: labels of source {spec.name!r} exist; pass "
                                "--overwrite (overwrite=True) to replace them")
    res = compute_labels(ds, spec, seed=seed, reuse_visibility=not overwrite, progress=progress, **kwargs)
    t0 = time.perf_counter()
    new = res.labels.to_table()
    if res.doors is not None:
        new = pa.concat_tables([new, res.doors.to_table()])
    meta: dict[str, Any] = {}
    if old is not None:
        raw = (old.schema.metadata or {}).get(b"psg_label_sources")
        meta = json.loads(raw) if raw else {}
        keep = old.filter(pc.not_equal(old.column("source"), spec.name))
        new = pa.concat_tables([keep.select(new.schema.names).cast(new.schema), new])
    meta[spec.name] = {**res.labels.meta, "seed": seed, "source": str(source)}
    if res.doors is not None:
        meta[spec.name]["doors"] = {"n_doors": len(res.doors.object_ids), **res.doors.meta}
    if res.visibility is not None and not res.visibility_reused:
        vm = (res.visibility.schema.metadata or {}).get(b"psg_visibility_params")
        if vm:
            meta[spec.name]["visibility"] = json.loads(vm)
    new = new.replace_schema_metadata({**(TABLES["labels"].schema.metadata or {}),
                                       b"psg_label_sources": json.dumps(meta, sort_keys=True, default=str).encode()})
    out = {"labels": new}
    if res.visibility is not None and (not res.visibility_reused or res.door_visibility is not None):
        vis = res.visibility
        if res.door_visibility is not None:
            vis = pa.concat_tables([vis, res.door_visibility.cast(vis.schema)]).replace_schema_metadata(
                vis.schema.metadata)
        out["visibility"] = vis
    written = add_tables(ds.root, out, overwrite=True)
    summary = summarize(res)
    summary.timings["write"] = time.perf_counter() - t0
    summary.written = [str(p) for p in written]
    return summary


def _valid_from_file(path: str | Path) -> dict[str, list[str]]:
    """Read a JSON file ``{object_id: [receptacle_id, ...]}``."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise LabelingError(f"{p}: not a readable JSON file ({exc})") from exc
    if not isinstance(data, dict) or not all(isinstance(v, list) and all(isinstance(x, str) for x in v)
                                             for v in data.values()):
        raise LabelingError(f"{p}: expected a JSON object {{object_id: [receptacle_id, ...]}}")
    return data

