"""``psg-eval --dataset door-benchmark|room-presence-benchmark``: the public real benchmarks, two protocols.

The dataset name may carry reader and patrol settings after a colon, as estimators do:
``door-benchmark:stamps=utc,state_one=open,patrol=9-17/2h``; ``room-presence-benchmark:start=2010-11-04,
train_weeks=8``. ``--labels noisy:P[,P_F]`` flips the patrol's observations (seed ``--label-seed``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from psg_data.errors import EvaluationError

__all__ = ["STATE_DATASETS", "is_state_benchmark", "run_state_task", "check_state_options"]

STATE_DATASETS = {"door-benchmark": ("state_one", "stamps", "patrol"),
                  "room-presence-benchmark": ("start", "train_weeks", "patrol")}
"""Real benchmark name -> the settings its ``NAME:key=value`` form takes."""


def is_state_benchmark(dataset: str | None) -> bool:
    """Whether ``--dataset`` names a real benchmark (``NAME`` or ``NAME:key=value,...``), not a folder."""
    return dataset is not None and dataset.split(":", 1)[0] in STATE_DATASETS and not Path(dataset).is_dir()


def parse_state_dataset(text: str) -> tuple[str, dict[str, str]]:
    """``NAME[:key=value,...]`` -> (name, settings); unknown keys refused in one line."""
    name, _, rest = text.partition(":")
    settings: dict[str, str] = {}
    for part in [p.strip() for p in rest.split(",")] if rest.strip() else []:
        key, eq, value = part.partition("=")
        if not eq or key.strip() not in STATE_DATASETS[name]:
            raise EvaluationError(f"--dataset {text!r}: setting {part!r}; {name} takes "
                                  f"{', '.join(k + '=...' for k in STATE_DATASETS[name])}")
        settings[key.strip()] = value.strip()
    return name, settings


def check_state_options(dataset: str, *, task: str, protocol: str | None, lab_seeds: Any, rerun: Any,
                        weighting: str) -> str:
    """The protocol of a real-benchmark run (default patrol), refusing what does not apply, in one line each."""
    name = dataset.split(":", 1)[0]
    if task != "persistence":
        raise EvaluationError(f"--task {task} on {name}: a real benchmark holds state streams only (no map, no "
                              "scans); it takes --task persistence")
    if protocol not in (None, "patrol", "published"):
        raise EvaluationError(f"--protocol {protocol} on {name}: its protocols are patrol (default) and published")
    if lab_seeds is not None:
        raise EvaluationError(f"--lab-seeds with {name}: a real benchmark is one recording; its test weeks are the "
                              "draws")
    if rerun is not None:
        raise EvaluationError(f"--rerun with {name}: beliefs are written to results.json's per-week values only")
    if weighting != "auto":
        raise EvaluationError(f"--weighting {weighting} with {name}: every published row is weighed by its time, a "
                              "gap by nothing (see --help); leave --weighting at auto")
    return protocol or "patrol"


def _bench(name: str, settings: dict[str, str], quiet: bool) -> Any:
    from psg_data.cli._progress import Progress
    from psg_data.datasets import door_benchmark, room_presence_benchmark

    reader: dict[str, Any] = {k: v for k, v in settings.items() if k != "patrol"}
    if "train_weeks" in reader:
        try:
            reader["train_weeks"] = int(reader["train_weeks"])
        except ValueError:
            raise EvaluationError(f"--dataset {name}: train_weeks={reader['train_weeks']!r}; expected a whole "
                                  "number of weeks") from None
    with Progress(f"reading {name}", total=None, unit="B", quiet=quiet) as prog:
        def got(n: int) -> None:
            prog.bytes += n
            prog.update(0)

        fn = door_benchmark if name == "door-benchmark" else room_presence_benchmark
        return fn(progress=got, **reader)


def _options(bench: Any, protocol: str, settings: dict[str, str], *, setting: str, horizon: str, windows: str,
             labels: str, label_seed: int, seeds: tuple[int, ...] | None) -> Any:
    from psg_data.evaluation._state_benchmark import StateRunOptions
    from psg_data.evaluation._state_protocols import PatrolPlan
    from psg_data.evaluation._windows import DailyWindows, parse_duration, parse_windows
    from psg_data.labeling import parse_source

    src = parse_source(labels)
    if src.kind not in ("gt", "noisy") or (src.kind == "noisy" and protocol != "patrol"):
        raise EvaluationError(f"--labels {labels} on {bench.name}: the patrol's observations are the truth (gt) or the "
                              "truth flipped (noisy:P[,P_F], --protocol patrol); the published protocol uses the rows")
    flips = {"p_m": src.p_m, "p_f": src.p_f} if src.kind == "noisy" else {}
    plan = PatrolPlan.parse(settings.get("patrol", "9-17/2h"), seed=label_seed, **flips)
    if protocol == "published" and (setting == "adaptive" and horizon != "auto"):
        raise EvaluationError("--horizon with --protocol published: the authors' protocol forecasts each test week "
                              "with no test observation (predictive); use --protocol patrol for the adaptive setting")
    h = plan.step_h * 3600.0 if horizon == "auto" else parse_duration(horizon)
    if windows == "auto":
        win = DailyWindows(((plan.start_h, plan.end_h),), bench.timezone, source="the patrol's hours") \
            if protocol == "patrol" else None
    else:
        win = parse_windows(windows, bench.timezone)
    return StateRunOptions(protocol=protocol, setting="predictive" if protocol == "published" else setting,
                           horizon_s=h, patrol=plan, seeds="auto" if seeds is None else tuple(seeds), windows=win)


def run_state_task(specs: list[Any], dataset: str, protocol: str, *, setting: str, horizon: str, windows: str,
                   labels: str, label_seed: int, seeds: tuple[int, ...] | None, jobs: int, scheduler: str | None,
                   out: Path, no_plots: bool, quiet: bool, references: bool, table_format: str) -> bool:
    """Run, write results.json / CSV / PNG into ``out``, print the tables; False when a row had problems."""
    from psg_data.cli._eval_persistence import _executor
    from psg_data.cli._eval_provenance import provenance
    from psg_data.cli._progress import Progress
    from psg_data.evaluation._state_benchmark import run_state_benchmark, state_rows, summarize_state_run
    from psg_data.evaluation._state_report import render, state_results, state_tables, write_state_outputs

    name, settings = parse_state_dataset(dataset)
    bench = _bench(name, settings, quiet)
    opts = _options(bench, protocol, settings, setting=setting, horizon=horizon, windows=windows, labels=labels,
                    label_seed=label_seed, seeds=seeds)
    rows = state_rows(specs, references=references)
    with Progress(f"scoring {len(rows)} rows on {len(bench.periods)} test weeks", total=len(rows), unit="rows",
                  quiet=quiet) as prog, _executor(jobs, scheduler) as executor:
        def progress(done: int, _total: int) -> None:
            prog.done = done
            prog.update(0)

        run = run_state_benchmark(bench, rows, opts, executor=executor, progress=progress)
    summary = summarize_state_run(run, rows, one_hot=bench.one_hot)
    info = provenance({"dataset": name, "dataset_spec": dataset, "labels": labels,
                       "windows": None if opts.windows is None else opts.windows.describe()})
    title = f"{name} ({len(bench.periods)} test weeks), protocol {protocol}"
    doc = state_results(run, rows, summary, info, title)
    text = render(state_tables(doc, title), "text")
    write_state_outputs(doc, out, text, plots=not no_plots)
    if table_format == "text":
        click.echo("")
    click.echo(text if table_format == "text" else render(state_tables(doc, title), table_format))
    for e in run.errors[:20]:
        click.echo(f"error: {e}", err=True)
    return not run.errors
