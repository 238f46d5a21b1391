"""A fuzzer over recording bytes: whatever bytes of a recording are flipped or cut, ``convert`` either
writes a dataset that validates and loads frame by frame (the autouse fixture of tests/conftest.py
checks it), or exits 1 with one ``error:`` line and leaves nothing behind. Never a traceback.

``PSG_FUZZ_EXAMPLES=2000 python -m pytest tests/convert/test_fuzz_recordings.py`` fuzzes longer.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from psg_data.cli.psg_data_cmd import main
from tests.contract import assert_one_error

from tests.conftest import assert_dataset_agrees

from .conftest import write_bag

FORMATS = {  # (recording, options of write_bag)
    "ros1-raw": ("ros1", {}),
    "ros1-compressed": ("ros1", {"color": "jpeg", "depth": "compressedDepth"}),
    "ros2-sqlite3": ("ros2-sqlite3", {"color": "jpeg"}),
    "ros2-mcap": ("ros2-mcap", {"depth": "compressedDepth"}),
}


class Pristine(dict):
    """format -> (recording, bytes of its data file); a short repr for hypothesis' reports."""

    def __repr__(self) -> str:
        return f"Pristine({', '.join(self)})"


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Pristine:
    """One small recording per format."""
    out = Pristine()
    for name, (fmt, kw) in FORMATS.items():
        d = tmp_path_factory.mktemp(name)
        rec = write_bag(d / ("a.bag" if fmt == "ros1" else "a"), fmt, n=5, **kw)
        data_file = rec if rec.is_file() else next(p for p in rec.iterdir() if p.suffix in (".db3", ".mcap"))
        out[name] = (rec, data_file.read_bytes())
    return out


damage = st.tuples(
    st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255), st.integers(1, 16)), min_size=0,
             max_size=6),
    st.one_of(st.none(), st.floats(0, 1, exclude_max=True)),
)


def _mutate(data: bytes, flips: list[tuple[float, int, int]], cut: float | None) -> bytes:
    b = bytearray(data)
    for where, mask, length in flips:
        i = int(where * len(b))
        for k in range(i, min(i + length, len(b))):
            b[k] ^= mask
    return bytes(b[: int(cut * len(b))] if cut is not None else b)


@pytest.mark.damaged_passthrough  # converts_or_fails_cleanly validates itself (passed-through damage allowed)
@pytest.mark.parametrize("name", list(FORMATS))
@settings(max_examples=int(os.environ.get("PSG_FUZZ_EXAMPLES", "25")), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(d=damage)
def test_damaged_recording_converts_or_fails_cleanly(tmp_path: Path, pristine: dict, name: str,
                                                     d: tuple[list[tuple[float, int, int]], float | None]) -> None:
    src, data = pristine[name]
    work = tmp_path / "w"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    rec = work / src.name
    if src.is_dir():
        shutil.copytree(src, rec)
        target = next(p for p in rec.iterdir() if p.suffix in (".db3", ".mcap"))
    else:
        target = rec
    target.write_bytes(_mutate(data, *d))
    converts_or_fails_cleanly(rec, "converted 1 scans")


def converts_or_fails_cleanly(rec: Path, summary: str) -> None:
    """``convert REC OUT`` (OUT beside REC) either writes OUT and prints ``summary``, or prints one
    error line and leaves the folder holding only REC.

    A dataset it writes validates and loads, except for one documented case (docs/FORMAT.md,
    "Validation"): damage inside a passed-through image's compressed data, which convert's default
    ``structure`` check cannot see and validate's strict decode refuses. Then every problem must be
    such an image, and ``--image-check full`` must catch it at convert: skip the frame (a dataset
    that validates) or refuse the recording in one line."""
    work, out = rec.parent, rec.parent / "out"
    r = CliRunner().invoke(main, ["convert", str(rec), str(out), "-q"])
    if r.exit_code != 0:
        assert_one_error(r)
        assert sorted(p.name for p in work.iterdir()) == [rec.name]  # no OUT, no OUT.partial
        return
    assert out.is_dir() and summary in r.stdout, r.output
    from psg_data.schemas.validate import validate_dataset

    problems = validate_dataset(out)
    if not problems:
        assert_dataset_agrees(out)
        return
    assert all(p.field == "image" and "corrupt" in p.message for p in problems), [str(p) for p in problems]
    full = work / "out-full"
    r = CliRunner().invoke(main, ["convert", str(rec), str(full), "-q", "--image-check", "full"])
    if r.exit_code == 0:
        assert "corrupt_image" in r.output, r.output
        assert_dataset_agrees(full)
    else:
        assert_one_error(r)
        assert not full.exists() and not full.with_name(full.name + ".partial").exists()


def test_ros2_sqlite3_message_with_null_data_is_one_error(tmp_path: Path, pristine: dict) -> None:
    """A damaged ROS 2 sqlite3 bag can hold a message row whose data is NULL (found by the fuzzer:
    rosbags then yields None and convert raised a TypeError); it is a recording error."""
    import sqlite3

    src, _ = pristine["ros2-sqlite3"]
    rec = tmp_path / src.name
    shutil.copytree(src, rec)
    db = next(p for p in rec.iterdir() if p.suffix == ".db3")
    with sqlite3.connect(db) as con:  # as truncation leaves it: the schema's NOT NULL no longer holds
        con.execute("PRAGMA writable_schema = ON")
        con.execute("UPDATE sqlite_master SET sql = replace(sql, 'data BLOB NOT NULL', 'data BLOB') "
                    "WHERE name = 'messages'")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE messages SET data = NULL WHERE id = (SELECT MAX(id) FROM messages)")
    r = CliRunner().invoke(main, ["convert", str(rec), str(tmp_path / "out")])
    line = assert_one_error(r, "has no data")
    assert str(db.name) in line or str(rec) in line
    assert sorted(p.name for p in tmp_path.iterdir()) == [rec.name]
