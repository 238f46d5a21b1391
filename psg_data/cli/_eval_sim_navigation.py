"""``psg-eval --task navigation --dataset navigation-benchmark --protocol paper-sim-predictive|paper-sim-adaptive``.

The work is in :mod:`psg_data.navigation._sim_benchmark` (protocols, agent) and
:mod:`psg_data.evaluation._sim_navigation_report` (tables, paper rows, per-scene plot).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from psg_data.cli._common import Progress
from psg_data.cli._eval_provenance import provenance

__all__ = ["run_sim_navigation_task", "sim_methods", "SIM_REFERENCES", "check_sim_options", "reading_options",
           "check_reading_options"]

SIM_REFERENCES: list[tuple[str, str, tuple[tuple[str, Any], ...], str, str]] = [
    ("oracle", "oracle", (), "ceiling", "the true receptacle at the query time"),
    ("process_oracle", "process_oracle", (), "ceiling",
     "exact posterior of the model that generated the scene, test-week regime included"),
    ("process_oracle:model=train", "process_oracle", (("model", "train"),), "ceiling",
     "exact posterior of the training model only: the best a predictor that does not adapt can do"),
    ("last_seen_map", "last_seen_map", (), "baseline", "the last observed state of each edge"),
    ("time_of_week_frequency", "time_of_week_frequency", (), "baseline",
     "training frequency of presence per hour of the week"),
    ("random_receptacle", "random_receptacle", (), "chance", "uniform random beliefs over the edges"),
]
"""(label, name, settings, role, description) of the reference rows."""


_READING_HELP = {
    "agent_memory": ("--agent-memory", ("visits", "estimator"),
                     "paper-sim-adaptive: does the agent remember the receptacles it reached (visits, the default: "
                     "\"up to two attempts\" as two receptacles) or only what its estimator's beliefs now say "
                     "(estimator)? Tool 3 says only \"Navigation terminates when either the object is found or the "
                     "target receptacle is reached\"."),
    "absence": ("--absence", ("delta", "list-exhausted"),
                "paper-sim-adaptive: when the agent declares the object absent: delta (the default, Tool 2: \"If no "
                "receptacle exceeds the threshold, the object is reported as absent\") or list-exhausted (also when "
                "every receptacle above delta has been reached; not in the paper)."),
    "last_map": ("--last-map", ("end-of-validation", "test-week"),
                 "paper-sim-adaptive: where the last map update falls (\"a future time point up to one week ahead "
                 "from the last map update\"): end-of-validation (the default: end of week 3, as for the predictive "
                 "protocol) or test-week (a uniform test-week step whose observations up to it the filters "
                 "consume; our earlier reading)."),
}


def reading_options(f: Any) -> Any:
    """The click options of the adaptive protocol's open choices and ``--queries-per-scene`` (one block)."""
    f = click.option("--queries-per-scene", "queries_per_scene", type=click.IntRange(1), default=None,
                     help="paper-sim protocols: queries drawn per house (default 25, the paper's 250 / 10 and "
                          "125 / 5; more for a verdict; --quick: 6). The first 25 draws are the default's.")(f)
    for key, (flag, choices, text) in reversed(_READING_HELP.items()):
        f = click.option(flag, key, type=click.Choice(choices), default=None, help=text)(f)
    return f


def check_reading_options(task: str, protocol: str, readings: dict[str, Any]) -> None:
    """Refuse the reading options outside the protocols they apply to (one ``error:`` line)."""
    from psg_data.errors import EvaluationError

    flags = {"agent_memory": "--agent-memory", "absence": "--absence", "last_map": "--last-map",
             "queries_per_scene": "--queries-per-scene"}
    given = [flags[k] for k, v in readings.items() if v is not None]
    allowed = {"paper-sim-adaptive": list(flags.values()), "paper-sim-predictive": ["--queries-per-scene"]}
    bad = [g for g in given if task != "navigation" or g not in allowed.get(protocol, [])]
    if bad:
        raise EvaluationError(f"{', '.join(bad)}: only with --task navigation --protocol paper-sim-adaptive "
                              "(--queries-per-scene also with paper-sim-predictive)")


