"""``psg-eval``: score persistence estimators (and navigation with them) on a dataset.

Exit codes: 0 success; 1 bad input or output, or an estimator returned invalid predictions (the run
still completes for the others and the problems are listed); 2 bad command line; 130 interrupted
(see ``psg_data.cli._errors``).
"""

from __future__ import annotations

import logging
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import click

from psg_data import __version__
from psg_data._executors import SCHEDULER_HELP, check_scheduler
from psg_data.cli._common import EXIT_PROBLEMS, handle_errors, quiet_option, setup_logging
from psg_data.cli._errors import ContractGroup, check_jobs
from psg_data.cli._eval_sim_navigation import check_reading_options
from psg_data.cli._eval_sim_navigation import reading_options as sim_reading_options
from psg_data.cli._label_source import LabelSourceType
from psg_data.cli._seeds import SeedsType

__all__ = ["main"]

log = logging.getLogger(__name__)

DEFAULT_ESTIMATOR = "perpetua_star"
ESTIMATOR_TIMEOUT_S = 600.0
"""Default ``--estimator-timeout``, seconds: ``psg_data.estimators._guard.DEFAULT_TIMEOUT_S`` (a copy: --help
stays light)."""
TABLE_FORMATS = ("text", "markdown", "latex")
"""``--format`` of the printed table (``psg_data.evaluation._table_formats``)."""
COMPARE_FORMATS = ("text", "csv", "json", "markdown", "latex")
"""``compare --format`` (``psg_data.evaluation._tables.COMPARE_FORMATS``)."""


def _out_dir(out: Path | None, overwrite: bool, inputs: list[Path | None]) -> Path:
    """The results folder: ``--out`` (checked by the safe-output rule) or a new ``psg-eval-out/<timestamp>``."""
    from psg_data.writers._safe_output import check_output

    if out is None:
        base = Path("psg-eval-out") / time.strftime("%Y%m%d-%H%M%S")
        out, k = base, 1
        while out.exists() or out.with_name(out.name + ".partial").exists():
            k += 1
            out = base.with_name(f"{base.name}-{k}")
        overwrite = False
    check_output(out, overwrite=overwrite, kind="results", inputs=inputs)
    return out


def _eval_inputs(dataset: str | None, labels: str) -> list[Path | None]:
    """Paths psg-eval reads (``--out`` may not be, contain or lie inside one)."""
    paths: list[Path | None] = []
    from psg_data.cli._eval_state import is_state_benchmark

    if dataset not in (None, "demo", "persistence-benchmark", "navigation-benchmark", "door-loop", "door-loop-lab") \
            and not is_state_benchmark(dataset):
        paths.append(Path(dataset))  # type: ignore[arg-type]
    if is_state_benchmark(dataset):
        import os

        from psg_data.datasets import cache_dir

        paths.append(cache_dir())
        if os.environ.get("PSG_DATA_SOURCES"):
            paths.append(Path(os.environ["PSG_DATA_SOURCES"]))
    if labels.startswith("detections:"):
        paths.append(Path(labels.split(":", 1)[1]))
    if dataset in (None, "demo", "navigation-benchmark"):
        from psg_data.datasets import cache_dir

        paths.append(cache_dir())
    return paths


def _check_rerun(path: Path | None, task: str, overwrite: bool, inputs: list[Path | None]) -> None:
    from psg_data.errors import EvaluationError
    from psg_data.writers._safe_output import check_file_output

    if path is None:
        return
    if task != "persistence":
        raise EvaluationError(f"--rerun: beliefs are recorded for --task persistence, not {task}")
    check_file_output(path, overwrite=overwrite, kind="rrd", inputs=inputs)
    from psg_data.viewer._recording import import_rerun

    import_rerun()  # says which extra to install before any work is done


@click.group(cls=ContractGroup, invoke_without_command=True, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--dataset", "dataset", default=None,
              metavar="PATH|demo|persistence-benchmark|navigation-benchmark|door-benchmark|room-presence-benchmark",
              help="Dataset to evaluate on (default: demo, the built-in synthetic lab; navigation-benchmark: 15 "
                   "procedural houses, hourly steps, a shifted test week, each scene a draw; door-benchmark, "
                   "room-presence-benchmark: the public real benchmarks, read from $PSG_DATA_SOURCES or fetched by "
                   "pinned checksum, settings after ':' e.g. door-benchmark:stamps=utc,patrol=8-18/1h).")
