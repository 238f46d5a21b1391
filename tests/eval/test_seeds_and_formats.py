"""Chosen seeds (``--seeds`` / ``--lab-seeds`` as a count, a list or a range), the noise draw of
``noisy:P`` (``--label-seed``, recorded in results.json), and tables for a paper: ``psg-eval
--format markdown|latex`` and ``psg-eval compare --no-references --metric --format``."""

from __future__ import annotations

import csv
import io
import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from psg_data.cli._seeds import parse_seeds
from psg_data.cli.psg_eval_cmd import main
from psg_data.synth import LabConfig, build_lab
from tests.contract import assert_one_error

SMALL = LabConfig(seed=5, days=4, train_days=3, frames_per_scan=1, width=40, height=30)


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_lab(tmp_path_factory.mktemp("seeds") / "lab", SMALL)


@pytest.fixture(scope="module")
def full_run(lab: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One run with every reference row (ceiling, baselines, chance) and the paper's methods."""
    out = tmp_path_factory.mktemp("full") / "res"
    r = run("--dataset", str(lab), "-e", "last_seen", "--seeds", "1", "--out", str(out), "--no-plots", "-q")
    assert r.exit_code == 0, r.output
    return out


def run(*args: str) -> Any:
    return CliRunner().invoke(main, list(args))


def test_parse_seeds() -> None:
    assert parse_seeds("3") == (0, 1, 2)
    assert parse_seeds("0,3,5") == (0, 3, 5) and parse_seeds("3-7") == (3, 4, 5, 6, 7)
    assert parse_seeds("3-3") == (3,) and parse_seeds(" 0, 10-12 ") == (0, 10, 11, 12)
    for bad in ("0", "x", "3-1", "1,1", "-1", "0-200", "", "1,,2", "2.5"):
        with pytest.raises(ValueError):
            parse_seeds(bad)


@pytest.mark.parametrize("option", ["--seeds", "--lab-seeds"])
def test_bad_seeds_are_a_usage_error(option: str, tmp_path: Path) -> None:
    line = assert_one_error(run(option, "5-2", "--out", str(tmp_path / "o")), code=2)
    assert option in line and "the end is below the start" in line


def test_lab_seeds_picks_the_draws(tmp_path: Path) -> None:
    out = tmp_path / "a"
    r = run("--dataset", "persistence-benchmark", "-e", "always_present", "--no-references", "--lab-seeds", "3,5",
            "--out", str(out), "--no-plots", "-q")
    assert r.exit_code == 0, r.output
    data = json.loads((out / "results.json").read_text())
    assert data["config"]["draws"] == [3, 5] and data["info"]["lab_seeds"] == [3, 5]
    assert data["interval"]["method"] == "t" and data["interval"]["n"] == 2


def test_seeds_list_picks_the_estimator_seeds(lab: Path, tmp_path: Path) -> None:
    out = tmp_path / "a"
    r = run("--dataset", str(lab), "-e", "persistence_filter", "-e", "perpetua:max_components=1", "--no-references",
            "--seeds", "4-5", "--out", str(out), "--no-plots", "-q")
    assert r.exit_code == 0, r.output
    seeds = json.loads((out / "results.json").read_text())["config"]["estimator_seeds"]
    assert seeds["perpetua:max_components=1"] == [4, 5] and seeds["persistence_filter"] == [4]


def _noisy(lab: Path, out: Path, *extra: str) -> dict[str, Any]:
    r = run("--dataset", str(lab), "-e", "last_seen", "--no-references", "--labels", "noisy:0.3", "--out", str(out),
            "--no-plots", "-q", *extra)
    assert r.exit_code == 0, r.output
    return json.loads((out / "results.json").read_text())


def test_noise_draw_is_recorded_and_settable(lab: Path, tmp_path: Path) -> None:
    default, four, again = (_noisy(lab, tmp_path / "d"), _noisy(lab, tmp_path / "k4", "--label-seed", "4"),
                            _noisy(lab, tmp_path / "k4b", "--label-seed", "4"))
    assert default["config"]["label_seed"] == 0 and default["info"]["label_seed"] == 0
    assert four["config"]["label_seed"] == 4 and four["info"]["label_seed"] == 4
    mae = [d["tables"][0]["rows"][0]["values"]["mae"]["mean"] for d in (default, four, again)]
    assert mae[1] == mae[2] and mae[0] != mae[1]  # another draw of the flips, the same draw reproduced


def test_format_markdown_prints_a_pipe_table_with_marks(full_run: Path, lab: Path, tmp_path: Path) -> None:
    from psg_data.evaluation import load_results

    table = load_results(full_run).table()
    r = run("--dataset", str(lab), "-e", "last_seen", "--seeds", "1", "--out", str(tmp_path / "m"), "--no-plots",
            "-q", "--format", "markdown")
    assert r.exit_code == 0, r.output
    assert r.stdout.startswith("**Persistence estimation") and "results written" not in r.stdout  # pastes as it is
    lines = r.stdout.splitlines()
    header = next(ln for ln in lines if ln.startswith("| Method"))
    assert "| MAE ↓ | B-Acc ↑ | F1 ↑ |" in header and "% of ceiling (B-Acc)" in header
    body = [ln for ln in lines if ln.startswith("| ") and ln is not header]
    assert len(body) == len(table.rows)
    roles = [ln.split(" | ")[1] for ln in body]
    assert roles[0] == "ceiling" and "chance" in roles and roles[-1] == ""  # references first, methods last
    assert sum(ln.count("**") for ln in body) >= 2 * 3  # a best cell in every metric column is bold
    assert any(ln.startswith("- ±: ") for ln in lines)


def _latex(full_run: Path, *extra: str) -> str:
    r = run("compare", str(full_run), "--format", "latex", *extra)
    assert r.exit_code == 0, r.output
    return r.stdout


def test_latex_table_structure_and_compile(full_run: Path, tmp_path: Path) -> None:
    from psg_data.evaluation import load_results
    from psg_data.evaluation._tables import format_as

    res = load_results(full_run)
    tex = format_as(res.tables, "latex")
    lines = tex.splitlines()
    assert "\\usepackage{booktabs}" in lines[0]
    body = lines[lines.index("\\midrule") + 1:lines.index("\\bottomrule")]
    refs = [r for r in res.table().rows if r.role != "method"]
    rule = body.index("\\midrule")
    assert rule == len(refs)  # reference rows, a rule, then the methods
    assert all(ln.endswith(r" \\") and ln.count(" & ") == body[0].count(" & ") for ln in body if ln != "\\midrule")
    assert all("$\\pm$" in ln for ln in body if ln != "\\midrule")
    assert "\\textbf{" in "\n".join(body[rule + 1:] + body[:rule])
    assert body[0].split(" & ")[1] == "ceiling" and "\\_" in tex  # method names escaped
    caption = next(ln for ln in lines if ln.startswith("\\caption{"))
    assert "above the rule" in caption and "bold" in caption and "95 \\%" in caption
    assert "\\begin{tabular}{ll" in tex and "\\toprule" in tex
    compare = _latex(full_run, "--no-references", "--metric", "mae")
    assert "ceiling" not in compare and "B-Acc" not in compare and "MAE" in compare
    _compile_where_tex_is(tex, tmp_path)


def _compile_where_tex_is(tex: str, tmp_path: Path) -> None:
    """pdflatex sets the table where TeX is installed (Debian: texlive-latex-base and, for booktabs,
    texlive-latex-recommended); the structure above is checked everywhere."""
    pdflatex = shutil.which("pdflatex")
    if pdflatex is None:
        return
    (tmp_path / "t.tex").write_text("\\documentclass{article}\n\\usepackage[T1]{fontenc}\n\\usepackage{booktabs}\n"
                                    "\\begin{document}\n" + tex + "\n\\end{document}\n", encoding="utf-8")
    r = subprocess.run([pdflatex, "-interaction=nonstopmode", "-halt-on-error", "t.tex"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout[-3000:]
    assert (tmp_path / "t.pdf").stat().st_size > 1000


def test_compare_formats_and_selection(full_run: Path, lab: Path, tmp_path: Path) -> None:
    other = tmp_path / "b"
    assert run("--dataset", str(lab), "-e", "always_present", "--no-references", "--out", str(other),
               "--no-plots", "-q").exit_code == 0
    r = run("compare", str(full_run), str(other), "--no-references", "--metric", "mae", "--metric", "B-Acc",
            "--format", "csv")
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader(io.StringIO(r.stdout)))
    assert {row["role"] for row in rows} == {"method"}
    assert [(row["run"], row["method"]) for row in rows if row["run"] == "b"] == [("b", "always_present")]
    assert "mae_half_width" in rows[0] and "balanced_accuracy_ci_low" in rows[0] and "f1" not in rows[0]
    from psg_data.evaluation import load_results

    last = load_results(full_run).table().row("fremen").values["mae"]
    got = next(row for row in rows if row["method"] == "fremen")
    assert float(got["mae"]) == pytest.approx(last.mean) and float(got["mae_ci_high"]) == pytest.approx(last.ci_high)
    j = json.loads(run("compare", str(full_run), "--format", "json").stdout)
    assert {row["role"] for row in j["tables"][0]["rows"]} >= {"ceiling", "baseline", "chance", "method"}
    md = run("compare", str(full_run), str(other), "--format", "markdown").stdout
    assert md.startswith("**[persistence] ") and "| run | setting | Method | ref |" in md
    line = assert_one_error(run("compare", str(full_run), "--metric", "nope"), "--metric nope")
    assert "mae (MAE)" in line
    text = run("compare", str(full_run), "--no-references").stdout
    assert "ceiling" not in text and "fremen" in text and "always_absent" not in text
