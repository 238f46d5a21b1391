"""Rebuild RESULTS.md (and README's main-job table) from the runs listed in results/manifest.json.

    python results/build.py                 # run what is stale, then rewrite the documents' blocks
    python results/build.py --jobs 2        # the same, two runs at once (the costliest first)
    python results/build.py --check         # exit 1 if a document differs from what the runs render
    python results/build.py --quick         # the manifest's quick form (tiny sizes): every block renders
    python results/build.py --list          # the runs, their commands and whether they are current

A document holds its generated parts between markers; everything outside them is hand-written::

    <!-- results:table main-job format=text -->...<!-- /results -->      a table of a run's results.json
    <!-- results:columns RUN1,RUN2 labels="gt|privileged" metrics=balanced_accuracy extra=mae,f1 -->...<!-- /results -->
                                       several runs' tables side by side (rows=RUN: only that run's rows;
                                       spread=std: ± the std across draws; interval=yes: the interval's ends;
                                       std=yes: a column of the stds across draws)
    <!-- results:state door-published -->...<!-- /results -->             a real-benchmark run's tables
    <!-- results:text sim-adaptive sim_table.txt start="overall SR" -->...<!-- /results -->  a text file of a run
    <!-- results:value main-job tables.0.rows[method=fremen].values.balanced_accuracy.mean -->0.597<!-- /results -->
    <!-- results:run main-job -->...<!-- /results -->                     the run's command, revision, date
    <!-- results:runs -->...<!-- /results -->                             the manifest: every run, its machine and time
    <!-- results:revision -->...<!-- /results -->                         the one code revision of every run

A run is current when its command and the code it ran (the git tree of ``psg_data/`` and
``pyproject.toml``) equal today's; stale runs are rerun into ``--runs DIR`` (default
``.results-runs/``, git-ignored): each into a temporary folder renamed into place when it ends, with
``run.json`` (command, revision, machine, wall and CPU seconds, load). A folder without the builder's
``run.json`` is never replaced. A run may read what an earlier run's setup built (``uses``: its ``{work:ID}``
folder, kept): it is stale whenever that run is made again. The documents are rewritten atomically, and only
their blocks change.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import partial
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "results" / "manifest.json"
DOCUMENTS = ("RESULTS.md", "README.md")
CODE = ("psg_data", "pyproject.toml")
"""What a run's numbers depend on: a change here makes every run stale."""
BLOCK = re.compile(r"<!-- results:(?P<kind>[a-z-]+)(?P<args>[^>]*?) -->(?P<body>.*?)<!-- /results -->", re.S)


class BuildError(Exception):
    """One line for the user: which document, block, run or field, and what was expected."""


# ---------------------------------------------------------------------------------------------- manifest


@dataclass(frozen=True)
class Run:
    """One manifest entry: ``command`` (and its ``quick`` form) with ``{out}`` (the run's folder) and
    ``{work}`` (a scratch folder of the builder), after the ``setup`` commands of the same form."""

    id: str
    purpose: str
    command: str
    setup: tuple[str, ...] = ()
    quick: str | None = None
    quick_setup: tuple[str, ...] = ()
    env: tuple[tuple[str, str], ...] = ()
    stdout: str | None = None
    """A file name in ``{out}``: the command's standard output is written there (for a command that prints
    its results as JSON instead of writing them)."""
    code: tuple[str, ...] = ()
    """Paths besides :data:`CODE` whose numbers the run depends on (a script it runs)."""
    uses: tuple[str, ...] = ()
    """Earlier runs whose ``{work}`` folder this run reads as ``{work:ID}`` (data one run's setup built, shared
    instead of built again); such a folder is kept after its run, and a rerun of it makes this run stale."""
    alone: bool = False
    """With ``--jobs`` above 1, run it with no other run beside it (a run whose wall time a document quotes)."""

    def form(self, quick: bool) -> tuple[tuple[str, ...], str | None]:
        """(setup commands, command) of the full or quick form; command None: no quick form."""
        return (self.quick_setup, self.quick) if quick else (self.setup, self.command)