@click.option("--estimator", "-e", "estimators", multiple=True, metavar="NAME[:key=value,...]",
              help=f"Estimator to score (repeatable; default {DEFAULT_ESTIMATOR}). Settings after ':'.")
@click.option("--references/--no-references", default=True, show_default=True,
              help="Also score the paper's methods (perpetua_star, perpetua, fremen) and the reference rows: the "
                   "ceiling (process_oracle where the dataset stores its generator model, else the ground truth), "
                   "baselines and chance. --no-references scores only the -e estimators.")
@click.option("--task", type=click.Choice(["persistence", "navigation", "doors"]), default="persistence",
              show_default=True, help="doors: planning around predicted closed doors on the dataset's own map.")
@click.option("--setting", type=click.Choice(["predictive", "adaptive"]), default="adaptive", show_default=True,
              help="adaptive: test observations update the estimators online (see --horizon); predictive: they do not.")
@click.option("--horizon", default="auto", show_default=True, metavar="auto|DURATION",
              help="Adaptive persistence: a prediction at t uses the observations up to t - HORIZON "
                   "(0, 30min, 2h, 1d). auto: one scan interval of the dataset (the lab: 2 h); the persistence "
                   "benchmark: 0 (the paper).")
@click.option("--windows", default="auto", show_default=True, metavar="auto|HH[:MM]-HH[:MM][,...]",
              help="Scoring windows, local hours (e.g. 9-17): time integrals and navigation / door queries stay inside "
                   "them. auto: the dataset's operating hours (the lab: 09:00-17:00; a converted dataset: the hours "
                   "its scans cover).")
@click.option("--weighting", type=click.Choice(["auto", "windows", "reference"]), default="auto", show_default=True,
              help="windows: integrals bounded by the scoring windows; reference: the plain trapezoid over the whole "
                   "span (the Perpetua reference). auto: reference for the persistence benchmark, windows otherwise.")
@click.option("--labels", default="gt", show_default=True, metavar="gt|privileged|noisy:P|detections:FILE|observed",
              type=LabelSourceType(),
              help="Observation source: gt (the schedule); noisy:P[,P_F]: the schedule at every scan with each "
                   "observation flipped (seeded; the paper's noised ground truth, the same in every task); "
                   "privileged, detections:FILE, observed (door states read from the depth; doors only) from the "
                   "dataset's labels table (psg-data label). Scoring always uses the schedule.")
@click.option("--protocol", type=click.Choice(["sim", "paper-real", "paper-sim-predictive", "paper-sim-adaptive",
                                              "patrol", "published"]),
              default=None,
              help="The real benchmarks (door-benchmark, room-presence-benchmark): patrol (default: observations only "
                   "at a robot's patrol times, 09:00-17:00 every 2 h, scored in those hours) or published (the "
                   "authors' protocol: fit on the dense training weeks, forecast each test week, mean squared error). "
                   "Navigation queries (default sim): sim (--queries per seed, random starts, natural mix) or "
                   "paper-real (25: 10 "
                   "static, 10 dynamic, 5 absent, one fixed start, adaptive, predicted doors; the paper's real-world "
                   "table); with --dataset navigation-benchmark: paper-sim-predictive (250 queries over 10 unshifted "
                   "houses) or paper-sim-adaptive (125 queries over 5 houses with the shifted test week, filters fed "
                   "the test week up to each query's last map update, an agent that adapts while it walks).")
@click.option("--quick", is_flag=True,
              help="With a paper-sim protocol: its small form (2 scenes, 6 queries each; for CI and a first look).")
@sim_reading_options  # --agent-memory, --absence, --last-map, --queries-per-scene (paper-sim protocols)
@click.option("--door-belief", type=click.Choice(["truth", "predicted", "last-map", "all-open"]), default=None,
              help="Navigation: door states the agent plans with (default: truth for sim, predicted for paper-real).")
@click.option("--seeds", type=SeedsType(), default=None, metavar="N|S,S,...|A-B",
              help="Persistence: estimator seeds for estimators whose fit depends on the seed (default: 3 for those, "
                   "1 for the others). Navigation and doors: query sets (default 3). A count N means seeds 0..N-1; "
                   "a list (0,3,5) or an inclusive range (3-7; one seed: 3-3) picks them.")
