"""Factory fixtures building tiny datasets in tmp_path (no binaries in the repository)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from psg_data.schemas import Box, CameraIntrinsics, Door, ObjectInfo, Receptacle, Room
from psg_data.writers import DatasetWriter

T0_NS = 1_700_000_000 * 10**9  # 2023-11-14 UTC


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def tiny_images(rng: np.random.Generator, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    color = rng.integers(0, 256, size=(h, w, 3), dtype=np.uint8)
    depth = rng.integers(0, 5000, size=(h, w), dtype=np.uint16)
    depth[rng.random((h, w)) < 0.05] = 0
    return color, depth


def write_tiny_dataset(root: Path, *, scans: int = 3, frames: int = 4, width: int = 32, height: int = 24,
                       color_encoding: str = "png", seed: int = 0, overwrite: bool = False,
                       image_layout: str = "tar") -> Path:
    """A small but complete dataset: 2 rooms, 3 receptacles, 1 door, 2 objects, images, schedule."""
    rng = np.random.default_rng(seed)
    cam = CameraIntrinsics("d435", width, height, 0.9 * width, 0.9 * width, (width - 1) / 2, (height - 1) / 2,
                           "plumb_bob", (0.01, -0.02, 0.0, 0.0, 0.0), 0.001, "camera_color_optical_frame")
    with DatasetWriter(root, name="tiny", timezone="America/Toronto", color_encoding=color_encoding,
                       overwrite=overwrite, image_layout=image_layout, extra={"generator": "tests"}) as w:
        w.add_camera(cam)
        w.set_rooms([Room("kitchen", "Kitchen", np.array([[0, 0], [4, 0], [4, 3], [0, 3.0]])), Room("office", "Office")])
        w.set_receptacles([
            Receptacle("table", "kitchen table", "kitchen", Box(np.array([1, 1, 0.375]), np.array([1.2, 0.8, 0.75]),
                                                                _rot_z(0.3)), "table"),
            Receptacle("shelf", "shelf", "kitchen", Box(np.array([3, 2, 0.9]), np.array([0.8, 0.4, 1.8])), "shelf"),
            Receptacle("desk", "desk", "office", Box(np.array([6, 1, 0.37]), np.array([1.4, 0.7, 0.74])), "desk"),
        ])
        w.set_doors([Door("door1", "kitchen-office", "kitchen", "office",
                          Box(np.array([4, 1.5, 1.0]), np.array([0.1, 0.9, 2.0])))])
        w.set_objects([ObjectInfo("redmug", "redmug", "a red mug"), ObjectInfo("spoon", "spoon", "a spoon")])
        door_rows, sched = [], []
        for s in range(scans):
            sid = f"scan_{s:03d}"
            with w.scan(sid, source=f"scan_{s:03d}.bag", split="train" if s < scans - 1 else "test") as sw:
                for i in range(frames):
                    T = np.eye(4)
                    T[:3, :3] = _rot_z(0.1 * i) @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0.0]])
                    T[:3, 3] = [0.5 + 0.1 * i, 0.2 * s, 1.2]
                    color, depth = tiny_images(rng, height, width)
                    sw.add_frame(T0_NS + s * 7200 * 10**9 + i * 10**8, T, color, depth, "d435")
            door_rows.append({"scan_id": sid, "door_id": "door1", "state": "open" if s % 2 == 0 else "closed"})
            sched.append({"scan_id": sid, "object_id": "redmug", "receptacle_id": "table" if s % 2 == 0 else "desk"})
            sched.append({"scan_id": sid, "object_id": "spoon", "receptacle_id": None if s == 1 else "shelf"})
        w.set_table("door_states", door_rows)
        w.set_table("schedule", sched)
    return root


@pytest.fixture
def make_dataset(tmp_path: Path) -> Callable[..., Path]:
    """Factory: ``make_dataset(name="ds", **kwargs)`` writes a tiny dataset under tmp_path."""

    def factory(name: str = "ds", **kwargs: object) -> Path:
        return write_tiny_dataset(tmp_path / name, **kwargs)  # type: ignore[arg-type]

    return factory


@pytest.fixture
def user_backend(monkeypatch: pytest.MonkeyPatch):  # type: ignore[no-untyped-def]
    """A user's own matplotlib backend ('svg', as a notebook sets its inline one) that library code
    must leave alone: fails the test if anything calls ``matplotlib.use`` or the backend changed."""
    import matplotlib

    before = matplotlib.get_backend()
    matplotlib.use("svg")
    calls: list[tuple] = []  # type: ignore[type-arg]
    monkeypatch.setattr(matplotlib, "use", lambda *a, **k: calls.append((a, k)))
    yield "svg"
    monkeypatch.undo()
    after = matplotlib.get_backend()
    matplotlib.use(before)
    assert calls == [], f"library code called matplotlib.use{calls[0]}"
    assert after == "svg", f"the backend changed from svg to {after}"


def assert_dataset_agrees(root: Path) -> int:
    """convert + validate + the loader agree on ``root``: it validates (every image decoded) and every
    frame of every scan loads. Returns the number of frames."""
    from psg_data.loaders import open_dataset
    from psg_data.schemas.validate import validate_dataset

    problems = validate_dataset(root)
    assert problems == [], [str(p) for p in problems]
    n = 0
    with open_dataset(root) as ds:
        for scan in ds.scans:
            for fr in scan.frames(prefetch=0):
                assert fr.color.shape[:2] == fr.depth_m.shape == (fr.camera.height, fr.camera.width)
                n += 1
    return n


@pytest.fixture(autouse=True)
def _converted_datasets_agree(monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest) -> None:
    """Every dataset a test converts is validated and loaded frame by frame as soon as it is written
    (except in tests marked ``damaged_passthrough``, which check that validate refuses it)."""
    from psg_data.convert import _pipeline

    if request.node.get_closest_marker("damaged_passthrough") is not None:
        return

    real = _pipeline._convert

    def checked(*args, **kwargs):  # type: ignore[no-untyped-def]
        report = real(*args, **kwargs)
        assert assert_dataset_agrees(Path(report.output)) == report.frames
        return report

    monkeypatch.setattr(_pipeline, "_convert", checked)


def reseal_checksums(root: Path) -> None:
    """Make ``files.parquet`` and the manifest's ``files_sha256`` fit the dataset's files as they now
    are (what an attacker does; also for a test that edits a table to build a case the checksum
    check would otherwise answer first). A listed path that leaves the dataset is left as it is."""
    import hashlib
    import json

    import pyarrow as pa
    import pyarrow.parquet as pq

    fp = root / "tables/files.parquet"
    rows = pq.read_table(fp).to_pylist()
    for r in rows:
        p = root / r["path"]
        if not Path(r["path"]).is_absolute() and ".." not in r["path"] and p.is_file():  # never outside
            data = p.read_bytes()
            r["size_bytes"], r["sha256"] = len(data), hashlib.sha256(data).hexdigest()
    pq.write_table(pa.Table.from_pylist(rows, schema=pq.read_schema(fp)), fp)
    m = json.loads((root / "dataset.json").read_text())
    m["files_sha256"] = hashlib.sha256(fp.read_bytes()).hexdigest()
    (root / "dataset.json").write_text(json.dumps(m, indent=2))


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Run the test files that hold a ``slow`` test first, then the others by number of tests, most
    first (a stable sort: within a file the order is kept). With the README's ``-n auto`` each file
    goes to one worker in this order (``--dist loadfile --no-loadscope-reorder`` in pyproject.toml),
    so the long files start early and the run does not end with one worker busy on a long file and
    the other idle; xdist's own order (by number of tests only) started one of them last."""
    files = [item.nodeid.split("::")[0] for item in items]
    count = Counter(files)
    slow = {f for f, item in zip(files, items) if item.get_closest_marker("slow") is not None}
    key = {item.nodeid: (f not in slow, -count[f]) for f, item in zip(files, items)}
    items.sort(key=lambda item: key[item.nodeid])
