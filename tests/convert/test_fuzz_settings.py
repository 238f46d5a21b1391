"""Arbitrary values for every convert and synth option and config key (issue 28).

Whatever the value (floats incl. NaN, infinities and subnormals, huge integers, strings, lists,
mappings), the command either exits 0 with a dataset ``validate`` accepts, or exits 1 (2 for a
command-line value click cannot parse) with one ``error:`` line and nothing left beside the
output. Small data and a bounded number of examples keep this within seconds per property.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.convert import CONVERT_SETTINGS
from psg_data.schemas.validate import validate_dataset
from tests.convert.conftest import CAMERA
from tests.convert.test_folders import make_tum

FLOATS = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)
HUGE = st.integers(min_value=-(10**40), max_value=10**40)
TEXT = st.text(min_size=0, max_size=12)
SCALARS = st.one_of(FLOATS, HUGE, st.integers(-3, 40), TEXT, st.booleans(), st.none(),
                    st.sampled_from([1e-300, 5e-324, 1e308, 2**63, 2**62, "gap:1", "slot:0.5", "every:2",
                                     "motion:0.1,5", "tf:map->cam", "UTC", "tar", "png", "full"]))
VALUES = st.one_of(SCALARS, st.lists(SCALARS, max_size=5),
                   st.dictionaries(st.sampled_from(["parent", "child", "translation", "rotation_xyzw"]), SCALARS,
                                   max_size=4))
FUZZ = settings(max_examples=30, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.fixture(scope="module")
def tum(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("in") / "fr1"
    make_tum(d, n=2)
    (d / "intrinsics.txt").write_text(f"{CAMERA.fx} {CAMERA.fy} {CAMERA.cx} {CAMERA.cy}\n")
    return d


def _check_outcome(r: Any, out: Path, allowed_errors: tuple[int, ...] = (1,)) -> None:
    assert "Traceback" not in r.output, r.output
    if r.exit_code == 0:
        assert validate_dataset(out) == []
    else:
        assert r.exit_code in allowed_errors, (r.exit_code, r.output, r.exception)
        assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
        left = [p.name for p in out.parent.iterdir() if p.name.startswith((out.name, f".{out.name}"))]
        assert left == [], left


def _encodable(value: Any) -> bool:
    try:
        json.dumps(value, allow_nan=True)
    except (TypeError, ValueError, OverflowError):
        return False
    return True


@FUZZ
@given(key=st.sampled_from(sorted(CONVERT_SETTINGS)), value=VALUES)
def test_any_config_value(tum: Path, key: str, value: Any) -> None:
    if not _encodable(value):
        return
    work = Path(tempfile.mkdtemp(dir=tum.parent.parent))
    try:
        cfg = work / "c.json"
        cfg.write_text(json.dumps({key: value}, allow_nan=True))
        out = work / "out"
        r = CliRunner().invoke(psg_data, ["convert", str(tum), str(out), "--config", str(cfg), "--quiet"])
        _check_outcome(r, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)


CONVERT_FLAGS = ["--sync-tolerance", "--depth-scale", "--split", "--keyframes", "--poses", "--camera-frame",
                 "--color-topic", "--side-dir", "--color-encoding", "--input-format", "--image-layout",
                 "--image-check"]


def _as_text(v: Any) -> str:
    return repr(v) if isinstance(v, float) and not math.isfinite(v) else str(v)


@FUZZ
@given(flag=st.sampled_from(CONVERT_FLAGS), value=SCALARS.map(_as_text))
def test_any_convert_option(tum: Path, flag: str, value: str) -> None:
    if "\0" in value:
        return
    work = Path(tempfile.mkdtemp(dir=tum.parent.parent))
    try:
        out = work / "out"
        r = CliRunner().invoke(psg_data, ["convert", str(tum), str(out), flag, value, "--quiet"])
        _check_outcome(r, out, allowed_errors=(1, 2))
    finally:
        shutil.rmtree(work, ignore_errors=True)


SYNTH_VALUES = st.one_of(st.integers(-(10**30), 0), st.integers(367, 10**30), st.integers(1, 2), FLOATS, TEXT,
                         st.sampled_from(["8x8", "9x8", "100000x100000", "20000x20000", "0x0", "long-weekend",
                                          "continuous-v1", "nan", "inf", "1e-320"]))


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(flag=st.sampled_from(["--seed", "--days", "--frames-per-scan", "--resolution", "--routine-strength",
                             "--shift", "--generator"]), value=SYNTH_VALUES.map(_as_text))
def test_any_synth_option(flag: str, value: str) -> None:
    if "\0" in value:
        return
    work = Path(tempfile.mkdtemp())
    try:
        out = work / "lab"
        base = {"--days": "1", "--frames-per-scan": "1", "--resolution": "8x8"}
        base[flag] = value
        args = [a for kv in base.items() for a in kv]
        r = CliRunner().invoke(psg_data, ["synth", str(out), *args, "--quiet"])
        _check_outcome(r, out, allowed_errors=(1, 2))
    finally:
        shutil.rmtree(work, ignore_errors=True)
