"""The recording fuzzer over RTAB-Map databases: whatever bytes of a database are flipped or cut,
``convert`` writes a dataset that validates and loads (the autouse fixture of tests/conftest.py
checks it), or exits 1 with one ``error:`` line and leaves nothing behind. Never a traceback.

``PSG_FUZZ_EXAMPLES=2000 python -m pytest tests/convert/test_fuzz_rtabmap.py`` fuzzes longer.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings

from .test_fuzz_recordings import _mutate, converts_or_fails_cleanly, damage
from .test_rtabmap import lab, lab_database  # noqa: F401  (the lab fixture)


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory, lab: Path) -> bytes:  # noqa: F811
    db, _ = lab_database(lab, tmp_path_factory.mktemp("db") / "map.db", "0.23.0", sessions=2)
    return db.read_bytes()


@pytest.mark.damaged_passthrough  # converts_or_fails_cleanly validates itself (passed-through damage allowed)
@settings(max_examples=int(os.environ.get("PSG_FUZZ_EXAMPLES", "25")), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(d=damage)
def test_damaged_database_converts_or_fails_cleanly(tmp_path: Path, pristine: bytes,
                                                    d: tuple[list[tuple[float, int, int]], float | None]) -> None:
    work = tmp_path / "w"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    db = work / "map.db"
    db.write_bytes(_mutate(pristine, *d))
    converts_or_fails_cleanly(db, "converted")


def test_schema_damaged_into_invalid_utf8_fails_cleanly(tmp_path: Path, pristine: bytes) -> None:
    """Found by the fuzz test above: a damaged index name in the schema makes even SQLite's error
    message invalid UTF-8 (``malformed database schema (IDX_Node_i\\xe4)``); still one error line."""
    at = pristine.find(b"IDX_Node_")
    assert at > 0, "the writer's database has no Node index; pick another name to damage"
    db = tmp_path / "map.db"
    db.write_bytes(pristine[:at + 10] + b"\xe4" + pristine[at + 11:])
    converts_or_fails_cleanly(db, "converted")
