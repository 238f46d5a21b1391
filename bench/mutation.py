"""Mutation testing of the numerical core: ``python bench/mutation.py --group NAME [--max-children N]``.

Runs mutmut (shared settings: ``[tool.mutmut]`` in pyproject.toml; the groups, each a list of modules
and the narrow test selection that pins them: ``[tool.psg_data.mutation.NAME]``, whose own ``mutmut`` table,
if any, overrides shared settings such as the timeouts for that group) for one group in its
own work folder ``bench/out/mutation/NAME`` (a fresh copy of the package, the tests and the files
the tests read, with the group's settings written into its pyproject.toml), then counts, per module,
the mutants that the tests killed (a test failed or timed out), the ones listed as equivalent in
``bench/mutation_equivalent.txt`` (``mutant-name  reason`` per line: a change no input can tell
apart), the survivors and the ones not checked yet, over every group run so far. Prints a Markdown
table and writes it with every survivor's name to ``bench/out/mutation.json``. mutmut resumes an
interrupted run and re-tests only the functions changed since; ``--report-only`` only counts;
``mutmut show NAME`` inside the work folder prints one mutant's diff. Not part of CI (it takes far
longer than the suite). Needs ``pip install mutmut`` (the tool, not a project dependency; 3.8).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import tomllib

ROOT = Path(__file__).resolve().parent.parent
WORK = ROOT / "bench" / "out" / "mutation"
EQUIVALENT = ROOT / "bench" / "mutation_equivalent.txt"
KILLED = {1, 3, 36, -24, 24, 152, 255}  # a failing test, pytest's internal error, or a timeout
COPIED = ["psg_data", "tests"]


def _config() -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]
    return tool["mutmut"], tool["psg_data"]["mutation"]


def _toml_value(v: Any) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(v)  # strings, numbers and booleans read the same in TOML


def prepare(group: str, settings: dict[str, Any], groups: dict[str, dict[str, Any]]) -> Path:
    """Refresh the group's work folder: the sources, tests and files the tests read; its pyproject.toml."""
    work = WORK / group
    work.mkdir(parents=True, exist_ok=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "out")
    for name in COPIED + [str(p).rstrip("/") for p in settings.get("also_copy", [])]:
        src, dst = ROOT / name, work / name
        if dst.is_dir():
            shutil.rmtree(dst)
        if src.is_dir():
            shutil.copytree(src, dst, ignore=ignore)
        elif src.is_file():
            shutil.copy2(src, dst)
    text = (ROOT / "pyproject.toml").read_text()
    text = text[: text.index("[tool.mutmut]")]
    mine = dict(settings, **groups[group].get("mutmut", {}), only_mutate=groups[group]["only_mutate"],
                pytest_add_cli_args_test_selection=groups[group]["tests"])  # a group's `mutmut` table overrides
    text += "[tool.mutmut]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in mine.items())
    tmp = work / "pyproject.toml.tmp"
    tmp.write_text(text)
    os.replace(tmp, work / "pyproject.toml")
    return work


def _equivalent() -> dict[str, str]:
    out: dict[str, str] = {}
    if EQUIVALENT.is_file():
        for line in EQUIVALENT.read_text().splitlines():
            if line.strip() and not line.startswith("#"):
                name, _, reason = line.strip().partition(" ")
                out[name] = reason.strip()
    return out


def _status(code: int | None, name: str, equivalent: dict[str, str]) -> str:
    if code is None:
        return "not checked"
    if code in KILLED:
        return "killed"
    if code == 0:
        return "equivalent" if name in equivalent else "survived"
    return "no tests" if code in (5, 33) else "other"


def collect() -> tuple[dict[str, Counter[str]], dict[str, list[str]]]:
    """Per module (file path): status counts, and the names of the surviving mutants, over all groups."""
    equivalent = _equivalent()
    counts: dict[str, Counter[str]] = defaultdict(Counter)
    survivors: dict[str, list[str]] = defaultdict(list)
    for meta in sorted(WORK.glob("*/mutants/psg_data/**/*.py.meta")):
        mutants = next(p for p in meta.parents if p.name == "mutants")
        module = str(meta.relative_to(mutants))[: -len(".meta")]
        for name, code in json.loads(meta.read_text())["exit_code_by_key"].items():
            status = _status(code, name, equivalent)
            counts[module][status] += 1
            if status == "survived":
                survivors[module].append(name)
    return counts, survivors


