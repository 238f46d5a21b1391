"""``psg-eval compare``: earlier runs side by side, one table per task."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

__all__ = ["compare_runs"]


def compare_runs(dirs: tuple[Path, ...]) -> None:
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
