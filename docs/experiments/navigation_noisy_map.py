"""Navigation (predictive, reachable-only) with 10 % flipped map observations (P_M = P_F = 0.1).

Run: python docs/experiments/navigation_noisy_map.py [ESTIMATOR[:key=value,...] ...]

`psg-eval --task navigation` takes only ground-truth map observations until navigation reads label
sources (issue 19); this script flips each map observation of the built-in lab with probability
0.1 (seeded) and runs the same predictive, reachable-only protocol (250 queries x seeds 0-2).
"""
import dataclasses
import sys

import numpy as np

from psg_data.datasets import demo
from psg_data.estimators import EdgeStream
from psg_data.navigation import run_navigation
from psg_data.navigation._env import NavigationEnv
env = NavigationEnv.coerce(demo())
rng = np.random.default_rng(12345)
noisy = [EdgeStream(s.edge, s.t_s, np.where(rng.random(len(s)) < 0.1, 1 - s.y, s.y).astype(np.int8), dict(s.meta))
         for s in env.map_streams]
env2 = dataclasses.replace(env, map_streams=noisy)
print(f"{sum(len(s) for s in noisy)} map observations, "
      f"{sum(int(np.sum(a.y != b.y)) for a, b in zip(noisy, env.map_streams))} flipped")
methods = {"oracle": "oracle", "last_seen_map": "last_seen_map"}
settings = {}
for a in sys.argv[1:]:
    name, _, rest = a.partition(":")
    methods[a] = name
    if rest:
        settings[a] = {k: (None if v == "none" else v) for k, v in (kv.split("=") for kv in rest.split(","))}
res = run_navigation(env2, methods, seed=[0, 1, 2], n_queries=250, setting="predictive", reachable_only=True,
                     estimator_settings=settings or None)
print(res.format_table())