@click.option("--lab-seeds", type=SeedsType(), default=None, metavar="N|S,S,...|A-B",
              help="Persistence: regenerate the synthetic dataset with these seeds (a count N: 0..N-1; a list or "
                   "range as for --seeds; the built-in lab: new layout and schedules, labels gt or noisy:P; the "
                   "benchmark: new draws) and report the t-interval over the draws.")
@click.option("--label-seed", type=click.IntRange(0), default=0, show_default=True,
              help="Seed of the noisy:P flips (the noise draw; and of the navigation agent's sightings); recorded "
                   "in results.json.")
@click.option("--queries", type=click.IntRange(1), default=None,
              help="Navigation / door queries per seed (default 250; the paper-real protocol has 25).")
@click.option("--delta", default="0.2", show_default=True, metavar="D|D1,D2,...",
              help="Navigation: abort (declare the object absent) when the best receptacle belief is below D. A list "
                   "(0.05,0.1,0.2,0.3) sweeps it: a table per delta and SR / AR against delta (delta_sweep.png).")
@click.option("--reachable-only", is_flag=True,
              help="Navigation: redraw queries whose present target is unreachable under the true door states "
                   "(default: keep them and report them as unreachable).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output directory (default: psg-eval-out/<timestamp>).")
@click.option("--overwrite", is_flag=True,
              help="Replace an existing --out folder written by psg-eval (or an empty one); never the dataset or "
                   "a folder holding other files.")
@click.option("--jobs", "-j", type=int, default=1, show_default=True, callback=check_jobs,
              help="Worker processes (-1: all CPUs).")
@click.option("--scheduler", default=None, metavar="local|tcp://HOST:PORT", help=SCHEDULER_HELP)
@click.option("--rerun", "rerun_file", type=click.Path(dir_okay=False, path_type=Path), default=None,
              metavar="FILE.rrd", help="Also save every estimator's beliefs over time for the scored edges (first "
                                       "seed) as a Rerun recording (needs psg-data[viewer]).")
@click.option("--estimator-timeout", type=click.FloatRange(min=0), default=ESTIMATOR_TIMEOUT_S, show_default=True,
              metavar="SECONDS", help="Time limit of one call into a plugin estimator (fit, predict, ...; 0: none): "
                                      "a plugin that runs longer is reported and the other estimators are scored.")
@click.option("--list-estimators", is_flag=True, help="List registered estimators (built-ins and plugins) and exit.")
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@click.option("--format", "table_format", type=click.Choice(TABLE_FORMATS), default="text", show_default=True,
              help="How the table is printed: text, or markdown / latex (booktabs) to paste into a paper. The files "
                   "written (table.txt, results.json, CSV) are the same.")