def _survivors(group: str) -> list[str]:
    equivalent = _equivalent()
    return [name for meta in sorted((WORK / group).glob("mutants/psg_data/**/*.py.meta"))
            for name, code in json.loads(meta.read_text())["exit_code_by_key"].items()
            if code in (0, 5, 33) and name not in equivalent]  # survived, or no test reached it


def table(counts: dict[str, Counter[str]]) -> str:
    """Markdown table per module; the kill rate counts a mutant no selected test reaches as not killed."""
    rows = ["| module | mutants | killed | equivalent | survived | no test reaches it | not checked "
            "| killed of non-equivalent |",
            "|---|---|---|---|---|---|---|---|"]
    total: Counter[str] = Counter()
    for module, c in sorted(counts.items()):
        total.update(c)
        rows.append(_row(module, c))
    rows.append(_row("**all**", total))
    return "\n".join(rows)


def _row(label: str, c: Counter[str]) -> str:
    n = sum(c.values())
    checked = c["killed"] + c["survived"] + c["no tests"]
    rate = f"{100.0 * c['killed'] / checked:.1f} %" if checked else "-"
    return (f"| {label} | {n} | {c['killed']} | {c['equivalent']} | {c['survived']} | {c['no tests']} | "
            f"{c['not checked'] + c['other']} | {rate} |")


def main() -> int:
    """Run the chosen groups (default: all), then print and write the per-module counts of every group."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--group", action="append", default=[], help="group to run (repeatable; see pyproject.toml)")
    ap.add_argument("--max-children", type=int, default=1, help="parallel mutant runs (default: 1)")
    ap.add_argument("--report-only", action="store_true", help="only count the results of earlier runs")
    ap.add_argument("--only", action="append", default=[], metavar="GLOB",
                    help="test only the mutants whose names match (mutmut's names, e.g. '*PerpetuaStarFilter*')")
    ap.add_argument("--survivors", action="store_true",
                    help="re-test only the group's survivors and unreached mutants (after adding tests for them)")
    args = ap.parse_args()
    settings, groups = _config()
    unknown = [g for g in args.group if g not in groups]
    if unknown:
        print(f"error: pyproject.toml: [tool.psg_data.mutation] has no group {unknown[0]!r} "
              f"(expected one of {', '.join(groups)})", file=sys.stderr)
        return 1
    start = time.time()
    git = ["git", "rev-parse", "--short", "HEAD"]
    rev = subprocess.run(git, cwd=ROOT, capture_output=True, text=True).stdout.strip()  # the revision tested
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "psg_data", "tests"], cwd=ROOT,
                           capture_output=True, text=True).stdout.strip()
    rev += "+uncommitted" if dirty else ""
    load = Path("/proc/loadavg").read_text().split()[0] if Path("/proc/loadavg").is_file() else "?"
    for group in [] if args.report_only else args.group or list(groups):
        names = _survivors(group) if args.survivors else args.only
        if args.survivors and not names:
            continue
        work = prepare(group, settings, groups)
        rc = subprocess.call(["mutmut", "run", "--max-children", str(args.max_children), *names], cwd=work)
        if rc != 0:
            print(f"error: mutmut run (group {group}) exited with {rc}", file=sys.stderr)
            return 1
    counts, survivors = collect()
    if not counts:
        print(f"error: {WORK}: no mutmut results (run without --report-only first)", file=sys.stderr)
        return 1
    print(f"# mutation testing, {time.strftime('%Y-%m-%d %H:%M')} at {rev} on {platform.node()} "
          f"({time.time() - start:.0f} s, 1-minute load at start {load})\n")
    print(table(counts))
    out = ROOT / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "mutation.json").write_text(json.dumps(
        {"date": time.strftime("%Y-%m-%d"), "git_revision": rev,
         "counts": {m: dict(c) for m, c in counts.items()}, "survivors": survivors}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
