"""results/build.py: RESULTS.md and README blocks rendered from the runs of results/manifest.json (issue 45, point 5).

The quick form runs the manifest's tiny commands for real (psg-data synth, psg-eval) and renders every block of
the documents whose run has a quick form; the rest pins the path language, the block parser, the cache rule and
the atomic, never-clobbering run folders.
"""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("results_build", ROOT / "results" / "build.py")
assert _spec is not None and _spec.loader is not None
build = importlib.util.module_from_spec(_spec)
sys.modules["results_build"] = build
_spec.loader.exec_module(build)


def test_lookup_follows_keys_indices_and_selectors() -> None:
    """A value path: keys, indices, [field=value] selectors (the value may hold "="), half_width derived."""
    doc = {"tables": [{"rows": [{"method": "fremen:max_order=5", "values": {"mae": {"mean": 0.25, "ci_low": 0.1,
                                                                                   "ci_high": 0.5}}},
                                {"method": "fremen", "values": {"mae": {"mean": 0.5}}}]}]}
    assert build.lookup(doc, "tables.0.rows[method=fremen].values.mae.mean") == 0.5
    assert build.lookup(doc, "tables.0.rows[method=fremen:max_order=5].values.mae.mean") == 0.25
    doc["tables"][0]["rows"][1]["method"] = "fremen:gamma=0.99,n=1"  # dots inside a selector's value
    assert build.lookup(doc, "tables.0.rows[method=fremen:gamma=0.99,n=1].values.mae.mean") == 0.5
    rows = {"rows": [{"m": "a", "s": "present", "v": 1}, {"m": "a", "s": "absent", "v": 2},
                     {"m": "b", "s": "absent", "v": 3}]}
    assert build.lookup(rows, "rows[m=a][s=absent].v") == 2 and build.lookup(rows, "rows[s=absent][m=b].v") == 3
    with pytest.raises(build.BuildError, match="found 2"):
        build.lookup(rows, "rows[m=a].v")
    rows["rows"].append({"m": "c [doors known] @ 0.05", "s": "x.y", "v": 4})  # brackets and dots in a value
    assert build.lookup(rows, "rows[m=c [doors known] @ 0.05][s=x.y].v") == 4
    for bad in ("rows[m=a", "rows[m=a]x.v", ".v", "rows[ma].v"):
        with pytest.raises(build.BuildError, match="path"):
            build.lookup(rows, bad)
    assert build.lookup(doc, "tables.0.rows[method=fremen:max_order=5].values.mae.half_width") == pytest.approx(0.2)
    doors = {"rows": [{"method": "fremen [doors known]", "v": 1}, {"method": "fremen", "v": 2}]}
    assert build.lookup(doors, "rows[method=fremen [doors known]].v") == 1  # the doors task's row names
    rows = [{"method": "fremen @ 0.05", "v": 1}, {"method": "fremen [doors known]", "v": 2},
            {"method": "fremen (expected cost)", "v": 3}]
    assert [build.lookup({"rows": rows}, f"rows[method={m}].v") for m in
            ("fremen @ 0.05", "fremen [doors known]", "fremen (expected cost)")] == [1, 2, 3]
    for bad in ("tables.1", "tables.0.rows[method=perpetua].values", "tables.0.rows.values", "nope"):
        with pytest.raises(build.BuildError, match="path"):
            build.lookup(doc, bad)


def test_value_alternatives_render_one_value_each(tmp_path: Path) -> None:
    """``{a|b}`` in a value path: the values of each alternative, joined by ``sep``, each in ``fmt``."""
    r = _renderer(tmp_path, {"rows": [{"m": "x", "v": 0.25}, {"m": "y", "v": 0.5}], "n": 3})
    text = "<!-- results:value r rows[m={x|y}].v fmt=.2f -->?<!-- /results -->"
    assert build.render_text(text, r, "D.md") == text.replace("?", "0.25 / 0.50")
    text = "<!-- results:value r rows[m={y|x}].v scale=100 fmt=.0f sep=, -->?<!-- /results -->"
    assert build.render_text(text, r, "D.md") == text.replace("?", "50,25")
    text = "<!-- results:value r rows[m=x].v scale=-100 offset=100 fmt=.1f -->?<!-- /results -->"
    assert build.render_text(text, r, "D.md") == text.replace("?", "75.0")
    with pytest.raises(build.BuildError, match="found 0"):
        build.render_text("<!-- results:value r rows[m={x|z}].v -->?<!-- /results -->", r, "D.md")


