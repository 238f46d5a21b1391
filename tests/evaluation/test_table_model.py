"""One table model, five formats: the same group header (Static / Dynamic / Absence / Overall) and the
same ± with its meaning in text, CSV, JSON, Markdown and LaTeX.
"""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psg_data.evaluation import load_results
from psg_data.evaluation._navigation_report import navigation_results
from psg_data.evaluation._results import save_results
from psg_data.evaluation._sim_navigation_report import sim_summary
from psg_data.evaluation._tables import format_as, format_compare
from psg_data.navigation import NavigationResult

GROUPS = ("Static presence", "Dynamic presence", "Absence", "Overall")
# per scene: (static successes, dynamic successes, absent correct aborts), 4 queries of each
WINS = {0: ([1, 1, 1, 0], [1, 0, 0, 0], [1, 1, 0, 0]), 1: ([1, 1, 0, 0], [1, 1, 1, 1], [1, 0, 0, 0]),
        2: ([1, 1, 1, 1], [0, 0, 0, 0], [1, 1, 1, 0])}


def _records() -> pd.DataFrame:
    rows = []
    for scene, kinds in WINS.items():
        for cat, wins in zip(("static", "dynamic", "absent"), kinds):
            for w in wins:
                present = cat != "absent"
                rows.append({"method": "m", "seed": scene, "query_id": len(rows), "category": cat, "reachable": True,
                             "success": bool(w) and present, "aborted": not present and bool(w),
                             "path_m": 2.0 if w else 5.0, "shortest_path_m": 2.0 if present else np.nan})
    return pd.DataFrame(rows)


def _results(spread: str):  # type: ignore[no-untyped-def]
    records = _records()
    per_scene, summary = sim_summary(records, ["m"])
    config = {"protocol": "paper-sim-adaptive", "setting": "adaptive", "seeds": [0, 1, 2], "delta": 0.2,
              "env": "navigation-benchmark", "unreachable": "exclude", "labels": "gt", "max_attempts": 2}
    kw = {"spread": spread} if spread != "interval" else {}
    return navigation_results(NavigationResult(records, per_scene, summary, {}, config), **kw), summary


def _all_formats(tmp_path: Path, spread: str) -> dict[str, str]:
    res, _ = _results(spread)
    save_results(res, tmp_path / "run")
    loaded = load_results(tmp_path / "run")  # what compare reads: the ± meaning survives results.json
    out = {fmt: format_as(res.tables[:1], fmt) for fmt in ("text", "markdown", "latex")}
    for fmt in ("csv", "json"):
        out[fmt] = format_compare([("run", loaded)], fmt=fmt)
    out["compare-latex"] = format_compare([("run", loaded)], fmt="latex")
    out["latex"] = re.sub(r"\\textbf\{([^}]*)\}", r"\1", out["latex"])  # the best cells' bold aside
    return out


@pytest.mark.parametrize("spread", ["interval", "std"])
def test_every_format_names_the_column_groups(tmp_path: Path, spread: str) -> None:
    """Static / Dynamic / Absence / Overall above their columns in text, LaTeX, Markdown and JSON."""
    forms = _all_formats(tmp_path, spread)
    for fmt in ("text", "markdown", "latex", "compare-latex"):
        for g in GROUPS:
            assert g in forms[fmt], (fmt, g)
    assert r"\multicolumn{2}{c}{Static presence (12)}" in forms["latex"] and r"\cmidrule(lr){3-4}" in forms["latex"]
    # Markdown has one header row: every grouped column says its group
    header = next(ln for ln in forms["markdown"].splitlines() if ln.startswith("| Method"))
    assert header.count("Dynamic presence (12)") == 2 and "Dynamic presence (12) SR % ↑" in header
    metrics = json.loads(forms["json"])["tables"][0]["metrics"]
    assert {m["key"]: m["group"] for m in metrics}["absent_ar"] == "Absence (12)"


def test_std_spread_is_the_same_number_in_every_format(tmp_path: Path) -> None:
    """The simulation tables' ± is the standard deviation across scenes (the paper's), in every format."""
    forms = _all_formats(tmp_path, "std")
    per_scene_static = [np.mean(WINS[s][0]) for s in WINS]
    std = 100 * float(np.std(per_scene_static, ddof=1))
    static = f"{100 * 9 / 12:.1f} ± {std:.1f}"
    assert static == "75.0 ± 25.0"
    for fmt in ("text", "markdown"):
        assert static in forms[fmt], fmt
        assert "±: standard deviation across the 3 scenes" in forms[fmt], fmt
    assert "75.0 $\\pm$ 25.0" in forms["latex"] and "standard deviation across the 3 scenes" in forms["latex"]
    row = next(csv.DictReader(io.StringIO(forms["csv"])))
    assert float(row["static_sr_pm"]) == pytest.approx(std / 100)
    assert row["pm"] == "standard deviation across query sets"
    values = json.loads(forms["json"])["tables"][0]["rows"][0]["values"]["static_sr"]
    assert values["pm"] == pytest.approx(std / 100)


def test_interval_spread_is_the_half_width_in_every_format(tmp_path: Path) -> None:
    """The other tables' ± stays the 95 % interval's half-width, in every format."""
    forms = _all_formats(tmp_path, "interval")
    res, summary = _results("interval")
    s = res.tables[0].row("m").values["static_sr"]
    cell = f"{100 * s.mean:.1f} ± {100 * (s.ci_high - s.ci_low) / 2:.1f}"
    for fmt in ("text", "markdown"):
        assert cell in forms[fmt], fmt
        assert "±: half-width of the 95 % interval" in forms[fmt], fmt
    assert cell.replace("±", "$\\pm$") in forms["latex"]
    row = next(csv.DictReader(io.StringIO(forms["csv"])))
    assert row["static_sr_pm"] == row["static_sr_half_width"] and row["pm"] == "half-width of the stated interval"


def test_sim_text_table_is_the_models_text_layout() -> None:
    """The simulation protocols print their main table with the one text renderer (group header row,
    ``*`` marks, the ± line), not a layout of their own; the paper's rows follow it.
    """
    from psg_data.evaluation._sim_navigation_report import sim_table_text
    from psg_data.evaluation._tables import format_table

    res, summary = _results("std")
    text = sim_table_text(summary, protocol="paper-sim-adaptive", labels="gt", roles={}, n_scenes=3,
                          table=format_table(res.tables[0]))
    model = format_table(res.tables[0])
    assert text.startswith(model)
    assert "The paper's rows" in text[len(model):]