@quiet_option
@click.version_option(__version__, prog_name="psg-eval")
@click.pass_context
@handle_errors
def main(ctx: click.Context, dataset: str | None, estimators: tuple[str, ...], references: bool, task: str,
         setting: str, horizon: str, windows: str, weighting: str, labels: str, protocol: str | None,
         door_belief: str | None, seeds: tuple[int, ...] | None, lab_seeds: tuple[int, ...] | None,
         label_seed: int, queries: int | None, delta: str, reachable_only: bool, out: Path | None, overwrite: bool,
         quick: bool,
         jobs: int, scheduler: str | None, rerun_file: Path | None, estimator_timeout: float, list_estimators: bool,
         no_plots: bool, table_format: str, quiet: bool, **sim_readings: Any) -> None:
    """Score persistence estimators like the paper's Table I (MAE, B-Acc, F1) next to a ceiling, baselines
    and chance, with a stated interval; or navigation (SR, SPL, AR, DIST) and doors with them.

    Writes results.json (the versioned results schema: psg_data.evaluation.load_results reads it),
    table.txt, summary.csv, results.csv, breakdowns per object / receptacle / weekday / horizon and PNG
    plots (beliefs over the scored test time, bars with intervals, scores by horizon).

    \b
    Examples:
      psg-eval --estimator perpetua_star                       # the built-in lab
      psg-eval --lab-seeds 5 -e perpetua_star                  # five regenerated labs, t-interval
      psg-eval --dataset persistence-benchmark --lab-seeds 5 -e perpetua_star -e perpetua_star_oracle
      psg-eval --dataset navigation-benchmark -e perpetua_star --jobs -1   # 15 houses, shifted test week
      psg-eval --dataset /data/lab --labels privileged -e my_plugin:alpha=0.3 --out res/
      psg-eval --task navigation -e perpetua_star -e fremen    # SR / SPL / AR / DIST
      psg-eval --task navigation --delta 0.05,0.1,0.2,0.3 -e perpetua_star
      psg-eval --task navigation --dataset /data/lab --labels noisy:0.1 --protocol paper-real -e perpetua_star
      psg-eval --task navigation --dataset navigation-benchmark --protocol paper-sim-adaptive -e perpetua_star -e fremen
      psg-eval --task doors --dataset /data/lab -e perpetua_star   # blocked first plans, extra metres
      psg-eval --dataset door-benchmark -e perpetua_star -e fremen   # a real door, patrol protocol
      psg-eval --dataset door-benchmark --protocol published -e fremen:max_order=5   # the authors' protocol
      psg-eval --dataset room-presence-benchmark -e perpetua_star  # a real home: which room, top-1 / top-3
      psg-eval compare res/a res/b                             # tabulate earlier runs
    """
    if ctx.invoked_subcommand is not None:
        return
    setup_logging(quiet)
    from psg_data.estimators._guard import estimator_timeout_set

    ctx.with_resource(estimator_timeout_set(estimator_timeout))  # every plugin call limited, in workers too
    from psg_data.cli._eval_checks import (
        check_builtin_task,
        check_lab_seeds,
        check_protocol,
        check_task_estimators,
        parse_deltas,
        persistence_options,
    )
    from psg_data.cli._eval_inputs import available_hints, check_estimators, parse_estimator_spec, require_hints

    if list_estimators:
        from psg_data.estimators import list_estimators as _list

        for name in _list():
            click.echo(name)
        return
    specs = [parse_estimator_spec(e) for e in (estimators or (DEFAULT_ESTIMATOR,))]
    check_estimators(specs)
    check_task_estimators(specs, task)
    check_scheduler(scheduler)
    from psg_data.cli._eval_state import check_state_options, is_state_benchmark

    if is_state_benchmark(dataset):
        assert dataset is not None
        state_protocol = check_state_options(dataset, task=task, protocol=protocol, lab_seeds=lab_seeds,
                                             rerun=rerun_file, weighting=weighting)
        _run_state(ctx, specs, dataset, state_protocol, setting=setting, horizon=horizon, windows=windows,
                   labels=labels, label_seed=label_seed, seeds=seeds, jobs=jobs, scheduler=scheduler, out=out,
                   overwrite=overwrite, no_plots=no_plots, quiet=quiet, references=references,
                   table_format=table_format)
        return
    if protocol in ("patrol", "published"):
        from psg_data.errors import EvaluationError

        raise EvaluationError(f"--protocol {protocol}: a protocol of the real benchmarks (--dataset door-benchmark or "
                              "room-presence-benchmark)")
    given_protocol = ctx.get_parameter_source("protocol") != click.core.ParameterSource.DEFAULT
    protocol = protocol or "sim"
    check_protocol(task, protocol, given=given_protocol)
    _check_rerun(rerun_file, task, overwrite, _eval_inputs(dataset, labels))
    deltas = parse_deltas(delta, task)
    p_opts = persistence_options(setting=setting, horizon=horizon, weighting=weighting, windows=windows, seeds=seeds)
    check_builtin_task(dataset, task, lab_seeds, protocol=protocol, quick=quick)
    check_lab_seeds(lab_seeds, dataset, task, labels)
    require_hints(specs, available_hints(dataset), "the " + (dataset or "demo") + " dataset")
    nav_options = None
    sim = task == "navigation" and protocol.startswith("paper-sim")
    check_reading_options(task, protocol, sim_readings)
    if sim:
        from psg_data.cli._eval_sim_navigation import check_sim_options

        check_sim_options(protocol, queries=queries, seeds=seeds, reachable_only=reachable_only,
                          door_belief=door_belief, windows=windows, delta=delta, lab_seeds=lab_seeds)
    if task in ("navigation", "doors") and not sim:
        from psg_data.cli._eval_navigation import door_task_options, navigation_options

        q_seeds = list(seeds or range(3))
        nav_options = (navigation_options(protocol, labels=labels, seeds=q_seeds, queries=queries, setting=setting,
                                          delta=deltas[0], reachable_only=reachable_only, door_belief=door_belief,
                                          windows=windows, label_seed=label_seed) if task == "navigation" else
                       door_task_options(labels=labels, seeds=q_seeds, queries=queries, windows=windows,
                                         label_seed=label_seed))
    from psg_data.writers._safe_output import commit_tree, make_staging

    out_dir = _out_dir(out, overwrite, _eval_inputs(dataset, labels))
    new_parent = not out_dir.parent.exists()
    tmp = make_staging(out_dir.with_name(out_dir.name + ".partial"))
    from psg_data.cli._eval_navigation import run_doors_task, run_navigation_task
    from psg_data.cli._eval_persistence import run_persistence

    try:
        if task == "persistence":
            ok = run_persistence(specs, dataset, p_opts, labels, jobs, tmp, no_plots, quiet, references=references,
                                 lab_seeds=lab_seeds, scheduler=scheduler, rerun_file=rerun_file, overwrite=overwrite,
                                 label_seed=label_seed, table_format=table_format)
        elif sim:
            from psg_data.cli._eval_sim_navigation import run_sim_navigation_task

            ok = run_sim_navigation_task(specs, protocol, labels, tmp, quick=quick, jobs=jobs, no_plots=no_plots,
                                         quiet=quiet, references=references, label_seed=label_seed,
                                         table_format=table_format, readings=sim_readings)
        elif task == "doors":
            ok = run_doors_task(specs, dataset, nav_options, tmp, no_plots, quiet, references=references,
                                table_format=table_format)
        else:
            ok = run_navigation_task(specs, dataset, nav_options, tmp, no_plots, quiet, references=references,
                                     deltas=deltas, table_format=table_format)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if new_parent and not any(out_dir.parent.iterdir()):
            out_dir.parent.rmdir()  # e.g. psg-eval-out/, created for this run
        raise
    commit_tree(tmp, out_dir, kind="results")
    click.echo(f"results written to {out_dir}/", err=table_format != "text")  # stdout: only the table
    if not ok:
        sys.exit(EXIT_PROBLEMS)


