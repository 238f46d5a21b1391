"""``--overwrite`` cannot destroy: every command replaces only what psg-data wrote, never an input.

Each refusal is one ``error:`` line with exit code 1 and leaves the file system exactly as it was.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main as psg_data
from psg_data.cli.psg_eval_cmd import main as psg_eval
from psg_data.errors import DatasetExistsError, UnsafeOutputError
from psg_data.loaders import open_dataset
from psg_data.schemas.validate import validate_dataset
from psg_data.writers import DatasetWriter
from psg_data.writers._safe_output import (OUTPUT_MARKER, PARTIAL_MARKER, check_output, commit_tree, make_staging,
                                          write_atomically)
from tests.conftest import write_tiny_dataset
from tests.contract import assert_one_error, files_in, snapshot
from tests.convert.conftest import write_bag

SYNTH = ["--days", "1", "--frames-per-scan", "1", "--resolution", "32x24", "-q"]


def _cli(cmd, *args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(cmd, [str(a) for a in args])


# -- the rule itself --------------------------------------------------------------------------------------

def test_inputs_are_never_outputs(tmp_path: Path) -> None:
    d = tmp_path / "recs"
    d.mkdir()
    bag = d / "a.bag"
    bag.write_bytes(b"x")
    for out, inputs, msg in [
        (bag, [bag], "is the input"),
        (d, [bag], "contains the input"),
        (d / "out", [d], "lies inside the input"),
        (tmp_path / "recs.partial" / "x", [tmp_path / "recs.partial"], "lies inside the input"),
        (tmp_path / "x", [tmp_path / "x.partial"], "staging folder is the input"),
    ]:
        with pytest.raises(UnsafeOutputError, match=msg):
            check_output(out, overwrite=True, inputs=inputs)
    link = tmp_path / "link"
    link.symlink_to(d)
    with pytest.raises(UnsafeOutputError, match="contains the input"):  # through a symbolic link too
        check_output(link, overwrite=True, inputs=[bag])
    check_output(tmp_path / "new", overwrite=False, inputs=[bag])  # unrelated and absent: fine


def test_only_what_psg_data_wrote_is_replaced(tmp_path: Path) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("x")
    foreign = tmp_path / "d"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("months of work")
    ds = write_tiny_dataset(tmp_path / "ds", scans=1, frames=1)
    empty = tmp_path / "empty"
    empty.mkdir()
    check_output(ds, overwrite=True)
    check_output(empty, overwrite=True)
    with pytest.raises(DatasetExistsError, match="output exists; pass --overwrite"):
        check_output(ds, overwrite=False)
    for out, msg in [(notes, "is a file"), (foreign, "is not a psg-dataset (no readable dataset.json) and holds "
                                                     "thesis.tex"),
                     (ds, None)]:
        if msg is None:
            (ds / "images" / "notes.md").write_text("mine")  # a stray file inside a dataset
            msg = "holds files psg-data did not write (images/notes.md)"
        with pytest.raises(UnsafeOutputError, match=msg.replace("(", r"\(").replace(")", r"\)")):
            check_output(out, overwrite=True)
    with pytest.raises(UnsafeOutputError, match="is a psg-dataset"):  # a command replaces only its own kind
        check_output(write_tiny_dataset(tmp_path / "ds2", scans=1, frames=1), overwrite=True, kind="results")
    link = tmp_path / "l"
    link.symlink_to(empty)
    with pytest.raises(UnsafeOutputError, match="symbolic link"):
        check_output(link, overwrite=True)


def test_staging_folder_of_someone_else_is_kept(tmp_path: Path) -> None:
    mine = tmp_path / "lab.partial"
    mine.mkdir()
    (mine / "data.csv").write_text("1,2")
    before = snapshot(tmp_path)
    with pytest.raises(UnsafeOutputError, match=f"lab.partial: exists and was not created by psg-data"):
        DatasetWriter(tmp_path / "lab")
    assert snapshot(tmp_path) == before
    ours = make_staging(tmp_path / "x.partial")
    (ours / "f").write_text("1")
    assert not (make_staging(tmp_path / "x.partial") / "f").exists()  # ours: restarted


def test_replacing_fsyncs_before_the_rename_and_leaves_nothing_beside(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    out = write_tiny_dataset(tmp_path / "ds", scans=1, frames=2)
    synced: list[str] = []
    events: list[tuple[str, str]] = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd: int) -> None:
        synced.append(os.path.realpath(f"/proc/self/fd/{fd}"))
        real_fsync(fd)

    def replace(a, b) -> None:  # type: ignore[no-untyped-def]
        events.append((str(a), str(b)))
        if Path(a).name == "ds.partial":  # the new tree is published: all of it must be on disk
            on_disk = {os.path.realpath(os.path.join(d, f)) for d, _, fs in os.walk(a) for f in fs}
            assert on_disk and on_disk <= set(synced)
        real_replace(a, b)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    write_tiny_dataset(out, scans=2, frames=1, overwrite=True)
    assert any(Path(a).name == "ds.partial" for a, _ in events)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
    assert validate_dataset(out) == [] and len(open_dataset(out).scan_ids) == 2


def test_commit_puts_back_the_old_output_when_the_swap_fails(tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    out = write_tiny_dataset(tmp_path / "ds", scans=1, frames=1)
    before = snapshot(out)
    tree = make_staging(tmp_path / "ds.partial")
    (tree / "dataset.json").write_text("{}")
    real = os.replace

    def fail_second(a, b) -> None:  # type: ignore[no-untyped-def]
        if Path(a) == tree:
            raise OSError(28, "No space left on device")
        real(a, b)

    monkeypatch.setattr(os, "replace", fail_second)
    with pytest.raises(OSError):
        commit_tree(tree, out)
    assert snapshot(out) == before


def _write_then_fail(tmp: Path) -> None:
    tmp.write_bytes(b"half of the new")
    raise KeyboardInterrupt


def test_write_atomically_keeps_the_previous_file_when_the_write_fails(tmp_path: Path) -> None:
    out = tmp_path / "summary.csv"
    out.write_bytes(b"the previous good file\n")
    with pytest.raises(KeyboardInterrupt):
        write_atomically(out, _write_then_fail)
    assert out.read_bytes() == b"the previous good file\n"
    assert files_in(tmp_path) == ["summary.csv"]  # no temporary file left
    assert write_atomically(out, lambda tmp: tmp.write_bytes(b"new")) == out
    assert out.read_bytes() == b"new" and files_in(tmp_path) == ["summary.csv"]
    write_atomically(tmp_path / "sub" / "new.txt", lambda tmp: tmp.write_text("x"))  # parents created
    assert (tmp_path / "sub" / "new.txt").read_text() == "x"


def test_write_atomically_never_writes_into_an_input(tmp_path: Path) -> None:
    ds = write_tiny_dataset(tmp_path / "ds", scans=1, frames=1)
    before = snapshot(ds)
    for out, msg in [(ds / "tables" / "objects.parquet", "lies inside the input"), (ds / "new" / "x.csv",
                     "lies inside the input"), (ds, "is the input"), (tmp_path, "contains the input")]:
        with pytest.raises(UnsafeOutputError, match=msg) as err:
            write_atomically(out, lambda tmp: tmp.write_bytes(b"x"), inputs=[None, ds])
        assert str(out) in str(err.value) and "expected" in str(err.value)
    assert snapshot(ds) == before and files_in(tmp_path) == ["ds"]


def test_write_atomically_leaves_a_foreign_file_of_its_temporary_name(tmp_path: Path) -> None:
    out = tmp_path / "t.txt"
    foreign = tmp_path / f".t.txt.psg-tmp-{os.getpid()}"
    foreign.write_bytes(b"not psg-data's")
    used: list[Path] = []

    def write(tmp: Path) -> None:
        used.append(tmp)
        tmp.write_bytes(b"new")

    write_atomically(out, write)
    with pytest.raises(KeyboardInterrupt):
        write_atomically(out, _write_then_fail)
    assert used[0] != foreign and foreign.read_bytes() == b"not psg-data's"
    assert out.read_bytes() == b"new" and files_in(tmp_path) == sorted([foreign.name, "t.txt"])


# -- every command ----------------------------------------------------------------------------------------

def test_convert_never_replaces_its_input(tmp_path: Path) -> None:
    d = tmp_path / "recs"
    d.mkdir()
    bag = write_bag(d / "a.bag")
    before = snapshot(tmp_path)
    for args, msg in [((bag, bag), "is the input"), ((bag, d), "contains the input"),
                      ((d, d), "is the input"), ((d, d / "out"), "lies inside the input"),
                      ((bag, tmp_path, "--side-dir", d), "contains the input")]:
        assert_one_error(_cli(psg_data, "convert", *args, "--overwrite", "-q"), msg)
        assert snapshot(tmp_path) == before


def test_convert_refuses_foreign_outputs(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "a.bag")
    notes = tmp_path / "notes.txt"
    notes.write_text("x")
    d = tmp_path / "d"
    d.mkdir()
    (d / "thesis.tex").write_text("x")
    before = snapshot(tmp_path)
    assert_one_error(_cli(psg_data, "convert", bag, notes, "--overwrite", "-q"), "is a file")
    assert_one_error(_cli(psg_data, "convert", bag, d, "--overwrite", "-q"), "holds thesis.tex")
    assert snapshot(tmp_path) == before


def test_synth_refuses_foreign_outputs_and_replaces_its_own(tmp_path: Path) -> None:
    d = tmp_path / "d"
    d.mkdir()
    (d / "thesis.tex").write_text("x")
    notes = tmp_path / "notes.txt"
    notes.write_text("x")
    before = snapshot(tmp_path)
    for fmt in ("canonical", "ros1"):
        assert_one_error(_cli(psg_data, "synth", d, "--format", fmt, "--overwrite", *SYNTH), "holds thesis.tex")
        assert_one_error(_cli(psg_data, "synth", notes, "--format", fmt, "--overwrite", *SYNTH), "is a file")
    assert snapshot(tmp_path) == before
    bags = tmp_path / "bags"
    for _ in range(2):
        r = _cli(psg_data, "synth", bags, "--format", "ros1", "--overwrite", *SYNTH)
        assert r.exit_code == 0, r.output
    assert json.loads((bags / OUTPUT_MARKER).read_text())["kind"] == "recordings"
    assert not any(p.name.startswith((".bags", "bags.")) for p in tmp_path.iterdir())
    assert_one_error(_cli(psg_data, "synth", bags, "--overwrite", *SYNTH), "is a folder of recordings")
    (bags / "notes.txt").write_text("mine")
    assert_one_error(_cli(psg_data, "synth", bags, "--format", "ros1", "--overwrite", *SYNTH),
                     "holds files psg-data did not write (notes.txt)")


def test_psg_eval_out_never_replaces_inputs_or_foreign_folders(tmp_path: Path) -> None:
    ds = write_tiny_dataset(tmp_path / "lab", scans=1, frames=1)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("x")
    before = snapshot(tmp_path)
    common = ["-e", "always_present", "--no-references", "--no-plots", "--overwrite", "-q"]
    for out, msg in [(ds, "is the input"), (ds / "res", "lies inside the input"), (tmp_path, "contains the input"),
                     (mine, "holds thesis.tex")]:
        assert_one_error(_cli(psg_eval, "--dataset", ds, "--out", out, *common), msg)
    assert_one_error(_cli(psg_eval, "--dataset", "persistence-benchmark", "--out", ds, *common), "is a psg-dataset")
    assert snapshot(tmp_path) == before


def test_label_never_writes_over_its_inputs_or_foreign_tables(tmp_path: Path) -> None:
    ds = write_tiny_dataset(tmp_path / "lab", scans=2, frames=1)
    r = _cli(psg_data, "label", ds, "--source", "gt", "--no-doors", "-q")
    assert r.exit_code == 0, r.output
    before = snapshot(tmp_path)
    labels = ds / "tables" / "labels.parquet"
    assert_one_error(_cli(psg_data, "label", ds, "--source", f"detections:{labels}", "--overwrite", "-q"),
                     "is the input")
    assert snapshot(tmp_path) == before
    ds2 = write_tiny_dataset(tmp_path / "lab2", scans=2, frames=1)
    foreign = ds2 / "tables" / "labels.parquet"
    pq.write_table(pq.read_table(labels), foreign)  # a labels table psg-data did not write into this dataset
    before = snapshot(tmp_path)
    assert_one_error(_cli(psg_data, "label", ds2, "--source", "privileged", "--no-doors", "--overwrite", "-q"),
                     "exists but psg-data did not write it")
    assert snapshot(tmp_path) == before
    assert pa.Table.equals(pq.read_table(foreign), pq.read_table(labels))
    assert PARTIAL_MARKER not in {p.name for p in ds.rglob("*")}


def test_single_file_outputs_replace_only_their_own_kind(tmp_path: Path) -> None:
    """``psg-data view --save FILE.rrd`` and ``psg-eval --rerun FILE.rrd``: a Rerun recording only."""
    ds = write_tiny_dataset(tmp_path / "lab", scans=1, frames=1)
    notes = tmp_path / "notes.rrd"
    notes.write_text("my notes")
    before = snapshot(tmp_path)
    assert_one_error(_cli(psg_data, "view", ds, "--save", notes, "--overwrite", "-q"),
                     "is not a Rerun recording (.rrd)")
    assert_one_error(_cli(psg_data, "view", ds, "--save", ds / "x.rrd", "-q"), "lies inside the input")
    assert_one_error(_cli(psg_eval, "--dataset", ds, "-e", "always_present", "--no-references", "--rerun", notes,
                          "--overwrite", "-q"), "is not a Rerun recording (.rrd)")
    assert snapshot(tmp_path) == before


def test_export_raw_replaces_only_its_own_recordings(tmp_path: Path) -> None:
    """The library call follows the rule too: a foreign output or staging folder is never deleted."""
    from psg_data.synth import export_raw

    ds = write_tiny_dataset(tmp_path / "canon")
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("x")
    staging = tmp_path / "out.partial"
    staging.mkdir()
    (staging / "draft.txt").write_text("x")
    before = snapshot(tmp_path)
    with pytest.raises(UnsafeOutputError, match="holds thesis.tex"):
        export_raw(ds, mine, "ros1", overwrite=True)
    with pytest.raises(UnsafeOutputError, match="was not created by psg-data"):
        export_raw(ds, tmp_path / "out", "ros1")
    with pytest.raises(UnsafeOutputError, match="input"):
        export_raw(ds, ds / "recordings", "ros1")
    assert snapshot(tmp_path) == before
    out = tmp_path / "bags"
    for _ in range(2):
        export_raw(ds, out, "ros1", overwrite=True)
    assert json.loads((out / OUTPUT_MARKER).read_text())["kind"] == "recordings"
    with pytest.raises(DatasetExistsError):
        export_raw(ds, out, "ros1")
    assert not any(p.name.startswith((".bags", "bags.")) for p in tmp_path.iterdir())
