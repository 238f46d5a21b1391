"""Scene graphs of ConceptGraphs, Spark-DSG (Hydra / Khronos) and HOV-SG as per-scan detections.

Round trips: the small lab's simulated detections (misses, spurious objects, noise) exported per
scan in each tool's layout (Spark-DSG files written by the real ``spark_dsg`` library), read back
equal to what the format can hold, and labelled into the same streams as the same detections
given as a psg-data table. Then the bad-file list (one line naming file and node, nothing
written), pickles refused unopened, and Spark-DSG's own published test graph.
"""

from __future__ import annotations

import gzip
import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
import spark_dsg  # the [graph] extra: Spark-DSG files here are written by the real library
from click.testing import CliRunner

from psg_data.cli._label_cmd import label_cmd
from psg_data.errors import LabelingError
from psg_data.labeling import compute_labels, label_dataset
from psg_data.labeling._detections import Detections, read_detections
from psg_data.labeling._scene_graph_export import export_scene_graphs, representable, write_detections_table
from psg_data.labeling._scene_graphs import (
    MAX_DEPTH,
    Y_UP_TO_Z_UP,
    detect_format,
    read_any_detections,
    vocabulary,
)
from psg_data.loaders import open_dataset

from .test_pipeline import RECS, _snapshot, scene  # noqa: F401  (fixture)

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def lab_dets(lab_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Detections:
    """The small lab's simulated detections: misses, spurious objects, confusions, noise."""
    from psg_data.synth import write_detections

    p = write_detections(lab_path, tmp_path_factory.mktemp("det") / "det.parquet", seed=3, miss_rate=0.1,
                         false_positive_rate=0.05)
    det = read_detections(p)
    assert len(set(det.kind.tolist())) == 2 and len(det) > 50
    return det


def _rows(d: Detections) -> list[tuple]:
    """Detections as sorted rows (order of nodes in a file is the tool's, not ours)."""
    rows = [(str(d.scan_id[i]), str(d.label[i]), str(d.kind[i]), *np.round(d.box_center_m[i], 9).tolist())
            for i in range(len(d))]
    return sorted(rows)


def _arrays(d: Detections) -> np.ndarray:
    o = np.lexsort((d.box_center_m[:, 0], d.label.astype(str), d.scan_id.astype(str)))
    return np.concatenate([d.centroid_m[o], d.box_center_m[o], d.box_extent_m[o], d.box_rotation[o].reshape(-1, 9),
                           d.score[o, None]], axis=1)


FORMATS = ["conceptgraphs", "conceptgraphs-realtime", "spark-dsg", "spark-dsg-binary", "khronos", "hovsg"]
NAMED = {"conceptgraphs": "conceptgraphs", "conceptgraphs-realtime": "conceptgraphs", "spark-dsg": "spark-dsg",
         "spark-dsg-binary": "spark-dsg", "khronos": "spark-dsg", "hovsg": "hovsg"}


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip(fmt: str, lab_path: Path, lab_dets: Detections, tmp_path: Path) -> None:
    """Export per scan in a tool's layout, read back: what the format holds; same streams as a table."""
    ds = open_dataset(lab_path)
    out = export_scene_graphs(lab_dets, tmp_path / fmt, fmt, vocabulary(ds).scan_spans)
    path = out / "khronos_dsg.json" if fmt == "khronos" else out
    assert detect_format(path) == NAMED[fmt]
    back = read_any_detections(ds, path)
    exp = representable(lab_dets, fmt)
    assert len(back) == len(lab_dets)
    assert [r[:3] for r in _rows(back)] == [r[:3] for r in _rows(exp)]
    tol = 2e-6 if NAMED[fmt] == "spark-dsg" else 1e-12  # Spark-DSG stores float32 boxes and quaternions
    np.testing.assert_allclose(_arrays(back), _arrays(exp), atol=tol, rtol=0)
    if NAMED[fmt] != "spark-dsg":  # an axis-aligned format: the world AABB of each box
        i = int(np.argmax(np.abs(lab_dets.box_rotation[:, 0, 1])))
        assert abs(lab_dets.box_rotation[i, 0, 1]) > 0.01  # a rotated box, so the check below bites
        R, e = lab_dets.box_rotation[i], lab_dets.box_extent_m[i]
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * e / 2 @ R.T
        j = next(k for k in range(len(exp)) if np.array_equal(exp.box_center_m[k], lab_dets.box_center_m[i]))
        np.testing.assert_allclose(exp.box_extent_m[j], np.ptp(corners, axis=0), atol=1e-12)
    # the same detections as a psg-data table give the same label streams
    table = write_detections_table(exp, tmp_path / "same.json")
    a = compute_labels(ds, f"detections:{path}", doors=False).labels
    b = compute_labels(ds, f"detections:{table}", doors=False).labels
    assert np.array_equal(a.codes, b.codes) and a.object_ids == b.object_ids
    assert (a.codes == 1).sum() > 10


def test_hovsg_up_axis(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """HOV-SG's y-up vertices land z-up: a box from y 0.5..0.9 (up) is z 0.5..0.9 in the dataset."""
    sess = tmp_path / "g" / "scan_00" / "objects"
    sess.mkdir(parents=True)
    pts = np.array([[x, y, z] for x in (1.0, 1.2) for y in (0.5, 0.9) for z in (-2.0, -2.3)])  # HOV-SG frame
    (sess / "0_0.json").write_text(json.dumps({"object_id": "0_0", "name": "mug", "room_id": "0",
                                               "vertices": pts.tolist(), "embedding": ""}))
    det = read_any_detections(open_dataset(scene), tmp_path / "g")
    np.testing.assert_allclose(det.box_center_m[0], [1.1, 2.15, 0.7])
    np.testing.assert_allclose(det.box_extent_m[0], [0.2, 0.3, 0.4])
    np.testing.assert_allclose(Y_UP_TO_Z_UP @ [0, 1, 0], [0, 0, 1])


def _cg_session(root: Path, scan: str, nodes: list[dict], relations: list | None = None) -> Path:
    d = root / scan / "sg_cache"
    d.mkdir(parents=True, exist_ok=True)
    (d / "scene_graph.json").write_text(json.dumps(nodes, allow_nan=True))
    if relations is not None:
        (d / "cfslam_object_relations.json").write_text(json.dumps(relations))
    return d / "scene_graph.json"


def _node(i: int, tag: str, c: list[float], e: list[float] | None = None) -> dict:
    return {"id": i, "bbox_center": c, "bbox_extent": e or [0.1, 0.1, 0.1], "object_tag": tag, "caption": tag}


def test_mapping_synonyms_transform_and_unmapped(scene: Path, tmp_path: Path, caplog) -> None:  # noqa: F811
    """Synonyms map tool labels, unknown labels are counted and reported, a transform moves the graph."""
    table = RECS[0]
    c = table.box.center_m
    root = tmp_path / "cg"
    shift = np.array([5.0, -1.0, 0.0])
    _cg_session(root, "scan_00", [_node(0, "dining table", (c - shift).tolist(), table.box.extent_m.tolist()),
                                  _node(1, "coffee mug", (c - shift + [0, 0, 0.5]).tolist()),
                                  _node(2, "plant", (c - shift).tolist()), _node(3, "plant", (c - shift).tolist())])
    T = np.eye(4)
    T[:3, 3] = shift
    (root / "psg_mapping.json").write_text(json.dumps({"synonyms": {"dining table": "table", "coffee mug": "mug"},
                                                       "transform": T.tolist()}))
    det = read_any_detections(open_dataset(scene), root)
    assert sorted(zip(det.label.tolist(), det.kind.tolist())) == [("mug", "object"), ("table", "receptacle")]
    np.testing.assert_allclose(det.box_center_m[det.label == "table"][0], c)
    assert "2 scene-graph nodes with 1 labels" in caplog.text and "plant (2)" in caplog.text
    assert "do not line up" not in caplog.text
    (root / "psg_mapping.json").write_text(json.dumps({"synonyms": {"dining table": "table", "coffee mug": "mug"}}))
    caplog.clear()
    read_any_detections(open_dataset(scene), root)
    res = min(np.linalg.norm(c - shift - r.box.center_m) for r in RECS)  # nearest annotated receptacle
    assert res > 0.5 and f"do not line up with the annotated boxes (median residual {res:.2f} m" in caplog.text


def test_session_mapping_file(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """Sessions named otherwise map to scans through the mapping file; unmapped folders are an error."""
    root = tmp_path / "cg"
    _cg_session(root, "monday_run", [_node(0, "mug", [1.0, 1.0, 1.0])])
    with pytest.raises(LabelingError, match=r"monday_run: session folder 'monday_run' is not a scan_id"):
        read_any_detections(open_dataset(scene), root)
    (root / "psg_mapping.json").write_text(json.dumps({"sessions": {"monday_run": "scan_01"}}))
    assert read_any_detections(open_dataset(scene), root).scan_id.tolist() == ["scan_01"]
    ds = open_dataset(scene)
    t0, t1 = ds.scan("scan_00").start_stamp_ns, ds.scan("scan_00").end_stamp_ns
    (root / "psg_mapping.json").write_text(json.dumps({"sessions": {"monday_run": int((t0 + t1) // 2)}}))
    assert read_any_detections(ds, root).scan_id.tolist() == ["scan_00"]  # by time: the scan containing it
    (root / "psg_mapping.json").write_text(json.dumps({"sessions": {"monday_run": int(t0) - 1}}))
    with pytest.raises(LabelingError, match=r"monday_run: session time \d+ ns lies in no scan"):
        read_any_detections(ds, root)


def _spark_file(path: Path, *, version: dict | None | str = "keep", bbox: dict | None = None,
                dup: bool = False) -> Path:
    G = spark_dsg.DynamicSceneGraph()
    for i, name in enumerate(["mug", "table"]):
        a = spark_dsg.ObjectNodeAttributes()
        a.name = name
        a.bounding_box = spark_dsg.BoundingBox(np.array([0.2, 0.2, 0.2]), np.array([1.0, 0.0, 0.5 + i]))
        G.add_node(spark_dsg.DsgLayers.OBJECTS, spark_dsg.NodeSymbol("O", i).value, a)
    path.parent.mkdir(parents=True, exist_ok=True)
    G.save(str(path), include_mesh=False)
    data = json.loads(path.read_text())
    if version != "keep":
        if version is None:
            del data["SPARK_DSG_header"]["version"]
        else:
            data["SPARK_DSG_header"]["version"] = version
    if bbox is not None:
        data["nodes"][0]["attributes"]["bounding_box"] = bbox
    if dup:
        data["nodes"].append(data["nodes"][0])
    path.write_text(json.dumps(data, allow_nan=True))
    return path


def _deep(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("[" * (MAX_DEPTH + 5) + "]" * (MAX_DEPTH + 5))


def _big(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        f.truncate(200 * 2**20)  # a sparse 200 MB file


HOSTILE = {
    "cg_no_box": (lambda r: _cg_session(r, "scan_00", [{"id": 7, "object_tag": "mug", "bbox_center": [0, 0, 1]}]),
                  r"scene_graph\.json: node 7: no box"),
    "cg_nan_box": (lambda r: _cg_session(r, "scan_00", [_node(4, "mug", [0.0, float("nan"), 1.0])]),
                   r"scene_graph\.json: node 4: box centre: .*expected 3 finite numbers"),
    "cg_zero_volume": (lambda r: _cg_session(r, "scan_00", [_node(5, "mug", [0, 0, 1], [0.0, 0.0, 0.0])]),
                       r"scene_graph\.json: node 5: box extent .*non-zero volume.*not all three"),
    "cg_negative_extent": (lambda r: _cg_session(r, "scan_00", [_node(6, "mug", [0, 0, 1], [0.1, -0.1, 0.0])]),
                           r"scene_graph\.json: node 6: box extent \[0\.1, -0\.1, 0\.0\], expected 3 positive"),
    "cg_duplicate_id": (lambda r: _cg_session(r, "scan_00", [_node(3, "mug", [0, 0, 1]), _node(3, "mug", [0, 0, 2])]),
                        r"scene_graph\.json: node 3: duplicate id"),
    "cg_unknown_relation": (lambda r: _cg_session(r, "scan_00", [_node(0, "mug", [0, 0, 1])], [
        {"object1": {"id": 0}, "object2": {"id": 9}, "object_relation": "a on b"}]),
        r"cfslam_object_relations\.json: relation 0: names unknown node id 9"),
    "cg_deep": (lambda r: _deep(r / "scan_00" / "sg_cache" / "scene_graph.json"),
                r"scene_graph\.json: JSON nested deeper than 64 levels"),
    "cg_200mb": (lambda r: _big(r / "scan_00" / "sg_cache" / "scene_graph.json"),
                 r"scene_graph\.json: 200 MB, larger than the 100 MB"),
    "dsg_wrong_version": (lambda r: _spark_file(r / "scan_00" / "dsg.json", version={"major": 7, "minor": 0,
                                                                                      "patch": 0}),
                          r"dsg\.json: SPARK_DSG_header: version 7\.0\.0, expected a 1\.x"),
    "dsg_missing_version": (lambda r: _spark_file(r / "scan_00" / "dsg.json", version=None),
                            r"dsg\.json: SPARK_DSG_header: version None, expected"),
    "dsg_no_box": (lambda r: _spark_file(r / "scan_00" / "dsg.json", bbox={"type": "INVALID"}),
                   r"dsg\.json: node 5692549928996306944: no bounding box"),
    "dsg_nan_box": (lambda r: _spark_file(r / "scan_00" / "dsg.json", bbox={
        "type": "AABB", "dimensions": [0.1, float("nan"), 0.1], "world_P_center": [0, 0, 1],
        "world_R_center": {"w": 1, "x": 0, "y": 0, "z": 0}}), r"dsg\.json: node 5692549928996306944: dimensions"),
    "dsg_duplicate": (lambda r: _spark_file(r / "scan_00" / "dsg.json", dup=True),
                      r"dsg\.json: node 5692549928996306944: duplicate node id"),
    "hovsg_2d": (lambda r: (r / "scan_00" / "objects").mkdir(parents=True) or (r / "scan_00" / "objects" / "0_1.json")
                 .write_text(json.dumps({"object_id": "0_1", "name": "mug", "room_id": "0",
                                         "vertices": [[0, 0], [1, 1]], "embedding": ""})),
                 r"0_1\.json: node '0_1': vertices of shape \[2, 2\], expected N x 3"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_files(case: str, scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """Each bad file: one line naming the file and node, exit 1, nothing written."""
    make, match = HOSTILE[case]
    root = tmp_path / "graphs"
    root.mkdir()
    make(root)
    before = _snapshot(scene)
    with pytest.raises(LabelingError, match=match) as ei:
        label_dataset(scene, f"detections:{root}")
    assert "\n" not in str(ei.value)
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", f"detections:{root}", "--quiet"])
    assert r.exit_code == 1
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(root) in lines[0], r.output
    assert _snapshot(scene) == before


class _Bomb:
    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (_explode, ())


def _explode() -> None:
    raise AssertionError("the pickle was loaded")


@pytest.mark.parametrize("name", ["scene_map_cfslam_pruned.pkl.gz", "dualmap.pkl"])
def test_pickled_map_refused_unopened(name: str, scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """A pickled map is refused by name, never unpickled (the pickle here raises if loaded)."""
    sess = tmp_path / "maps" / "scan_00"
    sess.mkdir(parents=True)
    data = pickle.dumps(_Bomb())
    with pytest.raises(AssertionError, match="was loaded"):
        pickle.loads(data)  # the file would run code if unpickled
    (sess / name).write_bytes(gzip.compress(data) if name.endswith(".gz") else data)
    for target in (tmp_path / "maps", sess / name):
        r = CliRunner().invoke(label_cmd, [str(scene), "--source", f"detections:{target}", "--quiet"])
        assert r.exit_code == 1 and r.output.startswith("error: ") and "never unpickled" in r.output, r.output
        assert "JSON" in r.output and r.output.count("\n") == 1


def test_spark_dsg_published_graph(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """Spark-DSG's own test graph (legacy, header-less): boxes equal to what spark_dsg itself reads."""
    sess = tmp_path / "hydra" / "scan_00"
    sess.mkdir(parents=True)
    with gzip.open(DATA / "spark_dsg_apartment_dsg.json.gz", "rb") as f:
        (sess / "dsg.json").write_bytes(f.read())
    G = spark_dsg.DynamicSceneGraph.load(str(sess / "dsg.json"))
    objs = {n.attributes.name: n.attributes.bounding_box for n in G.get_layer(spark_dsg.DsgLayers.OBJECTS).nodes}
    assert len(objs) == 7
    syn = {name: ("mug" if k % 2 else "table") for k, name in enumerate(sorted(objs))}
    (tmp_path / "hydra" / "psg_mapping.json").write_text(json.dumps({"synonyms": syn}))
    det = read_any_detections(open_dataset(scene), tmp_path / "hydra")
    assert len(det) == 7 and set(det.scan_id.tolist()) == {"scan_00"}
    got = sorted(zip(det.box_center_m.tolist(), det.box_extent_m.tolist()))
    ref = sorted((np.asarray(b.world_P_center, float).tolist(), np.asarray(b.dimensions, float).tolist())
                 for b in objs.values())
    np.testing.assert_allclose(np.array([g[0] + g[1] for g in got]), np.array([r[0] + r[1] for r in ref]), atol=1e-5)


def test_detections_format_option(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """--detections-format names the format; a wrong name for the content is one error line."""
    root = tmp_path / "cg"
    _cg_session(root, "scan_00", [_node(0, "mug", [1.0, 0.0, 0.8])])
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", f"detections:{root}", "--detections-format",
                                       "hovsg", "--quiet"])
    assert r.exit_code == 1 and r.output.startswith("error: ") and "objects/*.json" in r.output, r.output
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", f"detections:{root}", "--detections-format",
                                       "conceptgraphs", "--quiet"])
    assert r.exit_code == 0, r.output
    shutil.rmtree(root)


def test_spark_dsg_labelspace_names_semantic_labels(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """A Hydra graph with a label space: the node's semantic_label names it, not its name ('O(0)')."""
    G = spark_dsg.DynamicSceneGraph()
    G.set_labelspace(spark_dsg.Labelspace({3: "mug", 8: "table"}), 2)
    for i, (sem, z) in enumerate([(3, 0.9), (8, 0.5), (5, 0.7)]):  # 5: not in the label space -> its name
        a = spark_dsg.ObjectNodeAttributes()
        a.name, a.semantic_label = f"O({i})", sem
        a.bounding_box = spark_dsg.BoundingBox(np.array([0.2, 0.2, 0.2]), np.array([1.0, 0.0, z]))
        G.add_node(spark_dsg.DsgLayers.OBJECTS, spark_dsg.NodeSymbol("O", i).value, a)
    (tmp_path / "hydra" / "scan_01").mkdir(parents=True)
    G.save(str(tmp_path / "hydra" / "scan_01" / "dsg.json"), include_mesh=False)
    (tmp_path / "hydra" / "psg_mapping.json").write_text(json.dumps({"synonyms": {"O(2)": "mug"}}))
    det = read_any_detections(open_dataset(scene), tmp_path / "hydra")
    got = sorted(zip(det.label.tolist(), det.kind.tolist(), np.round(det.box_center_m[:, 2], 6).tolist()))
    assert got == [("mug", "object", 0.7), ("mug", "object", 0.9), ("table", "receptacle", 0.5)]


def test_khronos_intervals_give_scans(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """An object is detected in each scan whose time span overlaps one of its presence intervals."""
    ds = open_dataset(scene)
    spans = {s: (int(ds.scan(s).start_stamp_ns), int(ds.scan(s).end_stamp_ns)) for s in ds.scan_ids}
    (a0, b0), (a1, b1) = spans["scan_00"], spans["scan_01"]
    assert b0 < a1
    G = spark_dsg.DynamicSceneGraph()
    for i in range(3):
        a = spark_dsg.KhronosObjectAttributes()
        a.name = "mug"
        a.bounding_box = spark_dsg.BoundingBox(np.array([0.1, 0.1, 0.1]), np.array([float(i), 0.0, 1.0]))
        G.add_node(spark_dsg.DsgLayers.OBJECTS, spark_dsg.NodeSymbol("O", i).value, a)
    path = tmp_path / "khronos.json"
    G.save(str(path), include_mesh=False)
    data = json.loads(path.read_text())
    intervals = {0: ([a0 - 5], [a0]),  # touches scan_00's start
                 1: ([b0 + 1, a1 + 1], [a1 - 1, b1 + 9]),  # between the scans, then in scan_01
                 2: ([b1 + 1], [b1 + 100])}  # after both: in no scan
    for n in data["nodes"]:
        k = n["id"] - spark_dsg.NodeSymbol("O", 0).value
        n["attributes"]["first_observed_ns"], n["attributes"]["last_observed_ns"] = intervals[k]
    path.write_text(json.dumps(data))
    assert spark_dsg.DynamicSceneGraph.load(str(path)).num_nodes() == 3  # still a graph spark_dsg reads
    det = read_any_detections(ds, path)
    assert sorted(zip(det.scan_id.tolist(), det.box_center_m[:, 0].tolist())) == [("scan_00", 0.0), ("scan_01", 1.0)]
    data["nodes"][0]["attributes"]["last_observed_ns"] = [a0 - 10]  # ends before it starts
    path.write_text(json.dumps(data))
    with pytest.raises(LabelingError, match=r"khronos\.json: node \d+: first_observed_ns / last_observed_ns"):
        read_any_detections(ds, path)


@pytest.mark.parametrize("layout", ["scene_graph", "realtime"])
def test_stated_relations_checked_against_geometry(layout: str, scene: Path, tmp_path: Path, caplog) -> None:  # noqa: F811
    """'a on b' relations name nodes (cfslam: by position in scene_graph.json, realtime: by id); the
    log says how many the on-top association agrees with."""
    import logging

    caplog.set_level(logging.INFO, logger="psg_data.labeling._scene_graphs")
    table = RECS[0]
    top = table.box.center_m + [0, 0, table.box.extent_m[2] / 2 + 0.05]
    nodes = [_node(40, "table", table.box.center_m.tolist(), table.box.extent_m.tolist()),
             _node(17, "mug", top.tolist()), _node(23, "book", (top + [3.0, 0, 0]).tolist())]  # book far off
    root = tmp_path / "cg"
    if layout == "scene_graph":
        rel = [{"object1": {"id": 1}, "object2": {"id": 0}, "object_relation": "a on b"},
               {"object1": {"id": 0}, "object2": {"id": 2}, "object_relation": "b on a"},
               {"object1": {"id": 1}, "object2": {"id": 2}, "object_relation": "none of these"}]
        _cg_session(root, "scan_00", nodes, rel)
    else:
        d = root / "scan_00"
        d.mkdir(parents=True)
        (d / "obj_json_x.json").write_text(json.dumps({f"object_{i + 1}": n for i, n in enumerate(nodes)}))
        (d / "edge_json_x.json").write_text(json.dumps({
            "edge_0": {"object_1_id": 17, "object_2_id": 40, "relationship": "on top of"},
            "edge_1": {"object_1_id": 23, "object_2_id": 40, "relationship": "on top of"},
            "edge_2": {"object_1_id": 23, "object_2_id": 17, "relationship": "next to"}}))
    det = read_any_detections(open_dataset(scene), root)
    assert len(det) == 3
    assert "1 of 2 stated 'on' relations (object on receptacle) agree" in caplog.text


def test_label_help_shows_each_format() -> None:
    """`psg-data label --help`: one example per scene-graph format and the --detections-format choices."""
    out = CliRunner().invoke(label_cmd, ["--help"]).output
    for word in ("ConceptGraphs sg_cache", "Spark-DSG dsg.json", "khronos_map.json", "HOV-SG objects",
                 "--detections-format", "conceptgraphs|spark-dsg|hovsg"):
        assert word in out, word
    flat = " ".join(out.split())
    assert "relations: geometric (default" in flat and "stated (ConceptGraphs' 'a on b' relations" in flat, flat


def test_hydra_output_folder_reads_the_backend_graph_once(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """Hydra writes backend/ and frontend/ graphs, each as dsg.json and dsg_with_mesh.json: one is read."""
    sess = tmp_path / "hydra" / "scan_00"
    for rel in ("backend/dsg.json", "backend/dsg_with_mesh.json", "frontend/dsg.json"):
        _spark_file(sess / rel)
    det = read_any_detections(open_dataset(scene), tmp_path / "hydra")
    assert sorted(det.label.tolist()) == ["mug", "table"]
    cg = tmp_path / "cg"
    _cg_session(cg, "scan_00", [_node(0, "mug", [1.0, 0.0, 0.8])])
    (cg / "scan_00" / "obj_json_run.json").write_text(json.dumps({"object_1": _node(0, "mug", [1.0, 0.0, 0.8])}))
    with pytest.raises(LabelingError, match=r"scan_00: 2 conceptgraphs scene graphs in one session folder "
                                            r"\(obj_json_run\.json, sg_cache/scene_graph\.json\)"):
        read_any_detections(open_dataset(scene), cg)


def test_conceptgraphs_rounded_zero_side_is_half_a_step(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """ConceptGraphs rounds bbox_extent (scene_graph.json to 0.1 m, obj_json to 0.01 m): a side written as 0
    (a thin book) is read as half a step; Spark-DSG and HOV-SG have no such rounding (zero stays refused)."""
    root = tmp_path / "cg"
    _cg_session(root, "scan_00", [_node(0, "mug", [1.0, 0.0, 0.8], [0.2, 0.0, 0.0])])
    det = read_any_detections(open_dataset(scene), root)
    np.testing.assert_array_equal(det.box_extent_m, [[0.2, 0.05, 0.05]])
    rt = tmp_path / "rt" / "scan_00"
    rt.mkdir(parents=True)
    (rt / "obj_json_x.json").write_text(json.dumps({"object_1": _node(3, "mug", [1.0, 0.0, 0.8], [0.31, 0.0, 0.02])}))
    det = read_any_detections(open_dataset(scene), tmp_path / "rt")
    np.testing.assert_array_equal(det.box_extent_m, [[0.31, 0.005, 0.02]])
    with pytest.raises(LabelingError, match=r"dsg\.json: node \d+: box extent \[0\.2, 0\.0, 0\.2\], expected 3 positive"):
        read_any_detections(open_dataset(scene), _spark_file(tmp_path / "h" / "scan_00" / "dsg.json", bbox={
            "type": "AABB", "dimensions": [0.2, 0.0, 0.2], "world_P_center": [0, 0, 1],
            "world_R_center": {"w": 1, "x": 0, "y": 0, "z": 0}}).parent.parent)


def test_class_list_maps_numeric_labels(scene: Path, tmp_path: Path, caplog) -> None:  # noqa: F811
    """A class list in the mapping (a --class_set file, one class per line, read as ConceptGraphs reads it):
    numeric labels are its lines; class names then map by name or synonym; the rest is counted and reported."""
    import logging

    caplog.set_level(logging.INFO, logger="psg_data.labeling._scene_graphs")
    root = tmp_path / "cg"
    (tmp_path / "cg").mkdir()
    (root / "my_classes.txt").write_text("wall\n  coffee mug \n\ntable\nchair\n")  # line 2 empty: ids keep lines
    _cg_session(root, "scan_00", [_node(0, "1", [1.0, 0.0, 0.8]), _node(1, "3", [1.0, 0.0, 0.5]),
                                  _node(2, "9", [2.0, 0.0, 0.5]), _node(3, "2", [2.0, 0.0, 0.5]),
                                  _node(4, "4", [2.0, 0.0, 0.5]), _node(5, "table", [1.0, 1.0, 0.5])])
    (root / "psg_mapping.json").write_text(json.dumps({"classes": "my_classes.txt",
                                                       "synonyms": {"coffee mug": "mug"}}))
    det = read_any_detections(open_dataset(scene), root)
    assert sorted(zip(det.label.tolist(), det.kind.tolist(), det.box_center_m[:, 1].tolist())) == [
        ("mug", "object", 0.0), ("table", "receptacle", 0.0), ("table", "receptacle", 1.0)]
    assert "3 scene-graph nodes with 3 labels that are no dataset object or receptacle" in caplog.text
    assert "9 = class 9 (not in the class list of 5)" in caplog.text and "4 = chair (1)" in caplog.text
    assert "2 of 4 classes of the class list name dataset objects or receptacles (coffee mug, table)" in caplog.text
    # without the class list the numbers are labels of their own: nothing maps but the named table
    (root / "psg_mapping.json").write_text(json.dumps({"synonyms": {"coffee mug": "mug"}}))
    assert read_any_detections(open_dataset(scene), root).label.tolist() == ["table"]
    (root / "psg_mapping.json").write_text(json.dumps({"classes": "missing.txt"}))
    with pytest.raises(LabelingError, match=r"psg_mapping\.json: classes: cannot read class list .*missing\.txt"):
        read_any_detections(open_dataset(scene), root)


def test_class_list_names_spark_dsg_semantic_labels(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """A Spark-DSG graph without a label space: with a class list, semantic_label i is the list's line i."""
    G = spark_dsg.DynamicSceneGraph()
    for i, (sem, z) in enumerate([(2, 0.9), (0, 0.5)]):
        a = spark_dsg.ObjectNodeAttributes()
        a.name, a.semantic_label = f"O({i})", sem
        a.bounding_box = spark_dsg.BoundingBox(np.array([0.2, 0.2, 0.2]), np.array([1.0, 0.0, z]))
        G.add_node(spark_dsg.DsgLayers.OBJECTS, spark_dsg.NodeSymbol("O", i).value, a)
    (tmp_path / "hydra" / "scan_01").mkdir(parents=True)
    G.save(str(tmp_path / "hydra" / "scan_01" / "dsg.json"), include_mesh=False)
    (tmp_path / "hydra" / "psg_mapping.json").write_text(json.dumps({"classes": ["table", "wall", "mug"]}))
    det = read_any_detections(open_dataset(scene), tmp_path / "hydra")
    assert sorted(zip(det.label.tolist(), np.round(det.box_center_m[:, 2], 6).tolist())) == [("mug", 0.9),
                                                                                              ("table", 0.5)]
    (tmp_path / "hydra" / "psg_mapping.json").write_text(json.dumps({"synonyms": {"O(0)": "mug"}}))
    assert read_any_detections(open_dataset(scene), tmp_path / "hydra").label.tolist() == ["mug"]  # by name


@pytest.mark.parametrize("layout", ["scene_graph", "realtime"])
def test_relations_stated_replace_the_geometric_association(layout: str, scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """The mug stands on the table but ConceptGraphs states it is on the stool; the book stands on the stool
    with no stated relation. geometric (default): mug-table, book-stool; stated: mug-stool, book on nothing."""
    from .test_visibility import STOOL, TABLE

    def on_top(r: object, dx: float = 0.0) -> list[float]:
        b = r.box  # type: ignore[attr-defined]
        return (b.center_m + [dx, 0, b.extent_m[2] / 2 + 0.05]).tolist()

    nodes = [_node(40, "table", TABLE.box.center_m.tolist(), TABLE.box.extent_m.tolist()),
             _node(41, "stool", STOOL.box.center_m.tolist(), STOOL.box.extent_m.tolist()),
             _node(17, "mug", on_top(TABLE)), _node(23, "book", on_top(STOOL))]
    root = tmp_path / "cg"
    if layout == "scene_graph":  # cfslam relations name nodes by position
        _cg_session(root, "scan_00", nodes, [{"object1": {"id": 1}, "object2": {"id": 2}, "object_relation": "b on a"}])
    else:
        d = root / "scan_00"
        d.mkdir(parents=True)
        (d / "obj_json_x.json").write_text(json.dumps({f"object_{i + 1}": n for i, n in enumerate(nodes)}))
        (d / "edge_json_x.json").write_text(json.dumps({"edge_0": {"object_1_id": 17, "object_2_id": 41,
                                                                   "relationship": "on top of"}}))
    ds = open_dataset(scene)
    o, r = list(ds.objects), list(ds.receptacles)

    def pairs(relations: str | None) -> list[tuple[str, str]]:
        if relations is not None:
            (root / "psg_mapping.json").write_text(json.dumps({"relations": relations}))
        res = compute_labels(ds, f"detections:{root}", doors=False)
        a = res.perception.associations[ds.scan_ids.index("scan_00")]
        assert res.perception.matched[0, r.index("table")] and res.perception.matched[0, r.index("stool")]
        return sorted((o[i], r[k]) for i, k in zip(*np.nonzero(a)))

    assert pairs(None) == [("book", "stool"), ("mug", "table")]  # the default
    assert pairs("geometric") == [("book", "stool"), ("mug", "table")]
    assert pairs("stated") == [("mug", "stool")]
    res = compute_labels(ds, f"detections:{root}", doors=False)
    assert res.labels.meta["relations"] == "stated" and res.perception.n_unassociated == 1
    (root / "psg_mapping.json").write_text(json.dumps({"relations": "llm"}))
    with pytest.raises(LabelingError, match=r"psg_mapping\.json: relations: 'llm', expected one of geometric, stated"):
        compute_labels(ds, f"detections:{root}", doors=False)


def test_relations_stated_refused_for_formats_without_relations(scene: Path, tmp_path: Path) -> None:  # noqa: F811
    """Spark-DSG and HOV-SG state no object-on-receptacle relations: 'stated' is one error line."""
    _spark_file(tmp_path / "hydra" / "scan_00" / "dsg.json")
    (tmp_path / "hydra" / "psg_mapping.json").write_text(json.dumps({"relations": "stated"}))
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", f"detections:{tmp_path / 'hydra'}", "--quiet"])
    assert r.exit_code == 1 and r.output.count("\n") == 1, r.output
    assert r.output.startswith("error: ") and "spark-dsg scene graphs state no object-on-receptacle" in r.output


def test_psg_eval_same_numbers_from_conceptgraphs_and_table(lab_copy: Path, lab_dets: Detections,
                                                            tmp_path: Path) -> None:
    """The acceptance on the small lab: psg-eval -e perpetua_star --labels detections:DIR from a ConceptGraphs
    export (10 % missed, 5 % spurious detections) gives the numbers of the same detections as a psg-data table
    (the 84-scan demo: by hand, docs/RAW_FORMATS.md)."""
    from psg_data.cli.psg_eval_cmd import main

    cg = export_scene_graphs(lab_dets, tmp_path / "cg", "conceptgraphs")
    table = write_detections_table(representable(lab_dets, "conceptgraphs"), tmp_path / "cg_table.json")
    out = {}
    for src in (cg, table):
        label_dataset(lab_copy, f"detections:{src}")
        r = CliRunner().invoke(main, ["--dataset", str(lab_copy), "-e", "perpetua_star", "--no-references",
                                      "--labels", f"detections:{src}", "--out", str(tmp_path / "out" / src.name)])
        assert r.exit_code == 0, r.output
        res = json.loads((tmp_path / "out" / src.name / "results.json").read_text())
        row = res["tables"][0]["rows"][0]
        assert row["method"] == "perpetua_star" and 0 < row["values"]["mae"]["mean"] < 1
        out[src.name] = json.dumps(res["tables"]).replace(str(src), "SRC")
    assert out["cg"] == out["cg_table.json"]


def test_binary_spark_dsg_without_the_package_is_one_error_line(scene: Path, tmp_path: Path, monkeypatch) -> None:  # noqa: F811
    """A .sparkdsg needs the spark_dsg package: without it, one line naming the file and the extra."""
    import sys

    sess = tmp_path / "hydra" / "scan_00"
    sess.mkdir(parents=True)
    G = spark_dsg.DynamicSceneGraph()
    G.save(str(sess / "dsg.sparkdsg"), include_mesh=False)
    monkeypatch.setitem(sys.modules, "spark_dsg", None)  # import fails as if not installed
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", f"detections:{tmp_path / 'hydra'}", "--quiet"])
    assert r.exit_code == 1 and r.output.count("\n") == 1, r.output
    assert r.output.startswith(f"error: {sess / 'dsg.sparkdsg'}: ") and "psg-data[graph]" in r.output