def load_manifest(path: Path = MANIFEST) -> list[Run]:
    """The runs of ``path``, in order; one :class:`BuildError` for a malformed entry."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise BuildError(f"{path}: cannot read the manifest ({exc})") from None
    runs, known = [], {"id", "purpose", "command", "setup", "quick", "quick_setup", "env", "stdout", "code",
                                 "uses", "alone"}
    for k, e in enumerate(doc.get("runs", []) if isinstance(doc, dict) else []):
        where = f"{path}: runs[{k}]"
        if not isinstance(e, dict) or not isinstance(e.get("id"), str) or not isinstance(e.get("command"), str):
            raise BuildError(f"{where}: expected an object with string fields id and command")
        if set(e) - known:
            raise BuildError(f"{where}: unknown field(s) {sorted(set(e) - known)}, expected {sorted(known)}")
        runs.append(Run(e["id"], e.get("purpose", ""), e["command"], tuple(e.get("setup", ())), e.get("quick"),
                        tuple(e.get("quick_setup", ())), tuple(sorted(e.get("env", {}).items())),
                        e.get("stdout"), tuple(e.get("code", ())), tuple(e.get("uses", ())), bool(e.get("alone"))))
        if set(runs[-1].uses) - {r.id for r in runs[:-1]}:
            raise BuildError(f"{where}: uses {list(runs[-1].uses)}: expected ids of earlier runs")
    ids = [r.id for r in runs]
    if not runs or len(set(ids)) != len(ids):
        raise BuildError(f"{path}: expected a non-empty list 'runs' with distinct ids")
    return runs


# ---------------------------------------------------------------------------------------------- running


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()


def code_state(extra: tuple[str, ...] = ()) -> dict[str, Any]:
    """The revision, the hash of the code a run depends on (:data:`CODE` and a run's own ``extra`` paths) and
    whether it has local changes."""
    rev = _git("rev-parse", "HEAD")
    try:
        code = ":".join(_git("rev-parse", f"HEAD:{p}") for p in (*CODE, *extra))
    except subprocess.CalledProcessError:
        raise BuildError(f"one of {', '.join(extra)} is not committed (a run's 'code' names committed paths)") from None
    dirty = bool(_git("status", "--porcelain", "--", *CODE, *extra))
    return {"revision": rev, "code": code, "dirty": dirty}


def machine() -> dict[str, Any]:
    """What the wall times mean: platform, CPU model and count."""
    model = platform.processor()
    try:
        model = next(ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                     if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"platform": platform.platform(), "cpu": model, "cpus": os.cpu_count(), "python": platform.python_version()}


def _load() -> float | None:
    return round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None


def _run_command(argv: list[str], env: dict[str, str], stdout: Any) -> tuple[int, float]:
    """Run one command; (exit code, CPU seconds of it and the processes it waited for: NaN without ``os.wait4``).

    The CPU time is the command's own (``wait4``), so runs beside each other (``--jobs``) count apart.
    """
    proc = subprocess.Popen(argv, env=env, cwd=ROOT, stdout=stdout)
    if not hasattr(os, "wait4"):  # Windows
        return proc.wait(), float("nan")
    try:
        _, status, usage = os.wait4(proc.pid, 0)
    except BaseException:  # interrupted: the command does not outlive the builder
        proc.kill()
        proc.wait()
        raise
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, usage.ru_utime + usage.ru_stime


def _argv(command: str, subs: dict[str, str]) -> list[str]:
    """The command's words with ``{out}`` / ``{work}`` filled in; ``psg-eval`` / ``psg-data`` from this Python."""
    words = shlex.split(command)
    for key, value in subs.items():
        words = [w.replace("{" + key + "}", value) for w in words]
    exe = Path(sys.executable).parent / words[0]
    return [str(exe) if exe.exists() else words[0], *words[1:]]


def _started(folder: Path) -> str | None:
    """When the builder's run in ``folder`` started (None: no run there)."""
    try:
        return str(json.loads((folder / "run.json").read_text(encoding="utf-8"))["started"])
    except (OSError, ValueError, KeyError):
        return None


def is_current(folder: Path, command: str, state: dict[str, Any], setup: tuple[str, ...] = (),
               uses: dict[str, str | None] | None = None) -> bool:
    """The builder's run in ``folder`` ran ``command`` after ``setup`` on today's code (and ended well), on the
    ``uses`` runs' folders as they are now (``{id: started}``).
    """
    try:
        info = json.loads((folder / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return (info.get("command") == command and tuple(info.get("setup", ())) == setup
            and info.get("code") == state["code"] and not info.get("dirty")
            and info.get("exit_code") == 0 and not state["dirty"] and info.get("uses", {}) == (uses or {}))


def execute(run: Run, runs_dir: Path, *, quick: bool, state: dict[str, Any], quiet: bool = False,
            keep_work: bool = False) -> Path:
    """Run ``run`` (setup, then command) into a temporary folder and rename it to ``runs_dir/ID``.

    ``keep_work``: leave its ``{work}`` folder for the runs that use it (``Run.uses``).
    """
    setup, command = run.form(quick)
    assert command is not None
    final, tmp = runs_dir / run.id, runs_dir / f".{run.id}.partial-{os.getpid()}"
    if final.exists() and not (final / "run.json").exists():
        raise BuildError(f"{final}: exists and is not a run this builder wrote (no run.json); move it away")
    used = {u: _started(runs_dir / u) for u in run.uses}
    if any(v is None or not (runs_dir / ".work" / u).is_dir() for u, v in used.items()):
        raise BuildError(f"run {run.id}: uses the work folder of {', '.join(run.uses)}: run that first")
    work, reuse = _work_folder(runs_dir, run.id, setup, shared=not keep_work)
    shutil.rmtree(tmp, ignore_errors=True)
    if not reuse:
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
    subs, env = {"out": str(tmp), "work": str(work)}, {**os.environ, **dict(run.env)}
    subs.update({f"work:{u}": str(runs_dir / ".work" / u) for u in run.uses})
    load0, cpu, t0 = _load(), 0.0, time.perf_counter()
    started = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    if run.stdout:
        tmp.mkdir(parents=True)
    for cmd in ((command,) if reuse else (*setup, command)):
        if cmd is command and work.name != run.id:
            (work / ".setup-done").touch()  # later runs of this build with the same setup reuse the folder
        argv = _argv(cmd, subs)
        if not quiet:
            print(f"results: {run.id}: {' '.join(shlex.quote(a) for a in argv)}", file=sys.stderr, flush=True)
        if run.stdout and cmd is command:
            with open(tmp / run.stdout, "wb") as out:
                rc, used_cpu = _run_command(argv, env, out)
        else:
            rc, used_cpu = _run_command(argv, env, subprocess.DEVNULL if quiet else None)
        cpu += used_cpu
        if rc != 0:
            raise BuildError(f"run {run.id}: {cmd!r} exited with {rc}")
    now = code_state(run.code)  # a commit of other files (the documents, the manifest) while a run runs is fine
    if (now["code"], now["dirty"]) != (state["code"], state["dirty"]):
        raise BuildError(f"run {run.id}: {', '.join(CODE)} changed while it ran; its numbers name no one revision")
    if not (tmp / "results.json").is_file():
        raise BuildError(f"run {run.id}: {command!r} wrote no {tmp}/results.json (it must write to --out {{out}})")
    info = {"id": run.id, "command": command, **({"setup": list(setup)} if setup else {}), "quick": quick, **state,
            "started": started, "uses": used,
            "wall_s": round(time.perf_counter() - t0, 1), "cpu_s": round(cpu, 1),
            "load_before": load0, "load_after": _load(), "machine": machine(), "exit_code": 0}
    (tmp / "run.json").write_text(json.dumps(info, indent=1) + "\n", encoding="utf-8")
    old = runs_dir / f".{run.id}.old-{os.getpid()}"
    if final.exists():
        final.rename(old)
    tmp.rename(final)
    shutil.rmtree(old, ignore_errors=True)
    if work.name == run.id and not keep_work:
        shutil.rmtree(work, ignore_errors=True)
    return final


def _work_folder(runs_dir: Path, run_id: str, setup: tuple[str, ...], *, shared: bool = True) -> tuple[Path, bool]:
    """A run's ``{work}`` folder and whether its setup already ran there: runs with the same setup commands
    (none naming ``{out}``) share one folder within a build (the quick form's tiny lab is made once);
    ``shared=False`` (a folder later runs read as ``{work:ID}``): the run's own folder.
    """
    if not shared or not setup or any("{out}" in c for c in setup):
        return runs_dir / ".work" / run_id, False
    work = runs_dir / ".work" / ("setup-" + hashlib.sha256("\n".join(setup).encode()).hexdigest()[:16])
    return work, (work / ".setup-done").is_file()


# ---------------------------------------------------------------------------------------------- rendering


def _steps(path: str) -> list[tuple[str, list[tuple[str, str]]]]:
    """``path`` as (key, [(field, value), ...]) steps: dots and brackets inside a selector's value belong to it
    (``rows[method=perpetua_star:gamma=0.99][last_seen=present]``, ``rows[method=fremen [doors known]]``)."""
    steps: list[tuple[str, list[tuple[str, str]]]] = []
    key, depth, buf = "", 0, ""
    sels: list[tuple[str, str]] = []
    for ch in path + ".":
        if depth == 0 and ch == ".":
            if not key:
                raise BuildError(f"path {path!r}: cannot read it (an empty step)")
            steps.append((key, sels))
            key, sels = "", []  # a new list: the step keeps its own
        elif depth == 0 and ch == "[":
            if not key:
                raise BuildError(f"path {path!r}: a selector needs a key before it")
            depth, buf = 1, ""
        elif depth == 0:
            if sels:
                raise BuildError(f"path {path!r}: text after a selector")
            key += ch
        else:
            depth += (ch == "[") - (ch == "]")
            if depth == 0:
                field, eq, value = buf.partition("=")
                if not eq or not field:
                    raise BuildError(f"path {path!r}: expected [field=value], got [{buf}]")
                sels.append((field, value))
                buf = ""
            else:
                buf += ch
    if depth:
        raise BuildError(f"path {path!r}: unclosed selector")
    return steps


def lookup(doc: Any, path: str) -> Any:
    """``doc`` at ``path``: dotted keys, list indices, and ``key[field=value]`` for the list item whose
    ``field`` is ``value`` (``tables.0.rows[method=fremen].values.mae.mean``; ``rows[a=x][b=y]``: both)."""
    cur = doc
    for key, sel in _steps(path):
        if isinstance(cur, list) and key.isdigit() and int(key) < len(cur):
            cur = cur[int(key)]
        elif isinstance(cur, dict) and key in cur:
            cur = cur[key]
        elif isinstance(cur, dict) and key == "half_width" and {"ci_low", "ci_high"} <= set(cur):
            cur = _half_width(cur)
        else:
            raise BuildError(f"path {path!r}: no {key!r} at this step")
        if sel:
            hits = [x for x in cur if isinstance(x, dict) and all(str(x.get(f)) == v for f, v in sel)] \
                if isinstance(cur, list) else []
            if len(hits) != 1:
                what = ", ".join(f"{f}={v}" for f, v in sel)
                raise BuildError(f"path {path!r}: expected one item with {what}, found {len(hits)}")
            cur = hits[0]
    return cur


_ALTERNATIVES = re.compile(r"\{([^{}]*\|[^{}]*)\}")
"""``{a|b}`` in a value path: one value per alternative."""


def _number(v: Any, opts: dict[str, str]) -> str:
    """``v`` as a value block prints it: numbers times ``scale`` plus ``offset`` in ``fmt`` (default .3f; a
    share missed: ``scale=-100 offset=100``), anything else as text."""
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        return str(v)
    return format(float(v) * float(opts.get("scale", "1")) + float(opts.get("offset", "0")), opts.get("fmt", ".3f"))


def _half_width(summary: dict[str, Any]) -> float:
    """What a table prints after ``±``: :attr:`psg_data.evaluation.Summary.half_width` of a results.json summary."""
    from psg_data.evaluation._aggregate import Summary

    return float(Summary.from_dict(summary).half_width)


def _options(args: str, where: str) -> tuple[list[str], dict[str, str]]:
    words = shlex.split(args)
    is_opt = [re.match(r"[a-z_]+=", w) is not None for w in words]  # a path may hold '=' inside [...]
    pos = [w for w, o in zip(words, is_opt) if not o]
    opts = dict(w.split("=", 1) for w, o in zip(words, is_opt) if o)
    if not pos and where not in ("runs", "revision"):
        raise BuildError(f"results:{where}: expected a run id")
    return pos, opts


class Renderer:
    """Renders blocks from the runs in ``runs_dir`` (read through psg-data's own results loader)."""

    def __init__(self, runs: list[Run], runs_dir: Path) -> None:
        self.runs, self.runs_dir = {r.id: r for r in runs}, runs_dir
        self.used: set[str] = set()

    def _folder(self, run_id: str) -> Path:
        if run_id not in self.runs:
            raise BuildError(f"run {run_id!r} is not in the manifest")
        self.used.add(run_id)
        folder = self.runs_dir / run_id
        if not (folder / "results.json").is_file():
            raise BuildError(f"run {run_id!r}: no {folder}/results.json (run the builder without --render-only)")
        return folder

    def _json(self, run_id: str, name: str = "results.json") -> Any:
        return json.loads((self._folder(run_id) / name).read_text(encoding="utf-8"))

    def block(self, kind: str, args: str) -> str:
        """The new body of one block."""
        pos, opts = _options(args, kind)
        fn = getattr(self, "_" + kind.replace("-", "_"), None)
        if fn is None:
            raise BuildError(f"results:{kind}: unknown block kind (table, columns, state, text, value, run, runs, revision)")
        return str(fn(pos, opts))

    def _table(self, pos: list[str], opts: dict[str, str]) -> str:
        from psg_data.evaluation import load_results
        from psg_data.evaluation._table_formats import markdown_table, select_table, table_grid
        from psg_data.evaluation._tables import format_table

        table = self._one_table(load_results(self._folder(pos[0])), opts.get("table", "0"), pos[0])
        table = select_table(table, metrics=opts["metrics"].split(",") if "metrics" in opts else None,
                             references=opts.get("references", "yes") == "yes")
        if opts.get("notes", "no") != "yes":
            table = dataclasses.replace(table, notes=[])
        if opts.get("format", "markdown") == "text":
            return "\n```\n" + format_table(table) + "\n```\n"
        return "\n" + markdown_table(table_grid(table)) + "\n"

    def _columns(self, pos: list[str], opts: dict[str, str]) -> str:
        """Several runs' tables side by side (``RUN1,RUN2``).

        One row per method (the first run's order, then rows only later runs have; ``rows=RUN``: only that
        run's rows), each run's metric columns after the last's, headed ``LABEL: metric`` (``labels=A|B``;
        default the run ids, none for one run); ``metrics=a,b``: only these; ``extra=mae,f1``: those
        metrics' estimates in brackets after each cell; ``spread=std``: ± is the values' standard deviation
        (across scenes or draws; default: the table's own ±; ``none``: no ±); ``interval=yes``: the interval's ends
        after each cell (``interval=a,b``: after these metrics' cells); ``join=" / "``: each run's metrics in one
        cell, joined by this text (headed by the run's label); ``std=yes``: a last column per run with the shown
        metrics' standard deviations (across draws or scenes; ``0.004 / 0.005``). Bold: each column's (metric's)
        best non-ceiling value among the rows shown.
        """
        from psg_data.evaluation._table_formats import md_escape

        ids = pos[0].split(",")
        labels = opts["labels"].split("|") if "labels" in opts else ids
        if len(labels) != len(ids):
            raise BuildError(f"{len(ids)} runs but {len(labels)} labels")
        if opts.get("rows", ids[0]) not in ids:
            raise BuildError(f"rows={opts['rows']}: expected one of the block's runs {ids}")
        keep = set(self._run_columns(opts["rows"], opts)[1]) if "rows" in opts else None
        header, runs, roles = ["Method", "ref"], [], {}
        for rid, label in zip(ids, labels):
            names, cells = self._run_columns(rid, opts, keep)
            if "join" in opts:
                names, cells = [label if "labels" in opts else opts["join"].join(names)], \
                    {m: (role, [opts["join"].join(texts)]) for m, (role, texts) in cells.items()}
                header += names
            else:
                header += [f"{label}: {n}" if "labels" in opts or len(ids) > 1 else n for n in names]
            runs.append((cells, len(names)))
            if "rows" not in opts or opts["rows"] == rid:
                roles.update({m: role for m, (role, _) in cells.items() if m not in roles})
        lines = ["| " + " | ".join(md_escape(h) for h in header) + " |", "|---|---|" + "---:|" * (len(header) - 2)]
        for method, role in roles.items():
            row = [md_escape(method), "" if role == "method" else role]
            for cells, n in runs:
                row += cells[method][1] if method in cells else ["-"] * n
            lines.append("| " + " | ".join(row) + " |")
        return "\n" + "\n".join(lines) + "\n"

    def _run_columns(self, rid: str, opts: dict[str, str],
                     keep: set[str] | None = None) -> tuple[list[str], dict[str, tuple[str, list[str]]]]:
        """One run's part of a ``columns`` block: its column names and, per method, (role, cells).

        ``keep``: only these methods (the best values are marked among them).
        """
        from psg_data.evaluation import load_results
        from psg_data.evaluation._tables import best_marks, ordered_rows

        table = self._one_table(load_results(self._folder(rid)), opts.get("table", "0"), rid)
        keys = [m.key for m in table.metrics]
        want = opts["metrics"].split(",") if "metrics" in opts else keys
        extra = [k for k in opts.get("extra", "").split(",") if k]
        if set(want + extra) - set(keys):
            raise BuildError(f"run {rid}: no metric {sorted(set(want + extra) - set(keys))} (metrics: {keys})")
        spread = opts.get("spread", table.spread)
        if spread not in ("interval", "std", "none"):
            raise BuildError(f"spread={spread}: expected interval, std or none")
        metrics = [m for m in table.metrics if m.key in want]
        table = dataclasses.replace(table, rows=[r for r in table.rows if keep is None or r.method in keep])
        rows = ordered_rows(table.rows)
        out = {}
        for r, marks in zip(rows, best_marks(table, rows)):
            out[r.method] = (r.role, [_cell(_value_text(r.values.get(m.key), m.scale, m.digits, spread),
                                            marks[keys.index(m.key)],
                                            _after(r, table, m.key, extra, opts.get("interval") == "yes"
                                                   or m.key in opts.get("interval", "").split(",")))
                                      for m in metrics])
        arrow = {"lower": " ↓", "higher": " ↑"}
        group = {k: f"{g} " for g, ks in table.groups for k in ks}  # "Static presence (168) SR %"
        names = [f"{group.get(m.key, '')}{m.label}{arrow.get(m.better, '')}" for m in metrics]
        if opts.get("std") == "yes":  # one more column: each shown metric's std across draws / scenes
            names.append(f"std ({' / '.join(m.label for m in metrics)})")
            for r in rows:
                out[r.method][1].append(" / ".join(_std_text(r.values.get(m.key), m) for m in metrics))
        return names, out

    @staticmethod
    def _one_table(res: Any, which: str, rid: str) -> Any:
        """Table ``which`` (an index or a name) of run ``rid``'s results."""
        tables = [t for k, t in enumerate(res.tables) if str(k) == which or t.name == which]
        if len(tables) != 1:
            raise BuildError(f"run {rid}: no table {which!r} (tables: {[t.name for t in res.tables]})")
        return tables[0]

    def _state(self, pos: list[str], opts: dict[str, str]) -> str:
        from psg_data.evaluation._state_report import render, state_tables

        doc = self._json(pos[0])
        title = f"{doc.get('info', {}).get('dataset', pos[0])}, protocol {doc['protocol']}"
        names = ["headroom", "main", "per-week"]
        want = opts.get("tables", "headroom,main,per-week").split(",")
        if set(want) - set(names):
            raise BuildError(f"results:state {pos[0]}: tables={opts['tables']!r}, expected some of {names}")
        grids = state_tables(doc, title)[:3]
        return "\n" + render([g for g, n in zip(grids, names) if n in want], "markdown") + "\n"

    def _text(self, pos: list[str], opts: dict[str, str]) -> str:
        """A text file the run wrote (``RUN FILE``), verbatim in a code block; ``start=`` / ``end=``: from the first
        line holding ``start`` up to (not including) the next line holding ``end``.
        """
        if len(pos) != 2 or "/" in pos[1] or pos[1].startswith("."):
            raise BuildError("expected RUN FILE (a file name in the run's folder)")
        try:
            lines = (self._folder(pos[0]) / pos[1]).read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise BuildError(f"cannot read {pos[1]} of run {pos[0]} ({exc.strerror})") from None
        first = _line_index(lines, opts.get("start"), 0, pos)
        last = _line_index(lines, opts.get("end"), first + 1, pos) if "end" in opts else len(lines)
        body = "\n".join(ln.rstrip() for ln in lines[first:last]).strip("\n")
        return "\n```\n" + body + "\n```\n"

    def _value(self, pos: list[str], opts: dict[str, str]) -> str:
        """One value, or with ``{a|b|c}`` in the path each alternative's, joined by ``sep`` (default " / ")."""
        if len(pos) != 2:
            raise BuildError(f"results:value {' '.join(pos)}: expected RUN PATH")
        doc, alt = self._json(pos[0]), _ALTERNATIVES.search(pos[1])
        paths = [pos[1][:alt.start()] + a + pos[1][alt.end():] for a in alt[1].split("|")] if alt else [pos[1]]
        return opts.get("sep", " / ").join(_number(lookup(doc, p), opts) for p in paths)

    def _run(self, pos: list[str], opts: dict[str, str]) -> str:
        info = self._json(pos[0], "run.json")
        return (f"`{info['command'].replace(' --out {out}', '')}` (revision {info['revision'][:7]}, "
                f"{info['started']}, {info['wall_s']:.0f} s wall, {info['cpu_s']:.0f} CPU-s, load "
                f"{info['load_before']} -> {info['load_after']})")

    def _runs(self, pos: list[str], opts: dict[str, str]) -> str:
        rows = ["| run | command | revision | started (UTC) | wall s | CPU s | load |", "|---|---|---|---|---:|---:|---|"]
        machines, wall, cpu = set(), 0.0, 0.0
        for rid in self.runs:
            try:
                info = self._json(rid, "run.json")
            except (BuildError, OSError, ValueError):
                rows.append(f"| {rid} | `{self.runs[rid].command}` | not run | | | | |")
                continue
            machines.add(f"{info['machine']['cpus']} x {info['machine']['cpu']}, {info['machine']['platform']}")
            wall, cpu = wall + info["wall_s"], cpu + info["cpu_s"]
            rows.append(f"| {rid} | `{info['command'].replace(' --out {out}', '')}` | {info['revision'][:7]} | "
                        f"{info['started']} | {info['wall_s']:.0f} | {info['cpu_s']:.0f} | "
                        f"{info['load_before']} -> {info['load_after']} |")
        rows.append(f"| all | | | | {wall:.0f} | {cpu:.0f} | |")
        return "\n" + "\n".join(rows) + "\n\nMachine: " + "; ".join(sorted(machines) or ["-"]) + "\n"

    def _revision(self, pos: list[str], opts: dict[str, str]) -> str:
        infos = [self._json(rid, "run.json") for rid in self.runs if (self.runs_dir / rid / "run.json").exists()]
        codes = {":".join(i["code"].split(":")[:len(CODE)]) for i in infos}  # a run's own 'code' paths aside
        revs = sorted({i["revision"][:7] for i in infos})
        if len(codes) <= 1:
            return revs[0] if revs else "-"
        return f"(not one: the runs were made at {', '.join(revs)}; `python results/build.py` reruns the stale ones)"


def _line_index(lines: list[str], text: str | None, begin: int, pos: list[str]) -> int:
    """The index of the first line from ``begin`` holding ``text`` (``begin`` itself when ``text`` is None)."""
    if text is None:
        return begin
    for k in range(begin, len(lines)):
        if text in lines[k]:
            return k
    raise BuildError(f"{pos[1]} of run {pos[0]}: no line holding {text!r} (after line {begin})")


def _value_text(s: Any, scale: float, digits: int, spread: str) -> str:
    """A cell's estimate: psg-data's ``cell_text`` (``0.185 ± 0.012``), or the estimate alone (``spread=none``)."""
    from psg_data.evaluation._tables import cell_text

    if spread == "none":
        return "-" if s is None or not math.isfinite(s.mean) else f"{scale * s.mean:.{digits}f}"
    return cell_text(s, scale, digits, spread)


def _cell(text: str, best: bool, after: str) -> str:
    """A Markdown cell: the estimate (bold when the column's best non-ceiling value) and what follows it."""
    from psg_data.evaluation._table_formats import md_escape

    text = md_escape(text)
    return (f"**{text}**" if best and text != "-" else text) + (f" {after}" if after else "")


def _std_text(s: Any, metric: Any) -> str:
    """A summary's standard deviation in its metric's scale and digits; ``-`` when there is none."""
    return f"{metric.scale * s.std:.{metric.digits}f}" if s is not None and math.isfinite(s.std) else "-"


def _after(row: Any, table: Any, key: str, extra: list[str], interval: bool) -> str:
    """What follows the cell of metric ``key``: the interval's ends ``[0.067, 0.073]`` (``interval``) and the
    ``extra`` metrics' estimates ``(0.176, 0.426)``.
    """
    parts, s = [], row.values.get(key)
    if interval and s is not None and math.isfinite(s.ci_low) and math.isfinite(s.ci_high):
        m = table.metric(key)
        parts.append(f"[{m.scale * s.ci_low:.{m.digits}f}, {m.scale * s.ci_high:.{m.digits}f}]")
    values = [row.values.get(k) for k in extra]
    if extra and all(v is not None and math.isfinite(v.mean) for v in values):
        ms = [table.metric(k) for k in extra]
        parts.append("(" + ", ".join(f"{m.scale * v.mean:.{m.digits}f}" for m, v in zip(ms, values)) + ")")
    return " ".join(parts)


def render_text(text: str, renderer: Renderer, name: str) -> str:
    """``text`` with every block's body replaced by what the renderer makes of it."""
    def sub(m: re.Match[str]) -> str:
        try:
            body = renderer.block(m["kind"], m["args"])
        except BuildError as exc:
            line = text.count("\n", 0, m.start()) + 1
            raise BuildError(f"{name}:{line}: results:{m['kind']}{m['args']}: {exc}") from None
        return f"<!-- results:{m['kind']}{m['args']} -->{body}<!-- /results -->"
    return BLOCK.sub(sub, text)


def write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


# ---------------------------------------------------------------------------------------------- command


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="results/build.py", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("--runs", type=Path, default=None, help="folder of the runs (default .results-runs/, "
                   "--quick: .results-quick/)")
    p.add_argument("--quick", action="store_true", help="the manifest's quick form; documents are rendered into "
                   "RUNS/rendered/, never over the real ones")
    p.add_argument("--check", action="store_true", help="render and compare, write nothing; exit 1 on a difference")
    p.add_argument("--render-only", action="store_true", help="run nothing; render from the runs there are")
    p.add_argument("--only", action="append", default=[], metavar="ID", help="run only these runs (repeatable)")
    p.add_argument("--list", action="store_true", help="the runs and whether each is current; run nothing")
    p.add_argument("-j", "--jobs", type=int, default=1, metavar="N", help="runs at once (default 1; a run's own "
                   "workers come on top); a manifest entry with \"alone\": true runs with nothing beside it")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines, no output of the runs")
    a = p.parse_args(argv)
    if a.jobs < 1:
        p.error(f"--jobs {a.jobs}: expected a number of runs at once, 1 or more")
    from psg_data.cli._errors import ReaderGoneStdout

    stdout = sys.stdout
    sys.stdout = ReaderGoneStdout(stdout)  # `--list | head`: the rest of the list is dropped, no traceback
    try:
        return _build(a)
    except BuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    finally:
        sys.stdout = stdout


def _build(a: argparse.Namespace) -> int:
    runs = load_manifest()
    runs_dir = (a.runs or ROOT / (".results-quick" if a.quick else ".results-runs")).resolve()
    runs_dir.mkdir(parents=True, exist_ok=True)
    states = {r.id: code_state(r.code) for r in runs}
    if any(st["dirty"] for st in states.values()) and not (a.quick or a.check or a.render_only or a.list):
        raise BuildError(f"{', '.join(CODE)} or a run's 'code' have uncommitted changes: commit them so each run "
                         "names its code")
    todo = stale_runs(runs, runs_dir, states, quick=a.quick, only=a.only)
    if a.list:
        for r in runs:
            status = "no quick form" if r.form(a.quick)[1] is None else ("stale" if r in todo else "current")
            print(f"{r.id:28s} {status:14s} {r.form(a.quick)[1] or r.command}")
        return 0
    if not (a.check or a.render_only):
        _drop_shared_setups(runs_dir)  # a build makes its shared setups anew (the code may have changed)
        kept = {u for o in runs for u in o.uses}
        try:
            run_all(todo, lambda r: execute(r, runs_dir, quick=a.quick, state=states[r.id], quiet=a.quiet,
                                            keep_work=r.id in kept),
                    jobs=a.jobs, waits=_waits(todo, a.quick), cost=partial(_last_cpu, runs_dir), quiet=a.quiet)
        finally:
            _drop_shared_setups(runs_dir)
    return _render(runs, runs_dir, a)


def _waits(todo: list[Run], quick: bool) -> dict[str, set[str]]:
    """What each run waits for beside others: the runs it ``uses`` and the first run of its shared setup."""
    first: dict[str, str] = {}
    out: dict[str, set[str]] = {}
    ids = {r.id for r in todo}
    for r in todo:
        setup = r.form(quick)[0]
        out[r.id] = set(r.uses) & ids
        if setup and not any("{out}" in c for c in setup):
            owner = first.setdefault("\n".join(setup), r.id)
            if owner != r.id:
                out[r.id].add(owner)
    return out


def _last_cpu(runs_dir: Path, run: Run) -> float:
    """The CPU seconds of the run's last recorded run: the longest start first; a run never made (inf) before
    all, since it may be the longest (a new run left to the end would run alone).
    """
    try:
        v = float(json.loads((runs_dir / run.id / "run.json").read_text(encoding="utf-8"))["cpu_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return math.inf
    return v if math.isfinite(v) else math.inf


def run_all(todo: list[Run], do: Any, *, jobs: int, waits: dict[str, set[str]], cost: Any, quiet: bool) -> None:
    """``do(run)`` for every run: in manifest order with ``jobs`` 1, else up to ``jobs`` at once, the costliest
    ready run first, a run after those it ``waits`` for, an ``alone`` run with nothing beside it. The first
    failure stops new starts; the runs under way end, then it is raised.
    """
    from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait

    pending = list(todo) if jobs == 1 else sorted(todo, key=lambda r: -cost(r))
    done: set[str] = set()
    running: dict[Future[Any], Run] = {}
    error: BaseException | None = None
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        while (pending and error is None) or running:
            for r in _startable(pending, running.values(), done, waits, jobs) if error is None else []:
                pending.remove(r)
                if not quiet:
                    print(f"results: run {len(todo) - len(pending)}/{len(todo)}: {r.id}", file=sys.stderr, flush=True)
                running[pool.submit(do, r)] = r
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for f in finished:
                done.add(running.pop(f).id)
                if f.exception() is not None and error is None:
                    error = f.exception()
    if error is not None:
        raise error


def _startable(pending: list[Run], running: Any, done: set[str], waits: dict[str, set[str]], jobs: int) -> list[Run]:
    """The runs to start now (:func:`run_all`'s rules)."""
    busy = list(running)
    out: list[Run] = []
    for r in pending:
        if len(busy) + len(out) >= jobs or any(b.alone for b in (*busy, *out)):
            break
        if waits.get(r.id, set()) <= done and not (r.alone and (busy or out)):
            out.append(r)
    return out


def _drop_shared_setups(runs_dir: Path) -> None:
    """Remove the shared ``{work}`` folders of ``runs_dir`` (a run's own folder is its own business)."""
    for folder in (runs_dir / ".work").glob("setup-*"):
        shutil.rmtree(folder, ignore_errors=True)


def stale_runs(runs: list[Run], runs_dir: Path, states: dict[str, dict[str, Any]], *, quick: bool,
               only: list[str]) -> list[Run]:
    """The runs to make (of ``only``, if given), in manifest order: not current, or using a run that is to be made
    or was made again since; a run using a stale run that ``only`` leaves out is an error.
    """
    stale: set[str] = set()
    for r in runs:
        command = r.form(quick)[1]
        used = {u: _started(runs_dir / u) for u in r.uses}
        if command is not None and (set(r.uses) & stale or not is_current(runs_dir / r.id, command, states[r.id],
                                                                             r.form(quick)[0], used)):
            stale.add(r.id)
    todo = [r for r in runs if r.id in stale and (not only or r.id in only)]
    for r in todo:
        missing = sorted(set(r.uses) & stale - {t.id for t in todo})
        if missing:
            raise BuildError(f"run {r.id} uses {', '.join(missing)}, which is stale: run it too (--only {missing[0]})")
    return todo


def _render(runs: list[Run], runs_dir: Path, a: argparse.Namespace) -> int:
    renderer, changed = Renderer(runs, runs_dir), []
    skipped = {r.id for r in runs if r.form(a.quick)[1] is None}
    for name in DOCUMENTS:
        path = ROOT / name
        old = path.read_text(encoding="utf-8")
        if a.quick and skipped:  # blocks of runs without a quick form stay as they are
            renderer.runs = {k: v for k, v in renderer.runs.items() if k not in skipped}
            new = BLOCK.sub(partial(_render_unless, skipped=skipped, renderer=renderer, name=name), old)
        else:
            new = render_text(old, renderer, name)
        if a.quick:
            (runs_dir / "rendered").mkdir(exist_ok=True)
            write_atomic(runs_dir / "rendered" / name, new)
        elif new != old:
            changed.append(name)
            if not a.check:
                write_atomic(path, new)
    n_blocks = sum(len(BLOCK.findall((ROOT / d).read_text(encoding="utf-8"))) for d in DOCUMENTS)
    if not a.quiet:
        print(f"results: {n_blocks} blocks rendered from {len(renderer.used)} runs"
              + (f" ({len(skipped)} runs without a quick form left as they are: {', '.join(sorted(skipped))})"
                 if a.quick and skipped else "")
              + (f"; changed: {', '.join(changed)}" if changed else "; documents unchanged"), file=sys.stderr)
    return 1 if a.check and changed else 0


def _render_unless(m: re.Match[str], *, skipped: set[str], renderer: Renderer, name: str) -> str:
    """The block ``m`` rendered, or as it is when it reads a run in ``skipped``."""
    return m[0] if _runs_of(m) & skipped else render_text(m[0], renderer, name)


def _runs_of(m: re.Match[str]) -> set[str]:
    """The runs a block reads (a ``columns`` block names several, comma-separated)."""
    words = shlex.split(m["args"])
    return set(words[0].split(",")) if words and "=" not in words[0] else set()


if __name__ == "__main__":
    sys.exit(main())