def _renderer(tmp_path: Path, doc: dict) -> object:
    run = build.Run("r", "", "psg-eval --out {out}")
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "results.json").write_text(json.dumps(doc))
    return build.Renderer([run], tmp_path)


def test_render_replaces_only_block_bodies(tmp_path: Path) -> None:
    """Only what lies between the markers changes; prose numbers outside stay; a second render changes nothing."""
    r = _renderer(tmp_path, {"x": {"y": 0.123456}, "name": "lab"})
    text = ("Prose 0.9 stays. <!-- results:value r x.y fmt=.2f -->0.99<!-- /results --> and "
            "<!-- results:value r x.y scale=100 fmt=.1f -->1<!-- /results --> % of "
            "<!-- results:value r name -->?<!-- /results -->.\n")
    out = build.render_text(text, r, "DOC.md")
    assert out == ("Prose 0.9 stays. <!-- results:value r x.y fmt=.2f -->0.12<!-- /results --> and "
                   "<!-- results:value r x.y scale=100 fmt=.1f -->12.3<!-- /results --> % of "
                   "<!-- results:value r name -->lab<!-- /results -->.\n")
    assert build.render_text(out, r, "DOC.md") == out  # rendering is idempotent


@pytest.mark.parametrize(("block", "message"), [
    ("<!-- results:value other x.y -->1<!-- /results -->", "run 'other' is not in the manifest"),
    ("<!-- results:value r x.z -->1<!-- /results -->", "no 'z'"),
    ("<!-- results:bogus r -->1<!-- /results -->", "unknown block kind"),
    ("<!-- results:value r -->1<!-- /results -->", "expected RUN PATH"),
])
def test_a_bad_block_names_document_and_line(tmp_path: Path, block: str, message: str) -> None:
    """One error naming the document, its line and the block, for each way a block can be wrong."""
    r = _renderer(tmp_path, {"x": {"y": 1.0}})
    with pytest.raises(build.BuildError, match=r"^DOC\.md:3: results:") as exc:
        build.render_text("a\nb\n" + block + "\n", r, "DOC.md")
    assert message in str(exc.value)


def test_every_block_of_the_documents_names_a_manifest_run_and_a_known_kind() -> None:
    """RESULTS.md and README.md: every marker parses, names a known kind and a run of the manifest."""
    ids = {r.id for r in build.load_manifest()}
    kinds = {"table", "columns", "state", "text", "value", "run", "runs", "revision"}
    seen = 0
    for name in build.DOCUMENTS:
        for m in build.BLOCK.finditer((ROOT / name).read_text(encoding="utf-8")):
            seen += 1
            assert m["kind"] in kinds, (name, m[0][:80])
            words = m["args"].split()
            assert m["kind"] in ("runs", "revision") or set(words[0].split(",")) <= ids, (name, m[0][:80])
    assert seen >= 20
    # a marker the parser does not see (a typo in the closing tag) would leave a stale number unnoticed
    for name in build.DOCUMENTS:
        text = (ROOT / name).read_text(encoding="utf-8")
        assert text.count("<!-- results:") == len(build.BLOCK.findall(text)), name


def _table_run(folder: Path, rows: dict[str, tuple[str, float, float]],
               groups: list[tuple[str, list[str]]] | None = None) -> None:
    """A results.json written by psg-data's own writer: one table, MAE and B-Acc, per method (role, mae, bacc);
    each value's interval is value +- 0.01 (MAE) and +- 0.02 (B-Acc), its std 0.05 (MAE) and 0 (B-Acc).
    """
    from psg_data.evaluation import EvalResults, MetricInfo, ResultRow, ResultTable, Summary, save_results

    metrics = [MetricInfo("mae", "MAE", "lower", "mean absolute error"),
               MetricInfo("balanced_accuracy", "B-Acc", "higher", "balanced accuracy")]
    out = [ResultRow(m, role, {"mae": Summary(mae, 0.05, mae - 0.01, mae + 0.01, 21, "bootstrap", "objects"),
                               "balanced_accuracy": Summary(b, 0.0, b - 0.02, b + 0.02, 21, "bootstrap", "objects")})
           for m, (role, mae, b) in rows.items()]
    table = ResultTable("persistence", "t", metrics, out, groups=groups or [])
    save_results(EvalResults("persistence", [table]), folder)


