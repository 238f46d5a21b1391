"""Per-scan detections from scene graphs written by ConceptGraphs, Spark-DSG (Hydra / Khronos) and HOV-SG.

Each reader turns the object nodes of one mapping session into rows of psg-data's detections
table (:mod:`psg_data.labeling._detections`). The layouts follow each tool's own source (cited in
docs/RAW_FORMATS.md, "Scene graphs"):

* ``conceptgraphs``: ``scene_graph.json`` (a list of ``{id, bbox_center, bbox_extent, object_tag,
  caption}``; optional ``cfslam_object_relations.json`` next to it) or the realtime layout
  ``obj_json_*.json`` (``{"object_N": {id, object_tag, bbox_center, bbox_extent}}``; optional
  ``edge_json_*.json``). Boxes are axis-aligned (the files carry no rotation); score 1.
* ``spark-dsg``: a Spark-DSG JSON graph (``SPARK_DSG_header``; legacy files without a header are
  read as the library reads them: version 1.0.0) or a binary ``.sparkdsg`` (through the
  ``spark_dsg`` package). The OBJECTS layer's nodes: the label is ``name`` unless the layer's
  label space in ``metadata.labelspaces`` names ``semantic_label``; the box is ``bounding_box``
  (centre, dimensions, rotation from its quaternion). Khronos objects with
  ``first_observed_ns`` / ``last_observed_ns`` intervals are detected in every scan whose time
  span overlaps an interval, so one Khronos map covers all scans.
* ``hovsg``: ``objects/*.json`` (``object_id``, ``name``, ``room_id``, ``vertices``: 3D points, e.g.
  the 8 corners of the axis-aligned box) in HOV-SG's y-up frame, turned to psg-data's z-up frame
  by ``(x, y, z) -> (x, -z, y)`` before the optional transform.

Sessions map to scans: ``PATH`` is a folder holding one sub-folder per scan named by its
``scan_id`` (each with that session's files as the tool writes them), or a single file / session
folder named in the mapping file's ``sessions``. A mapping file ``psg_mapping.json`` in ``PATH``
(or given explicitly) may hold ``{"sessions": {folder: scan_id or time_ns}, "synonyms": {tool label: dataset
label}, "classes": class-list file or [names], "transform": 4x4 world-from-graph matrix}``. With a class
list (the tool's ``--class_set`` file, one class per line), a numeric label ``i`` (a digit string, or a
Spark-DSG ``semantic_label`` outside the file's label space) is the list's line ``i``. A label is an
object when it (or its synonym) is a dataset object id or name, a receptacle when it is a receptacle
id, name or category; other labels are counted and reported, and left out. ``"relations"``:
``geometric`` (default: objects go on receptacles by the on-top association, stated ConceptGraphs
relations are only checked against it and the agreement logged) or ``stated`` (ConceptGraphs only: an
object is on the receptacle node its "a on b" / "on top of" relation names, which goes to the annotated
receptacle it matched; an object without such a relation is on no receptacle).

Pickled maps (``.pkl``, ``.pkl.gz``, ``.pickle``) are refused without being opened.
"""

from __future__ import annotations

import json
import logging
import math
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from psg_data.errors import LabelingError
from psg_data.labeling._detections import Detections

__all__ = ["DETECTION_FORMATS", "SceneGraphMapping", "Vocabulary", "detect_format", "read_scene_graphs",
           "read_any_detections", "load_mapping", "vocabulary"]

log = logging.getLogger(__name__)

DETECTION_FORMATS = ("table", "conceptgraphs", "spark-dsg", "hovsg")
MAPPING_FILE = "psg_mapping.json"
MAX_FILE_BYTES = 100 * 2**20
"""Largest scene-graph file read (bytes)."""
MAX_DEPTH = 64
"""Deepest JSON nesting accepted."""
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
"""HOV-SG's y-up frame to psg-data's z-up frame: (x, y, z) -> (x, -z, y)."""
CG_ROUNDING_M = {"scene_graph": 0.1, "obj_json": 0.01}
"""ConceptGraphs' rounding of ``bbox_extent`` (``np.round(extent, 1)`` in ``generate_scenegraph_json``,
``round(val, 2)`` in ``save_obj_json``): a side written as 0 is read as half a step."""
_PICKLE_SUFFIXES = (".pkl", ".pickle", ".pkl.gz", ".pickle.gz")


@dataclass
class SceneGraphMapping:
    """How a tool's sessions, labels and frame map onto the dataset (module docstring)."""

    sessions: dict[str, str | int] = field(default_factory=dict)
    synonyms: dict[str, str] = field(default_factory=dict)
    transform: NDArray[np.float64] | None = None
    classes: list[str] | None = None
    """The class list the tool was run with: a numeric label ``i`` is ``classes[i]``."""
    relations: str = "geometric"
    """``geometric``: objects go on receptacles by the on-top rule (stated relations are only checked
    against it); ``stated``: on the receptacle a stated relation names (ConceptGraphs)."""


