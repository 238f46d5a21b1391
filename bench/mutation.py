"""Mutation testing of the numerical core: ``python bench/mutation.py [--max-children N] [--report-only]``.

Runs mutmut (configuration: ``[tool.mutmut]`` in pyproject.toml, the modules and test folders of
issue 33) from the repository root, then counts, per module, the mutants that the tests killed
(a test failed or timed out), the ones listed as equivalent in ``bench/mutation_equivalent.txt``
(``mutant-name  reason`` per line: a change no test can observe), the survivors and the ones not
checked yet. Prints a Markdown table and writes it with every survivor's name to
``bench/out/mutation.json``. mutmut resumes an interrupted run and re-tests only functions changed
since; ``mutmut show NAME`` prints one mutant's diff. Not part of CI (it takes far longer than the
suite). Needs ``pip install mutmut`` (the tool, not a project dependency).
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EQUIVALENT = ROOT / "bench" / "mutation_equivalent.txt"
KILLED = {1, 3, 36, -24, 24, 152, 255}  # a failing test, pytest's internal error, or a timeout


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
    """Per module (file path): status counts, and the names of the surviving mutants."""
    equivalent = _equivalent()
    counts: dict[str, Counter[str]] = defaultdict(Counter)
    survivors: dict[str, list[str]] = defaultdict(list)
    for meta in sorted((ROOT / "mutants").rglob("*.py.meta")):
        module = str(meta.relative_to(ROOT / "mutants"))[: -len(".meta")]
        for name, code in json.loads(meta.read_text())["exit_code_by_key"].items():
            status = _status(code, name, equivalent)
            counts[module][status] += 1
            if status == "survived":
                survivors[module].append(name)
    return counts, survivors


def table(counts: dict[str, Counter[str]]) -> str:
    """Markdown table: mutants, killed, equivalent, survived, not checked, kill rate of the non-equivalent."""
    rows = ["| module | mutants | killed | equivalent | survived | no tests / not checked | killed of non-equivalent |",
            "|---|---|---|---|---|---|---|"]
    total: Counter[str] = Counter()
    for module, c in sorted(counts.items()):
        total.update(c)
        rows.append(_row(module, c))
    rows.append(_row("**all**", total))
    return "\n".join(rows)


def _row(label: str, c: Counter[str]) -> str:
    n = sum(c.values())
    checked = c["killed"] + c["survived"]
    rate = f"{100.0 * c['killed'] / checked:.1f} %" if checked else "-"
    return (f"| {label} | {n} | {c['killed']} | {c['equivalent']} | {c['survived']} | "
            f"{c['no tests'] + c['not checked'] + c['other']} | {rate} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-children", type=int, default=None, help="parallel mutant runs (default: all CPUs)")
    ap.add_argument("--report-only", action="store_true", help="only count the results of earlier runs")
    args = ap.parse_args()
    start = time.time()
    if not args.report_only:
        cmd = ["mutmut", "run"] + ([] if args.max_children is None else ["--max-children", str(args.max_children)])
        rc = subprocess.call(cmd, cwd=ROOT)
        if rc != 0:
            print(f"error: mutmut run exited with {rc}", file=sys.stderr)
            return 1
    counts, survivors = collect()
    if not counts:
        print("error: mutants/: no mutmut results (run without --report-only first)", file=sys.stderr)
        return 1
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    print(f"# mutation testing, {time.strftime('%Y-%m-%d')} at {rev} on {platform.node()} "
          f"({time.time() - start:.0f} s)\n")
    print(table(counts))
    out = ROOT / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "mutation.json").write_text(json.dumps(
        {"date": time.strftime("%Y-%m-%d"), "git_revision": rev,
         "counts": {m: dict(c) for m, c in counts.items()}, "survivors": survivors}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
