"""PredictiveGraph speed against the per-edge loop it replaces.

Graphs: the demo lab (``perpetua_star`` on the ``gt`` training scans: 56 edges, 2 doors) and a
10,000-edge graph (500 synthetic objects x 20 of the lab's receptacles, each filter made by the
lab's fitted estimator and updated with one of the lab's real training streams). Timed, in the
same run and process, as medians of ``--repeat`` repetitions of CPU time (``time.process_time``):

- ``at``: ``g.at(t)`` (a Snapshot: every edge and door) vs the loop
  ``{edge: float(f.predict(np.array([t]))[0]) for edge, f in filters}`` plus the doors;
- ``at x100``: ``g.edge_probabilities(100 times)`` (one vectorised predict per filter) vs the loop
  over times and edges (timed on 10 of the times, x 10: one predict call per edge and time);
- ``locate``: ``g.locate(object, t)`` per query vs the loop over the object's filters and a sort;
- ``update``: ``g.update(one scan's (t, object, receptacle, present) tuples)`` per observation vs
  ``f.update(t, y)`` per observation on the filters directly.

Ratios are loop / graph (> 1: the graph is faster). The 1-minute load average is printed beside
the numbers. Run: ``python bench/bench_graph.py [--quick] [--repeat 5]``; writes bench/out/graph.json.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import time
from pathlib import Path

import numpy as np


def _median_cpu(fn, repeat: int, inner: int = 1) -> float:  # type: ignore[no-untyped-def]
    out = []
    for _ in range(repeat):
        t0 = time.process_time()
        for _ in range(inner):
            fn()
        out.append((time.process_time() - t0) / inner)
    return float(np.median(out))


def _lab_graph():  # type: ignore[no-untyped-def]
    from psg_data.datasets import demo
    from psg_data.graph import PredictiveGraph

    return PredictiveGraph.from_dataset(demo(), "perpetua_star")


def _big_graph(lab, n_objects: int):  # type: ignore[no-untyped-def]
    from psg_data.graph import DatasetTimeline, PredictiveGraph, SceneLayout, source_observations
    from psg_data.loaders import open_dataset

    ds = open_dataset(lab.info["dataset"])
    obs = source_observations(ds, "gt", DatasetTimeline.from_dataset(ds, None, need_schedule=False).map_ids)
    recs = sorted(lab.layout.receptacles)[:20]
    filters = {}
    for i in range(n_objects):
        for k, r in enumerate(recs):
            s = obs.object_streams[(i * 20 + k) % len(obs.object_streams)]
            f = lab.estimator.make_filter((f"obj{i:04d}", r))
            f.update_many(s.t_s, s.y)
            filters[(f"obj{i:04d}", r)] = f
    layout = SceneLayout(lab.layout.rooms, lab.layout.receptacles, lab.layout.doors, {}, lab.timezone,
                         lab.layout.openings)
    return PredictiveGraph(layout, filters, {d: lab.door_filter(d) for d in lab.doors}, estimator=lab.estimator)


def _loop_at(g, t: float) -> dict:  # type: ignore[no-untyped-def]
    ta = np.array([t])
    out = {e: float(g.filter(e).predict(ta)[0]) for e in g.edges}
    out.update({d: float(g.door_filter(d).predict(ta)[0]) for d in g.doors})
    return out


def _measure(g, name: str, t: float, repeat: int) -> dict:  # type: ignore[no-untyped-def]
    edges = g.edges
    filters = [g.filter(e) for e in edges]
    row: dict = {"graph": name, "edges": len(edges), "doors": len(g.doors), "load_1min": os.getloadavg()[0]}
    inner = max(1, 2000 // max(len(edges), 1))
    row["at_graph_s"] = _median_cpu(lambda: g.at(t), repeat, inner)
    row["at_loop_s"] = _median_cpu(lambda: _loop_at(g, t), repeat, inner)
    times = t + np.arange(100) * 600.0
    row["at100_graph_s"] = _median_cpu(lambda: g.edge_probabilities(times), repeat)
    row["at100_loop_s"] = 10 * _median_cpu(lambda: [[float(f.predict(np.array([x]))[0]) for f in filters]
                                                     for x in times[:10]], repeat)  # 10 of the 100 times, x 10
    objs = sorted({o for o, _ in edges})[:20]

    def loop_locate() -> None:
        for o in objs:
            ta = np.array([t])
            bel = {r: float(f.predict(ta)[0]) for r, f in g.filters_of(o).items()}
            sorted(bel, key=lambda r: (-bel[r], r))

    row["locate_graph_s"] = _median_cpu(lambda: [g.locate(o, t) for o in objs], repeat, 5) / len(objs)
    row["locate_loop_s"] = _median_cpu(loop_locate, repeat, 5) / len(objs)
    scan = [(t + 60.0, o, r, int(k % 3 == 0)) for k, (o, r) in enumerate(edges[:200])]

    def graph_update() -> None:
        h = g.copy()
        t0 = time.process_time()
        h.update(scan)
        graph_update.s = time.process_time() - t0  # type: ignore[attr-defined]

    def loop_update() -> None:
        fs = {e: copy.deepcopy(g.filter(e)) for e in edges[:200]}
        t0 = time.process_time()
        for tt, o, r, y in scan:
            fs[(o, r)].update(tt, y)
        loop_update.s = time.process_time() - t0  # type: ignore[attr-defined]

    ups, ls = [], []
    for _ in range(repeat):
        graph_update()
        loop_update()
        ups.append(graph_update.s)  # type: ignore[attr-defined]
        ls.append(loop_update.s)  # type: ignore[attr-defined]
    row["update_graph_s"] = float(np.median(ups)) / len(scan)
    row["update_loop_s"] = float(np.median(ls)) / len(scan)
    row["load_1min_end"] = os.getloadavg()[0]
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="1,000 instead of 10,000 edges, 3 repeats")
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    repeat = 3 if a.quick else a.repeat
    lab = _lab_graph()
    t = float(lab.info["t_train_end_s"]) + 2 * 86400.0
    rows = [_measure(lab, "lab", t, repeat)]
    big = _big_graph(lab, 50 if a.quick else 500)
    rows.append(_measure(big, f"{len(big)} edges", t, repeat))
    print(f"# {time.strftime('%Y-%m-%d %H:%M')} {platform.node()} {platform.processor() or platform.machine()}, "
          "CPU seconds, medians")
    print(f"{'graph':>14} {'what':>16} {'graph':>12} {'loop':>12} {'loop/graph':>10}  load")
    for r in rows:
        for key, what in (("at", "at(t)"), ("at100", "at x100 times"), ("locate", "locate / query"),
                          ("update", "update / obs")):
            gs, ls = r[f"{key}_graph_s"], r[f"{key}_loop_s"]
            print(f"{r['graph']:>14} {what:>16} {gs * 1e3:>10.3f}ms {ls * 1e3:>10.3f}ms {ls / gs:>10.2f}  "
                  f"{r['load_1min']:.1f}-{r['load_1min_end']:.1f}")
    out = Path(__file__).resolve().parent / "out"
    out.mkdir(exist_ok=True)
    (out / "graph.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