def test_text_block_puts_a_file_of_the_run_in_a_code_block(tmp_path: Path) -> None:
    """``results:text RUN FILE``: the file verbatim (trailing spaces cut) in a code block; ``start``/``end`` cut a
    part of it; a missing file, a path outside the run, a start no line holds: one error naming the block.
    """
    r = _renderer(tmp_path, {"v": 1})
    (tmp_path / "r" / "out.txt").write_text("title\nA table  \n 1 2\n\nB table\n 3 4\n", encoding="utf-8")
    doc = "<!-- results:text r out.txt -->old<!-- /results -->"
    assert build.render_text(doc, r, "D.md") == ("<!-- results:text r out.txt -->\n```\ntitle\nA table\n 1 2\n\n"
                                                  "B table\n 3 4\n```\n<!-- /results -->")
    part = '<!-- results:text r out.txt start="A table" end="B table" -->old<!-- /results -->'
    assert "```\nA table\n 1 2\n```" in build.render_text(part, r, "D.md")
    for bad, message in (("r nope.txt", "cannot read nope.txt"), ("r ../x.txt", "a file name in the run's folder"),
                         ('r out.txt start="C table"', "no line holding 'C table'")):
        with pytest.raises(build.BuildError, match=re.escape(message)):
            build.render_text(f"<!-- results:text {bad} -->x<!-- /results -->", r, "D.md")


def test_columns_block_sets_runs_side_by_side(tmp_path: Path) -> None:
    """Each run's columns after the last's, rows in the first run's order then the others', '-' where a run
    has no row, each column's best non-ceiling value bold on its own, extra metrics and interval ends.
    """
    _table_run(tmp_path / "a", {"fremen": ("method", 0.2, 0.6), "oracle": ("ceiling", 0.1, 0.7),
                                "last_seen": ("baseline", 0.3, 0.55)})
    _table_run(tmp_path / "b", {"fremen": ("method", 0.25, 0.5), "perpetua_star": ("method", 0.22, 0.58),
                                "oracle": ("ceiling", 0.1, 0.69)})
    r = build.Renderer([build.Run("a", "", "x"), build.Run("b", "", "x")], tmp_path)
    text = '<!-- results:columns a,b labels="gt|noisy 0.1" metrics=balanced_accuracy extra=mae -->?<!-- /results -->'
    body = build.render_text(text, r, "DOC.md").split("\n")[1:-1]
    assert body == ["| Method | ref | gt: B-Acc ↑ | noisy 0.1: B-Acc ↑ |", "|---|---|---:|---:|",
                    "| oracle | ceiling | 0.700 ± 0.020 (0.100) | 0.690 ± 0.020 (0.100) |",
                    "| last\\_seen | baseline | 0.550 ± 0.020 (0.300) | - |",
                    "| fremen |  | **0.600 ± 0.020** (0.200) | 0.500 ± 0.020 (0.250) |",
                    "| perpetua\\_star |  | - | **0.580 ± 0.020** (0.220) |"]
    one = build.render_text("<!-- results:columns b interval=yes -->?<!-- /results -->", r, "DOC.md")
    assert "| Method | ref | MAE ↓ | B-Acc ↑ |" in one  # one run, no labels: the metric names alone
    assert "| perpetua\\_star |  | **0.220 ± 0.010** [0.210, 0.230] | **0.580 ± 0.020** [0.560, 0.600] |" in one
    std = build.render_text("<!-- results:columns b spread=std interval=yes -->?<!-- /results -->", r, "DOC.md")
    assert "| **0.220 ± 0.050** [0.210, 0.230] | **0.580 ± 0.000** [0.560, 0.600] |" in std
    stds = build.render_text("<!-- results:columns b std=yes -->?<!-- /results -->", r, "DOC.md")
    assert "| Method | ref | MAE ↓ | B-Acc ↑ | std (MAE / B-Acc) |" in stds
    assert "| perpetua\\_star |  | **0.220 ± 0.010** | **0.580 ± 0.020** | 0.050 / 0.000 |" in stds
    only_b = build.render_text("<!-- results:columns a,b rows=b -->?<!-- /results -->", r, "DOC.md")
    assert "last\\_seen" not in only_b and "| perpetua\\_star |  | - |" in only_b
    only_a = build.render_text("<!-- results:columns a,b rows=a metrics=balanced_accuracy -->?<!-- /results -->", r,
                               "DOC.md")  # b's best (perpetua_star) not shown: its fremen is the shown best
    assert "| fremen |  | **0.600 ± 0.020** | **0.500 ± 0.020** |" in only_a and "perpetua\\_star" not in only_a
    join = '<!-- results:columns a,b labels="gt|noisy" join=" / " spread=none -->?<!-- /results -->'
    joined = build.render_text(join, r, "DOC.md").split("\n")[1:-1]  # a run's metrics in one cell, each bold alone
    assert joined[:2] == ["| Method | ref | gt | noisy |", "|---|---|---:|---:|"]
    assert "| fremen |  | **0.200** / **0.600** | 0.250 / 0.500 |" in joined
    assert "| perpetua\\_star |  | - | **0.220** / **0.580** |" in joined
    for bad, message in (('labels="x"', "2 runs but 1 labels"), ("rows=c", "rows=c: expected one of"),
                         ("spread=sd", "spread=sd: expected interval, std or none"), ("metrics=f1", "no metric ['f1']"),
                         ("extra=rmse", "no metric ['rmse']")):
        with pytest.raises(build.BuildError, match=re.escape(message)):
            build.render_text(f"<!-- results:columns a,b {bad} -->?<!-- /results -->", r, "DOC.md")


