"""Write -> read round trip of the canonical format through DatasetWriter and open_dataset."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import psg_data
from psg_data.errors import DatasetExistsError, FormatError
from psg_data.loaders import backproject
from psg_data.schemas import CameraIntrinsics
from psg_data.writers import DatasetWriter
from tests.conftest import T0_NS, tiny_images, write_tiny_dataset


@pytest.mark.parametrize("layout", ["tar", "files"])
def test_round_trip_tables_images_poses(tmp_path: Path, layout: str) -> None:
    root = write_tiny_dataset(tmp_path / "ds", scans=2, frames=3, seed=7, image_layout=layout)
    ds = psg_data.open_dataset(root)
    assert ds.info.format == "psg-dataset" and ds.info.format_version == "2.0"
    frames = ds.df("frames")
    if layout == "tar":
        assert set(frames.color_path) == {"images/scan_000.tar", "images/scan_001.tar"}
        assert (frames.color_offset % 512 == 0).all() and (frames.depth_offset > frames.color_offset).all()
    else:
        assert frames.color_offset.isna().all() and frames.depth_size.isna().all()
        assert frames.color_path[0] == "images/scan_000/color/000000.png"
    assert ds.info.timezone == "America/Toronto"
    assert ds.scan_ids == ["scan_000", "scan_001"]
    assert set(ds.receptacles) == {"table", "shelf", "desk"}
    assert ds.receptacles["table"].box.rotation == pytest.approx(
        np.array([[np.cos(0.3), -np.sin(0.3), 0], [np.sin(0.3), np.cos(0.3), 0], [0, 0, 1]]))
    assert ds.doors["door1"].room_b == "office"
    assert ds.rooms["kitchen"].floor_polygon_m.shape == (4, 2)
    assert ds.rooms["office"].floor_polygon_m is None
    assert ds.cameras["d435"].distortion_coeffs == (0.01, -0.02, 0.0, 0.0, 0.0)
    sched = ds.df("schedule")
    assert sched.loc[(sched.scan_id == "scan_001") & (sched.object_id == "spoon"), "receptacle_id"].isna().all()

    # regenerate the same random images and compare pixel-exactly (PNG is lossless)
    rng = np.random.default_rng(7)
    for s in range(2):
        scan = ds.scan(f"scan_{s:03d}")
        assert len(scan) == 3
        for i, fr in enumerate(scan.frames()):
            color, depth = tiny_images(rng, 24, 32)
            np.testing.assert_array_equal(fr.color, color)
            np.testing.assert_allclose(fr.depth_m, depth.astype(np.float32) * np.float32(0.001))
            assert fr.depth_m.dtype == np.float32 and fr.color.dtype == np.uint8
            assert fr.stamp_ns == T0_NS + s * 7200 * 10**9 + i * 10**8
            assert fr.T_world_camera[:3, 3] == pytest.approx([0.5 + 0.1 * i, 0.2 * s, 1.2])
            assert fr.camera.width == 32


def test_random_access_reads_one_frame_files_layout(make_dataset) -> None:
    ds = psg_data.open_dataset(make_dataset(frames=5, image_layout="files"))
    scan = ds.scan("scan_002")
    # delete every other image of the scan: frame 3 must still load on its own
    for i in (0, 1, 2, 4):
        (ds.root / f"images/scan_002/color/{i:06d}.png").unlink()
    fr = scan.frame(3)
    assert fr.index == 3 and fr.color.shape == (24, 32, 3)
    with pytest.raises(FormatError, match="missing or unreadable colour image"):
        scan.frame(0)
    with pytest.raises(IndexError, match="out of range"):
        scan.frame(5)


def test_random_access_reads_one_frame_tar_layout(make_dataset) -> None:
    ds = psg_data.open_dataset(make_dataset(frames=5))
    scan = ds.scan("scan_002")
    frames = ds.df("frames").query("scan_id == 'scan_002'").sort_values("frame_index")
    archive = ds.root / "images/scan_002.tar"
    # zero everything but frame 3's two byte ranges: frame 3 must still load on its own
    data = bytearray(archive.stat().st_size)
    raw = archive.read_bytes()
    for kind in ("color", "depth"):
        off, size = int(frames[f"{kind}_offset"].iloc[3]), int(frames[f"{kind}_size"].iloc[3])
        data[off:off + size] = raw[off:off + size]
    archive.write_bytes(bytes(data))
    ds.close()
    fr = scan.frame(3)
    assert fr.index == 3 and fr.color.shape == (24, 32, 3)
    with pytest.raises(FormatError, match=r"scan_002\.tar@\d+: missing or unreadable colour image"):
        scan.frame(0)
    archive.write_bytes(raw[: int(frames["color_offset"].iloc[4])])  # truncated before frame 4
    ds.close()
    with pytest.raises(FormatError, match="beyond the end of images/scan_002.tar"):
        scan.frame(4)
    assert scan.frame(1).color.shape == (24, 32, 3)


def test_tar_archive_is_a_plain_tar(make_dataset) -> None:
    import tarfile

    root = make_dataset(scans=1, frames=3, color_encoding="jpeg")
    ds = psg_data.open_dataset(root)
    frames = ds.df("frames")
    with tarfile.open(root / "images/scan_000.tar") as tf:
        members = tf.getmembers()
        assert [m.name for m in members] == ["color/000000.jpg", "depth/000000.png", "color/000001.jpg",
                                             "depth/000001.png", "color/000002.jpg", "depth/000002.png"]
        for i in range(3):
            c, d = members[2 * i], members[2 * i + 1]
            assert (c.offset_data, c.size) == (frames.color_offset[i], frames.color_size[i])
            assert (d.offset_data, d.size) == (frames.depth_offset[i], frames.depth_size[i])
            assert c.mtime == frames.stamp_ns[i] // 10**9
            cbytes, dbytes = ds.scan("scan_000").image_bytes(i)
            assert tf.extractfile(c).read() == cbytes and tf.extractfile(d).read() == dbytes
    assert (root / "images/scan_000.tar").stat().st_size % 4096 == 0


def test_scan_at_and_unknown_scan(make_dataset) -> None:
    ds = psg_data.open_dataset(make_dataset())
    assert ds.scan_at(T0_NS - 1) is None
    assert ds.scan_at(T0_NS + 10**8).scan_id == "scan_000"
    assert ds.scan_at(T0_NS + 7200 * 10**9 + 5).scan_id == "scan_001"
    assert ds.scan_at(T0_NS + 10**15).scan_id == "scan_002"
    with pytest.raises(KeyError, match="no scan 'nope'"):
        ds.scan("nope")


def test_point_cloud_matches_independent_backprojection(make_dataset) -> None:
    ds = psg_data.open_dataset(make_dataset(scans=1, frames=2))
    scan = ds.scan("scan_000")
    pcd = scan.point_cloud(stride=1, max_depth_m=3.0)
    pts = np.asarray(pcd.points)
    # independent per-pixel loop for frame 0 and 1
    expected = []
    for fr in scan.frames():
        K = fr.camera.K
        for v in range(fr.depth_m.shape[0]):
            for u in range(fr.depth_m.shape[1]):
                z = float(fr.depth_m[v, u])
                if 0 < z <= 3.0:
                    pc = np.linalg.solve(K, np.array([u, v, 1.0])) * z
                    expected.append(fr.T_world_camera @ np.append(pc, 1.0))
    expected = np.array(expected)[:, :3]
    assert pts.shape == expected.shape
    np.testing.assert_allclose(pts, expected, atol=1e-5)
    # colours are in [0, 1]
    cols = np.asarray(pcd.colors)
    assert cols.min() >= 0 and cols.max() <= 1


def test_backproject_respects_stride_and_max_depth(make_dataset) -> None:
    fr = psg_data.open_dataset(make_dataset(scans=1, frames=1)).scan("scan_000").frame(0)
    p1, _ = backproject(fr, stride=1, max_depth_m=2.0)
    p2, _ = backproject(fr, stride=2, max_depth_m=2.0)
    n_valid = int(((fr.depth_m > 0) & (fr.depth_m <= 2.0)).sum())
    n_valid2 = int(((fr.depth_m[::2, ::2] > 0) & (fr.depth_m[::2, ::2] <= 2.0)).sum())
    assert p1.shape == (n_valid, 3) and p2.shape == (n_valid2, 3)


def test_refuses_to_overwrite_without_flag_and_replaces_with_it(make_dataset) -> None:
    root = make_dataset()
    before = (root / "dataset.json").read_text()
    with pytest.raises(DatasetExistsError, match="output exists; pass --overwrite"):
        write_tiny_dataset(root)
    assert (root / "dataset.json").read_text() == before
    write_tiny_dataset(root, scans=1, overwrite=True)
    assert psg_data.open_dataset(root).scan_ids == ["scan_000"]
    assert not root.with_name(root.name + ".partial").exists()
    assert not root.with_name(root.name + ".old").exists()


def test_failed_write_leaves_no_dataset(tmp_path: Path) -> None:
    root = tmp_path / "out"
    cam = CameraIntrinsics("c", 8, 6, 5.0, 5.0, 3.5, 2.5)
    with pytest.raises(RuntimeError):
        with DatasetWriter(root, timezone="UTC") as w:
            w.add_camera(cam)
            with w.scan("s0") as sw:
                sw.add_frame(1, np.eye(4), np.zeros((6, 8, 3), np.uint8), np.zeros((6, 8), np.uint16), "c")
            raise RuntimeError("interrupted")
    assert not root.exists()
    assert root.with_name("out.partial").is_dir()  # kept for resuming


def test_resume_adopts_completed_scans(tmp_path: Path) -> None:
    root = tmp_path / "out"
    cam = CameraIntrinsics("c", 8, 6, 5.0, 5.0, 3.5, 2.5)
    img = np.full((6, 8, 3), 9, np.uint8), np.full((6, 8), 1234, np.uint16)
    try:
        with DatasetWriter(root, timezone="UTC") as w:
            w.add_camera(cam)
            with w.scan("s0") as sw:
                sw.add_frame(1, np.eye(4), *img, "c")
            with w.scan("s1") as sw:
                sw.add_frame(2, np.eye(4), *img, "c")
                raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass
    w2 = DatasetWriter(root, timezone="UTC", resume=True)
    done = w2.completed_scans()
    assert list(done) == ["s0"]  # s1 was interrupted before completing
    # a corrupted image makes the scan incomplete
    w2.adopt_scan(done["s0"])
    w2.add_camera(cam)
    with w2.scan("s1") as sw:
        sw.add_frame(2, np.eye(4), *img, "c")
    w2.close()
    ds = psg_data.open_dataset(root)
    assert ds.scan_ids == ["s0", "s1"]
    assert ds.scan("s0").frame(0).depth_m[0, 0] == pytest.approx(1.234)
    from psg_data.schemas.validate import validate_dataset

    assert validate_dataset(root) == []


def test_resume_rejects_scan_with_corrupted_image(tmp_path: Path) -> None:
    root = tmp_path / "out"
    cam = CameraIntrinsics("c", 8, 6, 5.0, 5.0, 3.5, 2.5)
    w = DatasetWriter(root, timezone="UTC")
    w.add_camera(cam)
    with w.scan("s0") as sw:
        sw.add_frame(1, np.eye(4), np.zeros((6, 8, 3), np.uint8), np.zeros((6, 8), np.uint16), "c")
    w.abort(keep_partial=True)
    archive = root.with_name("out.partial") / "images/s0.tar"
    data = bytearray(archive.read_bytes())
    data[700] ^= 0xFF  # same size, other content
    archive.write_bytes(bytes(data))
    assert DatasetWriter(root, timezone="UTC", resume=True).completed_scans() == {}


def test_writer_rejects_bad_frames(tmp_path: Path) -> None:
    w = DatasetWriter(tmp_path / "x", timezone="UTC")
    w.add_camera(CameraIntrinsics("c", 8, 6, 5.0, 5.0, 3.5, 2.5))
    sw = w.scan("s0")
    with pytest.raises(FormatError, match="depth must be 6x8 uint16 mm"):
        sw.add_frame(1, np.eye(4), np.zeros((6, 8, 3), np.uint8), np.zeros((6, 8), np.float32), "c")
    with pytest.raises(FormatError, match="unknown camera_id 'zz'"):
        sw.add_frame(1, np.eye(4), np.zeros((6, 8, 3), np.uint8), np.zeros((6, 8), np.uint16), "zz")
    with pytest.raises(FormatError, match="T_world_camera must be 4x4"):
        sw.add_frame(1, np.eye(3), np.zeros((6, 8, 3), np.uint8), np.zeros((6, 8), np.uint16), "c")
    with pytest.raises(FormatError, match="must be a non-empty name"):
        w.scan("a/b")
    w.abort()
    assert not (tmp_path / "x.partial").exists()


def test_jpeg_dataset(make_dataset) -> None:
    root = make_dataset(color_encoding="jpeg", scans=1, frames=1)
    ds = psg_data.open_dataset(root)
    assert ds.info.color_encoding == "jpeg"
    assert ds.scan("scan_000").image_bytes(0)[0][:2] == b"\xff\xd8"
    assert ds.scan("scan_000").frame(0).color.shape == (24, 32, 3)
    files = psg_data.open_dataset(make_dataset("files", color_encoding="jpeg", scans=1, frames=1, image_layout="files"))
    assert files.df("frames").color_path[0].endswith(".jpg")


def test_manifest_newer_major_is_refused(make_dataset) -> None:
    root = make_dataset(scans=1, frames=1)
    m = json.loads((root / "dataset.json").read_text())
    m["format_version"] = "3.0"
    (root / "dataset.json").write_text(json.dumps(m))
    with pytest.raises(FormatError, match="newer than this psg-data reads"):
        psg_data.open_dataset(root)


def test_manifest_unknown_keys_warn(make_dataset, caplog: pytest.LogCaptureFixture) -> None:
    root = make_dataset(scans=1, frames=1)
    m = json.loads((root / "dataset.json").read_text())
    m["format_version"] = "2.7"
    m["future_key"] = 1
    (root / "dataset.json").write_text(json.dumps(m))
    with caplog.at_level("WARNING"):
        ds = psg_data.open_dataset(root)
    assert ds.info.format_version == "2.7"
    assert "future_key" in caplog.text


def test_not_a_dataset(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="not a directory"):
        psg_data.open_dataset(tmp_path / "nothing")
    with pytest.raises(FormatError, match="missing manifest"):
        psg_data.open_dataset(tmp_path)
