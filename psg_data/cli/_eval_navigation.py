"""``psg-eval --task navigation`` and ``--task doors``: navigation runs from estimator beliefs."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import click

from psg_data.cli._eval_provenance import provenance

__all__ = ["run_navigation_task", "run_doors_task"]


def run_navigation_task(specs: list[Any], dataset: str | None, setting: str, labels: str, seeds: list[int],
                        n_queries: int, out: Path, no_plots: bool, quiet: bool, reachable_only: bool = False,
                        delta: float = 0.2) -> bool:
    """Object navigation on a dataset: SR / SPL / AR / DIST per method (paper Table "Predictive Navigation")."""
    from psg_data.cli._eval_inputs import resolve_dataset
    from psg_data.errors import EvaluationError
    from psg_data.navigation import run_navigation

    choice = resolve_dataset(dataset, quiet=quiet)
    if choice.kind != "dataset":
        raise EvaluationError("--task navigation needs a dataset with rooms, doors and receptacles (not the "
                              "persistence benchmark); use --dataset demo or a dataset path")
    if labels != "gt":
        raise EvaluationError("--task navigation: the map observations come from the dataset's schedule table; "
                              "--labels other than gt is not supported yet")
    methods = {"oracle": "oracle", "last_seen_map": "last_seen_map"}
    settings = {}
    for s in specs:
        methods[s.label] = s.name
        if s.settings:
            settings[s.label] = dict(s.settings)
    t0 = time.perf_counter()
    res = run_navigation(choice.path, methods, seed=seeds, n_queries=n_queries, setting=setting, out_dir=out,
                         estimator_settings=settings or None, reachable_only=reachable_only, delta=delta)
    res.save(out)
    info = provenance({"task": "navigation", "dataset_label": choice.label, "dataset": str(choice.path),
                       "seconds": round(time.perf_counter() - t0, 2), **res.config})
    (out / "results.json").write_text(json.dumps({"info": info, "summary": json.loads(res.summary.to_json(
        orient="records"))}, indent=1) + "\n", encoding="utf-8")
    res.summary.to_csv(out / "results.csv", index=False)
    if not no_plots and res.env is not None:
        from psg_data.navigation import plot_query

        q = res.queries[seeds[0]][0]
        for label in methods:
            key = (label, seeds[0], q.query_id)
            plot_query(res.env, q, out / f"map_{label}.png", beliefs=res.beliefs.get(key), trail=res.trails.get(key),
                       cache=res.cache, title=f"{label}: {q.object_id} at query {q.query_id}")
    click.echo(f"\nObject navigation on {choice.label} ({n_queries} queries per seed, {setting})")
    click.echo(res.format_table())
    return True


def run_doors_task(specs: list[Any], dataset: str | None, labels: str, seeds: list[int], n_queries: int, out: Path,
                   no_plots: bool) -> bool:
    """Door navigation: every estimator predicts P(open) per door; the planner closes doors below 0.5."""
    import pandas as pd

    from psg_data.errors import EvaluationError
    from psg_data.navigation import door_loop_world, plot_door_query, run_door_navigation

    if dataset not in (None, "door-loop", "door-loop-lab"):
        raise EvaluationError(f"--dataset {dataset}: --task doors runs on the built-in door loop world; "
                              "expected door-loop (weekly door pattern) or door-loop-lab (the lab's door schedule)")
    pattern = "lab" if dataset == "door-loop-lab" else "weekly"
    from psg_data.errors import LabelingError
    from psg_data.labeling import parse_source

    try:
        src = parse_source(labels)
    except LabelingError:
        src = None
    if src is None or src.kind not in ("gt", "noisy") or (src.kind == "noisy" and src.p_m != src.p_f):
        raise EvaluationError(f"--labels {labels}: --task doors takes gt or noisy:P (training door observations "
                              "flipped with probability P)")
    noise = 0.0 if src.kind == "gt" else float(src.p_m)
    if not 0.0 <= noise < 0.5:
        raise EvaluationError(f"--labels {labels}: expected noisy:P with P in [0, 0.5)")
    settings = {s.label: dict(s.settings) for s in specs if s.settings}
    t0 = time.perf_counter()
    tables, records, first = [], [], None
    for seed in seeds:
        world = door_loop_world(seed=seed, noise=noise, pattern=pattern)
        res = run_door_navigation(world, [(s.label, s.name) for s in specs], n_queries=n_queries, seed=seed,
                                  settings=settings or None)
        tables.append(res.table.assign(seed=seed))
        records.append(res.records.assign(seed=seed))
        if first is None:
            first = (world, res)
    per_seed = pd.concat(tables, ignore_index=True)
    cols = ["blocked_rate", "mean_extra_distance_m", "SR", "SPL"]
    g = per_seed.groupby("estimator", sort=False)
    summary = g[cols].mean()
    std = g[cols].std(ddof=1).fillna(0.0)  # one seed: 0
    summary = summary.join(std.add_suffix("_std")).reset_index()
    summary.insert(1, "queries", g["queries"].sum().to_numpy())
    summary.insert(2, "blocked_first_plans", g["blocked_first_plans"].sum().to_numpy())
    summary["seeds"] = len(seeds)
    summary["unseen_doors"] = g["unseen_doors"].first().to_numpy()
    per_seed.to_csv(out / "by_seed.csv", index=False)
    pd.concat(records, ignore_index=True).to_csv(out / "records.csv", index=False)
    summary.to_csv(out / "results.csv", index=False)
    info = provenance({"task": "doors", "dataset_label": dataset or "door-loop", "pattern": pattern,
                       "training_noise": noise, "seeds": seeds, "queries_per_seed": n_queries, "threshold": 0.5,
                       "seconds": round(time.perf_counter() - t0, 2),
                       "estimator_specs": {s.label: {"name": s.name, "settings": dict(s.settings)} for s in specs}})
    (out / "results.json").write_text(json.dumps({"info": info, "summary": json.loads(summary.to_json(
        orient="records"))}, indent=1) + "\n", encoding="utf-8")
    shown = summary.copy()
    for c in ("blocked_rate", "SR", "SPL"):
        shown[c] = (100 * shown[c]).round(1)
    shown["mean_extra_distance_m"] = shown["mean_extra_distance_m"].round(2)
    text = shown[["estimator", "queries", "blocked_first_plans", "blocked_rate", "mean_extra_distance_m", "SR",
                  "SPL"]].rename(columns={"blocked_rate": "blocked %", "mean_extra_distance_m": "extra m"}).to_string(
        index=False)
    text += (f"\nblocked %: first plans through a door closed at the query time; extra m: walked minus shortest "
             f"under the true door states; {len(seeds)} seed(s), training noise {noise}")
    (out / "table.txt").write_text(text + "\n", encoding="utf-8")
    if not no_plots and first is not None:
        world, res = first
        label = specs[0].label
        eps = res.episodes[label]
        pick = next((i for i, (q, e) in enumerate(zip(res.queries, eps)) if not q.doors_open.get("door_ab", True)
                     and not e.first_plan_blocked), 0)
        plot_door_query(world, res.queries[pick], eps[pick], out / f"doors_{label}.png")
    click.echo(f"\nDoor navigation on {dataset or 'door-loop'} ({n_queries} queries per seed, {len(seeds)} seed(s))")
    click.echo(text)
    return True
