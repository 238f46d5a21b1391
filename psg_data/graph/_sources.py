"""Label sources for navigation: the map the estimators learn from, the door observations, and what
the agent sees on the way.

A navigation run on a dataset takes one label source (``--labels``), the same strings as
``psg-data label`` (:func:`psg_data.labeling.parse_source`):

==================  ===========================================  ==========================================
source              map observations (objects; doors)             sightings of the agent (P_miss, P_false)
==================  ===========================================  ==========================================
``gt``              schedule at every map scan; door_states       exact (0, 0)
``noisy:P[,P_F]``   the same, each observation flipped (present   (P_M, P_F) of the source
                    -> absent with P_M, absent -> present with
                    P_F; seeded): the paper's "noised ground
                    truth" of its real-world table
``privileged``      ``labels`` table rows of ``privileged``       exact (0, 0): the agent looks from within
                    (ground truth where the receptacle / door     reach and in sight
                    was seen)
``detections:F``    ``labels`` table rows of that source          P_M, P_F of the source against the
                    (perception); doors: ``observed`` (depth)     schedule on the map scans (measured)
``observed``        doors only (state read from the depth);       -
                    no object observations
==================  ===========================================  ==========================================

``noisy`` here flips the *ground truth* (every map scan observes every edge), as the paper's
"Ours (noised)" row does; the ``noisy`` rows that ``psg-data label`` stores flip the privileged
codes instead (only what a scan saw) and are what the persistence task reads.

Map observations are restricted to the map scans. The edges of an object are the receptacles the
source saw it on at least once in those scans (the paper's previously observed receptacles); every
map scan with code 1 / 0 on an edge is one observation at the scan's start time. Door streams are
the ``(door_id, 'open')`` edges (1 = seen open, 0 = seen closed). The ground truth used for scoring
is always the ``schedule`` / ``door_states`` tables, whatever the source.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from psg_data.errors import EvaluationError, LabelingError
from psg_data.estimators._base import EdgeStream
from psg_data.schemas._tables import CODE_ABSENT, CODE_PRESENT

__all__ = ["ObservationModel", "SourceObservations", "source_observations", "grid_map_streams"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ObservationModel:
    """How the agent's sightings of its target are corrupted.

    Each time the agent looks at a receptacle (on arrival, or when its path first enters the
    approach set of the receptacle that holds the target) it sees the target there with
    probability ``1 - p_miss`` if the target is there, and with probability ``p_false`` if not.
    Draws are common random numbers: one uniform per (query seed, query id, receptacle, look
    index), so two methods that look at the same receptacle of the same query see the same thing.

    Attributes:
        p_miss: P(not seen | there).
        p_false: P(seen | not there).
        seed: seed of the draws.
        source: the label source the rates come from.
    """

    p_miss: float = 0.0
    p_false: float = 0.0
    seed: int = 0
    source: str = "gt"

    def __post_init__(self) -> None:
        for name, p in (("p_miss", self.p_miss), ("p_false", self.p_false)):
            if not (np.isfinite(p) and 0.0 <= p <= 1.0):
                raise EvaluationError(f"observation model {name}: {p}, expected a probability in [0, 1]")

    @property
    def exact(self) -> bool:
        """Whether every sighting is right (no misses, no false sightings)."""
        return self.p_miss == 0.0 and self.p_false == 0.0

    def sees(self, there: bool, key: Sequence[int]) -> bool:
        """Whether the target is seen on a receptacle (``there``: it truly is) for draw ``key``."""
        if self.exact:
            return bool(there)
        u = float(np.random.default_rng([int(self.seed), 5309, *(int(k) for k in key)]).random())
        return u >= self.p_miss if there else u < self.p_false


@dataclass
class SourceObservations:
    """What one label source gives a navigation run.

    Attributes:
        source: the source string as given (``gt``, ``noisy:0.1``, ...).
        object_streams: map observations, one stream per edge (empty for ``observed``).
        door_streams: ``(door_id, 'open')`` map observations, one per door with observations.
        observation: the agent's sighting model.
        info: provenance (what each part came from; measured error rates).
    """

    source: str
    object_streams: list[EdgeStream]
    door_streams: list[EdgeStream]
    observation: ObservationModel
    info: dict[str, Any] = field(default_factory=dict)


def grid_map_streams(grid: Any, map_scan_ids: Sequence[str], *, require_presence: bool = True) -> list[EdgeStream]:
    """Edge streams of a label grid restricted to the map scans.

    Args:
        grid: a :class:`~psg_data.labeling.LabelGrid`.
        map_scan_ids: scans forming the map.
        require_presence: keep only edges with at least one presence (code 1) in the map scans
            (objects); False keeps every valid edge with at least one observation (doors).

    Returns:
        Streams sorted by edge, times in float seconds UTC (the scans' start stamps).
    """
    keep = set(map_scan_ids)
    rows = np.array([s in keep for s in grid.scan_ids], bool)
    codes = grid.codes[rows]
    t_s = grid.stamps_ns[rows].astype(np.float64) / 1e9
    order = np.argsort(t_s, kind="stable")
    codes, t_s = codes[order], t_s[order]
    obs = (codes == CODE_PRESENT) | (codes == CODE_ABSENT)
    ok = np.any(codes == CODE_PRESENT, axis=0) if require_presence else np.any(obs, axis=0)
    out = []
    for o, r in sorted(zip(*np.nonzero(ok)), key=lambda x: (grid.object_ids[x[0]], grid.receptacle_ids[x[1]])):
        m = obs[:, o, r]
        out.append(EdgeStream((grid.object_ids[o], grid.receptacle_ids[r]), t_s[m], codes[m, o, r].astype(np.int8),
                              {"source": grid.source}))
    return out


def _table_grid(ds: Any, name: str, labels: str, *, doors: bool) -> Any:
    """The object (``doors=False``) or door rows of source ``name`` in the labels table."""
    from psg_data.labeling import LabelGrid, is_door_row

    hint = f"run `psg-data label {ds.root} --source {labels}` first"
    if not ds.has_table("labels"):
        raise EvaluationError(f"{ds.root}: dataset has no labels table; {hint}")
    t = ds.table("labels")
    import pyarrow as pa
    import pyarrow.compute as pc

    t = t.filter(pc.equal(t.column("source"), name))
    if t.num_rows == 0:
        have = sorted(set(ds.table("labels").column("source").to_pylist()))
        raise EvaluationError(f"{ds.root}: tables/labels.parquet has no {name!r} labels (it has "
                              f"{', '.join(have) or 'none'}); {hint}")
    door_ids = set(ds.doors) if ds.has_table("doors") else set()
    mask = is_door_row(t.column("object_id").to_pylist(), t.column("receptacle_id").to_pylist(), door_ids)
    t = t.filter(pa.array(mask if doors else ~mask, pa.bool_()))
    if t.num_rows == 0:
        return None
    try:
        return LabelGrid.from_table(t, name)
    except LabelingError as exc:
        raise EvaluationError(f"{ds.root}: labels of source {name!r}: {exc}") from None


def _object_grid(ds: Any, spec: Any, labels: str, seed: int) -> tuple[Any, Any]:
    """(source grid on the ground truth's axes, ground truth grid)."""
    from psg_data.labeling import ground_truth, inject_noise

    try:
        gt = ground_truth(ds)
    except LabelingError as exc:
        raise EvaluationError(f"{ds.root}: cannot derive ground truth ({exc})") from None
    if spec.kind == "gt":
        return gt, gt
    if spec.kind == "noisy":
        return inject_noise(gt, spec.p_m, spec.p_f, seed, f"{labels} (ground truth, flipped)"), gt
    grid = _table_grid(ds, spec.name, labels, doors=False)
    if grid is None:
        raise EvaluationError(f"{ds.root}: labels of source {spec.name!r} have no object rows")
    return gt.with_codes(gt.aligned(grid), spec.name), gt


def _door_grid(ds: Any, spec: Any, labels: str, seed: int) -> tuple[Any, str]:
    """Door label grid of the source (None without doors) and where it came from."""
    from psg_data.labeling import compute_labels, door_label_grid

    if not (ds.has_table("doors") and len(ds.doors)):
        return None, "no doors"
    has_states = ds.has_table("door_states") and ds.table("door_states").num_rows > 0
    if spec.kind in ("gt", "noisy") and not has_states:
        raise EvaluationError(f"{ds.root}/tables/door_states.parquet: missing or empty; door observations of "
                              f"source {labels} come from the door states")
    if spec.kind == "gt":
        return door_label_grid(ds, "gt"), "door_states"
    if spec.kind == "noisy":
        vis = np.ones((len(ds.scan_ids), len(ds.doors)), bool)
        return (door_label_grid(ds, "noisy", source=labels, visible=vis, p_m=spec.p_m, p_f=spec.p_f, seed=seed),
                "door_states, flipped")
    name = "observed" if spec.kind in ("detections", "observed") else spec.name
    stored = ds.has_table("labels") and name in set(ds.table("labels").column("source").to_pylist())
    grid = _table_grid(ds, name, name, doors=True) if stored or spec.kind == "privileged" else None
    if grid is not None:
        return grid, f"labels table, source {name}"
    if spec.kind == "privileged":
        raise EvaluationError(f"{ds.root}: tables/labels.parquet has no door rows of source 'privileged'; run "
                              f"`psg-data label {ds.root} --source privileged --overwrite` (with --doors)")
    log.info("door states read from the depth images (source 'observed', not stored)")
    try:
        res = compute_labels(ds, "observed")
    except LabelingError as exc:
        raise EvaluationError(f"{ds.root}: door observation failed ({exc})") from None
    return res.doors, "read from the depth images (observed, computed on the fly)"


def source_observations(dataset: Any, labels: str, map_scan_ids: Sequence[str], *, seed: int = 0,
                        objects: bool = True) -> SourceObservations:
    """Map observations, door observations and the sighting model of one label source.

    Args:
        dataset: a :class:`~psg_data.loaders.Dataset`.
        labels: the source (module docstring).
        map_scan_ids: scans forming the map.
        seed: seed of on-the-fly noise (``noisy``) and of the sighting draws.
        objects: also build the object streams (False: doors only, e.g. for the door task).

    Raises:
        EvaluationError: unknown source, labels missing from the dataset (the message names the
            ``psg-data label`` command to run), or ``observed`` asked for object observations.
    """
    from psg_data.labeling import error_rates, parse_source

    ds = dataset
    try:
        spec = parse_source(labels)
    except LabelingError as exc:
        raise EvaluationError(str(exc)) from None
    info: dict[str, Any] = {"labels": labels}
    streams: list[EdgeStream] = []
    model = ObservationModel(seed=seed, source=labels)
    if objects:
        if spec.kind == "observed":
            raise EvaluationError("--labels observed: a door-only source (door states read from the depth); object "
                                  "navigation needs object observations: use gt, privileged, noisy:P or "
                                  "detections:FILE (doors then come from the same source), or --task doors")
        grid, gt = _object_grid(ds, spec, labels, seed)
        streams = grid_map_streams(grid, map_scan_ids)
        if not streams:
            raise EvaluationError(f"{ds.root}: source {labels} saw no object on any receptacle in the "
                                  f"{len(map_scan_ids)} map scans")
        from psg_data.labeling import LabelGrid

        keep = set(map_scan_ids)
        rows = [k for k, s in enumerate(grid.scan_ids) if s in keep]
        sub = LabelGrid([grid.scan_ids[k] for k in rows], list(grid.object_ids), list(grid.receptacle_ids),
                        grid.stamps_ns[rows], grid.codes[rows], grid.source)
        rates = error_rates(sub, gt)
        info["objects"] = {"from": {"gt": "schedule", "noisy": "schedule, flipped"}.get(spec.kind, "labels table"),
                           "edges": len(streams), "observations": int(sum(len(s) for s in streams)),
                           "p_m": rates.p_m, "p_f": rates.p_f, "n_present": rates.n_present, "n_absent": rates.n_absent}
        if spec.kind == "noisy":
            model = ObservationModel(spec.p_m, spec.p_f, seed, labels)
        elif spec.kind == "detections":
            model = ObservationModel(float(np.nan_to_num(rates.p_m)), float(np.nan_to_num(rates.p_f)), seed, labels)
        info["sightings"] = {"p_miss": model.p_miss, "p_false": model.p_false,
                             "rates": "measured on the map scans" if spec.kind == "detections" else "of the source"}
    dgrid, dfrom = _door_grid(ds, spec, labels, seed)
    doors = [s for s in grid_map_streams(dgrid, map_scan_ids, require_presence=False) if s.edge[1] == "open"] \
        if dgrid is not None else []
    info["doors"] = {"from": dfrom, "streams": len(doors), "observations": int(sum(len(s) for s in doors))}
    return SourceObservations(labels, streams, doors, model, info)