def test_columns_block_names_groups_and_puts_intervals_after_chosen_metrics(tmp_path: Path) -> None:
    """A grouped table's headers carry the group (the sim tables' "Static presence (168) SR %"); ``interval=mae``:
    the interval's ends after the MAE cells only.
    """
    _table_run(tmp_path / "g", {"fremen": ("method", 0.2, 0.6)}, groups=[("Error (3)", ["mae"])])
    r = build.Renderer([build.Run("g", "", "x")], tmp_path)
    lines = build.render_text("<!-- results:columns g interval=mae -->?<!-- /results -->", r, "DOC.md").split("\n")
    assert lines[1] == "| Method | ref | Error (3) MAE ↓ | B-Acc ↑ |"
    assert lines[3] == "| fremen |  | **0.200 ± 0.010** [0.190, 0.210] | **0.600 ± 0.020** |"


def test_quick_render_leaves_blocks_of_runs_without_a_quick_form(tmp_path: Path) -> None:
    """A columns block reading any run without a quick form stays as committed (the others render)."""
    block = build.BLOCK.search("<!-- results:columns a,b x=1 -->?<!-- /results -->")
    assert block is not None and build._runs_of(block) == {"a", "b"}
    runs = build.BLOCK.search("<!-- results:runs -->?<!-- /results -->")
    assert runs is not None and build._runs_of(runs) == set()


WRITES_RESULTS = ("import json, os, sys; os.makedirs(sys.argv[1]); "
                  "json.dump({'v': 1}, open(sys.argv[1] + '/results.json', 'w'))")


def _script_run(tmp_path: Path, code: str) -> object:
    return build.Run("s", "", f"python -c {code!r} {{out}}")


CLEAN = {"revision": "a" * 40, "code": "tree:blob", "dirty": False}


