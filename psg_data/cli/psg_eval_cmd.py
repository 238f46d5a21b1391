"""``psg-eval``: score persistence estimators (and navigation with them) on a dataset.

Exit codes: 0 success; 1 bad input, or an estimator returned invalid predictions (the run still
completes for the others and the problems are listed); 2 bad command line.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import click

from psg_data import __version__
from psg_data.cli._common import EXIT_PROBLEMS, Progress, handle_errors, quiet_option, setup_logging

__all__ = ["main"]

log = logging.getLogger(__name__)

DEFAULT_ESTIMATOR = "perpetua_star"
REFERENCE_ESTIMATORS = ("perpetua", "fremen")


def _git_revision() -> str | None:
    here = Path(__file__).resolve().parents[2]
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def _out_dir(out: Path | None, overwrite: bool) -> Path:
    from psg_data.errors import EvaluationError

    if out is None:
        return Path("psg-eval-out") / time.strftime("%Y%m%d-%H%M%S")
    if out.exists() and not overwrite:
        raise EvaluationError(f"{out}: output exists; pass --overwrite to replace it (or choose another --out)")
    return out


def _finish_dir(tmp: Path, out: Path) -> None:
    """Move the completed results from ``tmp`` into ``out`` (replacing it) in one rename."""
    if out.exists():
        old = out.with_name(out.name + ".old")
        shutil.rmtree(old, ignore_errors=True)
        os.replace(out, old)
        os.replace(tmp, out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
        os.replace(tmp, out)


@click.group(invoke_without_command=True, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--dataset", "dataset", default=None, metavar="PATH|demo|persistence-benchmark",
              help="Dataset to evaluate on (default: demo, the built-in synthetic lab).")
@click.option("--estimator", "-e", "estimators", multiple=True, metavar="NAME[:key=value,...]",
              help=f"Estimator to score (repeatable; default {DEFAULT_ESTIMATOR}). Settings after ':'.")
@click.option("--references/--no-references", default=True, show_default=True,
              help=f"Also score the reference methods ({', '.join(REFERENCE_ESTIMATORS)}) for the paper's table.")
@click.option("--task", type=click.Choice(["persistence", "navigation", "doors"]), default="persistence",
              show_default=True, help="doors: planning around predicted closed doors (the door loop world).")
@click.option("--setting", type=click.Choice(["predictive", "adaptive"]), default="adaptive", show_default=True,
              help="adaptive: test observations update the estimators online; predictive: they do not.")
@click.option("--labels", default="gt", show_default=True, metavar="gt|privileged|noisy:P|detections:FILE",
              help="Observation source (non-gt sources are read from the dataset's label tables).")
@click.option("--seeds", type=click.IntRange(1, 100), default=3, show_default=True,
              help="Seeds 0..N-1 (benchmark: one draw per seed; datasets: estimator seeds / query sets).")
@click.option("--queries", type=click.IntRange(1), default=250, show_default=True, help="Navigation queries per seed.")
@click.option("--delta", type=click.FloatRange(0.0, 1.0), default=0.2, show_default=True,
              help="Navigation: abort (declare the object absent) when the best receptacle belief is below this.")
@click.option("--reachable-only", is_flag=True,
              help="Navigation: redraw queries whose present target is unreachable under the true door states "
                   "(default: keep them and report them as unreachable).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output directory (default: psg-eval-out/<timestamp>).")
@click.option("--overwrite", is_flag=True, help="Replace an existing --out directory.")
@click.option("--jobs", "-j", type=int, default=1, show_default=True, help="Worker processes (-1: all CPUs).")
@click.option("--list-estimators", is_flag=True, help="List registered estimators (built-ins and plugins) and exit.")
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@quiet_option
@click.version_option(__version__, prog_name="psg-eval")
@click.pass_context
@handle_errors
def main(ctx: click.Context, dataset: str | None, estimators: tuple[str, ...], references: bool, task: str,
         setting: str, labels: str, seeds: int, queries: int, delta: float, reachable_only: bool, out: Path | None,
         overwrite: bool, jobs: int,
         list_estimators: bool, no_plots: bool, quiet: bool) -> None:
    """Score persistence estimators like the paper's Table I (MAE, B-Acc, F1, mean +- std over seeds).

    Writes results.json, results.csv, summary.csv, breakdowns per object / receptacle / weekday and
    PNG plots (belief vs ground truth over the test window, per-estimator bars).

    \b
    Examples:
      psg-eval --estimator perpetua_star                       # the built-in lab
      psg-eval --dataset persistence-benchmark -e perpetua_star -e perpetua_star_oracle
      psg-eval --dataset /data/lab --labels privileged -e my_plugin:alpha=0.3 --out res/
      psg-eval --task navigation -e perpetua_star -e fremen    # SR / SPL / AR / DIST
      psg-eval --task doors -e perpetua_star --no-references   # blocked first plans, extra metres
      psg-eval compare res/a res/b                             # tabulate earlier runs
    """
    if ctx.invoked_subcommand is not None:
        return
    setup_logging(quiet)
    from psg_data.cli._eval_inputs import check_estimators, parse_estimator_spec

    if list_estimators:
        from psg_data.estimators import list_estimators as _list

        for name in _list():
            click.echo(name)
        return
    specs = [parse_estimator_spec(e) for e in (estimators or (DEFAULT_ESTIMATOR,))]
    if references:
        have = {s.name for s in specs}
        specs += [parse_estimator_spec(r) for r in REFERENCE_ESTIMATORS if r not in have]
    check_estimators(specs)
    out_dir = _out_dir(out, overwrite)
    tmp = out_dir.with_name(out_dir.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        if task == "persistence":
            ok = _run_persistence(specs, dataset, setting, labels, list(range(seeds)), jobs, tmp, no_plots, quiet)
        elif task == "doors":
            ok = _run_doors(specs, dataset, labels, list(range(seeds)), queries, tmp, no_plots)
        else:
            ok = _run_navigation(specs, dataset, setting, labels, list(range(seeds)), queries, tmp, no_plots, quiet,
                                 reachable_only, delta)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _finish_dir(tmp, out_dir)
    click.echo(f"results written to {out_dir}/")
    if not ok:
        sys.exit(EXIT_PROBLEMS)


def _provenance(extra: dict[str, Any]) -> dict[str, Any]:
    from psg_data.schemas import FORMAT_VERSION

    return {"psg_data_version": __version__, "git_revision": _git_revision(), "format_version": FORMAT_VERSION,
            "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]), "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            **extra}


def _run_persistence(specs: list[Any], dataset: str | None, setting: str, labels: str, seeds: list[int], jobs: int,
                     out: Path, no_plots: bool, quiet: bool) -> bool:
    from psg_data.cli._eval_inputs import persistence_tasks, resolve_dataset, with_hints
    from psg_data.metrics import (
        RegistryFactory,
        choose_plot_edges,
        evaluate_persistence,
        format_persistence_table,
        merge_results,
        plot_beliefs,
        plot_metric_bars,
        write_persistence_results,
    )

    choice = resolve_dataset(dataset, quiet=quiet)
    tasks, info = persistence_tasks(choice, labels=labels, seeds=seeds, quiet=quiet)
    n_edges = len(tasks[0].ground_truth)
    prog = Progress("evaluating", total=len(specs) * len(seeds) * n_edges, unit="edge runs", quiet=quiet)
    offset = 0
    results = []
    plot_edges = choose_plot_edges(tasks[0].ground_truth, k=4)
    run_seeds = [[s] for s in seeds] if len(tasks) > 1 else [seeds]
    for task, task_seeds in zip(tasks, run_seeds):
        factories = {s.label: RegistryFactory(s.name, with_hints(s, task.estimator_hints).settings) for s in specs}

        def progress(done: int, total: int, base: int = offset) -> None:
            prog.done = base + done
            prog.update(0)

        results.append(evaluate_persistence(
            factories, task.train_streams, task.test_streams, task.ground_truth, val_streams=task.val_streams,
            setting=setting, timezone=task.timezone, seeds=task_seeds, jobs=jobs, progress=progress,
            keep_predictions=plot_edges if task is tasks[0] else ()))
        offset += len(specs) * len(task_seeds) * len(task.ground_truth)
    prog.close()
    result = results[0] if len(results) == 1 else merge_results(results)
    info = _provenance({"task": "persistence", "dataset_label": choice.label, "labels": labels, **info,
                        "estimator_specs": {s.label: {"name": s.name, "settings": dict(s.settings)} for s in specs}})
    write_persistence_results(result, out, info=info)
    if not no_plots:
        plot_beliefs(result.traces, out / "belief.png", timezone=tasks[0].timezone)
        plot_metric_bars(result, out / "bars.png")
    click.echo(f"\nPersistence estimation on {choice.label} ({info.get('edges')} edges, labels {labels}, "
               f"{setting}, seeds {seeds[0]}..{seeds[-1]})")
    click.echo(format_persistence_table(result))
    if result.errors:
        click.echo(f"\n{len(result.errors)} problem(s) (see results.json 'errors'):", err=True)
        for e in result.errors[:20]:
            click.echo(f"error: {e.message}", err=True)
    return result.ok


def _run_navigation(specs: list[Any], dataset: str | None, setting: str, labels: str, seeds: list[int],
                    n_queries: int, out: Path, no_plots: bool, quiet: bool, reachable_only: bool = False,
                    delta: float = 0.2) -> bool:
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
    info = _provenance({"task": "navigation", "dataset_label": choice.label, "dataset": str(choice.path),
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


def _run_doors(specs: list[Any], dataset: str | None, labels: str, seeds: list[int], n_queries: int, out: Path,
               no_plots: bool) -> bool:
    """Door navigation (issue "doors"): every estimator predicts P(open) per door; the planner closes doors below 0.5."""
    import pandas as pd

    from psg_data.errors import EvaluationError
    from psg_data.navigation import door_loop_world, plot_door_query, run_door_navigation

    if dataset not in (None, "door-loop", "door-loop-lab"):
        raise EvaluationError(f"--dataset {dataset}: --task doors runs on the built-in door loop world; "
                              "expected door-loop (weekly door pattern) or door-loop-lab (the lab's door schedule)")
    pattern = "lab" if dataset == "door-loop-lab" else "weekly"
    if labels == "gt":
        noise = 0.0
    elif labels.startswith("noisy:"):
        try:
            noise = float(labels[len("noisy:"):])
        except ValueError:
            noise = -1.0
        if not 0.0 <= noise < 0.5:
            raise EvaluationError(f"--labels {labels}: expected noisy:P with P in [0, 0.5)")
    else:
        raise EvaluationError(f"--labels {labels}: --task doors takes gt or noisy:P (training door observations)")
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
    std = g[cols].std(ddof=1).fillna(0.0) if len(seeds) > 1 else g[cols].mean() * 0.0
    summary = summary.join(std.add_suffix("_std")).reset_index()
    summary.insert(1, "queries", g["queries"].sum().to_numpy())
    summary.insert(2, "blocked_first_plans", g["blocked_first_plans"].sum().to_numpy())
    summary["seeds"] = len(seeds)
    summary["unseen_doors"] = g["unseen_doors"].first().to_numpy()
    per_seed.to_csv(out / "by_seed.csv", index=False)
    pd.concat(records, ignore_index=True).to_csv(out / "records.csv", index=False)
    summary.to_csv(out / "results.csv", index=False)
    info = _provenance({"task": "doors", "dataset_label": dataset or "door-loop", "pattern": pattern,
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


@main.command("compare")
@click.argument("dirs", nargs=-1, required=True, type=click.Path(path_type=Path))
@handle_errors
def compare_cmd(dirs: tuple[Path, ...]) -> None:
    """Tabulate earlier psg-eval runs side by side (reads each DIR/results.json).

    Persistence, navigation and door runs may be mixed: each task gets its own table.

    \b
    Example:
      psg-eval compare psg-eval-out/run1 psg-eval-out/run2
    """
    from psg_data.errors import EvaluationError

    tables: dict[str, list[list[str]]] = {"persistence": [], "navigation": [], "doors": []}
    for d in dirs:
        p = d / "results.json"
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise EvaluationError(f"{p}: missing; expected a psg-eval output directory") from None
        except json.JSONDecodeError as exc:
            raise EvaluationError(f"{p}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
        info = data.get("info", {})
        task = info.get("task", "persistence")
        if task not in tables or "summary" not in data:
            raise EvaluationError(f"{p}: not a psg-eval result (expected task persistence, navigation or doors)")
        label = str(info.get("dataset_label", "?"))
        if task == "persistence":
            for name, metrics in data["summary"].items():
                def cell(m: str, metrics: dict[str, Any] = metrics) -> str:
                    st = metrics.get(m) or {}
                    mu, sd = st.get("mean"), st.get("std")
                    return "-" if mu is None else f"{mu:.3f} +- {0.0 if sd is None else sd:.3f}"
                tables[task].append([d.name, name, label, str(data.get("config", {}).get("setting")),
                                     str(info.get("labels", "?")), cell("mae"), cell("balanced_accuracy"), cell("f1"),
                                     str((metrics.get("mae") or {}).get("n", "?"))])
        elif task == "navigation":
            for r in data["summary"]:
                def pct(k: str, r: dict[str, Any] = r) -> str:
                    mu, sd = r.get(f"{k}_mean"), r.get(f"{k}_std")
                    return "-" if mu is None else f"{100 * mu:.1f} +- {100 * (sd or 0.0):.1f}"
                dist = r.get("absent_dist_m_mean")
                tables[task].append([d.name, str(r["method"]), label, str(info.get("setting", "?")), pct("static_sr"),
                                     pct("dynamic_sr"), pct("absent_ar"), "-" if dist is None else f"{dist:.2f}",
                                     pct("overall_sr"), pct("overall_spl"), str(r.get("n_seeds", "?"))])
        else:
            for r in data["summary"]:
                tables[task].append([d.name, str(r["estimator"]), label, f"{100 * r['blocked_rate']:.1f}",
                                     f"{r['mean_extra_distance_m']:.2f}", f"{100 * r['SR']:.1f}",
                                     f"{100 * r['SPL']:.1f}", str(r.get("seeds", "?"))])
    headers = {
        "persistence": ["run", "method", "dataset", "setting", "labels", "MAE", "B-Acc", "F1", "seeds"],
        "navigation": ["run", "method", "dataset", "setting", "static SR %", "dynamic SR %", "AR %", "DIST m",
                       "overall SR %", "overall SPL %", "seeds"],
        "doors": ["run", "estimator", "dataset", "blocked %", "extra m", "SR %", "SPL %", "seeds"],
    }
    first = True
    for task, rows in tables.items():
        if not rows:
            continue
        header = headers[task]
        if not first:
            click.echo("")
        first = False
        click.echo(f"[{task}]")
        w = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
        click.echo("  ".join(h.ljust(w[i]) for i, h in enumerate(header)))
        click.echo("  ".join("-" * x for x in w))
        for r in rows:
            click.echo("  ".join(c.ljust(w[i]) for i, c in enumerate(r)))
