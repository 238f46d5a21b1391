"""Seeded, stratified sample of bench/mutation_equivalent.txt for an audit of the equivalents.

``python bench/equivalent_sample.py SEED [REVISION [BASE [TOTAL]]]`` prints the sample: 3 lines per module
(all of a module with fewer), then draws up to TOTAL (default 40) in all from the rest; every draw is weighted 3:1 toward
reasons that argue "rounding only", "never", "only", "unreachable", "grid", "discarded", "same double"
(the reasons most likely to be wrong). The file is read as at REVISION (default 0b2d16b, the audit's);
with BASE, only the lines whose mutant is not named in the file as at BASE are sampled (the second
audit: ``python bench/equivalent_sample.py 34 85d1599 0b2d16b 25``).
"""

from __future__ import annotations

import random
import re
import subprocess
import sys
from collections import defaultdict

FAVOURED = re.compile(r"rounding|never binds|unreachable|grid|never read|never used|same double|discard|never|only",
                      re.I)
TOTAL = 40
PER_MODULE = 3


def _weight(reason: str) -> float:
    return 3.0 if FAVOURED.search(reason) else 1.0


def _draw(rng: random.Random, pool: list[tuple[str, str, str]], k: int) -> list[tuple[str, str, str]]:
    """Draw k rows (module, name, reason), weighted, without replacement; the pool is consumed."""
    out = []
    for _ in range(min(k, len(pool))):
        i = rng.choices(range(len(pool)), weights=[_weight(r) for _, _, r in pool])[0]
        out.append(pool.pop(i))
    return out


def _lines(rev: str) -> list[str]:
    """The listed lines (no comments, no blanks) of bench/mutation_equivalent.txt as at rev."""
    text = subprocess.run(["git", "show", f"{rev}:bench/mutation_equivalent.txt"], capture_output=True, text=True,
                          check=True).stdout
    return [line for line in text.splitlines() if line.strip() and not line.startswith("#")]


def main() -> None:
    """Print the sample of the revision's file for the seed given on the command line."""
    seed = int(sys.argv[1])
    rev = sys.argv[2] if len(sys.argv) > 2 else "0b2d16b"
    old = {line.split(None, 1)[0] for line in _lines(sys.argv[3])} if len(sys.argv) > 3 else set()
    total = int(sys.argv[4]) if len(sys.argv) > 4 else TOTAL
    by_module: dict[str, list[tuple[str, str, str]]] = defaultdict(list)
    for line in _lines(rev):
        name, reason = line.split(None, 1)
        if name not in old:
            by_module[name.split(".x")[0]].append((name.split(".x")[0], name, reason.strip()))
    rng = random.Random(seed)
    sample = {m: _draw(rng, list(rows), PER_MODULE) for m, rows in sorted(by_module.items())}
    rest = [row for m, rows in sorted(by_module.items()) for row in rows if row not in sample[m]]
    for row in _draw(rng, rest, total - sum(len(v) for v in sample.values())):
        sample[row[0]].append(row)
    print(f"# {sum(len(v) for v in by_module.values())} lines, {len(by_module)} modules, seed {seed}, at {rev}")
    for m, rows in sample.items():
        print(f"# {m}: {len(rows)} of {len(by_module[m])}")
        for _, name, reason in rows:
            print(f"{name}  {reason}")


if __name__ == "__main__":
    main()