def test_runs_are_renamed_into_place_and_foreign_folders_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run lands in RUNS/ID with run.json (the cache key); a folder the builder did not write is refused."""
    run = _script_run(tmp_path, WRITES_RESULTS)
    monkeypatch.setattr(build, "code_state", lambda *extra: dict(CLEAN))  # the repository's own state may be dirty
    state = dict(CLEAN)
    folder = build.execute(run, tmp_path, quick=False, state=state, quiet=True)
    info = json.loads((folder / "run.json").read_text())
    assert folder == tmp_path / "s" and info["command"] == run.command and info["code"] == state["code"]
    assert build.is_current(folder, run.command, state)
    assert not build.is_current(folder, run.command, {**state, "code": "other"})
    assert not build.is_current(folder, run.command + " -x", state)
    assert not build.is_current(folder, run.command, state, setup=("psg-data synth {work}/lab",))
    assert [p.name for p in tmp_path.iterdir()] in (["s", ".work"], [".work", "s"])
    build.execute(run, tmp_path, quick=False, state=state, quiet=True)  # its own run: replaced
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(build.BuildError, match="not a run this builder wrote"):
        build.execute(build.Run("mine", "", run.command), tmp_path, quick=False, state=state, quiet=True)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


def test_a_failing_run_leaves_the_previous_one(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run that fails, or whose code changed while it ran, replaces nothing: the last good results stay."""
    monkeypatch.setattr(build, "code_state", lambda *extra: dict(CLEAN))  # the repository's own state may be dirty
    state = dict(CLEAN)
    build.execute(_script_run(tmp_path, WRITES_RESULTS), tmp_path, quick=False, state=state, quiet=True)
    with pytest.raises(build.BuildError, match="exited with 3"):
        build.execute(_script_run(tmp_path, "import sys; sys.exit(3)"), tmp_path, quick=False, state=state, quiet=True)
    with pytest.raises(build.BuildError, match="changed while it ran"):
        build.execute(_script_run(tmp_path, WRITES_RESULTS), tmp_path, quick=False, state={**state, "code": "x"},
                      quiet=True)
    assert json.loads((tmp_path / "s" / "results.json").read_text()) == {"v": 1}


