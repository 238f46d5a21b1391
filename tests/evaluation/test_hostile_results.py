"""``psg-eval compare`` on crafted results folders (docs/SECURITY.md): texts that would be live LaTeX,
Markdown, HTML or terminal escape sequences come out as literal text in every format; ``digits`` and
huge integers are one error line; a FIFO named results.json is refused without waiting on it."""

from __future__ import annotations

import json
import math
import os
import re
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from psg_data.cli.psg_eval_cmd import main
from psg_data.evaluation import EvalResults, MetricInfo, ResultRow, ResultTable, Summary, save_results
from psg_data.evaluation._tables import format_as
from tests.contract import assert_one_error

EVIL_METHOD = "a|b *x* _y_ `c` <img src=x onerror=alert(1)> [l](http://e) \x1b[31mRED\x1b[0m \\input{/etc/hostname}\nz"
EVIL_NOTE = "MAE: fine\n\\input{/etc/hostname}\x1b]0;title\x07"


def _results(method: str = "mine", note: str = "±: what it is", title: str = "A table") -> EvalResults:
    m = [MetricInfo("mae", "MAE", "lower", "mean error")]
    s = Summary(0.2, 0.01, 0.15, 0.25, 21, "bootstrap", "objects")
    rows = [ResultRow(method, "method", {"mae": s}, counts={"edges": 56}),
            ResultRow("ceil", "ceiling", {"mae": Summary(0.1, 0.0, math.nan, math.nan, 1, "none", "objects")})]
    t = ResultTable("persistence", title, m, rows, [note, "±: what it is"], count_columns=["edges"])
    return EvalResults("persistence", [t], config={"setting_text": "adaptive\x1b[2J"})


def _folder(tmp_path: Path, name: str, change: Callable[[dict[str, Any]], None] | None = None,
            res: EvalResults | None = None) -> Path:
    out = tmp_path / name
    save_results(res or _results(), out)
    if change is not None:
        d = json.loads((out / "results.json").read_text())
        change(d)
        (out / "results.json").write_text(json.dumps(d))
    return out


def _compare(*args: str) -> Any:
    return CliRunner().invoke(main, ["compare", *args])


def test_texts_of_a_results_file_are_never_live_in_any_format(tmp_path: Path) -> None:
    run = _folder(tmp_path, "run", res=_results(EVIL_METHOD, EVIL_NOTE, "T\x1b]0;pwned\x07"))
    for fmt in ("text", "markdown", "latex"):
        r = _compare(str(run), "--format", fmt)
        assert r.exit_code == 0, r.output
        assert "\x1b" not in r.stdout and "\x07" not in r.stdout, fmt  # no terminal escape sequence
        assert "x1b" in r.stdout, fmt  # shown (LaTeX: \\textbackslash{}x1b), not dropped
    md = _compare(str(run), "--format", "markdown").stdout
    row = next(ln for ln in md.splitlines() if "RED" in ln)
    cells = re.split(r"(?<!\\)\|", row.strip().strip("|"))
    assert len(cells) == len(re.split(r"(?<!\\)\|", md.splitlines()[2].strip().strip("|")))  # no cell injected
    assert "<img" not in md and "&lt;img" in md and "\\*x\\*" in md and "\\`c\\`" in md and "[l]\\(http" in md
    tex = format_as(_results(EVIL_METHOD, EVIL_NOTE).tables, "latex")
    for line in tex.splitlines():
        if not line.startswith("%"):  # outside comments every backslash starts one of the renderer's commands
            assert "\\input" not in line, line
    assert "\\textbackslash{}input\\{/etc/hostname\\}" in tex
    assert not any(ln.startswith("\\input") for ln in tex.splitlines())


@pytest.mark.parametrize("value, said", [(100_000_000, "0..15"), (2**40, "0..15"), (-3, "0..15")])
def test_digits_out_of_range_is_one_error_line(tmp_path: Path, value: int, said: str) -> None:
    run = _folder(tmp_path, "run", lambda d: d["tables"][0]["metrics"][0].__setitem__("digits", value))
    assert_one_error(_compare(str(run)), said)


def test_huge_integers_are_one_error_line(tmp_path: Path) -> None:
    run = _folder(tmp_path, "pct", lambda d: d["tables"][0]["rows"][0].__setitem__("pct_of_ceiling", 10**400))
    assert_one_error(_compare(str(run)), "pct_of_ceiling")
    run = _folder(tmp_path, "n", lambda d: d["tables"][0]["rows"][0]["values"]["mae"].__setitem__("n", 2**70))
    assert_one_error(_compare(str(run)), ".n: expected an integer")
    big = tmp_path / "digits5000"
    big.mkdir()
    text = json.dumps(_results().to_dict()).replace('"task"', '"x": ' + "7" * 5000 + ', "task"', 1)
    (big / "results.json").write_text(text)
    assert_one_error(_compare(str(big)), "not a psg-eval results file")


def test_a_fifo_named_results_json_is_refused_without_waiting(tmp_path: Path) -> None:
    run = tmp_path / "fifo"
    run.mkdir()
    os.mkfifo(run / "results.json")
    done: list[Any] = []
    worker = threading.Thread(target=lambda: done.append(_compare(str(run))), daemon=True)
    worker.start()
    worker.join(60)
    if worker.is_alive():  # unblock the reader the old code left waiting, then fail
        with open(run / "results.json", "wb"):
            pass
        worker.join(10)
        pytest.fail("psg-eval compare waited on a FIFO named results.json")
    assert_one_error(done[0], "not a regular file")
