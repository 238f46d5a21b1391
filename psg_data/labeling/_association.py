"""Perception path: detections -> receptacle matching -> object association -> edge history -> codes.

Per scan (paper, "Object Classification and Spatial Association"):

1. Receptacle nodes are matched to the annotated receptacle boxes by maximum-weight bipartite
   matching (Hungarian algorithm, ``scipy.optimize.linear_sum_assignment``) on the 3D IoU of the
   oriented boxes; pairs with IoU below ``min_iou`` are not matched (their weight is 0). A
   receptacle is *observed* in the scan if it was matched (``observed="matched"``), or if its top
   surface was visible (``"visibility"``), or either (``"either"``).
2. Each object node whose label is an object of the dataset (``object_id``, else a unique object
   ``name``; other labels are ignored) is associated with one observed receptacle: with rule
   ``"on_top"`` (default) the candidates are the receptacles it stands on - its centroid lies within
   the receptacle's footprint grown by ``margin_m`` (box x/y axes) and between ``below_m`` under and
   ``above_m`` over the top face - and the nearest top face wins (ties: the first receptacle in table
   order); rule ``"centroid"`` takes the nearest receptacle centroid within ``max_distance_m``
   (the paper's plain centroid distance). An object without a candidate is not associated.
   Scene graphs read with ``relations: stated`` (``Detections.stated_on``) replace this rule: an
   object is on the annotated receptacle its stated receptacle node was matched to in step 1 (if
   observed), and an object without a stated relation is on none.
3. Edge history: ``A(o, k) = 1`` if object ``o`` was associated with receptacle ``k`` in any scan.
4. Codes: for every edge and scan, 1 if the object was associated with the receptacle in that scan,
   0 if the receptacle was observed but the object was not associated with it, -1 if the
   receptacle was not observed; pairs that are not edges get -2. Several detections of one object
   in a scan may associate it with several receptacles (each gets a 1).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data._settings import Options, Real, check_settings
from psg_data.errors import LabelingError
from psg_data.labeling._codes import LabelGrid
from psg_data.labeling._detections import Detections
from psg_data.labeling._geometry import box_iou_matrix
from psg_data.schemas._records import Box
from psg_data.schemas._tables import CODE_ABSENT, CODE_INVALID, CODE_MISSING, CODE_PRESENT

__all__ = ["AssociationParams", "match_boxes", "max_weight_matching", "associate_objects", "perception_labels",
           "PerceptionInfo"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AssociationParams:
    """Settings of matching and association (see the module docstring).

    Attributes:
        min_iou: minimum 3D IoU of a receptacle node and an annotated box to match them.
        rule: ``on_top`` or ``centroid``.
        margin_m: footprint growth for ``on_top``, metres.
        below_m: how far below the top face an object centroid may be, metres.
        above_m: how far above the top face an object centroid may be, metres.
        max_distance_m: distance limit of the ``centroid`` rule, metres.
        observed: ``matched``, ``visibility`` or ``either``.
        min_score: detections with a lower score are ignored.
    """

    min_iou: float = 0.25
    rule: str = "on_top"
    margin_m: float = 0.10
    below_m: float = 0.05
    above_m: float = 0.60
    max_distance_m: float = 1.0
    observed: str = "matched"
    min_score: float = 0.0

    def __post_init__(self) -> None:
        check_settings(ASSOCIATION_SETTINGS, asdict(self), "association", LabelingError,
                       {"min_iou": "--min-iou", "margin_m": "--margin", "observed": "--observed"})

    def to_dict(self) -> dict[str, Any]:
        """The settings as a dictionary (stored with the labels)."""
        return asdict(self)


ASSOCIATION_SETTINGS = {
    "min_iou": Real(0.0, 1.0, finite=True),
    "rule": Options("on_top", "centroid"),
    "margin_m": Real(0.0, 10.0, finite=True, help="metres"),
    "below_m": Real(0.0, 10.0, finite=True, help="metres"),
    "above_m": Real(0.0, 10.0, finite=True, help="metres"),
    "max_distance_m": Real(0.0, 100.0, finite=True, help="metres"),
    "observed": Options("matched", "visibility", "either"),
    "min_score": Real(0.0, 1.0, finite=True),
}
"""The declared settings of :class:`AssociationParams` (``label`` options; see :mod:`psg_data._settings`)."""


def max_weight_matching(weights: NDArray[np.float64]) -> list[tuple[int, int]]:
    """Pairs (row, col) of a maximum-total-weight matching; zero-weight pairs are left out.

    Args:
        weights: (M, N) non-negative weights (0 = not allowed).
    """
    from scipy.optimize import linear_sum_assignment

    w = np.asarray(weights, float)
    if w.size == 0:
        return []
    rows, cols = linear_sum_assignment(w, maximize=True)
    return [(int(r), int(c)) for r, c in zip(rows, cols) if w[r, c] > 0]


def match_boxes(detected: list[Box], annotated: list[Box], min_iou: float = 0.25
                ) -> tuple[list[tuple[int, int]], NDArray[np.float64]]:
    """Match detected boxes to annotated boxes by 3D IoU (Hungarian algorithm).

    Returns:
        (pairs (detected index, annotated index), the (M, N) IoU matrix). Pairs with
        ``IoU < min_iou`` are never matched; among the rest the total IoU is maximal.
    """
    iou = box_iou_matrix(detected, annotated)
    w = np.where(iou >= min_iou, iou, 0.0)
    return max_weight_matching(w), iou


def associate_objects(centroids_m: NDArray[np.float64], boxes: list[Box], candidates: NDArray[np.bool_] | None = None,
                      params: AssociationParams | None = None) -> NDArray[np.int64]:
    """Receptacle index of each object centroid, -1 if none (rule of ``params``; module docstring).

    Args:
        centroids_m: (M, 3) object centroids, world frame.
        boxes: (R) receptacle boxes.
        candidates: (R,) receptacles allowed (default all).
        params: association settings.
    """
    p = params or AssociationParams()
    c = np.asarray(centroids_m, float).reshape(-1, 3)
    R = len(boxes)
    out = np.full(len(c), -1, np.int64)
    if R == 0 or len(c) == 0:
        return out
    cand = np.ones(R, bool) if candidates is None else np.asarray(candidates, bool)
    ctr = np.array([np.asarray(b.center_m, float) for b in boxes])
    ext = np.array([np.asarray(b.extent_m, float) for b in boxes])
    rot = np.array([np.asarray(b.rotation, float) for b in boxes])
    local = np.einsum("mrj,rjk->mrk", c[:, None, :] - ctr[None], rot)  # (M, R, 3) in box frames
    half = ext / 2
    if p.rule == "centroid":
        d = np.linalg.norm(c[:, None, :] - ctr[None], axis=-1)
        ok = cand[None] & (d <= p.max_distance_m)
    else:
        inside = np.all(np.abs(local[..., :2]) <= half[None, :, :2] + p.margin_m, axis=-1)
        dz = local[..., 2] - half[None, :, 2]
        ok = cand[None] & inside & (dz >= -p.below_m) & (dz <= p.above_m)
        clamp = np.clip(local[..., :2], -half[None, :, :2], half[None, :, :2])
        d = np.sqrt(np.sum((local[..., :2] - clamp) ** 2, axis=-1) + dz ** 2)
    d = np.where(ok, d, np.inf)
    best = np.argmin(d, axis=1)
    has = np.isfinite(d[np.arange(len(c)), best])
    out[has] = best[has]
    return out


@dataclass
class PerceptionInfo:
    """Diagnostics of :func:`perception_labels`.

    Attributes:
        matched: (S, R) receptacles matched to a detected node per scan.
        observed: (S, R) receptacles counted as observed.
        associations: (S, O, R) per-session associations A^(lambda).
        n_unknown_labels: object detections whose label is not a dataset object.
        n_unassociated: known-object detections without a receptacle.
        n_unmatched_nodes: receptacle nodes not matched to any annotation.
        mean_iou: mean IoU of the matched pairs.
    """

    matched: NDArray[np.bool_]
    observed: NDArray[np.bool_]
    associations: NDArray[np.bool_]
    n_unknown_labels: int = 0
    n_unassociated: int = 0
    n_unmatched_nodes: int = 0
    mean_iou: float = float("nan")
    unknown_labels: list[str] = field(default_factory=list)


def perception_labels(ds: Any, detections: Detections, params: AssociationParams | None = None, *,
                      receptacle_visible: NDArray[np.bool_] | None = None, source: str = "detections"
                      ) -> tuple[LabelGrid, PerceptionInfo]:
    """Codes from detections (see the module docstring).

    Args:
        ds: opened dataset (scans, receptacles, objects).
        detections: checked detections (:func:`~psg_data.labeling.read_detections`).
        params: matching and association settings.
        receptacle_visible: (S, R) visibility, needed when ``params.observed`` is not ``matched``.
        source: name of the source.

    Raises:
        LabelingError: detections of an unknown scan, or visibility missing when needed.
    """
    p = params or AssociationParams()
    scan_ids = list(ds.scan_ids)
    obj_ids, rec_ids = list(ds.objects), list(ds.receptacles)
    S, O, R = len(scan_ids), len(obj_ids), len(rec_ids)
    si = {s: i for i, s in enumerate(scan_ids)}
    _check_detections(detections, si, p, receptacle_visible)
    det = detections.subset(detections.score >= p.min_score) if p.min_score > 0 else detections
    rec_boxes = [ds.receptacles[r].box for r in rec_ids]
    name_to_id = _object_ids_by_name(ds, obj_ids)
    oi = {o: i for i, o in enumerate(obj_ids)}
    matched = np.zeros((S, R), bool)
    assoc = np.zeros((S, O, R), bool)
    rec_of_node = np.full(len(det), -1, np.int64)  # the annotated receptacle each receptacle node matched
    tally = _Tally()
    scan_of = np.array([si[s] for s in det.scan_id], np.int64) if len(det) else np.zeros(0, np.int64)
    is_rec = det.kind == "receptacle"
    for s in range(S):
        in_scan = scan_of == s
        ridx = np.flatnonzero(in_scan & is_rec)
        if ridx.size:
            pairs, iou = match_boxes([det.box(int(i)) for i in ridx], rec_boxes, p.min_iou)
            for a, b in pairs:
                matched[s, b] = True
                rec_of_node[ridx[a]] = b
                tally.ious.append(float(iou[a, b]))
            tally.unmatched += ridx.size - len(pairs)
        obs = _observed(matched[s], p, None if receptacle_visible is None else receptacle_visible[s])
        oidx = np.flatnonzero(in_scan & ~is_rec)
        stated = None if det.stated_on is None else _stated_receptacles(det, oidx, rec_of_node)
        _associate_scan(det, oidx, name_to_id, oi, rec_boxes, obs, p, assoc[s], tally, stated)
    observed = _observed(matched, p, receptacle_visible)
    history = assoc.any(axis=0)
    codes = np.full((S, O, R), CODE_MISSING, np.int8)
    codes[observed[:, None, :] & ~assoc] = CODE_ABSENT
    codes[assoc] = CODE_PRESENT
    codes[:, ~history] = CODE_INVALID
    if tally.unknown:
        log.info("%s: ignored %d object detections with labels that are not dataset objects (%s)", detections.path,
                 tally.unknown, ", ".join(sorted(tally.unknown_labels)[:5]))
    stamps = np.array([ds.scan(s).start_stamp_ns for s in scan_ids], np.int64)
    grid = LabelGrid(scan_ids, obj_ids, rec_ids, stamps, codes, source, {"association": p.to_dict()})
    if det.stated_on is not None:
        grid.meta["relations"] = "stated"
    info = PerceptionInfo(matched, observed, assoc, tally.unknown, tally.unassociated, tally.unmatched,
                          float(np.mean(tally.ious)) if tally.ious else float("nan"), sorted(tally.unknown_labels))
    return grid, info


@dataclass
class _Tally:
    """Counts of detections that did not become labels."""

    unknown: int = 0
    unassociated: int = 0
    unmatched: int = 0
    ious: list[float] = field(default_factory=list)
    unknown_labels: set[str] = field(default_factory=set)


def _check_detections(detections: Detections, scan_index: dict[str, int], p: AssociationParams,
                      receptacle_visible: NDArray[np.bool_] | None) -> None:
    unknown_scans = sorted(set(detections.scan_id.tolist()) - set(scan_index))
    if unknown_scans:
        i = int(np.flatnonzero(detections.scan_id == unknown_scans[0])[0])
        raise LabelingError(f"{detections.path}:{int(detections.row[i])}: scan_id: unknown scan {unknown_scans[0]!r}, "
                            "expected a scan_id of tables/scans.parquet")
    if p.observed != "matched" and receptacle_visible is None:
        raise LabelingError(f"observed={p.observed!r} needs receptacle visibility (compute it first)")


def _object_ids_by_name(ds: Any, obj_ids: list[str]) -> dict[str, str]:
    """Detection label -> object id: every object id, and every object name that only one object has."""
    names: dict[str, list[str]] = {}
    for oid, info in ds.objects.items():
        names.setdefault(info.name, []).append(oid)
    out = {n: ids[0] for n, ids in names.items() if len(ids) == 1}
    out.update({o: o for o in obj_ids})
    return out


def _observed(matched: NDArray[np.bool_], p: AssociationParams, visible: NDArray[np.bool_] | None
              ) -> NDArray[np.bool_]:
    """Receptacles counted as observed: matched by a detection, visible, or either (``p.observed``)."""
    if p.observed == "visibility":
        return np.asarray(visible, bool).copy()
    if p.observed == "either":
        return matched | np.asarray(visible, bool)
    return matched.copy()


def _stated_receptacles(det: Detections, oidx: NDArray[np.int64], rec_of_node: NDArray[np.int64]
                        ) -> NDArray[np.int64]:
    """For object detections ``oidx``: the annotated receptacle their stated receptacle node matched, else -1."""
    assert det.stated_on is not None
    pos = {int(r): i for i, r in enumerate(det.row)}
    return np.array([rec_of_node[pos[int(r)]] if int(r) in pos else -1 for r in det.stated_on[oidx]], np.int64)


def _associate_scan(det: Detections, oidx: NDArray[np.int64], name_to_id: dict[str, str], oi: dict[str, int],
                    rec_boxes: list[Any], obs: NDArray[np.bool_], p: AssociationParams, assoc: NDArray[np.bool_],
                    tally: _Tally, stated: NDArray[np.int64] | None = None) -> None:
    """Associate one scan's object detections ``oidx`` with observed receptacles, into ``assoc`` (O, R).

    ``stated``: per detection of ``oidx`` the receptacle a stated relation names (-1 none), used instead of
    the geometric rule (an object without one is associated with no receptacle).
    """
    if oidx.size == 0:
        return
    labels = [name_to_id.get(str(lb)) for lb in det.label[oidx]]
    keep = np.array([lb is not None for lb in labels], bool)
    tally.unknown += int((~keep).sum())
    tally.unknown_labels.update(str(lb) for lb, k in zip(det.label[oidx], keep) if not k)
    if not keep.any():
        return
    obj_index = np.array([oi[lb] for lb in labels if lb is not None], np.int64)
    if stated is None:
        k = associate_objects(det.centroid_m[oidx[keep]], rec_boxes, obs, p)
    else:
        k = stated[keep]
        k = np.where((k >= 0) & obs[np.maximum(k, 0)], k, -1)
    tally.unassociated += int((k < 0).sum())
    assoc[obj_index[k >= 0], k[k >= 0]] = True
