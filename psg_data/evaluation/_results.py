"""One versioned results schema for every task (persistence, navigation, doors), written and read here.

Every ``psg-eval`` run writes ``results.json`` (evo's ``save_res_file`` / ``load_res_file`` habit:
one file a notebook can load without psg-data internals, one loader that knows its versions)::

    {"schema": "psg-eval-results", "schema_version": 1, "task": "persistence",
     "tables": [{"name": "persistence", "title": "...",
                 "metrics": [{"key": "mae", "label": "MAE", "better": "lower", "scale": 1.0,
                              "digits": 3, "description": "...", "chance": 0.32}, ...],
                 "groups": [], "count_columns": ["edges"], "primary": "balanced_accuracy", "spread": "interval",
                 "rows": [{"method": "process_oracle", "role": "ceiling", "description": "...",
                           "values": {"mae": {"mean": ..., "std": ..., "ci_low": ..., "ci_high": ...,
                                              "n": 21, "method": "bootstrap", "unit": "objects"}, ...},
                           "pct_of_ceiling": 100.0, "counts": {"edges": 56}}, ...],
                 "notes": ["MAE: ...", "±: ..."]}, ...],
     "interval": {"method": "bootstrap", "unit": "objects", "n": 21, "confidence": 0.95, "text": "..."},
     "config": {...}, "info": {...}, "breakdowns": {"horizon": [...]}, "errors": [...], "ok": true}

Values are fractions in [0, 1] (SR 0.84, not 84; ``scale`` 100 is for display) or metres; NaN is
``null``. :func:`load_results` reads a file or a run folder and refuses, with one line, unknown
schemas, files larger than :data:`MAX_RESULTS_BYTES` and any field of the wrong type (a results
folder is untrusted input, docs/SECURITY.md); :func:`results_frame` gives the long table (one row
per method and metric) for pandas.
"""

from __future__ import annotations

import json
import math
import os
import stat
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from psg_data.errors import EvaluationError
from psg_data.evaluation._aggregate import Summary
from psg_data.evaluation._persistence_types import clean_json

__all__ = ["SCHEMA", "SCHEMA_VERSION", "MetricInfo", "ResultRow", "ResultTable", "EvalResults", "save_results",
           "load_results", "results_frame", "ROLES", "MAX_RESULTS_BYTES", "MAX_DIGITS"]

SCHEMA = "psg-eval-results"
SCHEMA_VERSION = 1
ROLES = ("ceiling", "baseline", "chance", "method")
"""Row roles in table order: reference rows (the best achievable, simple baselines, chance) first."""
MAX_RESULTS_BYTES = 16 << 20
"""Largest ``results.json`` :func:`load_results` reads (runs write tens of kilobytes)."""
_MAX_ITEMS = 10_000
"""Most tables, rows, metrics or values one results file may hold."""

# The shape of results.json that the readers rely on: field -> (type, required). Types: "str",
# "num" (a number or null), "int", "obj" (any object), "list" (any array), a dict (an object of
# these fields), ("list", T) (an array of T), ("map", T) (an object whose values are T).
_SUMMARY = {"mean": ("num", False), "std": ("num", False), "ci_low": ("num", False), "ci_high": ("num", False),
            "n": ("int", False), "method": ("str", False), "unit": ("str", False)}
_METRIC = {"key": ("str", True), "label": ("str", True), "better": ("str", True), "description": ("str", False),
           "scale": ("num", False), "digits": ("int", False), "chance": ("num", False)}
_ROW = {"method": ("str", True), "role": ("str", False), "description": ("str", False),
        "values": (("map", _SUMMARY), False), "pct_of_ceiling": ("num", False), "counts": ("obj", False)}
_TABLE = {"name": ("str", True), "title": ("str", False), "metrics": (("list", _METRIC), True),
          "groups": (("list", "list"), False), "count_columns": (("list", "str"), False), "primary": ("str", False),
          "rows": (("list", _ROW), True), "notes": (("list", "str"), False), "spread": ("str", False)}
_RESULTS = {"task": ("str", True), "tables": (("list", _TABLE), True), "config": ("obj", False),
            "info": ("obj", False), "interval": ("obj", False), "breakdowns": ("obj", False),
            "errors": ("list", False)}
_JSON_TYPES = {"str": (str,), "num": (int, float), "int": (int,), "obj": (dict,), "list": (list,)}
_JSON_NAMES = {"str": "a string", "num": "a number or null", "int": "an integer", "obj": "an object",
               "list": "an array"}


