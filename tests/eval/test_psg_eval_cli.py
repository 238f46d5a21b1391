"""psg-eval end to end on small generated data: table, result files, plots, bad inputs."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_eval_cmd import main
from psg_data.estimators import register_estimator
from psg_data.estimators._simple import LastSeenEstimator
from psg_data.synth import LabConfig, build_lab
from psg_data.writers import sha256_file
from tests.conftest import reseal_checksums

SMALL = LabConfig(seed=5, days=4, train_days=3, frames_per_scan=1, width=40, height=30)


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_lab(tmp_path_factory.mktemp("eval") / "lab", SMALL)


def run(*args: str) -> Any:
    return CliRunner().invoke(main, list(args))


def _assert_png(path: Path) -> None:
    img = cv2.imread(str(path))
    assert img is not None, f"{path} is not a readable image"
    assert img.shape[0] > 100 and img.shape[1] > 100
    assert img.std() > 5, f"{path} looks blank"


def test_persistence_on_dataset_writes_table_files_and_plots(lab: Path, tmp_path: Path) -> None:
    out = tmp_path / "res"
    res = run("--dataset", str(lab), "-e", "last_seen", "-e", "always_present", "--no-references",
              "--seeds", "2", "--out", str(out), "--quiet")
    assert res.exit_code == 0, res.output + str(res.exception)
    assert "Method" in res.stdout and "last_seen" in res.stdout and "always_present" in res.stdout
    assert "MAE" in res.stdout and "B-Acc" in res.stdout and "F1" in res.stdout
    assert "±: " in res.stdout  # the line that says what the interval is
    from psg_data.evaluation import load_results

    data = json.loads((out / "results.json").read_text())
    assert data["schema"] == "psg-eval-results" and data["schema_version"] == 1 and data["task"] == "persistence"
    # neither estimator's fit depends on the seed: each is fitted once, whatever --seeds says
    assert data["config"]["estimator_seeds"] == {"last_seen": [0], "always_present": [0]}
    assert data["info"]["psg_data_version"] and data["info"]["format_version"] == "2.0"
    assert data["info"]["labels"] == "gt" and "dense schedule" in data["info"]["ground_truth"]
    table = load_results(out).table()
    assert {r.method for r in table.rows} == {"last_seen", "always_present"}
    assert all(r.role == "method" for r in table.rows) and table.primary is None  # no ceiling: no % column
    csv = pd.read_csv(out / "results.csv")
    n_edges = data["config"]["n_edges"]
    assert len(csv) == 2 * n_edges
    # always_present predicts 1: its time-integrated MAE equals the absent share of the ground truth
    ap = csv[(csv.estimator == "always_present") & (csv.status == "ok")]
    assert ap["mae"].between(0, 1).all()
    for name in ("belief.png", "bars.png", "horizon.png"):
        _assert_png(out / name)
    for name in ("by_object.csv", "by_receptacle.csv", "by_weekday.csv", "by_horizon.csv", "summary.csv", "table.txt"):
        assert (out / name).stat().st_size > 0
    assert not out.with_name("res.partial").exists()


def test_always_present_mae_matches_independent_computation(lab: Path, tmp_path: Path) -> None:
    from psg_data.cli._eval_inputs import persistence_task_for, resolve_dataset

    out = tmp_path / "res"
    assert run("--dataset", str(lab), "-e", "always_present", "--no-references", "--seeds", "1", "--out", str(out),
               "--quiet", "--no-plots").exit_code == 0
    task = persistence_task_for(resolve_dataset(str(lab), quiet=True), labels="gt", quiet=True)
    assert task.windows is not None and task.windows.hours == ((9.0, 17.0),)
    num = den = 0.0
    for t, y in task.ground_truth.values():  # |1 - y| integrated piecewise linearly inside 9:00-17:00, day by day
        err = 1.0 - y.astype(float)
        for a, b in task.windows.intervals(float(t[0]), float(t[-1])):
            m = (t >= a) & (t <= b)
            tt, ee = t[m], err[m]
            num += float(np.sum((ee[1:] + ee[:-1]) / 2 * np.diff(tt)))
            den += float(tt[-1] - tt[0]) if tt.size > 1 else 0.0
    data = json.loads((out / "results.json").read_text())
    row = next(r for r in data["tables"][0]["rows"] if r["method"] == "always_present")
    assert row["values"]["mae"]["mean"] == pytest.approx(num / den, rel=1e-9)


def test_benchmark_and_compare(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    assert run("--dataset", "persistence-benchmark", "-e", "always_present", "--no-references", "--lab-seeds", "2",
               "--out", str(a), "--quiet", "--no-plots").exit_code == 0
    assert run("--dataset", "persistence-benchmark", "-e", "time_of_week_frequency", "--no-references",
               "--out", str(b), "--quiet", "--no-plots", "--setting", "predictive").exit_code == 0
    data = json.loads((a / "results.json").read_text())
    assert data["config"]["draws"] == [0, 1] and data["info"]["lab_seeds"] == [0, 1]
    # the benchmark keeps the paper's protocol: plain trapezoid, no horizon; two draws: a t-interval
    assert data["config"]["weighting"] == "reference" and data["config"]["horizon"] == 0.0
    assert data["interval"]["method"] == "t" and data["interval"]["unit"] == "lab draws"
    res = run("compare", str(a), str(b))
    assert res.exit_code == 0
    lines = res.stdout.splitlines()
    assert any(ln.startswith("a ") and "always_present" in ln and "adaptive" in ln for ln in lines)
    assert any(ln.startswith("b ") and "time_of_week_frequency" in ln and "predictive" in ln for ln in lines)


def test_unknown_estimator_lists_valid_names(tmp_path: Path) -> None:
    res = run("--dataset", "persistence-benchmark", "-e", "perpetua_starr", "--out", str(tmp_path / "x"))
    assert res.exit_code == 1
    assert "unknown estimator 'perpetua_starr'" in res.stderr and "perpetua_star" in res.stderr
    assert "Traceback" not in res.output
    assert not (tmp_path / "x").exists()


def test_list_estimators() -> None:
    res = run("--list-estimators")
    assert res.exit_code == 0
    names = res.stdout.split()
    assert {"perpetua_star", "perpetua", "fremen", "persistence_filter", "last_seen"} <= set(names)


def test_dataset_without_labels_says_which_label_command(lab: Path, tmp_path: Path) -> None:
    res = run("--dataset", str(lab), "--labels", "privileged", "-e", "last_seen", "--no-references",
              "--out", str(tmp_path / "x"))
    assert res.exit_code == 1
    assert f"run `psg-data label {lab} --source privileged` first" in res.stderr


def test_empty_test_split(lab: Path, tmp_path: Path) -> None:
    import shutil

    root = tmp_path / "lab"
    shutil.copytree(lab, root)
    p = root / "tables/scans.parquet"
    t = pq.read_table(p)
    t = t.set_column(t.column_names.index("split"), t.schema.field("split"), pa.array(["train"] * t.num_rows))
    pq.write_table(t, p)
    reseal_checksums(root)
    res = run("--dataset", str(root), "-e", "last_seen", "--no-references", "--out", str(tmp_path / "x"))
    assert res.exit_code == 1
    assert "test split is empty" in res.stderr


class _NaNOnOneEdge(LastSeenEstimator):
    """A broken plugin: NaN beliefs on the first edge it is asked about."""

    def make_filter(self, edge: Any) -> Any:
        f = super().make_filter(edge)
        if edge == ("keys", "hallway_hook"):
            inner = f.predict
            f.predict = lambda t: np.where(np.asarray(t) > -1, np.nan, inner(t))  # type: ignore[method-assign]
        return f


def test_plugin_returning_nan_is_reported_and_others_scored(tmp_path: Path) -> None:
    register_estimator("nan_plugin_for_test", _NaNOnOneEdge, overwrite=True)
    out = tmp_path / "res"
    res = run("--dataset", "persistence-benchmark", "-e", "nan_plugin_for_test", "-e", "always_present",
              "--no-references", "--seeds", "1", "--out", str(out), "--no-plots", "--quiet")
    assert res.exit_code == 1
    assert "estimator 'nan_plugin_for_test' seed 0 edge ('keys', 'hallway_hook'): prediction is NaN" in res.stderr
    assert "at t_s=" in res.stderr
    data = json.loads((out / "results.json").read_text())
    assert data["ok"] is False and len(data["errors"]) == 1
    csv = pd.read_csv(out / "results.csv")
    assert (csv[csv.estimator == "always_present"].status == "ok").all()
    plugin = csv[csv.estimator == "nan_plugin_for_test"]
    assert (plugin.status == "error").sum() == 1 and (plugin.status == "ok").sum() == len(plugin) - 1


def test_existing_output_needs_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "res"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    res = run("--dataset", "persistence-benchmark", "-e", "always_present", "--no-references", "--out", str(out))
    assert res.exit_code == 1 and "output exists; pass --overwrite" in res.stderr
    assert (out / "keep.txt").read_text() == "mine"


def test_navigation_task(lab: Path, tmp_path: Path) -> None:
    from psg_data.evaluation import load_results

    out = tmp_path / "nav"
    res = run("--task", "navigation", "--dataset", str(lab), "-e", "last_seen", "--seeds", "1",
              "--queries", "12", "--out", str(out), "--quiet")
    assert res.exit_code == 0, res.output + str(res.exception)
    assert "Static presence" in res.stdout and "oracle" in res.stdout and "±: " in res.stdout
    table = load_results(out).table()
    roles = {r.method: r.role for r in table.rows}
    assert roles["oracle"] == "ceiling" and roles["process_oracle"] == "ceiling"
    assert roles["last_seen_map"] == "baseline" and roles["random_receptacle"] == "chance"
    assert roles["last_seen"] == "method" and {"perpetua", "fremen"} <= set(roles)
    assert table.row("oracle").values["overall_sr"].mean == pytest.approx(1.0)
    maps = sorted(p.name for p in out.glob("map_*.png"))
    assert "map_oracle.png" in maps and "map_last_seen.png" in maps
    _assert_png(out / "map_oracle.png")
    out2 = tmp_path / "nav_reachable"
    res = run("--task", "navigation", "--dataset", str(lab), "-e", "last_seen", "--no-references", "--seeds", "1",
              "--queries", "12", "--reachable-only", "--delta", "0.1", "--out", str(out2), "--quiet")
    assert res.exit_code == 0, res.output + str(res.exception)
    data2 = load_results(out2)
    assert data2.info["reachable_only"] is True and data2.info["delta"] == 0.1
    assert [r.method for r in data2.table().rows] == ["last_seen"]  # --no-references: only the -e rows
    assert data2.table().row("last_seen").counts["queries"] == 12
    cmp = run("compare", str(out), str(out2))
    assert cmp.exit_code == 0 and "[navigation]" in cmp.output and "[persistence]" not in cmp.output
    assert sum(" oracle " in l and "100.0" in l for l in cmp.output.splitlines()) == 1
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "results.json").write_text(json.dumps({"info": {"task": "mapping"}, "summary": []}))
    res = run("compare", str(bad))
    assert res.exit_code == 1 and "not a psg-eval results file" in res.stderr


def test_navigation_delta_sweep(lab: Path, tmp_path: Path) -> None:
    from psg_data.evaluation import load_results

    out = tmp_path / "sweep"
    res = run("--task", "navigation", "--dataset", str(lab), "-e", "last_seen", "--no-references", "--seeds", "1",
              "--queries", "15", "--delta", "0.05,0.5,0.99", "--out", str(out), "--quiet")
    assert res.exit_code == 0, res.output + str(res.exception)
    sweep = load_results(out).table("delta_sweep")
    assert [r.counts["delta"] for r in sweep.rows] == ["0.05", "0.5", "0.99"]
    # last_seen beliefs are 0 or 1: a delta of 0.99 changes nothing, the main table is the first delta
    ar = [r.values["absent_ar"].mean for r in sweep.rows]
    assert ar[0] == ar[1] == ar[2]
    _assert_png(out / "delta_sweep.png")
    assert run("--task", "persistence", "--delta", "0.1,0.2", "--out", str(tmp_path / "x")).exit_code == 1


def test_dataset_files_untouched_by_eval(lab: Path, tmp_path: Path) -> None:
    before = sha256_file(lab / "tables/files.parquet")
    assert run("--dataset", str(lab), "-e", "last_seen", "--no-references", "--seeds", "1", "--out",
               str(tmp_path / "r"), "--quiet", "--no-plots").exit_code == 0
    assert sha256_file(lab / "tables/files.parquet") == before


def test_doors_task_table_files_and_figure(lab: Path, tmp_path: Path) -> None:
    out = tmp_path / "doors"
    res = run("--task", "doors", "--dataset", str(lab), "-e", "perpetua_star", "--no-references", "--seeds", "2",
              "--queries", "60", "--out", str(out), "--quiet")
    assert res.exit_code == 0, res.output + str(res.exception)
    summary = pd.read_csv(out / "results.csv").set_index("estimator")
    assert set(summary.index) == {"all_open", "oracle", "perpetua_star", "perpetua_star (expected cost)"}
    assert (summary["queries"] == 120).all()
    assert summary.loc["oracle", "blocked_first_plans"] == 0 and summary.loc["oracle", "wasted_m"] == 0.0
    assert summary.loc["all_open", "declined"] == 0
    per_seed = pd.read_csv(out / "by_seed.csv")
    # the summary is the mean of the per-seed rows (an independent recomputation)
    m = per_seed.groupby("estimator").blocked_rate.mean()
    np.testing.assert_allclose(summary.loc[m.index, "blocked_rate"], m)
    rec = pd.read_csv(out / "records.csv")
    assert len(rec) == 4 * 120 and rec["p_open:door_ab"].between(0, 1).all()
    info = json.loads((out / "results.json").read_text())["info"]
    assert info["task"] == "doors" and info["seeds"] == [0, 1] and info["labels"] == "gt"
    _assert_png(out / "door_plan_perpetua_star.png")
    assert "perpetua_star" in res.output and "blocked %" in res.output
    assert res.output.index("headroom") < res.output.index("perpetua_star (expected cost)")  # headroom first
    assert (out / "objects" / "summary.csv").is_file()
    cmp = run("compare", str(out))
    assert cmp.exit_code == 0 and "[doors]" in cmp.output
    line = next(l for l in cmp.output.splitlines() if " perpetua_star " in l)
    assert f"{100 * summary.loc['perpetua_star', 'blocked_rate']:.1f}" in line


def test_doors_task_rejects_other_inputs(tmp_path: Path) -> None:
    res = run("--task", "doors", "--dataset", "door-loop", "--out", str(tmp_path / "x"), "--quiet")
    assert res.exit_code == 1 and "unit-test world" in res.stderr and "Traceback" not in res.output
    res = run("--task", "doors", "--dataset", "persistence-benchmark", "--out", str(tmp_path / "y"), "--quiet")
    assert res.exit_code == 1 and "needs a dataset" in res.stderr
    res = run("--task", "doors", "--labels", "psychic", "--out", str(tmp_path / "z"), "--quiet")
    assert res.exit_code == 2 and "psychic" in res.stderr  # a malformed label source is a usage error
    assert not any((tmp_path / d).exists() for d in "xyz")
