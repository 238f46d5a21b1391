"""Run every benchmark of the suite: ``python bench/run.py [--quick]``.

Each ``bench/bench_*.py`` script is run in its own process with the same flags; their tables are
printed in turn. Record notable results in BENCHMARKS.md with the machine and date.
``--help`` prints this and runs nothing.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from pathlib import Path


def main() -> int:
    here = Path(__file__).resolve().parent
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="every script's quick form")
    _, rest = ap.parse_known_args()  # other --flags go to every script as they are
    flags = [a for a in sys.argv[1:] if a.startswith("--")]
    if rest != [a for a in rest if a.startswith("--")]:
        ap.error(f"unexpected arguments: {' '.join(a for a in rest if not a.startswith('--'))}")
    print(f"# psg-data benchmarks, {time.strftime('%Y-%m-%d %H:%M')} on {platform.node()} "
          f"({platform.machine()}, {platform.processor() or 'cpu'}, Python {platform.python_version()})")
    failed = 0
    for script in sorted(here.glob("bench_*.py")):
        print(f"\n## {script.stem}")
        sys.stdout.flush()
        rc = subprocess.call([sys.executable, str(script), *flags])
        failed += rc != 0
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