MAX_DIGITS = 15
"""Most decimals a metric column shows (``digits``): a double holds 15 to 17 significant digits."""
_RANGES = {"digits": (0, MAX_DIGITS)}
"""Metric fields bounded to a closed range (an unbounded ``digits`` formats numbers for minutes)."""


def _finite_or_nan(v: int | float) -> bool:
    """A JSON number the readers can turn into a float: finite (or NaN); no integer beyond a double's range."""
    try:
        return not math.isinf(float(v))
    except OverflowError:
        return False


def _check_range(value: Any, bounds: Any, where: str) -> None:
    if bounds and not bounds[0] <= value <= bounds[1]:
        raise EvaluationError(f"{where}: expected an integer in {bounds[0]}..{bounds[1]}, got {str(value)[:40]!r}")


def _check_shape(value: Any, spec: Any = None, where: str = "") -> None:
    """``value`` (parsed ``results.json``) has the shape the readers rely on.

    Raises:
        EvaluationError: ``FIELD.PATH: expected TYPE, got ...`` for the first field that does not fit.
    """
    spec = _RESULTS if spec is None else spec
    if isinstance(spec, str):
        ok = isinstance(value, _JSON_TYPES[spec]) and not isinstance(value, bool) or (spec == "num" and value is None)
        if spec == "num" and isinstance(value, (int, float)) and not _finite_or_nan(value):
            ok = False
        if spec == "int" and isinstance(value, int) and abs(value) >= 1 << 63:
            ok = False
        if not ok:
            raise EvaluationError(f"{where}: expected {_JSON_NAMES[spec]}, got {type(value).__name__} "
                                  f"{str(value)[:40]!r}")
        return
    if isinstance(spec, tuple):
        kind, item = spec
        _check_shape(value, "list" if kind == "list" else "obj", where)
        if len(value) > _MAX_ITEMS:
            raise EvaluationError(f"{where}: {len(value)} entries, expected at most {_MAX_ITEMS}")
        pairs = enumerate(value) if kind == "list" else value.items()
        for k, v in pairs:
            _check_shape(v, item, f"{where}[{k}]" if kind == "list" else f"{where}.{k}")
        return
    _check_shape(value, "obj", where)
    for key, (item, required) in spec.items():
        if key in value and not (value[key] is None and not required):
            _check_shape(value[key], item, f"{where}.{key}".lstrip("."))
            _check_range(value[key], spec is _METRIC and _RANGES.get(key), f"{where}.{key}".lstrip("."))
        elif required:
            raise EvaluationError(f"{where}.{key}".lstrip(".") + ": missing, expected by results schema "
                                  f"{SCHEMA_VERSION}")


