"""The graph command's tables without pandas: the text and CSV equal what pandas prints for the same columns
(pandas is the independent reference: ``DataFrame.to_string(index=False)`` / ``to_csv(index=False)``), and
the command's output equals the pandas rendering of the snapshot it answers from.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from psg_data.cli._graph_cmd import _sorted_edges
from psg_data.cli._text_table import columns_to_csv, columns_to_text, rounded
from psg_data.cli.psg_data_cmd import main
from tests.graph.test_graph_cli import AT

_TEXT = st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=20)
_FLOAT = st.floats(min_value=-1e4, max_value=1e4) | st.sampled_from(
    [0.0, 1.0, 0.5, 0.25, 1e-7, -3e-9, 2.5e6, 1234567.891, 0.1, float("nan")])


@st.composite
def _columns(draw: st.DrawFn) -> dict[str, list[object]]:
    n = draw(st.integers(1, 8))
    cols: dict[str, list[object]] = {}
    for j, kind in enumerate(draw(st.lists(st.sampled_from(["text", "opt_text", "float", "int"]), min_size=1,
                                           max_size=5))):
        name = draw(_TEXT) + f"_{j}"
        if kind == "text":
            cols[name] = draw(st.lists(_TEXT, min_size=n, max_size=n))
        elif kind == "opt_text":
            cols[name] = draw(st.lists(_TEXT | st.none(), min_size=n, max_size=n))
        elif kind == "float":
            cols[name] = draw(st.lists(_FLOAT, min_size=n, max_size=n))
        else:
            cols[name] = draw(st.lists(st.integers(-10**6, 10**6), min_size=n, max_size=n))
    return cols


def _frame(cols: dict[str, list[object]]) -> pd.DataFrame:
    """As the command built its tables: text columns as object arrays, numbers as numpy arrays."""
    return pd.DataFrame({k: (np.asarray(v, dtype=object) if any(isinstance(x, str) or x is None for x in v)
                             else np.asarray(v)) for k, v in cols.items()})


@settings(max_examples=300, deadline=None)
@given(_columns())
def test_text_equals_pandas_to_string(cols: dict[str, list[object]]) -> None:
    """Text, optional text, float (NaN, tiny, large) and int columns print as pandas prints them."""
    assert columns_to_text(cols) == _frame(cols).to_string(index=False)


@settings(max_examples=300, deadline=None)
@given(_columns())
def test_csv_equals_pandas_to_csv(cols: dict[str, list[object]]) -> None:
    """The same columns write the CSV pandas writes (shortest floats, missing cells empty, quoting)."""
    assert columns_to_csv(cols) == _frame(cols).to_csv(index=False, lineterminator="\n")


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-100, 100, allow_nan=False), min_size=1, max_size=10), st.integers(0, 4))
def test_rounded_equals_pandas_round(values: list[float], decimals: int) -> None:
    """Rounding is pandas' (numpy's half-to-even on the scaled value); other columns are left alone."""
    got = rounded({"x": values, "name": ["a"] * len(values)}, {"x": decimals})
    want = pd.DataFrame({"x": values}).round({"x": decimals})["x"].tolist()
    assert got["x"] == want and got["name"] == ["a"] * len(values)


def test_empty_table_as_pandas() -> None:
    """A graph without edges prints pandas' empty-frame text."""
    cols: dict[str, list[object]] = {"object_id": [], "p": []}
    assert columns_to_text(cols) == pd.DataFrame(cols).to_string(index=False)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["a", "b", "c"]), st.sampled_from([0.1, 0.5, 0.9, float("nan")])),
                min_size=1, max_size=12))
def test_edge_order_equals_pandas_sort(rows: list[tuple[str, float]]) -> None:
    """By object, most probable first, ties in their order, NaN last: pandas' stable two-key sort."""
    cols: dict[str, list[Any]] = {"object_id": [r[0] for r in rows], "p": [r[1] for r in rows],
                                  "row": list(range(len(rows)))}
    want = pd.DataFrame(cols).sort_values(["object_id", "p"], ascending=[True, False], kind="stable")
    assert _sorted_edges(cols)["row"] == want["row"].tolist()


@pytest.fixture()
def _own_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PSG_DATA_CACHE", str(tmp_path / "cache"))


@pytest.mark.usefixtures("_own_cache")
def test_command_prints_the_pandas_rendering_of_its_snapshot(graph_dataset: Path) -> None:
    """The whole text and CSV output of ``psg-data graph`` equals the snapshot rendered through pandas."""
    from psg_data.graph import PredictiveGraph

    g = PredictiveGraph.from_dataset(graph_dataset, "fremen", labels="gt")
    snap = g.at(AT)
    table = snap.to_pandas().sort_values(["object_id", "p"], ascending=[True, False], kind="stable")
    text = CliRunner().invoke(main, ["graph", str(graph_dataset), "--at", AT, "-e", "fremen"])
    assert text.exit_code == 0, text.output
    assert table.round({"p": 3, "x_m": 2, "y_m": 2, "z_m": 2}).to_string(index=False) in text.stdout
    doors = snap.doors_to_pandas()
    assert len(doors) > 0 and not any(isinstance(v, float) and math.isnan(v) for v in doors["p_open"])
    doors = doors.assign(between=doors["room_a"].astype(str) + " and " + doors["room_b"].astype(str))
    assert doors[["door_id", "p_open", "between"]].round({"p_open": 3}).to_string(index=False) in text.stdout
    csv = CliRunner().invoke(main, ["graph", str(graph_dataset), "--at", AT, "-e", "fremen", "--format", "csv"])
    assert csv.exit_code == 0 and csv.stdout == table.to_csv(index=False, lineterminator="\n"), csv.output
    obj = str(table["object_id"].iloc[0])
    ranked = CliRunner().invoke(main, ["graph", str(graph_dataset), "--at", AT, "-e", "fremen", "--object", obj])
    want = g.locate(obj, AT).to_pandas().round({"p": 3, "x_m": 2, "y_m": 2, "z_m": 2}).to_string(index=False)
    assert ranked.exit_code == 0 and want in ranked.stdout, ranked.output
