"""``psg-data graph`` on crafted input, as an attacker would run it (docs/SECURITY.md): outputs that
never replace a file psg-data did not write or an input (D), saved graphs checked before any filter is
built, bombs refused in bounded memory (E), ``--at`` outside the datetime range (F)."""

from __future__ import annotations

import base64
import copy
import functools
import json
import os
import tracemalloc
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.errors import GraphError
from psg_data.graph import PredictiveGraph
from tests.contract import assert_one_error

AT = "2023-11-16 07:00"
BOMB_MB = 200


@pytest.fixture(scope="module")
def saved(graph_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Graphs of three estimators saved by psg-data (each filter state a different shape)."""
    d = tmp_path_factory.mktemp("saved")
    return {name: PredictiveGraph.from_dataset(graph_dataset, name).save(d / f"{name}.json")
            for name in ("fremen", "perpetua", "time_of_week_frequency")}


def _graph(*args: str) -> Any:
    return CliRunner().invoke(main, ["graph", *args, "-q"])


# -- D: outputs ---------------------------------------------------------------------------------------
def test_outputs_never_replace_inputs_or_foreign_files(graph_dataset: Path, saved: dict[str, Path],
                                                       tmp_path: Path) -> None:
    manifest = graph_dataset / "dataset.json"
    before = manifest.read_bytes()
    g = tmp_path / "g.json"
    g.write_bytes(saved["fremen"].read_bytes())
    mine = tmp_path / "notes.csv"
    mine.write_text("my own notes\n")
    cases = [  # (PATH, extra options, what the error line says, exit code)
        (str(graph_dataset), ["-e", "fremen", "--csv", str(manifest)], "lies inside the input", 1),
        (str(graph_dataset), ["-e", "fremen", "--png", str(graph_dataset / "tables" / "x.png")], "inside the input", 1),
        (str(g), ["--csv", str(g)], "is the input", 1),
        (str(g), ["--csv", str(g), "--overwrite"], "is the input", 1),
        (str(g), ["--csv", str(mine)], "pass --overwrite", 1),
        (str(g), ["--csv", str(mine), "--overwrite"], "is not a table written by psg-data graph --csv", 1),
        (str(g), ["--png", str(mine), "--overwrite"], "ending in .png", 2),
        (str(g), ["--save-graph", str(tmp_path / "again.json")], "is a saved graph already", 2),
    ]
    for path, extra, said, code in cases:
        assert_one_error(_graph(path, "--at", AT, *extra), said, code=code)
    assert manifest.read_bytes() == before and mine.read_text() == "my own notes\n"
    assert g.read_bytes() == saved["fremen"].read_bytes()
    assert_one_error(_graph(str(g), "--at", AT, "--png", str(tmp_path / "x.json")), "ending in .png", code=2)
    out = tmp_path / "t.csv"
    assert _graph(str(g), "--at", AT, "--csv", str(out)).exit_code == 0
    assert_one_error(_graph(str(g), "--at", AT, "--csv", str(out)), "pass --overwrite")
    r = _graph(str(g), "--at", AT, "--csv", str(out), "--overwrite")  # its own output: replaced
    assert r.exit_code == 0, r.output
    assert not list(tmp_path.glob(".*psg-tmp*"))


# -- E: saved graphs -----------------------------------------------------------------------------------
def _edit(path: Path, out: Path, change: Callable[[dict[str, Any]], None]) -> Path:
    d = json.loads(path.read_text())
    change(d)
    out.write_text(json.dumps(d))
    return out


def _set(where: str, key: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def change(d: dict[str, Any]) -> None:
        node: Any = d
        for part in filter(None, where.split(".")):
            node = node[int(part)] if isinstance(node, list) else node[part]
        node[key] = value
    return change


@functools.cache
def _packed_zeros(n: int) -> str:
    return base64.b64encode(zlib.compress(b"\0" * n, 9)).decode()


def _bomb_grid(shape: list[int], masks: int = 0) -> Callable[[dict[str, Any]], None]:
    """A grid whose masks inflate to 64 MB each (``masks`` = 0: one mask) or ``masks`` masks of its full size."""
    def change(d: dict[str, Any]) -> None:
        full = _packed_zeros(shape[0] * shape[1] // 8) if masks else _packed_zeros(64 << 20)
        d["grid"]["arrays"] = {"shape": shape, "origin_m": [0.0, 0.0], "resolution_m": 0.05, "robot_radius_m": 0.25,
                               "source": "geometry", "static_obstacle": full,
                               "door_cells": {f"d{k}": full for k in range(masks)}, "receptacle_cells": {}}
    return change


HOSTILE_GRAPHS: dict[str, tuple[str, Callable[[dict[str, Any]], None], str]] = {
    "fremen k 1e300": ("fremen", _set("filters.0.components", "k", [1e300]), "components.k[0]"),
    "fremen base period 0": ("fremen", _set("filters.0.components", "base_period_s", 0), "base_period_s"),
    "bad time zone": ("fremen", _set("filters.0.clock", "timezone", "Mars/Olympus"), "clock.timezone"),
    "zone path": ("fremen", _set("layout", "timezone", "../../../etc/passwd"), "layout.timezone"),
    "num_steps 1e9": ("perpetua", _set("filters.0", "num_steps", 10**9), "num_steps"),
    "bin_s 0": ("time_of_week_frequency", _set("filters.0", "bin_s", 0), "bin_s"),
    "bin_s NaN": ("time_of_week_frequency", _set("filters.0", "bin_s", float("nan")), "bin_s"),
    "empty table": ("time_of_week_frequency", _set("filters.0", "table", []), "table"),
    "edges without filters": ("fremen", lambda d: d["filters"].pop(), "one per edge"),
    "grid bomb": ("fremen", _bomb_grid([100, 100]), "inflates to more than"),
    "huge grid": ("fremen", _bomb_grid([1 << 20, 1 << 20]), "cells, expected at most"),
    "many masks": ("fremen", _bomb_grid([4096, 4096], masks=64), "cells in all"),
    "prior door out of range": ("fremen", lambda d: d["doors"].__setitem__("door1", {"kind": "prior", "value": 7}),
                                "doors.door1.value"),
}


@pytest.mark.parametrize("case", list(HOSTILE_GRAPHS))
def test_hostile_saved_graph_is_one_error_line_in_bounded_memory(case: str, saved: dict[str, Path],
                                                                 tmp_path: Path) -> None:
    name, change, said = HOSTILE_GRAPHS[case]
    path = _edit(saved[name], tmp_path / "evil.json", change)
    tracemalloc.start()
    try:
        r = _graph(str(path), "--at", AT)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    line = assert_one_error(r, said)
    assert "malformed predictive graph" in line
    assert peak < BOMB_MB << 20, f"{case}: peak {peak / 2**20:.0f} MB"


def test_deep_nesting_and_non_regular_files(saved: dict[str, Path], tmp_path: Path) -> None:
    deep = tmp_path / "deep.json"
    deep.write_text('{"format": "psg-predictive-graph", "version": 1, "info": ' + "[" * 100_000 + "]" * 100_000 + "}")
    assert_one_error(_graph(str(deep), "--at", AT), "nested too deeply")
    nested = _edit(saved["fremen"], tmp_path / "nested.json", _set("", "info", json.loads("[" * 60 + "]" * 60)))
    assert_one_error(_graph(str(nested), "--at", AT), "nested more than")
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)  # a FIFO is not waited on (a hang would fail the run)
    with pytest.raises(GraphError, match="not a regular file"):
        PredictiveGraph.load(fifo)


def test_a_saved_grid_round_trips(graph_dataset: Path, tmp_path: Path) -> None:
    """The bounded inflation reads the grids psg-data writes (a graph saved after planning holds its grid)."""
    g = PredictiveGraph.from_dataset(graph_dataset, "fremen")
    t = 1_700_118_000.0
    p = g.plan((1.5, 1.5), "book", t)
    path = g.save(tmp_path / "g.json")
    assert "arrays" in json.loads(path.read_text())["grid"]
    h = PredictiveGraph.load(path)
    q = h.plan((1.5, 1.5), "book", t)
    assert (h.grid.static_obstacle == g.grid.static_obstacle).all() and q.path_m == p.path_m


# -- F: --at ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("at", ["9999-12-31 23:59", "0001-01-01 00:00", "1e20", "100000000000000000000",
                                "-1e300", "9" * 5000])
def test_at_outside_the_datetime_range_is_one_error_line(at: str, saved: dict[str, Path]) -> None:
    assert_one_error(_graph(str(saved["fremen"]), "--at", at), "time ")


def test_at_inside_the_range_still_works(saved: dict[str, Path]) -> None:
    for at in ("9999-12-29 00:00", "0001-01-03 00:00", "1700118000", "2023-11-16T07:00Z"):
        r = _graph(str(saved["fremen"]), "--at", at)
        assert r.exit_code == 0, (at, r.output)
    snap = copy.deepcopy(PredictiveGraph.load(saved["fremen"]).at(1700118000.0))
    assert snap.t_s == 1700118000.0