@dataclass(frozen=True)
class MetricInfo:
    """One column: what it is, which way is better, how it is shown, this dataset's chance level."""

    key: str
    label: str
    better: str
    description: str
    scale: float = 1.0
    digits: int = 3
    chance: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict (:meth:`from_dict` restores it)."""
        return clean_json(self.__dict__)

    @staticmethod
    def from_dict(d: dict[str, Any]) -> MetricInfo:
        """The object a :meth:`to_dict` dict describes."""
        return MetricInfo(str(d["key"]), str(d["label"]), str(d["better"]), str(d.get("description", "")),
                          float(d.get("scale", 1.0)), int(d.get("digits", 3)),
                          None if d.get("chance") is None else float(d["chance"]))


@dataclass
class ResultRow:
    """One method's row: its role, what it is, a :class:`Summary` per metric, counts."""

    method: str
    role: str
    values: dict[str, Summary]
    description: str = ""
    pct_of_ceiling: float | None = None
    counts: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict (:meth:`from_dict` restores it)."""
        return clean_json({"method": self.method, "role": self.role, "description": self.description,
                           "values": {k: v.to_dict() for k, v in self.values.items()},
                           "pct_of_ceiling": self.pct_of_ceiling, "counts": self.counts})

    @staticmethod
    def from_dict(d: dict[str, Any]) -> ResultRow:
        """The object a :meth:`to_dict` dict describes."""
        return ResultRow(str(d["method"]), str(d.get("role", "method")),
                         {k: Summary.from_dict(v or {}) for k, v in (d.get("values") or {}).items()},
                         str(d.get("description", "")), d.get("pct_of_ceiling"), dict(d.get("counts") or {}))


@dataclass
class ResultTable:
    """A table of one task: columns (metrics, optionally grouped), rows, and the lines under it."""

    name: str
    title: str
    metrics: list[MetricInfo]
    rows: list[ResultRow]
    notes: list[str] = field(default_factory=list)
    groups: list[tuple[str, list[str]]] = field(default_factory=list)
    count_columns: list[str] = field(default_factory=list)
    primary: str | None = None
    """the metric the ``% of ceiling`` column is computed on (None: no such column)"""
    spread: str = "interval"
    """what a cell's ``±`` is, in every format: ``interval`` (half-width of the stated interval) or ``std``
    (standard deviation across the interval's units, ddof 1: the paper's ± of the simulation tables)"""

    def row(self, method: str) -> ResultRow:
        """The row of ``method``; :class:`EvaluationError` if there is none."""
        for r in self.rows:
            if r.method == method:
                return r
        rows = ", ".join(r.method for r in self.rows)
        raise EvaluationError(f"table {self.name!r}: no row {method!r} (rows: {rows})")

    def metric(self, key: str) -> MetricInfo:
        """The column of metric ``key``."""
        return next(m for m in self.metrics if m.key == key)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict (:meth:`from_dict` restores it)."""
        return clean_json({"name": self.name, "title": self.title, "metrics": [m.to_dict() for m in self.metrics],
                           "groups": [[g, list(ks)] for g, ks in self.groups], "count_columns": self.count_columns,
                           "primary": self.primary, "rows": [r.to_dict() for r in self.rows], "notes": self.notes,
                           "spread": self.spread})

    @staticmethod
    def from_dict(d: dict[str, Any]) -> ResultTable:
        """The object a :meth:`to_dict` dict describes."""
        return ResultTable(str(d["name"]), str(d.get("title", "")), [MetricInfo.from_dict(m) for m in d["metrics"]],
                           [ResultRow.from_dict(r) for r in d["rows"]], list(d.get("notes") or []),
                           [(str(g), list(ks)) for g, ks in d.get("groups") or []], list(d.get("count_columns") or []),
                           d.get("primary"), "std" if d.get("spread") == "std" else "interval")


@dataclass
class EvalResults:
    """Everything a ``psg-eval`` run reports, in the shape of ``results.json`` (module docstring)."""

    task: str
    tables: list[ResultTable]
    config: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    interval: dict[str, Any] = field(default_factory=dict)
    breakdowns: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    errors: list[dict[str, Any]] = field(default_factory=list)
    schema_version: int = SCHEMA_VERSION

    @property
    def ok(self) -> bool:
        """Whether no estimator reported an error."""
        return not self.errors

    def table(self, name: str | None = None) -> ResultTable:
        """The table called ``name`` (default: the first)."""
        if name is None:
            return self.tables[0]
        for t in self.tables:
            if t.name == name:
                return t
        raise EvaluationError(f"results of task {self.task!r}: no table {name!r} (tables: "
                              f"{', '.join(t.name for t in self.tables)})")

    def to_dict(self) -> dict[str, Any]:
        """The versioned JSON form (``results.json``; :meth:`from_dict` reads it)."""
        return clean_json({"schema": SCHEMA, "schema_version": self.schema_version, "task": self.task,
                           "tables": [t.to_dict() for t in self.tables], "interval": self.interval,
                           "config": self.config, "info": self.info, "breakdowns": self.breakdowns,
                           "errors": self.errors, "ok": self.ok})

    @staticmethod
    def from_dict(d: dict[str, Any], where: str = "results") -> EvalResults:
        """Read the versioned JSON form; newer schema versions raise :class:`EvaluationError`."""
        if d.get("schema") != SCHEMA:
            raise EvaluationError(f"{where}: not a psg-eval results file (no 'schema': {SCHEMA!r}; files of psg-eval "
                                  "before results schema 1 are not read: rerun the command in info.command)")
        v = d.get("schema_version")
        if not isinstance(v, int) or v > SCHEMA_VERSION or v < 1:
            raise EvaluationError(f"{where}: results schema version {v!r}; this psg-data reads versions 1 to "
                                  f"{SCHEMA_VERSION} (upgrade psg-data to read newer files)")
        try:
            _check_shape(d)
        except EvaluationError as exc:
            raise EvaluationError(f"{where}: malformed results file: {exc}") from None
        try:
            return EvalResults(str(d["task"]), [ResultTable.from_dict(t) for t in d["tables"]],
                               dict(d.get("config") or {}),
                               dict(d.get("info") or {}), dict(d.get("interval") or {}),
                               dict(d.get("breakdowns") or {}), list(d.get("errors") or []), int(v))
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
            raise EvaluationError(f"{where}: malformed results file ({type(exc).__name__}: {exc})") from None