def check_sim_options(protocol: str, *, queries: int | None, seeds: Any, reachable_only: bool,
                      door_belief: str | None, windows: str, delta: str, lab_seeds: Any) -> None:
    """Refuse the lab protocols' settings that a paper-sim protocol fixes (one ``error:`` line each)."""
    from psg_data.errors import EvaluationError

    fixed = {"--queries": queries is not None, "--seeds": seeds is not None, "--reachable-only": reachable_only,
             "--door-belief": door_belief is not None, "--windows": windows != "auto",
             "--delta": str(delta).strip() not in ("0.2", "0.20"), "--lab-seeds": lab_seeds is not None}
    given = [k for k, v in fixed.items() if v]
    if given:
        raise EvaluationError(f"{', '.join(given)} with --protocol {protocol}: the protocol fixes its scenes, "
                              "queries (25 per house), delta 0.2, the true door states and query times around "
                              "the clock; use --quick for the small form")


def sim_methods(specs: list[Any], references: bool) -> tuple[dict[str, str], dict[str, dict[str, Any]],
                                                              dict[str, tuple[str, str]]]:
    """(label -> name, label -> settings, label -> (role, description)): references first, then the user's."""
    methods: dict[str, str] = {}
    settings: dict[str, dict[str, Any]] = {}
    roles: dict[str, tuple[str, str]] = {}
    have = {s.label for s in specs}
    if references:
        for label, name, sett, role, desc in SIM_REFERENCES:
            roles[label] = (role, desc)
            if label not in have:
                methods[label], settings[label] = name, dict(sett)
    for s in specs:
        methods[s.label], settings[s.label] = s.name, dict(s.settings)
    return methods, settings, roles


def _executor(jobs: int) -> Any:
    from psg_data.cli._eval_persistence import _executor as ex

    return ex(jobs, None)


def sim_protocol(protocol: str, quick: bool, readings: dict[str, Any] | None = None) -> Any:
    """The protocol run: the named one (its quick form), with the user's reading options (None: the defaults)."""
    from dataclasses import replace

    from psg_data.navigation._sim_benchmark import SIM_PROTOCOLS

    proto = SIM_PROTOCOLS[protocol].quick() if quick else SIM_PROTOCOLS[protocol]
    return replace(proto, **{k: v for k, v in (readings or {}).items() if v is not None})


def _run_houses(proto: Any, methods: dict[str, str], settings: dict[str, dict[str, Any]], labels: str,
                label_seed: int, jobs: int, quiet: bool) -> tuple[Any, dict[int, dict[str, Any]], Path]:
    """Build (or find) the protocol's houses and run every reading on them: (records, raw outputs, root)."""
    from psg_data.datasets import navigation_benchmark
    from psg_data.navigation._sim_benchmark import run_sim_navigation

    with Progress("navigation benchmark scenes", total=len(proto.scenes), unit="scenes", quiet=quiet) as prog:
        root = navigation_benchmark(shift=proto.shift, which=proto.scenes, progress=lambda k: prog.update(k))
    paths = [root / f"scene_{k:02d}" for k in proto.scenes]
    with Progress(f"{proto.name}: {len(paths)} scenes", total=len(paths), unit="scenes", quiet=quiet) as prog, \
            _executor(jobs) as executor:
        prog.start()  # a scene takes tens of seconds: the clock runs from the start

        def progress(done: int, _total: int) -> None:
            prog.done = done
            prog.update(0)

        records, outs = run_sim_navigation(paths, methods, settings, proto, labels=labels, label_seed=label_seed,
                                           executor=executor, progress=progress, readings=proto.readings())
    return records, outs, root


def _shift_label(shift: float | None) -> str:
    from psg_data.synth._house_process import HouseProcessParams

    return f"shift {HouseProcessParams().shift if shift is None else shift:g}"