@dataclass
class Vocabulary:
    """The dataset's label space: object labels, receptacle labels, scan time spans (ns)."""

    objects: set[str]
    receptacles: set[str]
    scan_spans: dict[str, tuple[int, int]]


@dataclass
class _Node:
    scan_id: str
    label: str
    center: NDArray[np.float64]
    extent: NDArray[np.float64]
    rotation: NDArray[np.float64]
    where: str  # FILE: node
    on: list[_Node] = field(default_factory=list)  # nodes a stated relation puts this one on


def _err(where: str, msg: str) -> LabelingError:
    return LabelingError(f"{where}: {msg}")


def _check_depth(obj: Any, where: str) -> None:
    stack = [(obj, 1)]
    while stack:
        o, d = stack.pop()
        if d > MAX_DEPTH:
            raise _err(where, f"JSON nested deeper than {MAX_DEPTH} levels, expected a scene-graph export")
        if isinstance(o, dict):
            stack.extend((v, d + 1) for v in o.values())
        elif isinstance(o, list):
            stack.extend((v, d + 1) for v in o if isinstance(v, (dict, list)))


def _refuse_pickle(p: Path) -> None:
    name = p.name.lower()
    if name.endswith(_PICKLE_SUFFIXES):
        raise _err(str(p), "a pickled map is never unpickled (it can run code); export the scene graph as JSON "
                           "instead (ConceptGraphs: sg_cache/scene_graph.json or obj_json_*.json; DualMap / Spark-DSG: "
                           "the JSON graph)")


def _load_json(p: Path) -> Any:
    _refuse_pickle(p)
    size = p.stat().st_size
    if size > MAX_FILE_BYTES:
        raise _err(str(p), f"{size / 2**20:.0f} MB, larger than the {MAX_FILE_BYTES // 2**20} MB a scene-graph "
                           "file may have")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except RecursionError as exc:
        raise _err(str(p), f"JSON nested deeper than {MAX_DEPTH} levels, expected a scene-graph export") from exc
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise _err(str(p), f"not valid JSON ({exc})") from exc
    _check_depth(data, str(p))
    return data


_MAPPING_KEYS = ("sessions", "synonyms", "classes", "transform", "relations")
RELATIONS = ("geometric", "stated")


def load_mapping(path: str | Path) -> SceneGraphMapping:
    """Read a mapping file ``{"sessions": {...}, "synonyms": {...}, "classes": FILE or [...], "transform": 4x4}``
    (all optional; module docstring).
    """
    p = Path(path)
    data = _load_json(p)
    if not isinstance(data, dict) or set(data) - set(_MAPPING_KEYS):
        raise _err(str(p), f"expected an object with keys {', '.join(_MAPPING_KEYS)}")
    out = SceneGraphMapping()
    if data.get("classes") is not None:
        out.classes = _load_classes(p, data["classes"])
    out.relations = data.get("relations", "geometric")
    if out.relations not in RELATIONS:
        raise _err(f"{p}: relations", f"{out.relations!r}, expected one of {', '.join(RELATIONS)}")
    for key in ("sessions", "synonyms"):
        d = data.get(key, {})
        ok = (lambda v: isinstance(v, str) and v) if key == "synonyms" else (
            lambda v: (isinstance(v, str) and v) or (isinstance(v, int) and not isinstance(v, bool)))
        if not isinstance(d, dict) or not all(isinstance(k, str) and ok(v) for k, v in d.items()):
            raise _err(f"{p}: {key}", "expected an object of non-empty strings" + (
                " (a scan_id) or integer times (ns, the scan that contains it)" if key == "sessions" else ""))
        setattr(out, key, dict(d))
    if data.get("transform") is not None:
        try:
            T = np.asarray(data["transform"], dtype=float)
        except (TypeError, ValueError) as exc:
            raise _err(f"{p}: transform", "expected a 4x4 matrix of numbers") from exc
        R = T[:3, :3] if T.shape == (4, 4) else None
        if (R is None or not np.all(np.isfinite(T)) or np.abs(R.T @ R - np.eye(3)).max() > 1e-6
                or np.linalg.det(R) <= 0 or np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-12):
            raise _err(f"{p}: transform", "expected a 4x4 rigid transform (rotation with det +1, last row 0 0 0 1)")
        out.transform = T
    return out


def _load_classes(mapping_file: Path, value: Any) -> list[str]:
    """A class list: a list of names, or a text file with one class per line (relative to the mapping file),
    read as ConceptGraphs reads its ``--class_set`` file (each line stripped, line ``i`` is class ``i``).
    """
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return [v.strip() for v in value]
    if not isinstance(value, str) or not value:
        raise _err(f"{mapping_file}: classes", "expected a class-list file (one class per line) or a list of names")
    f = (mapping_file.parent / value) if not Path(value).is_absolute() else Path(value)
    _refuse_pickle(f)
    try:
        if f.stat().st_size > MAX_FILE_BYTES:
            raise _err(str(f), f"larger than the {MAX_FILE_BYTES // 2**20} MB a class list may have")
        lines = f.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise _err(f"{mapping_file}: classes", f"cannot read class list {f} ({exc}), expected a UTF-8 text file "
                                               "with one class per line") from exc
    return [line.strip() for line in lines]