def _run_state(ctx: click.Context, specs: list, dataset: str, protocol: str, *, out: Path | None, overwrite: bool,
               **kw: object) -> None:
    """A real-benchmark run into a staged results folder (committed only when it completes)."""
    from psg_data.cli._eval_state import run_state_task
    from psg_data.writers._safe_output import commit_tree, make_staging

    out_dir = _out_dir(out, overwrite, _eval_inputs(dataset, "gt"))
    new_parent = not out_dir.parent.exists()
    tmp = make_staging(out_dir.with_name(out_dir.name + ".partial"))
    try:
        ok = run_state_task(specs, dataset, protocol, out=tmp, **kw)  # type: ignore[arg-type]
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if new_parent and out_dir.parent.exists() and not any(out_dir.parent.iterdir()):
            out_dir.parent.rmdir()
        raise
    commit_tree(tmp, out_dir, kind="results")
    click.echo(f"results written to {out_dir}/", err=kw.get("table_format") != "text")
    if not ok:
        sys.exit(EXIT_PROBLEMS)


@main.command("compare")
@click.argument("dirs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--references/--no-references", default=True, show_default=True,
              help="Keep the reference rows (ceiling, baselines, chance); --no-references shows only the methods.")
@click.option("--metric", "metrics", multiple=True, metavar="KEY",
              help="Only this metric's column (repeatable; a key or a label: mae, balanced_accuracy, F1, SR, ...).")
@click.option("--format", "table_format", type=click.Choice(COMPARE_FORMATS), default="text", show_default=True,
              help="text; csv or json (each metric's mean, interval ends and half-width per run and method); "
                   "markdown or latex (booktabs) to paste into a paper.")
@handle_errors
def compare_cmd(dirs: tuple[Path, ...], references: bool, metrics: tuple[str, ...], table_format: str) -> None:
    """Tabulate earlier psg-eval runs side by side (reads each DIR/results.json).

    Persistence, navigation and door runs may be mixed: each task gets its own table.

    \b
    Examples:
      psg-eval compare psg-eval-out/run1 psg-eval-out/run2
      psg-eval compare run1 run2 --no-references --metric mae --metric balanced_accuracy
      psg-eval compare run1 --format latex > table.tex
    """
    from psg_data.cli._eval_compare import compare_runs

    compare_runs(dirs, fmt=table_format, metrics=metrics, references=references)
