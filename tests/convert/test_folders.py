"""TUM RGB-D and ScanNet-style frame folders -> dataset."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from .conftest import CAMERA, images, pose

from psg_data.convert import ConvertConfig, convert
from psg_data.loaders import open_dataset
from psg_data.loaders.raw._transforms import matrix_to_quat_xyzw


def make_tum(d: Path, n: int = 4) -> list[int]:
    (d / "rgb").mkdir(parents=True)
    (d / "depth").mkdir()
    rgb, dep, gt = ["# color images"], ["# depth"], ["# timestamp tx ty tz qx qy qz qw"]
    stamps = []
    for i in range(n):
        t_s = f"1305031102.{175304 + 33333 * i:06d}"
        c, dm = images(i, 0)
        cv2.imwrite(str(d / "rgb" / f"{t_s}.png"), cv2.cvtColor(c, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(d / "depth" / f"{t_s}.png"), (dm.astype(np.uint32) * 5).clip(0, 65535).astype(np.uint16))
        rgb.append(f"{t_s} rgb/{t_s}.png")
        d_s = f"1305031102.{175304 + 33333 * i + 5000:06d}"  # depth 5 ms later (as in TUM)
        (d / "depth" / f"{t_s}.png").rename(d / "depth" / f"{d_s}.png")
        dep.append(f"{d_s} depth/{d_s}.png")
        T = pose(i, 0)
        q = matrix_to_quat_xyzw(T[:3, :3])
        gt.append(f"{t_s} " + " ".join(f"{v:.17g}" for v in [*T[:3, 3], *q]))
        stamps.append(1305031102_000_000_000 + (175304 + 33333 * i) * 1000)
    (d / "rgb.txt").write_text("\n".join(rgb) + "\n")
    (d / "depth.txt").write_text("\n".join(dep) + "\n")
    (d / "groundtruth.txt").write_text("\n".join(gt) + "\n")
    return stamps


def test_tum_folder(tmp_path: Path) -> None:
    stamps = make_tum(tmp_path / "fr1")
    cfg = ConvertConfig(intrinsics=[CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy])
    rep = convert(tmp_path / "fr1", tmp_path / "out", config=cfg)
    assert rep.frames == 4 and rep.n_skipped == 0
    sc = open_dataset(tmp_path / "out").scan("fr1")
    assert sc.stamps_ns.tolist() == stamps
    for i in range(4):
        f = sc.frame(i)
        c, dm = images(i, 0)
        assert np.array_equal(f.color, c)
        exp = (dm.astype(np.uint32) * 5).clip(0, 65535) / 5000.0  # depth factor 5000 -> metres
        np.testing.assert_allclose(f.depth_m, np.rint(exp * 1000) / 1000, atol=1e-6)
        np.testing.assert_allclose(f.T_world_camera, pose(i, 0), atol=1e-9)
    cam = open_dataset(tmp_path / "out").cameras["camera"]
    assert (cam.fx, cam.width, cam.height) == (CAMERA.fx, CAMERA.width, CAMERA.height)


def test_tum_without_intrinsics_is_an_error(tmp_path: Path) -> None:
    import pytest

    from psg_data.errors import ConversionError

    make_tum(tmp_path / "fr1", n=2)
    with pytest.raises(ConversionError, match="no camera intrinsics"):
        convert(tmp_path / "fr1", tmp_path / "out")
    assert not (tmp_path / "out.partial").exists()


def test_scannet_folder_with_invalid_pose(tmp_path: Path) -> None:
    d = tmp_path / "scene0000_00"
    for sub in ("color", "depth", "pose", "intrinsic"):
        (d / sub).mkdir(parents=True)
    K = np.eye(4)
    K[0, 0], K[1, 1], K[0, 2], K[1, 2] = CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy
    np.savetxt(d / "intrinsic" / "intrinsic_depth.txt", K)
    for i in range(3):
        c, dm = images(i, 0)
        cv2.imwrite(str(d / "color" / f"{i}.png"), cv2.cvtColor(c, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(d / "depth" / f"{i}.png"), dm)
        np.savetxt(d / "pose" / f"{i}.txt", pose(i, 0) if i != 1 else np.full((4, 4), -np.inf))
    rep = convert(d, tmp_path / "out", config=ConvertConfig(fps=10.0, start_stamp_ns=5))
    assert rep.frames == 2 and rep.skipped == {"nonfinite_pose": 1}
    sc = open_dataset(tmp_path / "out").scan("scene0000_00")
    assert sc.stamps_ns.tolist() == [5, 5 + 200_000_000]
    np.testing.assert_allclose(sc.poses[1], pose(2, 0), atol=1e-12)
    assert np.array_equal(sc.frame(1).color, images(2, 0)[0])


def test_tum_list_naming_a_file_outside_the_recording_is_an_error(tmp_path: Path) -> None:
    import pytest

    from psg_data.errors import ConversionError

    make_tum(tmp_path / "fr1", n=2)
    outside = tmp_path / "outside.png"
    (tmp_path / "fr1/rgb").iterdir().__next__().rename(outside)  # a valid image, now beside the recording
    text = (tmp_path / "fr1/rgb.txt").read_text().splitlines()
    for bad in ("../outside.png", str(outside)):
        stamp = text[1].split()[0]
        (tmp_path / "fr1/rgb.txt").write_text("\n".join([text[0], f"{stamp} {bad}", *text[2:]]) + "\n")
        cfg = ConvertConfig(intrinsics=[CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy])
        with pytest.raises(ConversionError, match=r"rgb\.txt:2: .*(has a '\.\.' component|is absolute); expected a "
                                                  r"path relative to"):
            convert(tmp_path / "fr1", tmp_path / "out")