def detect_format(path: str | Path) -> str:
    """The format of ``path`` (``table``, ``conceptgraphs``, ``spark-dsg`` or ``hovsg``), from its content.

    Raises:
        LabelingError: a pickled map, or nothing recognisable.
    """
    p = Path(path)
    _refuse_pickle(p)
    if p.is_file():
        if p.suffix.lower() == ".parquet":
            return "table"
        if p.suffix.lower() == ".sparkdsg":
            return "spark-dsg"
        if p.suffix.lower() != ".json":
            return "table"  # the table reader names the file types it reads
        return _format_of_json(p, _load_json(p))
    if p.is_dir():
        subs = [p, *sorted(d for d in p.iterdir() if d.is_dir())]
        for f in (f for d in subs for f in _session_files(d) if f.name != MAPPING_FILE):
            return _format_of_file(f)
        raise _err(str(p), "no scene-graph files found (scene_graph.json, obj_json_*.json, a Spark-DSG .json / "
                           ".sparkdsg, objects/*.json), expected one folder per scan named by its scan_id")
    raise _err(str(p), "detections file not found (nor a folder of scene graphs)")


def _format_of_file(f: Path) -> str:
    if f.suffix.lower() == ".sparkdsg":
        return "spark-dsg"
    if f.parent.name == "objects":
        return "hovsg"
    return _format_of_json(f, _load_json(f))


def _format_of_json(p: Path, data: Any) -> str:
    if isinstance(data, dict) and ("SPARK_DSG_header" in data or ("nodes" in data and "edges" in data)):
        return "spark-dsg"
    if isinstance(data, dict) and "detections" in data:
        return "table"
    if isinstance(data, list) and data and isinstance(data[0], dict):
        if "scan_id" in data[0] and "kind" in data[0]:
            return "table"
        if "object_tag" in data[0] or "bbox_center" in data[0]:
            return "conceptgraphs"
    if isinstance(data, dict) and data and all(isinstance(v, dict) and "object_tag" in v for v in data.values()):
        return "conceptgraphs"
    if isinstance(data, dict) and "vertices" in data and "object_id" in data:
        return "hovsg"
    return "table"  # anything else: the table reader says what a detections table must hold


def _session_files(folder: Path) -> list[Path]:
    """Scene-graph files of one session folder (searched two levels deep)."""
    pats = ("scene_graph.json", "obj_json_*.json", "*.sparkdsg", "dsg*.json", "*_dsg.json", "objects/*.json",
            "*.pkl", "*.pkl.gz")
    out: list[Path] = []
    for pat in pats:
        out += [f for f in folder.glob(pat) if f.is_file()]
        out += [f for f in folder.glob(f"*/{pat}") if f.is_file()]
    return sorted(set(out))


def _vec(v: Any, n: int, where: str, what: str) -> NDArray[np.float64]:
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise _err(where, f"{what}: {v!r} is not numeric, expected {n} numbers") from exc
    if a.size != n or not np.all(np.isfinite(a)):
        raise _err(where, f"{what}: {np.asarray(v).tolist() if a.size < 20 else '...'}, expected {n} finite numbers")
    return a


def _box_node(scan_id: str, label: Any, center: Any, extent: Any, R: NDArray[np.float64], where: str,
              rounded_to: float = 0.0) -> _Node:
    """One node; ``rounded_to``: the tool's rounding step of the extent (a zero side becomes half of it)."""
    if not isinstance(label, str) or not label.strip():
        raise _err(where, f"label {label!r}, expected a non-empty string")
    c = _vec(center, 3, where, "box centre")
    e = _vec(extent, 3, where, "box extent")
    if rounded_to > 0 and np.all(e >= 0) and np.any(e > 0):
        e = np.where(e == 0, rounded_to / 2, e)  # a side the tool rounded to 0 is shorter than half a step
    if not np.all(e > 0):
        raise _err(where, f"box extent {e.tolist()}, expected 3 positive side lengths (a box with non-zero volume)"
                   + (f"; a side rounded to 0 is read as {rounded_to / 2:g} m, not all three" if rounded_to else ""))
    return _Node(scan_id, label.strip(), c, e, R, where)


# ----------------------------------------------------------------------------------------------- ConceptGraphs