def _all_records(proto: Any, methods: dict[str, str], settings: dict[str, dict[str, Any]], labels: str,
                 label_seed: int, jobs: int, quiet: bool) -> tuple[Any, Any, dict[int, dict[str, Any]], Path]:
    """(the protocol's records, every reading's records with the shift-0 control's, raw outputs, root)."""
    import pandas as pd

    records, outs, root = _run_houses(proto, methods, settings, labels, label_seed, jobs, quiet)
    allrec = [records.assign(shift=_shift_label(proto.shift))]
    if proto.adaptive and proto.shift != 0:
        from dataclasses import replace

        control = replace(proto, name=proto.name + " shift-0 control", shift=0.0)
        rec0, _, _ = _run_houses(control, methods, settings, labels, label_seed, jobs, quiet)
        allrec.append(rec0.assign(shift=_shift_label(0.0)))
    main = records
    if proto.adaptive:
        last, mem, ab = proto.reading
        main = records[(records["last_map"] == last) & (records["agent_memory"] == mem)
                       & (records["absence"] == ab)].reset_index(drop=True)
    return main, pd.concat(allrec, ignore_index=True), outs, root


def run_sim_navigation_task(specs: list[Any], protocol: str, labels: str, out: Path, *, quick: bool, jobs: int,
                            no_plots: bool, quiet: bool, references: bool = True, label_seed: int = 0,
                            table_format: str = "text", readings: dict[str, Any] | None = None) -> bool:
    """Run a simulation protocol over its scenes, write the files, print the paper-shaped table (adaptive: with
    every reading of the open choices and the shift-0 control beside it, and SR by time since the last map).
    """
    import time

    from psg_data.evaluation import _sim_navigation_report as rep
    from psg_data.evaluation._navigation_report import navigation_results
    from psg_data.evaluation._tables import format_table, print_results

    proto = sim_protocol(protocol, quick, readings)
    t0 = time.perf_counter()
    methods, settings, roles = sim_methods(specs, references)
    records, allrec, outs, root = _all_records(proto, methods, settings, labels, label_seed, jobs, quiet)
    paths = [root / f"scene_{k:02d}" for k in proto.scenes]
    errors = [e for sc in proto.scenes for e in outs[sc].get("errors", [])]
    names = _scored(methods, errors)
    records = records[records["method"].isin(names)] if len(records) else records
    allrec = allrec[allrec["method"].isin(names)] if len(allrec) else allrec
    per_scene, summary = rep.sim_summary(records, names)
    seconds = round(time.perf_counter() - t0, 2)
    config = {"protocol": proto.name, **proto.to_dict(), "labels": labels, "label_seed": label_seed,
              "methods": names, "setting": "adaptive" if proto.adaptive else "predictive",
              "door_belief": "truth", "unreachable": "exclude", "absent_in_overall": "abort_is_success",
              "seeds": list(proto.scenes), "env": "navigation-benchmark", "dataset": str(root),
              "settings": {k: v for k, v in outs[proto.scenes[0]]["settings"].items()}}
    info = provenance({"task": "navigation", "dataset_label": "navigation-benchmark", "dataset": str(root),
                       "seconds": seconds, "jobs": jobs})
    results = navigation_results(_result(records, per_scene, summary, config, errors), roles=roles, info=info,
                                 spread="std")
    text = rep.sim_table_text(summary, protocol=proto.name, labels=labels, roles=roles, n_scenes=len(paths),
                              table=format_table(results.tables[0]))
    text += "\n" + rep.elapsed_text(records, names, roles)
    if proto.adaptive:
        shifts = list(dict.fromkeys(allrec["shift"]))
        text += "\n" + rep.readings_text(allrec, names, roles, proto.readings(), proto.reading, shifts)
    _write(out, records, per_scene, summary, config, roles, info, text, errors)
    if proto.adaptive:
        from psg_data.writers._safe_output import write_atomically

        write_atomically(out / "readings.parquet", lambda tmp: allrec.to_parquet(tmp, index=False))
    if not no_plots:
        rep.plot_scene_sr(per_scene, out / "scene_sr.png", roles=roles,
                      title=f"{proto.name}, labels {labels}: overall SR per scene (scene = house seed)")
        _maps(out, paths[0], proto, outs[proto.scenes[0]], records, names, roles, labels, label_seed)
    if table_format == "text":
        click.echo("")
        click.echo(text, nl=False)
    else:
        print_results(results, fmt=table_format)
    from psg_data.cli._eval_navigation import print_problems

    return print_problems(errors)