def save_results(results: EvalResults, out_dir: str | Path, *,
                 inputs: Iterable[str | Path | None] = ()) -> dict[str, Path]:
    """Write ``results.json``, ``summary.csv`` (the long table) and ``table.txt`` (the rendered tables).

    Replaces each of these files in ``out_dir`` atomically (an interrupted call leaves the previous
    file as it was; other files in ``out_dir`` are left alone); never inside ``inputs``.

    Args:
        results: the results to write.
        out_dir: the folder (created if missing).
        inputs: paths the files must not be or lie inside (the input dataset, when known).

    Returns:
        ``{"json": ..., "summary": ..., "table": ...}``, the paths written.

    Raises:
        UnsafeOutputError: ``out_dir`` is or lies inside one of ``inputs``; nothing is written.
    """
    from psg_data.evaluation._tables import format_results
    from psg_data.writers._safe_output import write_atomically

    out, inputs = Path(out_dir), list(inputs)
    paths = {"json": out / "results.json", "summary": out / "summary.csv", "table": out / "table.txt"}
    text = json.dumps(results.to_dict(), indent=1, allow_nan=False) + "\n"
    write_atomically(paths["json"], lambda tmp: tmp.write_text(text, encoding="utf-8"), inputs=inputs)
    write_atomically(paths["summary"], lambda tmp: results_frame(results).to_csv(tmp, index=False), inputs=inputs)
    table = format_results(results) + "\n"
    write_atomically(paths["table"], lambda tmp: tmp.write_text(table, encoding="utf-8"), inputs=inputs)
    return paths


def load_results(path: str | Path) -> EvalResults:
    """Read ``results.json`` (a file, or a run folder holding one).

    Raises:
        EvaluationError: missing, not JSON, or not a known results schema (one line).
    """
    p = Path(path)
    if p.is_dir() or p.suffix != ".json":
        p = p / "results.json"
    try:
        raw = _read_regular(p)
        if len(raw) > MAX_RESULTS_BYTES:
            raise EvaluationError(f"{p}: larger than {MAX_RESULTS_BYTES} bytes, expected a psg-eval results.json "
                                  "(runs write tens of kilobytes)")
        data = json.loads(raw.decode("utf-8"))
    except EvaluationError:
        raise
    except FileNotFoundError:
        raise EvaluationError(f"{p}: missing; expected a psg-eval output folder or its results.json") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise EvaluationError(f"{p}: cannot read ({exc})") from None
    except json.JSONDecodeError as exc:
        raise EvaluationError(f"{p}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise EvaluationError(f"{p}: not a psg-eval results file (JSON nested too deeply)") from None
    except ValueError as exc:  # an integer of more digits than Python converts
        raise EvaluationError(f"{p}: not a psg-eval results file ({str(exc)[:80]})") from None
    if not isinstance(data, dict):
        raise EvaluationError(f"{p}: not a psg-eval results file (expected a JSON object)")
    return EvalResults.from_dict(data, str(p))


def _read_regular(p: Path) -> bytes:
    """At most ``MAX_RESULTS_BYTES + 1`` bytes of ``p``, a regular file (a FIFO or a device is refused
    without waiting on it: opened non-blocking, checked with ``fstat`` before any read).
    """
    fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise EvaluationError(f"{p}: not a regular file; expected a psg-eval results.json")
        return fh.read(MAX_RESULTS_BYTES + 1)


def results_frame(results: EvalResults) -> Any:
    """Long table: one row per (table, method, metric) with role, mean, std, ci_low, ci_high, n, method, unit."""
    import pandas as pd

    recs = []
    for t in results.tables:
        for r in t.rows:
            for m in t.metrics:
                s = r.values.get(m.key)
                if s is None:
                    continue
                recs.append({"table": t.name, "method": r.method, "role": r.role, "metric": m.key, "mean": s.mean,
                             "std": s.std, "ci_low": s.ci_low, "ci_high": s.ci_high, "n": s.n,
                             "interval": s.method, "unit": s.unit,
                             "pct_of_ceiling": r.pct_of_ceiling if m.key == t.primary else math.nan})
    return pd.DataFrame.from_records(recs, columns=["table", "method", "role", "metric", "mean", "std", "ci_low",
                                                    "ci_high", "n", "interval", "unit", "pct_of_ceiling"])