def _read_conceptgraphs(p: Path, scan_id: str) -> list[_Node]:
    data = _load_json(p)
    if isinstance(data, dict) and all(isinstance(v, dict) for v in data.values()):
        items = list(data.items())  # realtime obj_json: {"object_N": {...}}
        rel_glob, step = "edge_json_*.json", CG_ROUNDING_M["obj_json"]
    elif isinstance(data, list):
        items = [(f"#{i}", v) for i, v in enumerate(data)]
        rel_glob, step = "cfslam_object_relations.json", CG_ROUNDING_M["scene_graph"]
    else:
        raise _err(str(p), "expected a ConceptGraphs scene_graph.json list or an obj_json {\"object_N\": {...}} map")
    nodes: list[_Node] = []
    ids: dict[Any, _Node] = {}
    for key, rec in items:
        where = f"{p}: node {key}"
        if not isinstance(rec, dict):
            raise _err(where, f"expected an object, got {type(rec).__name__}")
        if "id" not in rec:
            raise _err(where, "no 'id', expected a ConceptGraphs node id")
        where = f"{p}: node {rec['id']!r}"
        if rec["id"] in ids:
            raise _err(where, "duplicate id, expected unique node ids")
        if "bbox_center" not in rec or "bbox_extent" not in rec:
            raise _err(where, "no box (bbox_center, bbox_extent), expected both")
        nodes.append(_box_node(scan_id, rec.get("object_tag"), rec["bbox_center"], rec["bbox_extent"], np.eye(3),
                               where, rounded_to=step))
        ids[rec["id"]] = nodes[-1]
    # cfslam relations name nodes by their position in scene_graph.json (build_scenegraph's segmentidx into
    # the pruned map, which generate_scenegraph_json writes in order); edge_json by obj_json's id
    by_ref = ids if rel_glob.startswith("edge") else dict(enumerate(nodes))
    for rp in sorted(p.parent.glob(rel_glob)):
        _read_relations(rp, by_ref)
    return nodes


def _read_relations(p: Path, nodes: dict[Any, _Node]) -> None:
    """Stated 'on' relations of ``cfslam_object_relations.json`` / ``edge_json_*.json`` (ids checked)."""
    data = _load_json(p)
    recs = list(data.values()) if isinstance(data, dict) else data
    if not isinstance(recs, list):
        raise _err(str(p), "expected a list (or map) of relations")
    for i, r in enumerate(recs):
        if not isinstance(r, dict):
            raise _err(f"{p}: relation {i}", "expected an object")
        if "object1" in r:
            o1, o2 = r.get("object1"), r.get("object2")
            refs = [o.get("id") if isinstance(o, dict) else None for o in (o1, o2)]
            rel = {"a on b": (0, 1), "b on a": (1, 0)}.get(str(r.get("object_relation")))
        else:
            refs = [r.get("object_1_id"), r.get("object_2_id")]
            rel = (0, 1) if r.get("relationship") == "on top of" else None
        for ref in refs:
            if isinstance(ref, (dict, list)) or ref not in nodes:
                raise _err(f"{p}: relation {i}", f"names unknown node id {ref!r}, expected an id of the session's "
                                                 "objects")
        if rel is not None:
            nodes[refs[rel[0]]].on.append(nodes[refs[rel[1]]])


def _check_stated_on(path: str, kept: list[_Node], kinds: list[str]) -> None:
    """Log how many stated 'a on b' relations (object on receptacle) the geometric association agrees with.

    The test is relative (the object in the receptacle's box frame), so the world transform does not change it.
    """
    from psg_data.labeling._association import AssociationParams, associate_objects
    from psg_data.schemas._records import Box

    kind = {id(n): k for n, k in zip(kept, kinds)}
    pairs = [(a, b) for a in kept for b in a.on if kind.get(id(a)) == "object" and kind.get(id(b)) == "receptacle"]
    if not pairs:
        return
    agree = sum(int(associate_objects(a.center[None], [Box(b.center, b.extent, b.rotation)],
                                      params=AssociationParams())[0] == 0) for a, b in pairs)
    log.info("%s: %d of %d stated 'on' relations (object on receptacle) agree with the geometric association "
             "(on top within the default footprint margin)", path, agree, len(pairs))


# ----------------------------------------------------------------------------------------------- Spark-DSG


def _quat(q: Any, where: str) -> NDArray[np.float64]:
    if not isinstance(q, dict) or not all(k in q for k in "wxyz"):
        raise _err(where, f"world_R_center {q!r}, expected a quaternion {{w, x, y, z}}")
    w, x, y, z = _vec([q["w"], q["x"], q["y"], q["z"]], 4, where, "quaternion")
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if n < 1e-6:
        raise _err(where, "zero quaternion, expected a rotation")
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _dsg_json(p: Path) -> Any:
    if p.suffix.lower() != ".sparkdsg":
        return _load_json(p)
    try:
        import spark_dsg
    except ImportError as exc:
        raise _err(str(p), "a binary Spark-DSG graph needs the spark_dsg package (pip install 'psg-data[graph]'), "
                           "or save the graph as JSON") from exc
    import tempfile

    if p.stat().st_size > MAX_FILE_BYTES:
        raise _err(str(p), f"larger than the {MAX_FILE_BYTES // 2**20} MB a scene-graph file may have")
    try:
        G = spark_dsg.DynamicSceneGraph.load(str(p))
    except Exception as exc:  # the binding raises plain RuntimeErrors
        raise _err(str(p), f"spark_dsg could not read it ({str(exc).splitlines()[0][:120] if str(exc) else exc!r})"
                   ) from exc
    with tempfile.TemporaryDirectory() as tmp:
        G.save(str(Path(tmp) / "g.json"), include_mesh=False)
        return _load_json(Path(tmp) / "g.json")