def test_a_commit_of_other_files_during_a_run_is_fine(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """HEAD moving while a run runs (a commit of RESULTS.md or the manifest) keeps the run: only the code counts;
    run.json names the revision the run started at.
    """
    monkeypatch.setattr(build, "code_state", lambda *extra: {**CLEAN, "revision": "b" * 40})
    folder = build.execute(_script_run(tmp_path, WRITES_RESULTS), tmp_path, quick=False, state=dict(CLEAN), quiet=True)
    assert json.loads((folder / "run.json").read_text())["revision"] == "a" * 40


def test_a_run_whose_command_prints_its_results(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``stdout``: the command's output becomes RUN/FILE (setup commands' output is not captured)."""
    monkeypatch.setattr(build, "code_state", lambda *extra: dict(CLEAN))
    printer = "import json; print(json.dumps({'n': 3}))"
    run = build.Run("p", "", f"python -c {printer!r}", setup=("python -c \"print('setup')\"",), stdout="results.json")
    folder = build.execute(run, tmp_path, quick=False, state=dict(CLEAN), quiet=True)
    assert json.loads((folder / "results.json").read_text()) == {"n": 3}
    assert build.is_current(folder, run.command, dict(CLEAN), run.setup)  # the setup is part of the key
    assert not build.is_current(folder, run.command, dict(CLEAN))
    with pytest.raises(build.BuildError, match="exited with 2"):
        build.execute(build.Run("p", "", "python -c 'import sys; sys.exit(2)'", stdout="results.json"), tmp_path,
                      quick=False, state=dict(CLEAN), quiet=True)
    assert json.loads((folder / "results.json").read_text()) == {"n": 3}


def test_runs_with_the_same_setup_share_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Within a build, runs whose setup commands are equal run them once and share {work}; a setup naming
    {out} is never shared; a new build makes the shared setup anew.
    """
    monkeypatch.setattr(build, "code_state", lambda *extra: dict(CLEAN))
    log = tmp_path / "setups.log"
    setup = (f"python -c \"open({str(log)!r}, 'a').write('s'); open('{{work}}/lab', 'w').write('lab')\"",)
    reads = ("import json, os, sys; os.makedirs(sys.argv[1]); "
             "json.dump({'lab': open(sys.argv[2]).read()}, open(sys.argv[1] + '/results.json', 'w'))")
    runs = [build.Run(rid, "", f"python -c {reads!r} {{out}} {{work}}/lab", setup=setup) for rid in ("a", "b")]
    for run in runs:
        folder = build.execute(run, tmp_path / "runs", quick=False, state=dict(CLEAN), quiet=True)
        assert json.loads((folder / "results.json").read_text()) == {"lab": "lab"}
    assert log.read_text() == "s"  # made once for both runs
    own = build.Run("c", "", "python -c 'pass'", setup=("python -c 'pass' {out}",))
    assert build._work_folder(tmp_path, "c", own.setup) == (tmp_path / ".work" / "c", False)
    build._drop_shared_setups(tmp_path / "runs")
    build.execute(runs[0], tmp_path / "runs", quick=False, state=dict(CLEAN), quiet=True)
    assert log.read_text() == "ss"


def _sched(n: int, **kw: object) -> list[object]:
    return [build.Run(f"r{k}", "", "x", **kw) for k in range(n)]


def test_jobs_run_side_by_side_after_what_they_wait_for() -> None:
    """``--jobs 2``: two runs are under way at once (a barrier both must reach), never three; a run starts after
    the runs it waits for; the costliest ready run first; ``--jobs 1`` keeps the manifest order, one at a time.
    """
    import threading

    lock, now, most, order = threading.Lock(), [0], [0], []
    pair = threading.Barrier(2, timeout=20)

    def do(run: object) -> None:
        with lock:
            now[0] += 1
            most[0] = max(most[0], now[0])
            order.append(run.id)  # type: ignore[attr-defined]
        if run.id in ("r0", "r1"):  # type: ignore[attr-defined]
            pair.wait()  # breaks (an error) unless both run at once
        with lock:
            now[0] -= 1

    runs = _sched(5)
    cost = {"r0": 1.0, "r1": 2.0, "r2": 3.0, "r3": 9.0, "r4": 0.0}
    build.run_all(runs, do, jobs=2, waits={"r0": {"r3"}, "r1": {"r3"}, "r4": {"r0"}}, cost=lambda r: cost[r.id],
                  quiet=True)
    assert most[0] == 2 and sorted(order) == [r.id for r in runs]
    assert order.index("r3") < min(order.index("r0"), order.index("r1")) and order.index("r0") < order.index("r4")
    assert order[:2] == ["r3", "r2"]  # costliest first among the ready ones
    order.clear()
    most[0] = 0
    build.run_all(_sched(4), lambda r: order.append(r.id), jobs=1, waits={}, cost=lambda r: -int(r.id[1]),
                  quiet=True)
    assert order == ["r0", "r1", "r2", "r3"]


def test_an_alone_run_has_nothing_beside_it_and_a_failure_stops_new_starts() -> None:
    """A run marked ``alone`` (its wall time is quoted) runs by itself; the first failure is raised after the
    runs under way end, and nothing new starts after it.
    """
    import threading
    import time

    lock, now, beside, started = threading.Lock(), [0], {}, []

    def do(run: object) -> None:
        with lock:
            now[0] += 1
            started.append(run.id)  # type: ignore[attr-defined]
        time.sleep(0.05)
        with lock:
            beside[run.id] = now[0]  # type: ignore[attr-defined]
            now[0] -= 1
        if run.id == "bad":  # type: ignore[attr-defined]
            raise build.BuildError("run bad: exited with 1")

    runs = [*_sched(3), build.Run("solo", "", "x", alone=True), build.Run("r9", "", "x")]
    build.run_all(runs, do, jobs=2, waits={}, cost=lambda r: 1.0 if r.id == "solo" else 0.0, quiet=True)
    assert beside["solo"] == 1 and sorted(started) == sorted(r.id for r in runs)
    started.clear()
    runs = [build.Run("bad", "", "x"), *_sched(4)]
    with pytest.raises(build.BuildError, match="run bad"):
        build.run_all(runs, do, jobs=1, waits={}, cost=lambda r: 0.0, quiet=True)
    assert started == ["bad"]


def test_the_cost_of_a_run_is_its_last_cpu_and_a_new_run_goes_first(tmp_path: Path) -> None:
    """Runs start costliest first by their last run.json's CPU seconds; a run never made counts as the costliest."""
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "run.json").write_text(json.dumps({"cpu_s": 12.5}))
    assert build._last_cpu(tmp_path, build.Run("old", "", "x")) == 12.5
    assert build._last_cpu(tmp_path, build.Run("new", "", "x")) == float("inf")


