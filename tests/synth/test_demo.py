"""``psg_data.datasets.demo()``: the default lab (84 scans), cached and rebuilt when corrupted."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

from psg_data.datasets import DEMO_VERSION, demo
from psg_data.loaders import open_dataset


@pytest.mark.slow
def test_demo_builds_once_and_rebuilds_when_corrupted(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "cache"))
    root = demo()
    assert root.parent == tmp_path / "cache" and DEMO_VERSION in root.name
    ds = open_dataset(root)
    assert len(ds.scan_ids) == 84 and len(ds.doors) == 2 and len(ds.objects) == 21
    assert sorted(ds.rooms) == ["corridor", "room_a", "room_b", "room_c"]  # the lab's 3 rooms and its corridor
    assert sorted(Counter(r.room_id for r in ds.receptacles.values()).values()) == [8, 10, 10]
    splits = Counter(ds.scan(s).split for s in ds.scan_ids)
    assert splits == {"train": 56, "test": 28}
    assert ds.table("door_states").num_rows == 168 and ds.table("schedule").num_rows == 84 * 21
    manifest = root / "dataset.json"
    stamp = manifest.stat().st_mtime_ns
    assert demo() == root and manifest.stat().st_mtime_ns == stamp  # cached, not rebuilt
    archive = next((root / "images").glob("*.tar"))
    archive.write_bytes(b"corrupt")
    assert demo() == root and manifest.stat().st_mtime_ns != stamp  # rebuilt
    assert archive.read_bytes()[257:262] == b"ustar"