def _dsg_version(p: Path, data: dict[str, Any]) -> tuple[int, int, int]:
    if "SPARK_DSG_header" not in data:
        return (1, 0, 0)  # what Spark-DSG reads a header-less file as (FileHeader::legacy)
    v = data["SPARK_DSG_header"].get("version") if isinstance(data["SPARK_DSG_header"], dict) else None
    if not isinstance(v, dict) or not all(isinstance(v.get(k), int) for k in ("major", "minor", "patch")):
        raise _err(f"{p}: SPARK_DSG_header", f"version {v!r}, expected {{major, minor, patch}} integers")
    ver = (v["major"], v["minor"], v["patch"])
    if ver[0] != 1:
        raise _err(f"{p}: SPARK_DSG_header", f"version {'.'.join(map(str, ver))}, expected a 1.x Spark-DSG file")
    return ver


def _dsg_objects_layer(p: Path, data: dict[str, Any], ver: tuple[int, int, int]) -> tuple[int, int]:
    names = data.get("layer_names")
    if ver < (1, 1, 0) or not isinstance(names, dict) or "OBJECTS" not in names:
        return (2, 0)
    key = names["OBJECTS"]
    if isinstance(key, dict):
        return (int(key.get("layer", 2)), int(key.get("partition", 0)))
    return (int(key), 0)


def _dsg_labelspace(data: dict[str, Any], layer: tuple[int, int]) -> dict[int, str]:
    meta = data.get("metadata")
    spaces = meta.get("labelspaces") if isinstance(meta, dict) else None
    space = spaces.get(f"_l{layer[0]}p{layer[1]}") if isinstance(spaces, dict) else None
    if isinstance(space, list):
        return {int(k): str(v) for k, v in space if isinstance(k, int)}
    if isinstance(space, dict):
        return {int(k): str(v) for k, v in space.items() if str(k).lstrip("-").isdigit()}
    return {}


def _read_spark_dsg(p: Path, scan_id: str | None, vocab: Vocabulary, numeric: bool = False) -> list[_Node]:
    """The OBJECTS layer's nodes; ``numeric``: a ``semantic_label`` outside the file's label space is the label
    (its number, for the mapping's class list) instead of ``name``.
    """
    data = _dsg_json(p)
    if not isinstance(data, dict) or not isinstance(data.get("nodes"), list):
        raise _err(str(p), "expected a Spark-DSG JSON graph with a 'nodes' list")
    ver = _dsg_version(p, data)
    layer = _dsg_objects_layer(p, data, ver)
    labels = _dsg_labelspace(data, layer)
    nodes: list[_Node] = []
    seen: set[Any] = set()
    for i, n in enumerate(data["nodes"]):
        if not isinstance(n, dict) or not isinstance(n.get("attributes"), dict):
            raise _err(f"{p}: node {i}", "expected {id, layer, attributes}")
        nid = n.get("id")
        where = f"{p}: node {nid}"
        if nid in seen:
            raise _err(where, "duplicate node id, expected unique ids")
        seen.add(nid)
        a = n["attributes"]
        if n.get("layer") != layer[0] or a.get("type") not in ("ObjectNodeAttributes", "KhronosObjectAttributes"):
            continue
        if "partition" in n and n["partition"] != layer[1]:
            continue
        nodes += _dsg_node(p, where, a, ver, labels, scan_id, vocab, numeric)
    return nodes


