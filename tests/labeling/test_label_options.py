"""``label`` options a user can type (issue 28): declared, checked before any work, one line.

Arbitrary values for each option end in exit 0 with a dataset validate accepts, or exit 1 (2 when
click cannot parse the text) with one ``error:`` line and the dataset exactly as it was.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.errors import LabelingError
from psg_data.labeling import AssociationParams
from psg_data.schemas.validate import validate_dataset
from tests.conftest import write_tiny_dataset
from tests.contract import assert_one_error, snapshot


@pytest.mark.parametrize(("opts", "match"), [
    (["--margin", "inf"], "--margin (margin_m): expected a finite number in [0, 10], got inf"),
    (["--min-iou", "nan"], "--min-iou (min_iou): expected a finite number in [0, 1], got nan"),
    (["--label-seed", "-1"], "--label-seed (seed): expected an integer in [0, 9223372036854775807], got -1"),
    (["--source", "noisy:nan"], "expected noisy:P or noisy:P_M,P_F"),
])
def test_bad_label_options(tmp_path: Path, opts: list[str], match: str) -> None:
    ds = write_tiny_dataset(tmp_path / "ds", scans=2, frames=2)
    before = snapshot(ds)
    args = ["label", str(ds), "--source", "gt", *opts]
    assert_one_error(CliRunner().invoke(psg_data, args), match)
    assert snapshot(ds) == before


def test_association_params_declared() -> None:
    with pytest.raises(LabelingError, match="below_m: expected a finite number in"):
        AssociationParams(below_m=float("-inf"))


def _as_text(v: Any) -> str:
    return repr(v) if isinstance(v, float) and not math.isfinite(v) else str(v)


VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True),
                   st.integers(-(10**30), 10**30), st.text(max_size=10),
                   st.sampled_from(["noisy:0.1", "noisy:0.1,0.2", "gt", "privileged", "0.5", "1e-320"]))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_tiny_dataset(tmp_path_factory.mktemp("label") / "ds", scans=2, frames=2)


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(flag=st.sampled_from(["--min-iou", "--margin", "--label-seed", "--source"]), value=VALUES.map(_as_text))
def test_any_label_option(tiny: Path, flag: str, value: str) -> None:
    if "\0" in value:
        return
    before = snapshot(tiny)
    opts = {"--source": "gt", flag: value}
    r = CliRunner().invoke(psg_data, ["label", str(tiny), *[a for kv in opts.items() for a in kv], "--overwrite",
                                      "--quiet"])
    assert "Traceback" not in r.output, r.output
    if r.exit_code == 0:
        assert validate_dataset(tiny) == []
    else:
        assert r.exit_code in (1, 2), (r.exit_code, r.output, r.exception)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
        assert snapshot(tiny) == before