def test_waits_name_used_runs_and_the_first_run_of_a_shared_setup() -> None:
    """Runs with one shared setup wait for the first of them (it builds {work}); a setup naming {out} is its
    own; ``uses`` of runs not being made are no wait.
    """
    s = ("psg-data synth {work}/lab",)
    runs = [build.Run("a", "", "x", setup=s), build.Run("b", "", "x", setup=s), build.Run("c", "", "x",
            setup=("make {out}",)), build.Run("d", "", "x", setup=("make {out}",)),
            build.Run("e", "", "x", uses=("a", "gone"))]
    assert build._waits(runs, quick=False) == {"a": set(), "b": {"a"}, "c": set(), "d": set(), "e": {"a"}}


def test_run_json_counts_each_runs_own_cpu(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """CPU seconds are the command's own (and its children's), so two runs at once do not count each other."""
    monkeypatch.setattr(build, "code_state", lambda *extra: dict(CLEAN))
    burn = ("import json, os, sys, time, subprocess; os.makedirs(sys.argv[1]); "
            "subprocess.run([sys.executable, '-c', 'import time\\nt=time.process_time()\\n"
            "while time.process_time() - t < 0.4: pass']); "
            "json.dump({'v': 1}, open(sys.argv[1] + '/results.json', 'w'))")
    idle = ("import json, os, sys, time; os.makedirs(sys.argv[1]); time.sleep(0.6); "
            "json.dump({'v': 1}, open(sys.argv[1] + '/results.json', 'w'))")
    runs = [build.Run("burn", "", f"python -c {burn!r} {{out}}"), build.Run("idle", "", f"python -c {idle!r} {{out}}")]
    build.run_all(runs, lambda r: build.execute(r, tmp_path, quick=False, state=dict(CLEAN), quiet=True), jobs=2,
                  waits={}, cost=lambda r: 0.0, quiet=True)
    cpu = {r.id: json.loads((tmp_path / r.id / "run.json").read_text())["cpu_s"] for r in runs}
    assert cpu["burn"] >= 0.35 and cpu["idle"] < 0.3, cpu  # the child's 0.4 s counted once, in its own run


def test_a_run_depends_on_its_own_code_paths(tmp_path: Path) -> None:
    """``code``: a script a run names joins the cache key (its blob hash after psg_data's and pyproject's)."""
    base, extra = build.code_state(), build.code_state(("results/build.py",))
    assert extra["code"].startswith(base["code"] + ":") and extra["code"] != base["code"]
    with pytest.raises(build.BuildError, match="not committed"):
        build.code_state(("results/no-such-script.py",))
    manifest = tmp_path / "m.json"
    manifest.write_text(json.dumps({"runs": [{"id": "a", "command": "x", "code": ["s.py"], "stdout": "r.json"}]}))
    assert build.load_manifest(manifest)[0].code == ("s.py",) and build.load_manifest(manifest)[0].stdout == "r.json"


def test_runs_share_the_work_folder_one_setup_built(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``uses``: a run reads an earlier run's kept {work:ID} folder; it is stale when that run is made again, and
    making it alone while that run is stale is refused.
    """
    monkeypatch.setattr(build, "code_state", lambda *extra: dict(CLEAN))
    make = "import sys, pathlib; pathlib.Path(sys.argv[1], 'lab.txt').write_text('built')"
    read = ("import json, os, pathlib, sys; os.makedirs(sys.argv[2]); json.dump({'lab': "
            "pathlib.Path(sys.argv[1], 'lab.txt').read_text()}, open(sys.argv[2] + '/results.json', 'w'))")
    owner = build.Run("lab", "", f"python -c {read!r} {{work}} {{out}}", setup=(f"python -c {make!r} {{work}}",))
    user = build.Run("nav", "", f"python -c {read!r} {{work:lab}} {{out}}", uses=("lab",))
    runs, states = [owner, user], {"lab": dict(CLEAN), "nav": dict(CLEAN)}

    def stale(*only: str) -> list[str]:
        return [r.id for r in build.stale_runs(runs, tmp_path, states, quick=False, only=list(only))]

    assert stale() == ["lab", "nav"]
    with pytest.raises(build.BuildError, match="uses the work folder of lab: run that first"):
        build.execute(user, tmp_path, quick=False, state=dict(CLEAN), quiet=True)
    with pytest.raises(build.BuildError, match=r"nav uses lab, which is stale: run it too \(--only lab\)"):
        stale("nav")
    build.execute(owner, tmp_path, quick=False, state=dict(CLEAN), quiet=True, keep_work=True)
    assert stale() == ["nav"] and (tmp_path / ".work" / "lab" / "lab.txt").is_file()
    folder = build.execute(user, tmp_path, quick=False, state=dict(CLEAN), quiet=True)
    assert json.loads((folder / "results.json").read_text()) == {"lab": "built"} and stale() == []
    assert not (tmp_path / ".work" / "nav").exists()  # a folder no run uses is removed
    info = json.loads((tmp_path / "lab" / "run.json").read_text())
    (tmp_path / "lab" / "run.json").write_text(json.dumps({**info, "started": "later"}))  # the lab made again
    assert stale() == ["nav"]
    manifest = tmp_path / "m.json"
    manifest.write_text(json.dumps({"runs": [{"id": "a", "command": "x", "uses": ["b"]}, {"id": "b", "command": "y"}]}))
    with pytest.raises(build.BuildError, match=r"runs\[0\]: uses \['b'\]: expected ids of earlier runs"):
        build.load_manifest(manifest)


def test_revision_block_compares_the_psg_data_code_only(tmp_path: Path) -> None:
    """One revision when every run ran the same psg_data and pyproject (a run's own script hash aside)."""
    for rid, rev, code in (("a", "a" * 40, "tree:blob"), ("b", "b" * 40, "tree:blob:script")):
        (tmp_path / rid).mkdir()
        (tmp_path / rid / "run.json").write_text(json.dumps({"revision": rev, "code": code}))
        (tmp_path / rid / "results.json").write_text("{}")
    r = build.Renderer([build.Run("a", "", "x"), build.Run("b", "", "x", code=("s.py",))], tmp_path)
    assert build.render_text("<!-- results:revision -->?<!-- /results -->", r, "D") == \
        "<!-- results:revision -->aaaaaaa<!-- /results -->"
    (tmp_path / "b" / "run.json").write_text(json.dumps({"revision": "b" * 40, "code": "other:blob:script"}))
    assert "not one: the runs were made at aaaaaaa, bbbbbbb" in build.render_text(
        "<!-- results:revision -->?<!-- /results -->", r, "D")


@pytest.mark.slow
def test_quick_form_renders_every_block_from_real_runs(tmp_path: Path) -> None:
    """CI's quick form: the tiny runs made for real, every block with a quick run rendered from them."""
    runs = tmp_path / "runs"
    res = subprocess.run([sys.executable, str(ROOT / "results" / "build.py"), "--quick", "--runs", str(runs), "-q"],
                         capture_output=True, text=True, timeout=1800)  # a hang guard, not a speed check
    assert res.returncode == 0, res.stderr[-2000:]
    rendered = (runs / "rendered" / "README.md").read_text(encoding="utf-8")
    committed = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.compile(r"<!-- results:table main-job format=text -->\n```\n(.*?)```", re.S)
    new, old = block.search(rendered), block.search(committed)
    assert new and old
    methods = lambda t: [ln.split()[0] for ln in t.splitlines()[4:] if ln.strip()]  # noqa: E731
    assert methods(new[1]) == methods(old[1])  # the same rows, from the tiny lab's run
    assert new[1] != old[1]
    assert (ROOT / "README.md").read_text(encoding="utf-8") == committed  # --quick never writes the documents
    tables = re.findall(r"<!-- results:columns [^>]*-->\n(.*?)<!-- /results -->",
                        (runs / "rendered" / "RESULTS.md").read_text(encoding="utf-8"), re.S)
    assert len(tables) >= 6  # RESULTS.md 3.2, 3.3 (two), 3.4, 3.5, 7.2: each a header, a rule and its rows
    for body in tables:
        lines = body.strip().splitlines()
        assert lines[0].startswith("| Method | ref |") and len(lines) >= 7 and "?" not in body, body[:300]
    info = json.loads((runs / "main-job" / "run.json").read_text())
    assert info["quick"] is True and info["exit_code"] == 0 and info["cpu_s"] > 0