def _dsg_node(p: Path, where: str, a: dict[str, Any], ver: tuple[int, int, int], labels: dict[int, str],
              scan_id: str | None, vocab: Vocabulary, numeric: bool = False) -> list[_Node]:
    bb = a.get("bounding_box")
    if not isinstance(bb, dict) or bb.get("type", "INVALID") == "INVALID":
        raise _err(where, "no bounding box (type INVALID or missing), expected an AABB / RAABB / OBB")
    if ver < (1, 0, 3) or "dimensions" not in bb:
        if "min" not in bb or "max" not in bb:
            raise _err(where, "bounding box without dimensions (or min / max)")
        ext = _vec(bb["max"], 3, where, "max") - _vec(bb["min"], 3, where, "min")
    else:
        ext = _vec(bb["dimensions"], 3, where, "dimensions")
    R = _quat(bb.get("world_R_center"), where) if bb.get("type") != "AABB" else np.eye(3)
    sem = a.get("semantic_label")
    label = labels.get(sem, str(sem) if numeric else a.get("name")) if isinstance(sem, int) else a.get("name")
    node = _box_node(scan_id or "", label, bb.get("world_P_center"), ext, R, where)
    first, last = a.get("first_observed_ns") or [], a.get("last_observed_ns") or []
    if not first and not last:
        if scan_id is None:
            raise _err(where, "a Spark-DSG map outside a scan folder needs Khronos first_observed_ns / "
                              "last_observed_ns intervals, or put it in a folder named by its scan_id")
        return [node]
    if (len(first) != len(last) or not all(isinstance(t, int) for t in [*first, *last])
            or any(f > la for f, la in zip(first, last))):
        raise _err(where, "first_observed_ns / last_observed_ns: expected equal-length lists of integer "
                          "start <= end times (ns)")
    scans = [s for s, (t0, t1) in vocab.scan_spans.items() if any(f <= t1 and la >= t0 for f, la in zip(first, last))]
    if scan_id is not None:
        scans = [s for s in scans if s == scan_id]
    return [_Node(s, node.label, node.center, node.extent, node.rotation, where) for s in scans]


# ----------------------------------------------------------------------------------------------- HOV-SG


def _read_hovsg(folder: Path, scan_id: str) -> list[_Node]:
    nodes, seen = [], set()
    for f in sorted(folder.glob("*.json")):
        rec = _load_json(f)
        if not isinstance(rec, dict) or "object_id" not in rec:
            raise _err(str(f), "expected a HOV-SG object {object_id, name, room_id, vertices}")
        where = f"{f}: node {rec['object_id']!r}"
        if rec["object_id"] in seen:
            raise _err(where, "duplicate object_id, expected unique ids")
        seen.add(rec["object_id"])
        try:
            v = np.asarray(rec.get("vertices"), dtype=float)
        except (TypeError, ValueError) as exc:
            raise _err(where, "vertices: not numeric, expected N x 3 points") from exc
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 2:
            raise _err(where, f"vertices of shape {list(v.shape)}, expected N x 3 points (e.g. the 8 box corners; "
                              "2D (x, z) footprints carry no height)")
        if not np.all(np.isfinite(v)):
            raise _err(where, "vertices: not finite, expected finite coordinates")
        v = v @ Y_UP_TO_Z_UP.T
        lo, hi = v.min(axis=0), v.max(axis=0)
        nodes.append(_box_node(scan_id, rec.get("name"), (lo + hi) / 2, hi - lo, np.eye(3), where))
    return nodes


# ----------------------------------------------------------------------------------------------- sessions


def _scan_of(v: str | int | None, spans: Mapping[str, tuple[int, int]], where: Path) -> str | None:
    """A sessions value as a scan_id: itself, or the scan whose time span contains an integer time (ns)."""
    if not isinstance(v, int):
        return v
    hit = [s for s, (t0, t1) in spans.items() if t0 <= v <= t1]
    if not hit:
        raise _err(str(where), f"session time {v} ns lies in no scan, expected a time inside a scan's "
                               "[start_stamp_ns, end_stamp_ns]")
    return hit[0]


def _sessions(root: Path, mapping: SceneGraphMapping, spans: Mapping[str, tuple[int, int]]
              ) -> list[tuple[Path, str | None]]:
    """(session path, scan_id) pairs; scan_id None for a whole-run map (Khronos intervals)."""
    if root.is_file():
        return [(root, _scan_of(mapping.sessions.get(root.name, mapping.sessions.get(root.stem)), spans, root))]
    known = set(spans)
    out: list[tuple[Path, str | None]] = []
    for d in sorted(x for x in root.iterdir() if x.is_dir()):
        sid = _scan_of(mapping.sessions.get(d.name, d.name if d.name in known else None), spans, d)
        if sid is None:
            if _session_files(d):
                raise _err(str(d), f"session folder {d.name!r} is not a scan_id of the dataset and not in the "
                                   "mapping file's sessions, expected one folder per scan named by its scan_id")
            continue
        if sid not in known:
            raise _err(str(d), f"session maps to unknown scan {sid!r}, expected a scan_id of tables/scans.parquet")
        out.append((d, sid))
    loose = [f for f in root.iterdir() if f.is_file() and f.name != MAPPING_FILE and f.suffix in (".json", ".sparkdsg")]
    out += [(f, _scan_of(mapping.sessions.get(f.name), spans, f)) for f in loose]
    if not out:
        raise _err(str(root), "no sessions found, expected one folder per scan named by its scan_id")
    return out


