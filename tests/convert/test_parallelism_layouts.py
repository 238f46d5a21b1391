"""``--jobs`` semantics, image layouts and direct I/O of ``psg-data convert``."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.convert import ConvertConfig, convert
from psg_data.convert._pipeline import plan_parallelism
from psg_data.errors import ConversionError
from psg_data.loaders import open_dataset
from psg_data.schemas.validate import validate_dataset
from psg_data.synth._raw_export import export_raw


@pytest.mark.parametrize("jobs, n_tasks, threads, expected", [
    (1, 8, None, (1, 0)),    # one core: convert here, encode in the reading thread
    (2, 8, None, (2, 0)),    # two recordings at a time, one core each
    (2, 1, None, (1, 2)),    # one recording: two encoding threads beside the reader
    (4, 3, None, (3, 0)),    # 4 // 3 = 1 CPU per process
    (4, 2, None, (2, 2)),
    (8, 2, None, (2, 4)),
    (2, 0, None, (1, 2)),
    (1, 4, 3, (1, 3)),       # threads given explicitly
    (3, 4, 1, (3, 0)),
])
def test_plan_parallelism(jobs: int, n_tasks: int, threads: int | None, expected: tuple[int, int]) -> None:
    assert plan_parallelism(jobs, n_tasks, threads) == expected


def test_plan_parallelism_all_cpus(monkeypatch: pytest.MonkeyPatch) -> None:
    import psg_data.convert._pipeline as pl

    monkeypatch.setattr(pl, "available_cpus", lambda: 6)
    assert plan_parallelism(-1, 2) == (2, 3)
    assert plan_parallelism(-1, 10) == (6, 0)
    with pytest.raises(ConversionError, match="jobs: 0"):
        plan_parallelism(0, 2)


def _images(root: Path) -> list[tuple[bytes, bytes]]:
    ds = open_dataset(root)
    return [s.image_bytes(i) for s in ds.scans for i in range(len(s))]


def test_layouts_and_processes_give_the_same_images(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros1", images="compressed")
    a = convert(raw, tmp_path / "tar").output
    b = convert(raw, tmp_path / "files", config=ConvertConfig(image_layout="files")).output
    c = convert(raw, tmp_path / "two_jobs", jobs=2).output
    assert _images(Path(a)) == _images(Path(b)) == _images(Path(c))
    assert len(_images(Path(a))) == 8
    assert sorted(p.name for p in (Path(a) / "images").iterdir()) == ["scan_000.tar", "scan_001.tar"]
    assert (Path(b) / "images/scan_000/color/000000.jpg").is_file()
    for root in (a, b, c):
        assert validate_dataset(root) == []
    # one process or two workers give byte-identical archives
    assert (Path(a) / "images/scan_001.tar").read_bytes() == (Path(c) / "images/scan_001.tar").read_bytes()


def test_cli_jobs_and_layout_options(tmp_path: Path, tiny_dataset: Path) -> None:
    raw = export_raw(tiny_dataset, tmp_path / "raw", "ros2-mcap", images="compressed")
    r = CliRunner().invoke(main, ["convert", str(raw), str(tmp_path / "out"), "-j", "-1", "--image-layout", "files",
                                  "-q"])
    assert r.exit_code == 0, r.output
    ds = open_dataset(tmp_path / "out")
    assert ds.df("frames").color_offset.isna().all()
    assert ds.info.extra["convert"]["config"]["image_layout"] == "files"
    r = CliRunner().invoke(main, ["convert", str(raw), str(tmp_path / "o2"), "-j", "-3", "-q"])
    assert r.exit_code == 2 and "expected a number of CPUs" in r.output
    cfg = tmp_path / "c.yaml"
    cfg.write_text("image_layout: zip\n")
    r = CliRunner().invoke(main, ["convert", str(raw), str(tmp_path / "o3"), "--config", str(cfg), "-q"])
    assert r.exit_code == 1 and "image_layout: expected one of tar, files, got 'zip'" in r.stderr
