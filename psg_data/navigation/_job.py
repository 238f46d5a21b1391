"""Navigation and door runs as ``psg-eval`` makes them: the methods (the user's, the paper's, the
reference rows), the run, the results schema, the files and the figures.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from psg_data.evaluation._hints import EstimatorSpec, with_hints, with_label_noise
from psg_data.evaluation._references import PAPER_METHODS, door_references, navigation_references

__all__ = ["navigation_methods", "run_navigation_job", "door_methods", "run_door_job"]

_NAV_BUILTINS = ("oracle", "last_seen_map", "random_receptacle")


def navigation_methods(specs: Sequence[EstimatorSpec], hints: dict[str, Any], *, references: bool = True,
                       labels: str = "gt"
                       ) -> tuple[dict[str, str], dict[str, dict[str, Any]], dict[str, tuple[str, str]]]:
    """(label -> method name, label -> settings with the dataset's hints, label -> (role, description))."""
    methods: dict[str, str] = {}
    roles: dict[str, tuple[str, str]] = {}
    rows = list(specs)
    if references:
        have = {s.label for s in rows}
        rows += [EstimatorSpec.of(m) for m in PAPER_METHODS if m not in have]
        for ref in navigation_references(hints):
            roles[ref.label] = (ref.role, ref.description)
            if ref.label not in have:
                rows.append(ref.spec)
    settings = {}
    for s in rows:
        methods[s.label] = s.name
        if s.name not in _NAV_BUILTINS:
            s = with_label_noise(with_hints(s, hints), labels)
        if s.settings:
            settings[s.label] = dict(s.settings)
    return methods, settings, roles


def _maps(res: Any, out: Path, methods: list[str]) -> None:
    from psg_data.evaluation._navigation_report import choose_map_query
    from psg_data.navigation import plot_query

    sd, qid = choose_map_query(res, [m for m in methods if m != "oracle"])
    q = next(x for x in res.queries[sd] if x.query_id == qid)
    rec = res.records.set_index(["method", "seed", "query_id", "delta"])
    for label in methods:
        key = (label, sd, qid)
        r = rec.loc[(label, sd, qid, float(res.config["delta"]))]
        title = (f"{label}: {r['outcome']} after {r['path_m']:.1f} m (query {qid} of seed {sd})\n{q.object_id} "
                 f"({q.category}): on {q.gt_receptacle or 'nothing'}, on {q.map_receptacle or 'nothing'} at the "
                 "last map")
        plot_query(res.env, q, out / f"map_{label}.png", beliefs=res.beliefs.get(key), trail=res.trails.get(key),
                   cache=res.cache, title=title)


def run_navigation_job(specs: Sequence[EstimatorSpec], dataset: Path, options: Any, out: Path, *,
                       references: bool = True, deltas: Sequence[float] = (), plots: bool = True,
                       info: dict[str, Any] | None = None) -> tuple[Any, Any]:
    """Run, write (results schema, records, CSV) and draw (maps of one informative query, the delta sweep).

    Returns:
        (the :class:`~psg_data.navigation.NavigationResult`, the :class:`EvalResults` written).
    """
    import time

    from psg_data.evaluation._hints import dataset_hints
    from psg_data.evaluation._navigation_report import navigation_results, plot_delta_sweep, write_navigation_results
    from psg_data.loaders import open_dataset
    from psg_data.navigation import run_navigation

    hints = dataset_hints(open_dataset(dataset))
    methods, settings, roles = navigation_methods(specs, hints, references=references, labels=options.labels)
    if len(deltas) > 1:
        options = replace(options, delta=float(deltas[0]), delta_sweep=tuple(float(d) for d in deltas[1:]))
    t0 = time.perf_counter()
    res = run_navigation(dataset, methods, options, out_dir=out, estimator_settings=settings or None)
    full = {**(info or {}), "seconds": round(time.perf_counter() - t0, 2), **res.config}
    write_navigation_results(res, out, roles=roles, info=full)
    if plots and res.env is not None:
        _maps(res, out, [m for m in methods if m in res.config["methods"]])  # failed plugins left out
        if res.sweep is not None:
            plot_delta_sweep(res, out / "delta_sweep.png", roles=roles)
    return res, navigation_results(res, roles=roles, info=full)


def door_methods(specs: Sequence[EstimatorSpec], hints: dict[str, Any], *, references: bool = True
                 ) -> tuple[list[tuple[str, str]], dict[str, dict[str, Any]], dict[str, tuple[str, str]], list[str]]:
    """(label, name) pairs of the door estimators, their settings, the roles of every row (baselines
    ``oracle`` and ``all_open`` included), and the labels whose object runs are made (not the references).
    """
    rows = list(specs)
    roles: dict[str, tuple[str, str]] = {}
    if references:
        have = {s.label for s in rows}
        rows += [EstimatorSpec.of(m) for m in PAPER_METHODS if m not in have]
        for ref in door_references():
            roles[ref.label] = (ref.role, ref.description)
            if ref.label not in have and ref.label not in ("oracle", "all_open"):
                rows.append(ref.spec)
    else:
        roles = {"oracle": ("ceiling", "the true door states at the query time"),
                 "all_open": ("baseline", "plans as if every door were open")}
    settings = {s.label: dict(with_hints(s, hints).settings) for s in rows if with_hints(s, hints).settings}
    objects_for = [s.label for s in rows if s.label not in roles]
    return [(s.label, s.name) for s in rows], settings, roles, objects_for


def _door_figures(res: Any, label: str, spec: EstimatorSpec, out: Path) -> None:
    """door_plan_<label>.png (a door query whose all-open first plan ran into a closed door) and
    doors_<label>.png (an object query planned around a predicted-closed door).
    """
    from psg_data.evaluation._door_report import pick_blocked_door_query
    from psg_data.navigation import pick_door_example, plot_door_example, plot_door_query

    first = res.first
    pick = pick_blocked_door_query(res, label)
    plot_door_query(res.world, first.queries[pick], first.episodes[label][pick], out / f"door_plan_{label}.png",
                    baseline=first.episodes["all_open"][pick])
    if res.objects is not None:
        ex = pick_door_example(res.objects, label)
        if ex is not None:
            plot_door_example(res.objects, label, ex, out / f"doors_{label}.png", estimator=spec.name,
                              settings=dict(spec.settings) or None)


def run_door_job(specs: Sequence[EstimatorSpec], dataset: Path, options: Any, out: Path, *, references: bool = True,
                 plots: bool = True, info: dict[str, Any] | None = None,
                 progress: Callable[[int, int], None] | None = None) -> tuple[Any, Any]:
    """Run the door task, write the results schema and CSV files, draw the figures of the first estimator
    (``progress(done, total)``: after each seed and the object runs).
    """
    import time

    from psg_data.evaluation._door_report import write_door_results
    from psg_data.evaluation._hints import dataset_hints
    from psg_data.loaders import open_dataset
    from psg_data.navigation import run_door_task

    hints = dataset_hints(open_dataset(dataset))
    estimators, settings, roles, objects_for = door_methods(specs, hints, references=references)
    t0 = time.perf_counter()
    res = run_door_task(dataset, estimators, options, settings=settings or None, objects_for=objects_for,
                        progress=progress)
    full = {**(info or {}), **options.to_dict(), "world": res.world.info, "seconds": round(time.perf_counter() - t0, 2)}
    results = write_door_results(res, out, roles=roles, info=full)
    if plots and specs and specs[0].label not in {e["estimator"] for e in res.errors}:
        _door_figures(res, specs[0].label, specs[0], out)
    return res, results