def _read_session(path: Path, scan_id: str | None, fmt: str, vocab: Vocabulary, mapping: SceneGraphMapping
                  ) -> list[_Node]:
    files = [path] if path.is_file() else _session_files(path)
    for f in files:
        _refuse_pickle(f)
    if not files:
        raise _err(str(path), f"no {fmt} files in this session folder")
    if fmt == "hovsg":
        dirs = sorted({f.parent for f in files if f.parent.name == "objects"})
        if not dirs:
            raise _err(str(path), "no objects/*.json, expected HOV-SG's graph folder")
        return [n for d in dirs for n in _read_hovsg(d, _need_scan(scan_id, d))]
    f = files[0] if path.is_file() else _one_graph(path, files, fmt)
    if fmt == "spark-dsg":
        return _read_spark_dsg(f, scan_id, vocab, numeric=mapping.classes is not None)
    if fmt == "conceptgraphs":
        return _read_conceptgraphs(f, _need_scan(scan_id, f))
    raise _err(str(f), f"format {fmt!r} is not a scene-graph format")


_HYDRA_ORDER = ("backend/dsg.json", "backend/dsg_with_mesh.json", "dsg.json", "dsg_with_mesh.json",
                "frontend/dsg.json", "frontend/dsg_with_mesh.json")
"""Hydra saves its graph twice per stage (``DsgUpdater::save``: ``dsg.json``, ``dsg_with_mesh.json``): the
first found is read."""


def _one_graph(session: Path, files: list[Path], fmt: str) -> Path:
    """The one scene graph of a session folder (Hydra: the backend graph first); several others are an error."""
    if fmt == "spark-dsg":
        for rel in _HYDRA_ORDER:
            if (session / rel).is_file():
                return session / rel
        files = [f for f in files if f.suffix.lower() == ".sparkdsg" or "dsg" in f.name]
    else:
        files = [f for f in files if f.name == "scene_graph.json" or f.name.startswith("obj_json_")]
    if len(files) != 1:
        names = ", ".join(str(f.relative_to(session)) for f in files) or "none"
        raise _err(str(session), f"{len(files)} {fmt} scene graphs in one session folder ({names}), expected one "
                                 "per scan folder")
    return files[0]


def _need_scan(scan_id: str | None, f: Path) -> str:
    if scan_id is None:
        raise _err(str(f), "no scan for this session: put it in a folder named by its scan_id or name it in the "
                           f"mapping file's sessions ({MAPPING_FILE})")
    return scan_id


# ----------------------------------------------------------------------------------------------- public


def read_scene_graphs(path: str | Path, fmt: str, vocab: Vocabulary, *, mapping: SceneGraphMapping | None = None,
                      receptacle_boxes: Mapping[str, Any] | None = None) -> Detections:
    """Detections (all scans) from scene-graph files at ``path`` (layouts in the module docstring).

    Args:
        path: a folder of per-scan session folders, or one file / session (named in ``mapping``).
        fmt: ``conceptgraphs``, ``spark-dsg`` or ``hovsg``.
        vocab: the dataset's labels and scan time spans.
        mapping: sessions, synonyms, transform (default: ``PATH/psg_mapping.json`` if it exists).
        receptacle_boxes: ``receptacle_id -> Box`` for the line-up check (a warning with the residual).

    Raises:
        LabelingError: one line naming the file and node for the first bad input.
    """
    root = Path(path)
    _refuse_pickle(root)
    if mapping is None:
        mf = root / MAPPING_FILE
        mapping = load_mapping(mf) if root.is_dir() and mf.is_file() else SceneGraphMapping()
    if mapping.classes is not None:
        _report_classes(str(root), mapping, vocab)
    if mapping.relations == "stated" and fmt != "conceptgraphs":
        raise _err(str(root), f"relations 'stated' in the mapping file: {fmt} scene graphs state no "
                              "object-on-receptacle relations, expected relations 'geometric'")
    nodes: list[_Node] = []
    for sess, sid in _sessions(root, mapping, vocab.scan_spans):
        nodes += _read_session(sess, sid, fmt, vocab, mapping)
    det = _to_detections(str(root), nodes, vocab, mapping)
    if receptacle_boxes:
        _line_up_check(det, receptacle_boxes)
    return det


def _to_detections(path: str, nodes: list[_Node], vocab: Vocabulary, mapping: SceneGraphMapping) -> Detections:
    keep, kinds, labels = [], [], []
    unmapped: Counter[str] = Counter()
    for n in nodes:
        name = _class_name(n.label, mapping.classes)
        lab = mapping.synonyms.get(name, name)
        if lab in vocab.objects:
            kinds.append("object")
        elif lab in vocab.receptacles:
            kinds.append("receptacle")
        else:
            unmapped[n.label if name == n.label else f"{n.label} = {name}"] += 1
            continue
        keep.append(n)
        labels.append(lab)
    if unmapped:
        log.warning("%s: %d scene-graph nodes with %d labels that are no dataset object or receptacle (left out; "
                    "map them with synonyms or a class list): %s", path, sum(unmapped.values()), len(unmapped),
                    ", ".join(f"{k} ({v})" for k, v in unmapped.most_common(10)))
    _check_stated_on(path, keep, kinds)
    if not keep:
        raise LabelingError(f"{path}: no scene-graph node maps onto a dataset object or receptacle "
                            f"({sum(unmapped.values())} unmapped nodes), expected labels or synonyms of the dataset")
    c = np.array([n.center for n in keep])
    R = np.array([n.rotation for n in keep])
    if mapping.transform is not None:
        T = mapping.transform
        c = c @ T[:3, :3].T + T[:3, 3]
        R = np.einsum("ij,njk->nik", T[:3, :3], R)
    det = Detections(path, np.array([n.scan_id for n in keep], dtype=object), np.array(labels, dtype=object),
                     np.array(kinds, dtype=object), c, c.copy(), np.array([n.extent for n in keep]), R,
                     np.ones(len(keep)), np.arange(len(keep)))
    if mapping.relations == "stated":
        det.stated_on = _stated_rows(path, keep, kinds)
    return det


