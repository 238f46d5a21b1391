"""One versioned results schema for every task: written and read by one module, rendered by one renderer."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from psg_data.errors import EvaluationError
from psg_data.evaluation import (
    EvalResults,
    MetricInfo,
    ResultRow,
    ResultTable,
    Summary,
    format_results,
    load_results,
    results_frame,
    save_results,
)
from tests.contract import files_in, interrupt_partway


def _results() -> EvalResults:
    m = [MetricInfo("mae", "MAE", "lower", "mean error", chance=0.4), MetricInfo("f1", "F1", "higher", "f1")]
    s = lambda v, lo, hi: Summary(v, 0.0, lo, hi, 21, "bootstrap", "objects")  # noqa: E731
    rows = [ResultRow("mine", "method", {"mae": s(0.2, 0.15, 0.25), "f1": s(0.5, 0.4, 0.6)}, "my estimator",
                      counts={"edges": 56}),
            ResultRow("ceil", "ceiling", {"mae": s(0.1, 0.08, 0.12), "f1": s(0.7, 0.6, 0.8)}, "the best", 100.0),
            ResultRow("zero", "chance", {"mae": s(0.4, 0.3, 0.5), "f1": Summary(0.0, 0.0, math.nan, math.nan, 1, "none", "objects")}),
            ResultRow("base", "baseline", {"mae": s(0.25, 0.2, 0.3), "f1": s(0.55, 0.5, 0.6)})]
    t = ResultTable("persistence", "A table", m, rows, ["MAE: ...", "±: what it is"], count_columns=["edges"],
                    primary="f1")
    return EvalResults("persistence", [t], config={"setting_text": "adaptive"}, info={"command": "psg-eval"})


def test_save_and_load_round_trip(tmp_path: Path) -> None:
    res = _results()
    paths = save_results(res, tmp_path)
    data = json.loads(paths["json"].read_text())
    assert data["schema"] == "psg-eval-results" and data["schema_version"] == 1
    back = load_results(tmp_path)
    assert back.to_dict() == res.to_dict()
    assert back.table().row("ceil").pct_of_ceiling == 100.0
    assert math.isnan(back.table().row("zero").values["f1"].ci_low)
    df = results_frame(back)
    assert len(df) == 8 and set(df["role"]) == {"method", "ceiling", "chance", "baseline"}


def test_loader_refuses_unknown_files_with_one_line(tmp_path: Path) -> None:
    (tmp_path / "results.json").write_text(json.dumps({"summary": {}}))
    with pytest.raises(EvaluationError, match="not a psg-eval results file"):
        load_results(tmp_path)
    (tmp_path / "results.json").write_text(json.dumps({"schema": "psg-eval-results", "schema_version": 99}))
    with pytest.raises(EvaluationError, match="schema version 99"):
        load_results(tmp_path)
    (tmp_path / "results.json").write_text("{not json")
    with pytest.raises(EvaluationError, match="not valid JSON"):
        load_results(tmp_path)
    with pytest.raises(EvaluationError, match="missing"):
        load_results(tmp_path / "nowhere")


def test_the_renderer_orders_reference_rows_first_and_marks_the_best_non_ceiling_row() -> None:
    text = format_results(_results())
    lines = text.splitlines()
    order = [next(i for i, ln in enumerate(lines) if ln.startswith(name + " ")) for name in ("ceil", "base", "zero", "mine")]
    assert order == sorted(order)
    mine = next(ln for ln in lines if ln.startswith("mine "))
    assert "0.200 ± 0.050*" in mine and "56" in mine  # best MAE among the non-ceiling rows, half-width of the interval
    ceil = next(ln for ln in lines if ln.startswith("ceil "))
    assert "*" not in ceil and "100 %" in ceil
    zero = next(ln for ln in lines if ln.startswith("zero "))
    assert "0.000 " in zero and "0.000 ±" not in zero  # no interval: the estimate alone
    assert lines[-1] == "±: what it is" and "\x1b" not in text  # plain text, notes under the table


def test_save_results_replaces_each_file_atomically(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import pandas as pd

    save_results(EvalResults("persistence", []), tmp_path)
    before = (tmp_path / "summary.csv").read_bytes()
    interrupt_partway(monkeypatch, pd.DataFrame, "to_csv")  # Ctrl-C while summary.csv is written
    with pytest.raises(KeyboardInterrupt):
        save_results(_results(), tmp_path)
    assert (tmp_path / "summary.csv").read_bytes() == before  # the previous good file, not half a new one
    assert files_in(tmp_path) == ["results.json", "summary.csv", "table.txt"]


def test_write_persistence_results_replaces_each_file_atomically(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    import pandas as pd

    from psg_data.evaluation import write_persistence_results
    from tests.evaluation.test_plots_figures import _result

    res = _result()
    paths = write_persistence_results(res, tmp_path, info={})
    before = {n: p.read_bytes() for n, p in paths.items()}
    interrupt_partway(monkeypatch, pd.DataFrame, "to_csv", only="by_receptacle")
    with pytest.raises(KeyboardInterrupt):
        write_persistence_results(res, tmp_path, info={"run": 2})
    assert paths["by_receptacle"].read_bytes() == before["by_receptacle"]
    assert files_in(tmp_path) == sorted(p.name for p in paths.values())


def _tamper(path: Path, fn) -> None:  # type: ignore[no-untyped-def]
    data = json.loads(path.read_text())
    fn(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize("tamper, message", [
    (lambda d: d.update(tables=["x"]), r"tables\[0\]: expected an object, got str"),
    (lambda d: d.update(tables={"a": 1}), r"tables: expected an array, got dict"),
    (lambda d: d["tables"][0]["rows"][0].update(method=7), r"tables\[0\]\.rows\[0\]\.method: expected a string"),
    (lambda d: d["tables"][0]["rows"][0]["values"]["mae"].update(n=float("inf")),
     r"tables\[0\]\.rows\[0\]\.values\.mae\.n: expected an integer, got float"),
    (lambda d: d["tables"][0]["rows"][0]["values"]["mae"].update(mean="0.2"),
     r"tables\[0\]\.rows\[0\]\.values\.mae\.mean: expected a number or null, got str"),
    (lambda d: d["tables"][0]["metrics"][0].pop("key"), r"tables\[0\]\.metrics\[0\]\.key: missing"),
    (lambda d: d["tables"][0].update(rows=[{"method": "m"}] * 10_001), r"tables\[0\]\.rows: 10001 entries, expected at most 10000"),
    (lambda d: d.pop("task"), r"task: missing"),
])
def test_loader_checks_the_schema_with_one_line(tmp_path: Path, tamper, message: str) -> None:  # type: ignore[no-untyped-def]
    path = save_results(_results(), tmp_path)["json"]
    _tamper(path, tamper)
    with pytest.raises(EvaluationError, match=r"results\.json: malformed results file: " + message) as err:
        load_results(tmp_path)
    assert "\n" not in str(err.value)


def test_loader_refuses_absurd_sizes_before_parsing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from psg_data.evaluation._results import MAX_RESULTS_BYTES

    path = save_results(_results(), tmp_path)["json"]
    parsed: list[int] = []
    loads = json.loads
    monkeypatch.setattr(json, "loads", lambda s, *a, **k: parsed.append(len(s)) or loads(s, *a, **k))
    with path.open("ab") as fh:
        fh.write(b" " * (MAX_RESULTS_BYTES + 1))
    with pytest.raises(EvaluationError, match=r"results\.json: larger than 16777216 bytes"):
        load_results(tmp_path)
    assert parsed == []
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(EvaluationError, match="nested too deeply"):
        load_results(tmp_path)


def test_compare_refuses_a_malformed_results_file_with_one_line(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from psg_data.cli.psg_eval_cmd import main

    save_results(_results(), tmp_path / "run")
    _tamper(tmp_path / "run/results.json", lambda d: d["tables"][0].update(metrics=[3]))
    res = CliRunner().invoke(main, ["compare", str(tmp_path / "run")])
    assert res.exit_code == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "tables[0].metrics[0]: expected an object" in lines[0]
