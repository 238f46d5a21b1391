"""RTAB-Map databases: the built-in lab written as a three-session database (every supported schema
version) and converted back; the pose-graph fallback; corrupt and hostile databases."""

from __future__ import annotations

import logging
import sqlite3
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.convert import ConvertConfig, convert
from psg_data.errors import ConversionError
from psg_data.loaders import open_dataset
from psg_data.loaders.raw._rtabmap import decode_rvl, parse_calibration, uncompress_data

from .rtabmap_writer import OPTICAL, VERSIONS, Link, Node, camera_blob, compress_data, rvl_blob, write_database

CODEC = {"0.17.0": "png", "0.18.0": "float", "0.23.0": "rvl"}
"""The depth codec each version's database uses (every codec RTAB-Map writes is covered once)."""


def _rot_z(a: float) -> np.ndarray:
    R = np.eye(4)
    R[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return R


LOCAL = _rot_z(0.0).copy()
LOCAL[:3, 3] = [0.12, 0.03, 0.45]
LOCAL = LOCAL @ np.array([[np.cos(0.1), 0, np.sin(0.1), 0], [0, 1, 0, 0], [-np.sin(0.1), 0, np.cos(0.1), 0],
                          [0, 0, 0, 1]]) @ OPTICAL
"""Base -> optical frame of the camera: 12 cm ahead, 45 cm up, pitched down by 0.1 rad."""


def session_offset(k: int) -> np.ndarray:
    """World -> odometry frame of session k (each session's odometry starts somewhere else)."""
    T = _rot_z(0.7 * k)
    T[:3, 3] = [3.0 * k, -2.0 * k, 0.0]
    return T


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from psg_data.synth._build import build_lab
    from psg_data.synth._model import LabConfig

    # two_routes: 3 frames per scan (the corridor layout adds two door keyframes), as the counts below expect
    return build_lab(tmp_path_factory.mktemp("lab") / "lab", LabConfig(days=1, frames_per_scan=3, width=64,
                                                                         height=48, layout="two_routes"))


def lab_database(lab: Path, path: Path, version: str, *, optimized: bool = True, loops: bool = True,
                 odom_noise: float = 0.0, sessions: int = 3) -> tuple[Path, dict[int, np.ndarray]]:
    """The lab's first ``sessions`` scans as one RTAB-Map database (session k = scan k); returns the
    database and the true base-to-world pose of every node."""
    ds = open_dataset(lab)
    cam = ds.cameras["d435"]
    rng = np.random.default_rng(7)
    nodes, links, truth, first = [], [], {}, {}
    nid = 1
    for k, sid in enumerate(ds.scan_ids[:sessions]):
        scan = ds.scan(sid)
        prev = None
        for i in range(len(scan)):
            base = scan.poses[i] @ np.linalg.inv(LOCAL)
            odom = np.linalg.inv(session_offset(k)) @ base
            if odom_noise and prev is not None:
                odom = odom @ _rot_z(rng.normal(0, odom_noise))
                odom[:3, 3] += rng.normal(0, odom_noise, 3)
            color, depth_png = scan.image_bytes(i)
            depth_mm = cv2.imdecode(np.frombuffer(depth_png, np.uint8), cv2.IMREAD_UNCHANGED)
            depth = {"png": depth_png, "rvl": rvl_blob(depth_mm)}.get(CODEC[version])
            if depth is None:
                from .rtabmap_writer import float_depth_blob

                depth = float_depth_blob(depth_mm)
            nodes.append(Node(nid, k, scan.stamps_ns[i] / 1e9, odom, color, depth,
                              camera_blob(version, cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height, LOCAL),
                              label=f"start of {sid}" if i == 0 else None))
            if prev is not None:
                links.append(Link(prev[0], nid, 0, np.linalg.inv(prev[1]) @ odom))
            truth[nid] = base
            first.setdefault(k, nid)
            prev = (nid, odom)
            nid += 1
        if loops and k > 0:  # a loop closure to the first session (exact, as a visual closure would be)
            links.append(Link(first[0], first[k], 1, np.linalg.inv(truth[first[0]]) @ truth[first[k]]))
            links.append(Link(first[0] + 1, nid - 1, 1, np.linalg.inv(truth[first[0] + 1]) @ truth[nid - 1]))
    write_database(path, version, nodes, links, optimized=truth if optimized else None)
    return path, truth


def rot_angle(R: np.ndarray) -> float:
    """Rotation angle, accurate near zero (arccos of the trace is not)."""
    s = np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    return float(np.arctan2(s, (np.trace(R) - 1) / 2))


@pytest.mark.parametrize("version", VERSIONS)
def test_lab_roundtrip_three_sessions(tmp_path: Path, lab: Path, version: str) -> None:
    db, _ = lab_database(lab, tmp_path / "lab.db", version)
    rep = convert(db, tmp_path / "out", config=ConvertConfig(camera_id="d435"))
    src, out = open_dataset(lab), open_dataset(tmp_path / "out")
    assert rep.scans == ["lab_000", "lab_001", "lab_002"] and rep.n_skipped == 0
    assert rep.passthrough.get("color") == 9
    assert rep.passthrough.get("depth", 0) == (9 if CODEC[version] == "png" else 0)
    a, b = src.cameras["d435"], out.cameras["d435"]
    tol = 4e-6 if version < "0.18.0" else 0.0  # 0.17 stores the calibration as float32
    for f in ("fx", "fy", "cx", "cy"):
        assert abs(getattr(a, f) - getattr(b, f)) <= tol * abs(getattr(a, f)), f
    assert (a.width, a.height) == (b.width, b.height)
    extra = out.info.extra["convert"]
    assert extra["pose_sources"] == {s: "optimized" for s in rep.scans}
    for k, sid in enumerate(src.scan_ids[:3]):
        sa, sb = src.scan(sid), out.scan(rep.scans[k])
        assert len(sa) == len(sb) == 3
        assert np.abs(sa.stamps_ns - sb.stamps_ns).max() <= 1000  # Node.stamp is a double in seconds
        assert np.abs(sa.poses[:, :3, 3] - sb.poses[:, :3, 3]).max() < 1e-6
        assert max(rot_angle(Ra.T @ Rb) for Ra, Rb in zip(sa.poses[:, :3, :3], sb.poses[:, :3, :3])) < 1e-6
        for i in range(3):
            ca, da = sa.image_bytes(i)
            cb, db_ = sb.image_bytes(i)
            assert ca == cb  # colour passed through
            if CODEC[version] == "png":
                assert da == db_
            assert np.array_equal(sa.frame(i).depth_m, sb.frame(i).depth_m)
        assert extra["node_labels"][rep.scans[k]] == {str(sb.stamps_ns[0]): f"start of {sid}"}


def test_pose_graph_fallback_with_loop_closures(tmp_path: Path, lab: Path, caplog: pytest.LogCaptureFixture) -> None:
    db, truth = lab_database(lab, tmp_path / "m.db", "0.23.0", optimized=False, odom_noise=0.002)
    with caplog.at_level(logging.WARNING):
        rep = convert(db, tmp_path / "out", config=ConvertConfig(camera_id="d435"))
    out, src = open_dataset(tmp_path / "out"), open_dataset(lab)
    assert out.info.extra["convert"]["pose_sources"] == {s: "pose_graph" for s in rep.scans}
    err = [np.linalg.norm(out.scan(rep.scans[k]).poses[:, :3, 3] - src.scan(sid).poses[:, :3, 3], axis=1).max()
           for k, sid in enumerate(src.scan_ids[:3])]
    assert max(err) < 0.01, err
    assert not [r for r in caplog.records if "Admin.opt_poses" in r.getMessage()]
    # the odometry alone (noise and every session's own frame) is far off: the optimisation did the work
    db2, _ = lab_database(lab, tmp_path / "n.db", "0.23.0", optimized=False, loops=False, odom_noise=0.002)
    with caplog.at_level(logging.WARNING):
        rep2 = convert(db2, tmp_path / "out2", config=ConvertConfig(camera_id="d435"))
    out2 = open_dataset(tmp_path / "out2")
    assert out2.info.extra["convert"]["pose_sources"] == {s: "odometry" for s in rep2.scans}
    msgs = [r.getMessage() for r in caplog.records if "no optimized poses" in r.getMessage()]
    assert len(msgs) == 1 and "each of the 3 sessions in its own frame" in msgs[0]
    far = np.linalg.norm(out2.scan(rep2.scans[2]).poses[:, :3, 3] - src.scan(src.scan_ids[2]).poses[:, :3, 3],
                         axis=1).max()
    assert far > 1.0


def test_nodes_without_images_counted_and_split_gap(tmp_path: Path, lab: Path) -> None:
    db, _ = lab_database(lab, tmp_path / "m.db", "0.18.0", sessions=2)
    con = sqlite3.connect(db)
    con.execute("UPDATE Data SET image = NULL WHERE id = 2")
    con.execute("DELETE FROM Data WHERE id = 5")
    con.commit()
    con.close()
    rep = convert(db, tmp_path / "out", config=ConvertConfig(camera_id="d435"))
    assert rep.skipped == {"no_image": 2} and rep.frames == 4
    res = CliRunner().invoke(main, ["convert", str(db), str(tmp_path / "gap"), "--split-gap", "20", "-q"])
    assert res.exit_code == 0, res.output
    ds = open_dataset(tmp_path / "gap")
    gaps = [np.diff(ds.scan(s).stamps_ns).max(initial=0) / 1e9 for s in ds.scan_ids]
    assert len(ds.scan_ids) > 2 and all(g <= 20 for g in gaps) and ds.scan_ids[0].startswith("m_000_")


def test_resume_after_interruption_keeps_finished_sessions(tmp_path: Path, lab: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    import psg_data.convert._rtabmap as rt

    from .conftest import dataset_bytes

    db, _ = lab_database(lab, tmp_path / "m.db", "0.23.0")
    cfg = ConvertConfig(camera_id="d435")
    real = rt._convert_session
    written: list[int] = []

    def interrupted(db_, members, *a):  # type: ignore[no-untyped-def]
        if members[0].map_id == 1:
            raise KeyboardInterrupt
        written.append(members[0].map_id)
        return real(db_, members, *a)

    monkeypatch.setattr(rt, "_convert_session", interrupted)
    with pytest.raises(KeyboardInterrupt):
        convert(db, tmp_path / "out", config=cfg)
    assert not (tmp_path / "out").exists() and (tmp_path / "out.partial").is_dir()
    monkeypatch.setattr(rt, "_convert_session", real)
    rep = convert(db, tmp_path / "out", config=cfg)
    assert rep.resumed == ["m_000"] and rep.scans == ["m_000", "m_001", "m_002"] and written == [0]
    convert(db, tmp_path / "fresh", config=cfg)
    assert dataset_bytes(tmp_path / "out") == dataset_bytes(tmp_path / "fresh")
    # interrupted once every session was written (before the dataset was committed): nothing is redone
    monkeypatch.setattr(rt, "_convert_session", interrupted)
    import psg_data.convert._pipeline as pl

    real_adopt = pl._adopt_scans
    monkeypatch.setattr(pl, "_adopt_scans", lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
    monkeypatch.setattr(rt, "_convert_session", real)
    with pytest.raises(KeyboardInterrupt):
        convert(db, tmp_path / "again", config=cfg)
    monkeypatch.setattr(pl, "_adopt_scans", real_adopt)
    monkeypatch.setattr(rt, "_convert_session", interrupted)  # a session converted again would raise
    rep = convert(db, tmp_path / "again", config=cfg)
    assert rep.resumed == ["m_000", "m_001", "m_002"]
    assert dataset_bytes(tmp_path / "again") == dataset_bytes(tmp_path / "fresh")
    assert open_dataset(tmp_path / "out").info.extra["convert"]["pose_sources"]["m_000"] == "optimized"


@pytest.mark.slow
def test_directory_of_databases_with_jobs(tmp_path: Path, lab: Path) -> None:
    d = tmp_path / "maps"
    d.mkdir()
    lab_database(lab, d / "a.db", "0.23.0", sessions=2)
    lab_database(lab, d / "b.db", "0.17.0", sessions=1)
    rep = convert(d, tmp_path / "out", jobs=2, config=ConvertConfig(camera_id="d435"))
    assert rep.scans == ["a_000", "a_001", "b"] and rep.frames == 9
    ref = {p.relative_to(tmp_path / "out"): p.read_bytes() for p in (tmp_path / "out").rglob("*") if p.is_file()}
    rep1 = convert(d, tmp_path / "one", jobs=1, config=ConvertConfig(camera_id="d435"))
    one = {p.relative_to(tmp_path / "one"): p.read_bytes() for p in (tmp_path / "one").rglob("*") if p.is_file()}
    assert rep1.scans == rep.scans and one == ref
    assert (d / "a.db").stat().st_size > 0 and not list(d.glob("*-journal"))


def test_rvl_codec_matches_reference_layout() -> None:
    rng = np.random.default_rng(3)
    depth = rng.integers(0, 3000, (13, 17)).astype(np.uint16)
    depth[rng.random(depth.shape) < 0.3] = 0
    depth[0, :5] = 0
    depth[-1, -3:] = 65535
    blob = rvl_blob(depth)
    assert blob[:8] == b"DEPTHRVL"
    assert np.array_equal(decode_rvl(blob[16:], depth.size, "x").reshape(depth.shape), depth)
    with pytest.raises(ConversionError, match="cut short"):
        decode_rvl(blob[16:40], depth.size, "x")


def test_calibration_and_compressed_layouts() -> None:
    blob = camera_blob("0.18.0", 500.0, 501.0, 320.5, 240.5, 640, 480, LOCAL, (0.1, -0.2, 0.0, 0.0, 0.01))
    (cam,) = parse_calibration(blob, (0, 18, 0), "x")
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (500.0, 501.0, 320.5, 240.5, 640, 480)
    assert np.allclose(cam.local, LOCAL, atol=1e-7) and cam.distortion == (0.1, -0.2, 0.0, 0.0, 0.01)
    with pytest.raises(ConversionError, match="wrong size"):
        parse_calibration(blob[:-4], (0, 18, 0), "x")
    old = camera_blob("0.17.0", 500.0, 501.0, 0.0, 0.0, 640, 480, LOCAL)
    (cam,) = parse_calibration(old, (0, 17, 0), "x")
    assert (cam.cx, cam.cy) == (319.5, 239.5)  # CameraModel: a zero principal point is the image centre
    assert len(parse_calibration(old + old, (0, 17, 0), "x")) == 2
    a = np.arange(24, dtype=np.float32)[None, :]
    assert np.array_equal(uncompress_data(compress_data(a), "x", a.nbytes), a)


# ---- corrupt and hostile databases: one error line naming the node and field, exit 1, nothing left ----


def _assert_error(tmp_path: Path, db: Path, match: str) -> None:
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["convert", str(db), str(out), "-q"])
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.exit_code == 1, (res.exit_code, res.output)
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in res.stderr, res.stderr
    assert match in lines[0], lines[0]
    assert not out.exists() and not (tmp_path / "out.partial").exists()


@pytest.fixture()
def small_db(tmp_path: Path, lab: Path) -> Path:
    return lab_database(lab, tmp_path / "map.db", "0.23.0", sessions=1)[0]


def _edit(db: Path, *sql: str, args: tuple[object, ...] = ()) -> None:
    con = sqlite3.connect(db)
    for s in sql:
        con.execute(s, args if "?" in s else ())
    con.commit()
    con.close()


def test_truncated_database(tmp_path: Path, small_db: Path) -> None:
    data = small_db.read_bytes()
    small_db.write_bytes(data[: len(data) // 2])
    _assert_error(tmp_path, small_db, "map.db: ")


def test_table_missing(tmp_path: Path, small_db: Path) -> None:
    _edit(small_db, "DROP TABLE Link")
    _assert_error(tmp_path, small_db, "table Link missing")


def test_zlib_blob_cut_short(tmp_path: Path, small_db: Path) -> None:
    con = sqlite3.connect(small_db)
    blob = con.execute("SELECT opt_poses FROM Admin").fetchone()[0]
    con.close()
    _edit(small_db, "UPDATE Admin SET opt_poses = ?", args=(blob[: len(blob) // 2] + blob[-12:],))
    _assert_error(tmp_path, small_db, "Admin.opt_poses: zlib data cut short")


def test_calibration_of_the_wrong_size(tmp_path: Path, small_db: Path) -> None:
    con = sqlite3.connect(small_db)
    blob = con.execute("SELECT calibration FROM Data WHERE id = 2").fetchone()[0]
    con.close()
    _edit(small_db, "UPDATE Data SET calibration = ? WHERE id = 2", args=(blob[:-8],))
    _assert_error(tmp_path, small_db, "node 2: Data.calibration")


def test_node_with_nan_pose(tmp_path: Path, small_db: Path) -> None:
    _edit(small_db, "UPDATE Node SET pose = ? WHERE id = 3", args=(np.full(12, np.nan, "<f4").tobytes(),))
    _assert_error(tmp_path, small_db, "node 3: Node.pose: NaN")


def test_empty_map(tmp_path: Path, small_db: Path) -> None:
    _edit(small_db, "DELETE FROM Data", "DELETE FROM Link", "DELETE FROM Node")
    _assert_error(tmp_path, small_db, "Node: no nodes (an empty map)")


def test_database_locked_by_another_writer(tmp_path: Path, small_db: Path) -> None:
    con = sqlite3.connect(small_db, isolation_level=None)
    con.execute("BEGIN EXCLUSIVE")
    con.execute("UPDATE Node SET weight = 1")
    try:
        _assert_error(tmp_path, small_db, "database is locked by another writer")
    finally:
        con.execute("ROLLBACK")
        con.close()


def test_input_never_modified(tmp_path: Path, small_db: Path) -> None:
    before = small_db.read_bytes()
    small_db.chmod(0o444)
    convert(small_db, tmp_path / "out", config=ConvertConfig(camera_id="d435"))
    assert small_db.read_bytes() == before and sorted(p.name for p in small_db.parent.iterdir()) == ["map.db", "out"]


def test_nodes_out_of_id_order_are_written_in_stamp_order(tmp_path: Path, lab: Path) -> None:
    db, _ = lab_database(lab, tmp_path / "m.db", "0.18.0", sessions=1)
    con = sqlite3.connect(db)
    (t3,) = con.execute("SELECT stamp FROM Node WHERE id = 3").fetchone()
    con.execute("UPDATE Node SET stamp = ? WHERE id = 1", (t3 + 1.0,))  # node 1 is now the last in time
    con.execute("DELETE FROM Data WHERE id = 2")
    con.commit()
    con.close()
    rep = convert(db, tmp_path / "out", config=ConvertConfig(camera_id="d435"))
    scan = open_dataset(tmp_path / "out").scan("m")
    assert rep.skipped == {"no_image": 1} and len(scan) == 2 and np.all(np.diff(scan.stamps_ns) > 0)
    assert abs(scan.stamps_ns[-1] / 1e9 - (t3 + 1.0)) < 1e-6