def _stated_rows(path: str, kept: list[_Node], kinds: list[str]) -> NDArray[np.int64]:
    """Per kept node: the row of the first receptacle node a stated relation puts it on (-1: none)."""
    row = {id(n): i for i, n in enumerate(kept) if kinds[i] == "receptacle"}
    out = np.array([next((row[id(b)] for b in n.on if id(b) in row), -1) if k == "object" else -1
                    for n, k in zip(kept, kinds)], np.int64)
    n_obj = kinds.count("object")
    log.info("%s: relations 'stated': %d of %d object nodes stated on a receptacle node (the others are on no "
             "receptacle)", path, int((out >= 0).sum()), n_obj)
    return out


def _report_classes(path: str, mapping: SceneGraphMapping, vocab: Vocabulary) -> None:
    """Log how many classes of the class list name a dataset object or receptacle (after synonyms)."""
    classes = [c for c in mapping.classes or [] if c]
    hit = [c for c in classes if mapping.synonyms.get(c, c) in vocab.objects | vocab.receptacles]
    log.info("%s: %d of %d classes of the class list name dataset objects or receptacles (%s)", path, len(hit),
             len(classes), ", ".join(hit[:10]))


def _class_name(label: str, classes: list[str] | None) -> str:
    """A numeric label as its name in the class list (``label`` itself without a list, or out of its range)."""
    if classes is None or not label.isdigit():
        return label
    i = int(label)
    return classes[i] if i < len(classes) and classes[i] else f"class {i} (not in the class list of {len(classes)})"


def _line_up_check(det: Detections, boxes: Mapping[str, Any], tol_m: float = 0.5) -> float | None:
    """Warn when the receptacle nodes lie far from every annotated receptacle box; the median residual (m)."""
    rec = np.flatnonzero(det.kind == "receptacle")
    if rec.size == 0 or not boxes:
        return None
    centers = np.array([np.asarray(b.center_m, float) for b in boxes.values()])
    d = np.linalg.norm(det.box_center_m[rec, None, :] - centers[None], axis=2).min(axis=1)
    res = float(np.median(d))
    if res > tol_m:
        log.warning("%s: the scene graph's receptacles do not line up with the annotated boxes (median residual "
                    "%.2f m over %d receptacle nodes); check the mapping file's transform", det.path, res, rec.size)
    else:
        log.info("%s: receptacle line-up residual %.3f m (median over %d nodes)", det.path, res, rec.size)
    return res


def vocabulary(ds: Any) -> Vocabulary:
    """The :class:`Vocabulary` of an opened dataset."""
    objs = {o for oid, info in ds.objects.items() for o in (oid, info.name) if o}
    recs = {r for rid, info in ds.receptacles.items() for r in (rid, info.name, info.category) if r}
    spans = {s: (int(ds.scan(s).start_stamp_ns), int(ds.scan(s).end_stamp_ns)) for s in ds.scan_ids}
    return Vocabulary(objs, recs, spans)


def iter_formats() -> Iterable[str]:
    """The names ``--detections-format`` accepts (plus ``auto``)."""
    return ("auto", *DETECTION_FORMATS)


def read_any_detections(ds: Any, path: str | Path, fmt: str = "auto", *, min_score: float = 0.0) -> Detections:
    """Detections of dataset ``ds`` from a psg-data table or a scene-graph export (``fmt`` or recognised).

    Raises:
        LabelingError: unknown format, bad file (one line naming the file and node).
    """
    from psg_data.labeling._detections import read_detections

    if fmt not in iter_formats():
        raise LabelingError(f"detections format {fmt!r}: expected one of {', '.join(iter_formats())}")
    p = Path(path)
    if not p.exists():
        raise _err(str(p), "detections file not found (nor a folder of scene graphs)")
    kind = detect_format(p) if fmt == "auto" else fmt
    if kind == "table":
        return read_detections(p, scan_ids=list(ds.scan_ids), min_score=min_score)
    return read_scene_graphs(p, kind, vocabulary(ds), receptacle_boxes={r: i.box for r, i in ds.receptacles.items()})