def _scored(methods: dict[str, str], errors: list[dict[str, Any]]) -> list[str]:
    """The methods that ran on every scene (a plugin that failed on one is left out of every table)."""
    from psg_data.errors import EvaluationError

    failed = {e["estimator"] for e in errors}
    names = [n for n in methods if n not in failed]
    if not names:
        raise EvaluationError("navigation: no method could be scored: " + "; ".join(e["message"] for e in errors))
    return names


def pick_disagreement(records: Any, labels: list[str]) -> int | None:
    """A query id of the records' first scene on which ``labels`` disagree most (success, then first
    receptacle), dynamic targets first; None without records.
    """
    if records.empty:
        return None
    rec = records[(records["seed"] == records["seed"].iloc[0]) & records["method"].isin(labels)]
    sig = rec.assign(sig=rec["success"].astype(str) + "|" + rec["predicted_receptacle"].astype(str),
                     dyn=rec["category"] == "dynamic")
    score = sig.groupby("query_id").agg(wins=("success", "nunique"), kinds=("sig", "nunique"), dyn=("dyn", "all"))
    return int(score.sort_values(["wins", "dyn", "kinds"], ascending=False, kind="stable").index[0])


def _maps(out: Path, path: Path, proto: Any, raw: dict[str, Any], records: Any, names: list[str],
          roles: dict[str, tuple[str, str]], labels: str, label_seed: int) -> None:
    """map_<label>.png: one query of the first house on which the methods disagree, each method's walk and beliefs."""
    from psg_data.loaders import open_dataset
    from psg_data.maps._planner import PlanningCache
    from psg_data.navigation import NavigationEnv, plot_query
    from psg_data.navigation._sim_benchmark import scene_split_ids

    shown = [n for n in names if roles.get(n, ("method", ""))[0] == "method"] + \
        [n for n in ("process_oracle", "process_oracle:model=train", "last_seen_map") if n in names]
    qid = pick_disagreement(records, shown)
    if qid is None:
        return
    q, t_m = next((q, t) for q, t in raw["queries"] if q.query_id == qid)
    ds = open_dataset(path)
    ids = scene_split_ids(ds)
    env = NavigationEnv.from_dataset(ds, map_scans=ids["train"] + ids["val"], labels=labels, label_seed=label_seed)
    cache = PlanningCache(env.grid, reach_m=proto.reach_m)
    rec = records[(records["seed"] == q.seed) & (records["query_id"] == qid)].set_index("method")
    for label in shown:
        r = rec.loc[label]
        title = (f"{label}: {r['outcome']} after {r['path_m']:.1f} m, {int(r['n_switches'])} target switches "
                 f"({proto.name}, house {q.seed}, query {qid})\n{q.object_id} ({q.category}): on "
                 f"{q.gt_receptacle or 'nothing'}; on {q.map_receptacle or 'nothing'} at the last map update, "
                 f"{(q.t_s - t_m) / 3600:.0f} h before the query")
        plot_query(env, q, out / f"map_{label.replace(':', '_').replace('=', '-')}.png",
                   beliefs=raw["beliefs"].get((label, qid)), trail=raw["trails"].get((label, qid)), cache=cache,
                   title=title)


def _result(records: Any, per_scene: Any, summary: Any, config: dict[str, Any],
            errors: list[dict[str, Any]] | None = None) -> Any:
    from psg_data.navigation import NavigationResult

    return NavigationResult(records, per_scene, summary, {}, config, errors=list(errors or []))


def _write(out: Path, records: Any, per_scene: Any, summary: Any, config: dict[str, Any],
           roles: dict[str, tuple[str, str]], info: dict[str, Any], text: str,
           errors: list[dict[str, Any]] | None = None) -> None:
    """results.json / table.txt / summary.csv (the results schema), records.parquet, per_seed.csv (per scene),
    results.csv, sim_table.txt (the paper-shaped table) and config.json.
    """
    from psg_data.evaluation._navigation_report import write_navigation_results
    from psg_data.writers._safe_output import write_atomically

    write_navigation_results(_result(records, per_scene, summary, config, errors), out, roles=roles, info=info,
                             spread="std")
    write_atomically(out / "sim_table.txt", lambda tmp: tmp.write_text(text))
    write_atomically(out / "sim_config.json", lambda tmp: tmp.write_text(json.dumps(config, indent=1, default=str)))
