"""The door task's two rules on the demo lab: ``run_door_navigation`` with the threshold rule vs the
expected-cost rule (:func:`psg_data.maps.expected_cost_route`), 250 queries, ``perpetua_star``.

Prints both wall times (best of two after a warm-up) and their ratio. Run: ``python bench/bench_door_rules.py``.
"""

import time
from psg_data.datasets import demo
from psg_data.navigation import DoorWorld, run_door_navigation
w = DoorWorld.from_dataset(demo())
run_door_navigation(w, ["perpetua_star"], n_queries=250, seed=0, baselines=(), rules=("threshold", "expected_cost"))  # warm caches
out = {}
for rules in [("threshold",), ("expected_cost",), ("threshold",), ("expected_cost",)]:
    t0 = time.perf_counter()
    run_door_navigation(w, ["perpetua_star"], n_queries=250, seed=0, baselines=(), rules=rules)
    out.setdefault(rules[0], []).append(time.perf_counter() - t0)
print({k: [round(x, 2) for x in v] for k, v in out.items()}, "ratio", round(min(out["expected_cost"]) / min(out["threshold"]), 2))
print(open("/proc/loadavg").read())
