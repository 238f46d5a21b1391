"""``psg-eval --task navigation`` and ``--task doors``: navigation runs from estimator beliefs."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import click

from psg_data.cli._eval_provenance import provenance

__all__ = ["run_navigation_task", "run_doors_task", "navigation_options", "door_task_options"]


def navigation_options(protocol: str, *, labels: str, seeds: list[int], queries: int | None, setting: str,
                       delta: float, reachable_only: bool, door_belief: str | None) -> Any:
    """The :class:`~psg_data.navigation.NavigationOptions` of the command line (checked before any work)."""
    from psg_data.errors import EvaluationError
    from psg_data.navigation import NavigationOptions

    over: dict[str, Any] = {"labels": labels, "seeds": tuple(seeds), "setting": setting, "delta": delta}
    if queries is not None:
        if protocol == "paper-real":
            raise EvaluationError("--queries: the paper-real protocol has 25 queries (10 static, 10 dynamic, 5 absent) "
                                  "per seed; use --seeds for more query sets")
        over["n_queries"] = queries
    if reachable_only:
        over["reachable_only"] = True
    if door_belief is not None:
        over["door_belief"] = door_belief.replace("-", "_")
    return NavigationOptions.preset(protocol, **over)


def door_task_options(*, labels: str, seeds: list[int], queries: int | None, setting: str = "adaptive") -> Any:
    """The :class:`~psg_data.navigation.DoorTaskOptions` of the command line."""
    from psg_data.errors import EvaluationError, LabelingError
    from psg_data.labeling import parse_source
    from psg_data.navigation import DoorTaskOptions

    try:
        parse_source(labels)
    except LabelingError as exc:
        raise EvaluationError(str(exc)) from None
    return DoorTaskOptions(labels=labels, seeds=tuple(seeds), n_queries=queries or 250, setting=setting)


def _dataset(dataset: str | None, labels: str, quiet: bool, task: str) -> Any:
    """The dataset choice; the cached demo lab is labelled on first use with a stored source."""
    from psg_data.cli._eval_inputs import _label_demo_if_needed, resolve_dataset
    from psg_data.errors import EvaluationError

    if dataset in ("door-loop", "door-loop-lab"):
        raise EvaluationError(f"--dataset {dataset}: the door loop world is a unit-test world now; --task doors runs on "
                              "a dataset's own map (--dataset demo or a dataset path)")
    choice = resolve_dataset(dataset, quiet=quiet)
    if choice.kind != "dataset":
        raise EvaluationError(f"--task {task} needs a dataset with rooms, doors and receptacles (not the persistence "
                              "benchmark); use --dataset demo or a dataset path")
    kind = labels.split(":", 1)[0]
    if choice.label == "demo lab" and kind in ("privileged", "detections", "observed"):
        from psg_data.loaders import open_dataset

        _label_demo_if_needed(open_dataset(choice.path), labels, quiet)
    return choice


def _methods(specs: list[Any], choice: Any) -> tuple[dict[str, str], dict[str, dict[str, Any]]]:
    """Method labels -> names, and each one's settings with the dataset's hints (e.g. the generator
    model for process_oracle); estimators that need a hint the dataset lacks are refused here."""
    from psg_data.cli._eval_inputs import dataset_hints, require_hints, with_hints
    from psg_data.loaders import open_dataset

    hints = dataset_hints(open_dataset(choice.path))
    require_hints(specs, hints, choice.label)
    methods = {"oracle": "oracle", "last_seen_map": "last_seen_map"}
    settings = {}
    for s in specs:
        methods[s.label] = s.name
        s = with_hints(s, hints)
        if s.settings:
            settings[s.label] = dict(s.settings)
    return methods, settings


def run_navigation_task(specs: list[Any], dataset: str | None, options: Any, out: Path, no_plots: bool,
                        quiet: bool) -> bool:
    """Object navigation on a dataset: SR / SPL / AR / DIST per method (the paper's navigation tables)."""
    from psg_data.navigation import run_navigation

    choice = _dataset(dataset, options.labels, quiet, "navigation")
    methods, settings = _methods(specs, choice)
    t0 = time.perf_counter()
    res = run_navigation(choice.path, methods, options, out_dir=out, estimator_settings=settings or None)
    info = provenance({"task": "navigation", "dataset_label": choice.label, "dataset": str(choice.path),
                       "seconds": round(time.perf_counter() - t0, 2), **res.config})
    (out / "results.json").write_text(json.dumps({"info": info, "summary": json.loads(res.summary.to_json(
        orient="records"))}, indent=1, default=str) + "\n", encoding="utf-8")
    res.summary.to_csv(out / "results.csv", index=False)
    if not no_plots and res.env is not None:
        from psg_data.navigation import plot_query

        sd = options.seeds[0]
        q = res.queries[sd][0]
        for label in methods:
            key = (label, sd, q.query_id)
            plot_query(res.env, q, out / f"map_{label}.png", beliefs=res.beliefs.get(key), trail=res.trails.get(key),
                       cache=res.cache, title=f"{label}: {q.object_id} at query {q.query_id}")
    n = options.n_queries
    click.echo(f"\nObject navigation on {choice.label} ({n} queries per seed, protocol {options.protocol}, "
               f"{options.setting}, labels {options.labels}, doors {options.door_belief})")
    click.echo(res.format_table())
    return True


def run_doors_task(specs: list[Any], dataset: str | None, options: Any, out: Path, no_plots: bool,
                   quiet: bool) -> bool:
    """Door navigation on a dataset's own map, and objects behind predicted-closed doors."""
    from psg_data.navigation import run_door_task

    choice = _dataset(dataset, options.labels, quiet, "doors")
    settings = {s.label: dict(s.settings) for s in specs if s.settings}
    t0 = time.perf_counter()
    res = run_door_task(choice.path, [(s.label, s.name) for s in specs], options, settings=settings or None)
    res.per_seed.to_csv(out / "by_seed.csv", index=False)
    res.records.to_csv(out / "records.csv", index=False)
    res.summary.to_csv(out / "results.csv", index=False)
    text = res.format_table()
    objects_text = ""
    if res.objects is not None:
        from psg_data.navigation import walk_summary

        res.objects.save(out / "objects")
        walk = walk_summary(res.objects)
        walk.to_csv(out / "objects" / "walk.csv", index=False)
        shown = walk.round(2).astype(object).where(walk.notna(), "-").rename(columns={"walked_m": "walked m", "walked_unreachable_m":
                                                          "walked m (unreachable)", "lost_vs_all_open": "lost",
                                                          "won_vs_all_open": "won"})
        objects_text = (res.objects.format_table() + "\n\n" + shown.to_string(index=False) +
                        "\nwalked m: mean per query; (unreachable): towards targets no route reached (left out of SR / "
                        "SPL); lost / won: queries found with all doors open and not with these doors / the reverse")
    info = provenance({"task": "doors", "dataset_label": choice.label, "dataset": str(choice.path),
                       **options.to_dict(), "world": res.world.info, "seconds": round(time.perf_counter() - t0, 2),
                       "estimator_specs": {s.label: {"name": s.name, "settings": dict(s.settings)} for s in specs}})
    (out / "results.json").write_text(json.dumps({"info": info, "summary": json.loads(res.summary.to_json(
        orient="records"))}, indent=1, default=str) + "\n", encoding="utf-8")
    (out / "table.txt").write_text(text + ("\n\n" + objects_text if objects_text else "") + "\n", encoding="utf-8")
    if not no_plots:
        _door_figures(res, specs[0], out)
    click.echo(f"\nDoor navigation on {choice.label} ({options.n_queries} queries per seed, {len(options.seeds)} "
               f"seed(s)): first plans through closed doors")
    click.echo(text)
    if objects_text:
        click.echo(f"\nObjects behind predicted-closed doors ({options.n_queries} object queries per seed, "
                   f"{options.setting}; each estimator with all doors open, its predicted doors, the true doors)")
        click.echo(objects_text)
    return True


def _door_figures(res: Any, spec: Any, out: Path) -> None:
    """doors_<label>.png (an object query planned around a predicted-closed door) and
    door_plan_<label>.png (a door query whose all-open plan ran into a closed door)."""
    from psg_data.navigation import pick_door_example, plot_door_example, plot_door_query

    label = spec.label
    first = res.first
    eps, base = first.episodes[label], first.episodes["all_open"]
    pick = next((i for i, (e, b) in enumerate(zip(eps, base)) if b.first_plan_blocked and not e.first_plan_blocked
                 and e.success), None)
    pick = pick if pick is not None else next((i for i, b in enumerate(base) if b.first_plan_blocked), 0)
    plot_door_query(res.world, first.queries[pick], eps[pick], out / f"door_plan_{label}.png", baseline=base[pick])
    if res.objects is not None:
        ex = pick_door_example(res.objects, label)
        if ex is not None:
            plot_door_example(res.objects, label, ex, out / f"doors_{label}.png", estimator=spec.name,
                              settings=dict(spec.settings) or None)
