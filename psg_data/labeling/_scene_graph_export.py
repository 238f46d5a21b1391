"""Writing detections as the scene-graph files ConceptGraphs, Spark-DSG and HOV-SG produce (round trips, demos).

One folder per scan named by its ``scan_id`` under ``out``, holding the files the tool writes for
one mapping session (layouts: :mod:`psg_data.labeling._scene_graphs`). A format keeps only what
it can say: ConceptGraphs and HOV-SG boxes are axis-aligned (the world AABB of each box), no
format has a score (1) or a separate centroid (the box centre); :func:`representable` gives the
detections a format can hold, i.e. what reading the export back returns.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import LabelingError
from psg_data.labeling._detections import Detections
from psg_data.labeling._scene_graphs import Y_UP_TO_Z_UP

__all__ = ["EXPORT_FORMATS", "export_scene_graphs", "representable", "write_detections_table"]

EXPORT_FORMATS = ("conceptgraphs", "conceptgraphs-realtime", "spark-dsg", "spark-dsg-binary", "khronos", "hovsg")


def _aabb_extent(det: Detections) -> NDArray[np.float64]:
    return np.einsum("nij,nj->ni", np.abs(det.box_rotation), det.box_extent_m)


def representable(det: Detections, fmt: str) -> Detections:
    """What format ``fmt`` keeps of ``det`` (AABB or float32 boxes, score 1, centroid = box centre)."""
    n = len(det)
    if fmt.startswith("spark-dsg") or fmt == "khronos":
        c = det.box_center_m.astype(np.float32).astype(float)
        e = det.box_extent_m.astype(np.float32).astype(float)
        R = det.box_rotation
    else:
        c, e, R = det.box_center_m.copy(), _aabb_extent(det), np.repeat(np.eye(3)[None], n, axis=0)
    return Detections(det.path, det.scan_id.copy(), det.label.copy(), det.kind.copy(), c, c.copy(), e, R,
                      np.ones(n), np.arange(n))


def write_detections_table(det: Detections, path: str | Path) -> Path:
    """Write ``det`` as a psg-data detections JSON table (docs/FORMAT.md, "Detections file")."""
    recs = [{"scan_id": str(det.scan_id[i]), "label": str(det.label[i]), "kind": str(det.kind[i]),
             "centroid_m": det.centroid_m[i].tolist(), "box_center_m": det.box_center_m[i].tolist(),
             "box_extent_m": det.box_extent_m[i].tolist(), "box_rotation": det.box_rotation[i].reshape(9).tolist(),
             "score": float(det.score[i])} for i in range(len(det))]
    p = Path(path)
    p.write_text(json.dumps({"detections": recs}), encoding="utf-8")
    return p


def export_scene_graphs(det: Detections, out: str | Path, fmt: str,
                        scan_spans: dict[str, tuple[int, int]] | None = None) -> Path:
    """Write ``det`` under ``out`` as ``fmt`` (:data:`EXPORT_FORMATS`); ``khronos`` needs ``scan_spans``."""
    if fmt not in EXPORT_FORMATS:
        raise LabelingError(f"export format {fmt!r}: expected one of {', '.join(EXPORT_FORMATS)}")
    root = Path(out)
    if fmt == "khronos":
        assert scan_spans is not None, "khronos needs the scans' time spans"
        root.mkdir(parents=True, exist_ok=True)
        _khronos(det, root / "khronos_dsg.json", scan_spans)
        return root
    rep = representable(det, fmt)
    for sid in sorted(set(rep.scan_id.tolist())):
        sub = rep.subset(rep.scan_id == sid)
        d = root / sid
        if fmt == "conceptgraphs":
            (d / "sg_cache").mkdir(parents=True, exist_ok=True)
            _write(d / "sg_cache" / "scene_graph.json", [_cg(sub, i) for i in range(len(sub))])
            _write(d / "sg_cache" / "cfslam_object_relations.json", _cg_relations(sub))
        elif fmt == "conceptgraphs-realtime":
            d.mkdir(parents=True, exist_ok=True)
            _write(d / f"obj_json_{sid}.json", {f"object_{i + 1}": {**_cg(sub, i), "object_caption": ""}
                                                for i in range(len(sub))})
            _write(d / f"edge_json_{sid}.json", {})
        elif fmt.startswith("spark-dsg"):
            d.mkdir(parents=True, exist_ok=True)
            _spark_graph(sub).save(str(d / ("dsg.sparkdsg" if fmt.endswith("binary") else "dsg.json")),
                                   include_mesh=False)
        else:
            (d / "objects").mkdir(parents=True, exist_ok=True)
            for i in range(len(sub)):
                _write(d / "objects" / f"0_{i}.json", _hovsg(sub, i))
    return root


def _write(path: Path, data: Any) -> None:
    path.write_text(json.dumps(data, indent=1), encoding="utf-8")


def _cg(d: Detections, i: int) -> dict[str, Any]:
    """One ConceptGraphs node (build_scenegraph_cfslam.generate_scenegraph_json's keys; unrounded)."""
    return {"id": i, "bbox_extent": d.box_extent_m[i].tolist(), "bbox_center": d.box_center_m[i].tolist(),
            "possible_tags": [str(d.label[i])], "object_tag": str(d.label[i]), "caption": str(d.label[i])}


def _cg_relations(d: Detections) -> list[dict[str, Any]]:
    """One 'a on b': the first object over the first receptacle (the relation file's layout, its ids checked on
    read; not a true relation, so the exported folder is for relations 'geometric').
    """
    recs = np.flatnonzero(d.kind == "receptacle")
    objs = np.flatnonzero(d.kind == "object")
    if not recs.size or not objs.size:
        return []
    b = int(recs[0])
    return [{"object1": {"id": int(a), "object_tag": str(d.label[a])}, "object2": {"id": b, "object_tag":
             str(d.label[b])}, "object_relation": "a on b", "reason": "psg-data export"} for a in objs[:1]]


def _hovsg(d: Detections, i: int) -> dict[str, Any]:
    """A HOV-SG object: the 8 corners of its AABB in HOV-SG's y-up frame (object.Object.save's keys)."""
    lo = d.box_center_m[i] - d.box_extent_m[i] / 2
    hi = d.box_center_m[i] + d.box_extent_m[i] / 2
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return {"object_id": f"0_{i}", "vertices": (corners @ Y_UP_TO_Z_UP).tolist(), "room_id": "0",
            "name": str(d.label[i]), "embedding": ""}


def _spark_graph(d: Detections, khronos: bool = False) -> Any:
    try:
        import spark_dsg as dsg
    except ImportError as exc:
        raise LabelingError("writing Spark-DSG graphs needs the spark_dsg package: pip install 'psg-data[graph]'"
                            ) from exc

    G = dsg.DynamicSceneGraph()
    for i in range(len(d)):
        a = dsg.KhronosObjectAttributes() if khronos else dsg.ObjectNodeAttributes()
        a.name = str(d.label[i])
        a.position = d.box_center_m[i]
        a.bounding_box = dsg.BoundingBox(dsg.BoundingBoxType.OBB, d.box_extent_m[i].astype(np.float32),
                                         d.box_center_m[i].astype(np.float32), d.box_rotation[i].astype(np.float32))
        G.add_node(dsg.DsgLayers.OBJECTS, dsg.NodeSymbol("O", i).value, a)
    return G


def _khronos(det: Detections, path: Path, spans: dict[str, tuple[int, int]]) -> None:
    """One Khronos map: a node per detection with the presence interval of its scan.

    ``spark_dsg``'s Python binding cannot set ``first_observed_ns`` / ``last_observed_ns`` (read-only
    lists), so the graph is written by ``spark_dsg`` and those two fields are filled in its JSON.
    """
    rep = representable(det, "khronos")
    G = _spark_graph(rep, khronos=True)
    G.save(str(path), include_mesh=False)
    data = json.loads(path.read_text(encoding="utf-8"))
    for n in data["nodes"]:
        i = n["id"] - _symbol0()
        t0, t1 = spans[str(rep.scan_id[i])]
        n["attributes"]["first_observed_ns"], n["attributes"]["last_observed_ns"] = [int(t0)], [int(t1)]
    path.write_text(json.dumps(data), encoding="utf-8")


def _symbol0() -> int:
    import spark_dsg as dsg

    return int(dsg.NodeSymbol("O", 0).value)
