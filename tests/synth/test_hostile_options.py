"""``synth`` options a user can type (issue 28): memory refused before allocating (D7), every
setting declared, the output named on a full disk, and a help text that says what --overwrite does."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest
from click.testing import CliRunner

from psg_data.cli._synth_cmd import synth_cmd
from psg_data.errors import PsgDataError
from psg_data.synth import LabConfig
from psg_data.synth._model import check_memory, memory_needed
from tests.contract import assert_one_error

SMALL = ["--days", "1", "--frames-per-scan", "1", "--resolution", "32x24", "--quiet"]


@pytest.mark.parametrize(("res", "match"), [
    ("100000x100000", "width: expected an integer in [8, 65535], got 100000"),
    ("20000x20000", "resolution: 20000x20000 needs about"),
])
def test_resolution_beyond_memory_is_refused_before_allocating(tmp_path: Path, res: str, match: str) -> None:
    out = tmp_path / "lab"
    r = CliRunner().invoke(synth_cmd, [str(out), "--days", "1", "--resolution", res])
    line = assert_one_error(r, match)
    assert "GiB" in line or "65535" in line
    assert list(tmp_path.iterdir()) == []


def test_memory_estimate_and_limit() -> None:
    small, big = LabConfig(width=160, height=120), LabConfig(width=1280, height=960)
    assert 300e6 < memory_needed(small) < 400e6 and memory_needed(big) > memory_needed(small) + 400e6
    check_memory(small, available=memory_needed(small))
    with pytest.raises(PsgDataError, match="needs about 0.8 GiB of memory, the machine has 0.5 GiB"):
        check_memory(big, available=2**29)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"seed": -1}, "seed: expected an integer in [0, 9223372036854775807], got -1"),
    ({"routine_strength": float("nan")}, "routine_strength: expected a finite number in [0, 1], got nan"),
    ({"timezone": "Mars/Olympus"}, "timezone: expected an IANA time zone name"),
    ({"days": 10**30}, "days: expected an integer in [1, 366], got 1000000000000000000000000000000"),
])
def test_lab_settings_declared(kwargs: dict, match: str) -> None:
    with pytest.raises(PsgDataError, match=match.replace("[", r"\[").replace("]", r"\]")):
        LabConfig(**kwargs)


def test_cli_seed_out_of_range(tmp_path: Path) -> None:
    assert_one_error(CliRunner().invoke(synth_cmd, [str(tmp_path / "x"), *SMALL, "--seed", "-1"]), "seed: expected")
    assert not (tmp_path / "x").exists()


def test_full_disk_names_the_output(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from psg_data.synth import _build

    def full(*_a: object, **_k: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(_build, "object_description", full)
    out = tmp_path / "lab"
    assert_one_error(CliRunner().invoke(synth_cmd, [str(out), *SMALL]), f"error: {out}: No space left on device")


def test_overwrite_help_says_what_it_replaces() -> None:
    text = CliRunner().invoke(synth_cmd, ["--help"]).output
    assert "psg-dataset psg-data wrote (by synth or convert" in " ".join(text.split())
