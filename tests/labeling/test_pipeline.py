"""End-to-end labelling of small box scenes: sources, label tables, CLI, streams and bad inputs."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from psg_data.cli._label_cmd import label_cmd
from psg_data.errors import FormatError, LabelingError
from psg_data.labeling import (
    compute_labels,
    label_dataset,
    label_streams,
    load_label_streams,
    parse_source,
)
from psg_data.loaders import open_dataset
from psg_data.schemas import TABLES
from psg_data.schemas.validate import validate_dataset
from psg_data.writers import add_tables

from .conftest import T0_NS
from .test_visibility import POSES, RECS, WALL

SCHEDULE = [
    {"scan_id": "scan_00", "object_id": "mug", "receptacle_id": "table"},
    {"scan_id": "scan_00", "object_id": "book", "receptacle_id": "hidden"},
    {"scan_id": "scan_01", "object_id": "mug", "receptacle_id": "stool"},
    {"scan_id": "scan_01", "object_id": "book", "receptacle_id": "table"},
]


@pytest.fixture
def scene(make_box_scene, small_cam) -> Path:  # type: ignore[no-untyped-def]
    return make_box_scene(receptacles=RECS, poses=[POSES, POSES], cam=small_cam, extra_boxes=[WALL],
                          schedule=SCHEDULE)


def _validate(root: Path) -> list[str]:
    return [str(p) for p in validate_dataset(root)]


def _snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _codes(root: Path, source: str) -> dict[tuple[str, str, str], int]:
    t = pq.read_table(root / "tables/labels.parquet").to_pydict()
    return {(s, o, r): c for s, o, r, c, src in zip(t["scan_id"], t["object_id"], t["receptacle_id"], t["code"],
                                                     t["source"]) if src == source}


def test_privileged_and_gt_codes_by_hand(scene: Path) -> None:
    label_dataset(scene, "privileged")
    c = _codes(scene, "privileged")
    assert len(c) == 2 * 2 * 4
    # valid sets: mug {table, stool}, book {hidden, table}
    assert c[("scan_00", "mug", "table")] == 1 and c[("scan_00", "mug", "stool")] == 0
    assert c[("scan_01", "mug", "table")] == 0 and c[("scan_01", "mug", "stool")] == 1
    assert c[("scan_00", "book", "hidden")] == -1  # behind the wall: never seen
    assert c[("scan_00", "book", "table")] == 0 and c[("scan_01", "book", "table")] == 1
    assert c[("scan_01", "book", "hidden")] == -1
    assert all(c[(s, "mug", r)] == -2 for s in ("scan_00", "scan_01") for r in ("hidden", "tall"))
    assert all(c[(s, "book", r)] == -2 for s in ("scan_00", "scan_01") for r in ("stool", "tall"))
    label_dataset(scene, "gt")
    g = _codes(scene, "gt")
    assert g[("scan_00", "book", "hidden")] == 1 and g[("scan_01", "book", "hidden")] == 0
    assert set(_codes(scene, "privileged")) == set(c)  # the first source was kept
    assert _validate(scene) == []
    info = json.loads((scene / "dataset.json").read_text())
    assert info["counts"]["labels"] == 32 and info["counts"]["visibility"] == 8


def test_streams(scene: Path) -> None:
    label_dataset(scene, "privileged")
    streams = {s.edge: s for s in load_label_streams(scene)}
    assert set(streams) == {("mug", "table"), ("mug", "stool"), ("book", "hidden"), ("book", "table")}
    s = streams[("mug", "stool")]
    assert s.y.tolist() == [0, 1]
    assert s.t_s.tolist() == [T0_NS / 1e9, (T0_NS + 3600 * 10**9) / 1e9]
    assert len(streams[("book", "hidden")]) == 0
    fresh = {s.edge: s for s in label_streams(scene, "privileged")}
    assert all(np.array_equal(fresh[e].y, streams[e].y) for e in streams)
    label_dataset(scene, "gt")
    with pytest.raises(LabelingError, match="choose one with source="):
        load_label_streams(scene)
    assert load_label_streams(scene, "gt")[0].y.size == 2


def _det(scan: str, label: str, kind: str, center, extent=(0.1, 0.1, 0.1), score: float = 0.9) -> dict:
    c = [float(x) for x in center]
    return {"scan_id": scan, "label": label, "kind": kind, "centroid_m": c, "box_center_m": c,
            "box_extent_m": [float(x) for x in extent], "box_rotation": np.eye(3).ravel().tolist(), "score": score}


def _table_node(scan: str, rec) -> dict:  # type: ignore[no-untyped-def]
    d = _det(scan, "table", "receptacle", rec.box.center_m + 0.02, rec.box.extent_m * 1.05)
    d["box_rotation"] = rec.box.rotation.ravel().tolist()
    return d


def test_detections_source(scene: Path, tmp_path: Path) -> None:
    table, hidden, tall, stool = RECS
    top = lambda r, dx=0.0: r.box.center_m + np.array([dx, 0, r.box.extent_m[2] / 2 + 0.05])  # noqa: E731
    dets = [
        _table_node("scan_00", table), _table_node("scan_00", stool),
        _det("scan_00", "mug", "object", top(table)),
        _det("scan_00", "plant", "object", top(stool)),  # not a dataset object: ignored
        _table_node("scan_01", stool), _table_node("scan_01", table),
        _det("scan_01", "mug", "object", top(stool)),
        # the book is never detected
    ]
    path = tmp_path / "det.json"
    path.write_text(json.dumps({"detections": dets}))
    s = label_dataset(scene, f"detections:{path}")
    assert s.source == "detections:det.json"
    c = _codes(scene, "detections:det.json")
    assert c[("scan_00", "mug", "table")] == 1 and c[("scan_00", "mug", "stool")] == 0
    assert c[("scan_01", "mug", "table")] == 0 and c[("scan_01", "mug", "stool")] == 1
    assert all(v == -2 for (sc, o, r), v in c.items() if o == "book")  # never seen: no edges
    assert all(v == -2 for (sc, o, r), v in c.items() if r in ("hidden", "tall"))
    # same streams as the privileged source on the same edges
    priv = {e.edge: e for e in label_streams(scene, "privileged")}
    for st in load_label_streams(scene, "detections:det.json"):
        assert np.array_equal(st.y, priv[st.edge].y)
    assert _validate(scene) == []
    # a receptacle seen in no frame of scan 1 (its node missing): its edges are -1 there
    path2 = tmp_path / "det2.json"
    path2.write_text(json.dumps([d for d in dets if not (d["scan_id"] == "scan_01" and d["label"] == "table"
                                                         and d["kind"] == "receptacle" and
                                                         d["box_center_m"][0] == float(table.box.center_m[0] + 0.02))]))
    res = compute_labels(scene, f"detections:{path2}")
    g = res.labels
    o, r = g.object_ids.index("mug"), g.receptacle_ids.index("table")
    assert g.codes[1, o, r] == -1 and g.codes[0, o, r] == 1


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d.__setitem__(0, {**d[0], "scan_id": "scan_99"}), r"det\.json:0: scan_id: unknown scan 'scan_99'"),
    (lambda d: d.__setitem__(1, {**d[1], "centroid_m": [0.0, float("nan"), 1.0]}),
     r"det\.json:1: centroid_m: .*expected 3 finite coordinates"),
    (lambda d: d.__setitem__(1, {**d[1], "box_extent_m": [0.1, 0.0, 0.1]}),
     r"det\.json:1: box_extent_m: .*positive"),
    (lambda d: d.clear(), r"det\.json: no detections \(0 rows\)"),
    (lambda d: d.__setitem__(0, {k: v for k, v in d[0].items() if k != "score"}), r"det\.json:0: score: missing"),
    (lambda d: d.__setitem__(0, {**d[0], "kind": "thing"}), r"det\.json:0: kind: 'thing', expected"),
    (lambda d: d.__setitem__(0, {**d[0], "score": 1.5}), r"det\.json:0: score: 1\.5, expected a number in \[0, 1\]"),
    (lambda d: d.__setitem__(0, {**d[0], "box_rotation": [2.0] + [0.0] * 8}), r"det\.json:0: box_rotation"),
])
def test_bad_detections_json(scene: Path, tmp_path: Path, mutate, match: str) -> None:  # type: ignore[no-untyped-def]
    dets = [_table_node("scan_00", RECS[0]), _det("scan_00", "mug", "object", [2.0, 0.0, 0.8])]
    mutate(dets)
    path = tmp_path / "det.json"
    path.write_text(json.dumps(dets, allow_nan=True))
    before = _snapshot(scene)
    with pytest.raises(LabelingError, match=match) as ei:
        label_dataset(scene, f"detections:{path}")
    assert "\n" not in str(ei.value)
    assert _snapshot(scene) == before


def test_bad_detections_parquet(scene: Path, tmp_path: Path) -> None:
    rows = [_table_node("scan_00", RECS[0]), _det("scan_00", "mug", "object", [2.0, 0.0, float("nan")])]
    t = pa.Table.from_pylist(rows)
    pq.write_table(t, tmp_path / "d.parquet")
    with pytest.raises(LabelingError, match=r"d\.parquet:1: centroid_m"):
        compute_labels(scene, f"detections:{tmp_path / 'd.parquet'}")
    pq.write_table(t.drop_columns(["box_rotation"]), tmp_path / "e.parquet")
    with pytest.raises(LabelingError, match=r"e\.parquet: missing columns \['box_rotation'\]"):
        compute_labels(scene, f"detections:{tmp_path / 'e.parquet'}")
    pq.write_table(t.slice(0, 0), tmp_path / "f.parquet")
    with pytest.raises(LabelingError, match=r"f\.parquet: no detections"):
        compute_labels(scene, f"detections:{tmp_path / 'f.parquet'}")
    with pytest.raises(LabelingError, match="detections file not found"):
        compute_labels(scene, f"detections:{tmp_path / 'nope.parquet'}")
    (tmp_path / "g.csv").write_text("x")
    with pytest.raises(LabelingError, match=r"expected \.parquet or \.json"):
        compute_labels(scene, f"detections:{tmp_path / 'g.csv'}")


def test_parse_source() -> None:
    assert parse_source("noisy:0.1").p_m == 0.1 and parse_source("noisy:0.1").p_f == 0.1
    s = parse_source("noisy:0.2,0.05")
    assert (s.p_m, s.p_f, s.name) == (0.2, 0.05, "noisy:0.2,0.05")
    for bad in ("noisy:", "noisy:2", "noisy:a", "truth", "detections:"):
        with pytest.raises(LabelingError, match="source"):
            parse_source(bad)


def test_cli(scene: Path) -> None:
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", "privileged", "--quiet"])
    assert r.exit_code == 0, r.output
    assert "source privileged: 4 edges" in r.output and "P_M = 0.0000" in r.output
    before = _snapshot(scene)
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", "privileged", "--quiet"])
    assert r.exit_code == 1
    assert r.output.strip().splitlines() == [
        f"error: {scene}/tables/labels.parquet: labels of source 'privileged' exist; pass --overwrite "
        "(overwrite=True) to replace them"]
    assert _snapshot(scene) == before
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", "privileged", "--overwrite", "--quiet"])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", "noisy:0.5", "--seed", "1", "--quiet"])
    assert r.exit_code == 0 and "source noisy:0.5,0.5" in r.output
    r = CliRunner().invoke(label_cmd, [str(scene), "--source", "bogus"])
    assert r.exit_code == 1 and "error: source 'bogus'" in r.output
    assert _validate(scene) == []


def test_add_tables_and_label_checks(scene: Path) -> None:
    ds = open_dataset(scene)
    res = compute_labels(ds, "gt")
    t = res.labels.to_table()
    add_tables(scene, {"labels": t})
    assert _validate(scene) == []
    with pytest.raises(FormatError, match="exists; pass --overwrite"):
        add_tables(scene, {"labels": t})
    with pytest.raises(FormatError, match="core table"):
        add_tables(scene, {"frames": t})
    bad = t.set_column(t.schema.get_field_index("code"), TABLES["labels"].schema.field("code"),
                       pa.array(np.full(t.num_rows, 5, np.int8)))
    bad = bad.set_column(0, TABLES["labels"].schema.field("scan_id"),
                         pa.array(["scan_77"] + t.column("scan_id").to_pylist()[1:]))
    add_tables(scene, {"labels": bad}, overwrite=True)
    problems = _validate(scene)
    assert any("tables/labels.parquet:0: code: 5, expected one of 1, 0, -1, -2" in p for p in problems)
    assert any("tables/labels.parquet:0: scan_id: dangling id 'scan_77'" in p for p in problems)
    # the files table and manifest stayed consistent (no checksum problems)
    assert not any("sha256" in p or "checksum" in p or "not listed" in p for p in problems)


def test_no_schedule_is_clear_error(make_box_scene, small_cam) -> None:  # type: ignore[no-untyped-def]
    root = make_box_scene(name="nosched", receptacles=RECS, poses=[POSES[:1]], cam=small_cam)
    with pytest.raises(LabelingError, match="schedule.parquet: (missing|empty)"):
        label_dataset(root, "privileged")
