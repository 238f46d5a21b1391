"""A saved graph's file checked before anything is built from it (a graph file is untrusted input).

:func:`read_graph_file` reads at most :data:`MAX_GRAPH_BYTES` from a regular file (a FIFO or a
device is refused without waiting on it), parses it and refuses, with one line naming the field, a
document nested deeper than :data:`MAX_DEPTH`, a list or object of more than :data:`MAX_ITEMS`
entries, an envelope of the wrong shape, a grid larger than :data:`MAX_GRID_CELLS` cells (its masks
are inflated with that bound, :func:`unpack_mask`), and the settings every built-in filter state
shares whose values would make a query fail or take unbounded time or memory (:data:`STATE_RULES`:
time zones, ``bin_s``, ``num_steps``, FreMEn ``k`` / ``base_period_s``, a time-of-week ``table`` or
``values``). :func:`psg_data.graph._store.load_graph` then builds the filters and asks each once
(a state the estimator accepts but cannot predict from is refused there, not at query time).
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import os
import stat
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.errors import GraphError

__all__ = ["GRAPH_FORMAT", "GRAPH_VERSION", "MAX_GRAPH_BYTES", "MAX_DEPTH", "MAX_ITEMS", "MAX_GRID_CELLS",
           "MAX_GRID_TOTAL_CELLS", "MAX_NUM_STEPS", "MAX_FREMEN_K", "STATE_RULES", "read_graph_file",
           "check_graph_dict", "unpack_mask", "zone_problem"]

GRAPH_FORMAT = "psg-predictive-graph"
GRAPH_VERSION = 1
MAX_GRAPH_BYTES = 64 << 20
"""Largest graph file read (the built-in lab's graph is 40 kB; a thousand-edge graph a few MB)."""
MAX_DEPTH = 32
"""Deepest nesting of lists and objects (the format nests 8 deep)."""
MAX_ITEMS = 1_000_000
"""Most entries of one list or object."""
MAX_GRID_CELLS = 1 << 26
"""Most cells of a saved occupancy grid (8192 x 8192, the image pixel cap); a mask inflates to 1/8 of that."""
MAX_GRID_TOTAL_CELLS = 1 << 27
"""Most cells of all masks of a saved grid together (one byte each in memory: 128 MB)."""
MAX_NUM_STEPS = 10_000
"""Most simulated sub-steps between two times of a Perpetua filter (the default is 1)."""
MAX_FREMEN_K = 100_000
"""Largest FreMEn harmonic index and most components of one model (the lab uses at most a few dozen)."""
_WEEK_S = 7 * 86400.0
_MAX_PERIOD_S = 100 * 365.25 * 86400.0


def _reject(where: str, expected: str, value: Any) -> GraphError:
    return GraphError(f"{where}: expected {expected}, got {str(value)[:40]!r}")


def _is_num(v: Any) -> bool:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def zone_problem(name: Any) -> str | None:
    """Why ``name`` is not an IANA time zone this machine knows (None if it is)."""
    import zoneinfo

    if not isinstance(name, str) or not name or len(name) > 64:
        return "an IANA time zone name"
    try:
        zoneinfo.ZoneInfo(name)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError, OSError):
        return "an IANA time zone name (like 'Europe/Berlin') known to this machine"
    return None


def _timezone(v: Any, where: str) -> None:
    problem = zone_problem(v)
    if problem is not None:
        raise _reject(where, problem, v)


def _bin_s(v: Any, where: str) -> None:
    if not _is_num(v) or not 0.0 < float(v) <= _WEEK_S:
        raise _reject(where, f"a finite bin width in (0, {_WEEK_S:.0f}] seconds", v)


def _num_steps(v: Any, where: str) -> None:
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= MAX_NUM_STEPS:
        raise _reject(where, f"an integer number of sub-steps in 0..{MAX_NUM_STEPS}", v)


def _base_period(v: Any, where: str) -> None:
    if not _is_num(v) or not 1.0 <= float(v) <= _MAX_PERIOD_S:
        raise _reject(where, "a finite base period of 1 s to 100 years", v)


def _k(v: Any, where: str) -> None:
    if not isinstance(v, list) or len(v) > MAX_FREMEN_K:
        raise _reject(where, f"a list of at most {MAX_FREMEN_K} harmonic indices", v)
    for i, k in enumerate(v):
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k <= MAX_FREMEN_K:
            raise _reject(f"{where}[{i}]", f"an integer harmonic index in 0..{MAX_FREMEN_K}", k)


def _table(v: Any, where: str) -> None:
    if not isinstance(v, list) or not v or not all(_is_num(x) and 0.0 <= float(x) <= 1.0 for x in v):
        raise _reject(where, "a non-empty list of probabilities in [0, 1]", v)


STATE_RULES: dict[str, Callable[[Any, str], None]] = {
    "timezone": _timezone, "bin_s": _bin_s, "num_steps": _num_steps, "base_period_s": _base_period, "k": _k,
    "table": _table, "values": _table}
"""Field name -> check, applied wherever the field appears in the estimators' settings and the filter
states (the built-in states share these names; a plugin reusing one is held to the same range)."""


def _walk(value: Any, where: str, rules: bool) -> None:
    """Depth, sizes and (with ``rules``) :data:`STATE_RULES` of every node below ``value`` (iteratively)."""
    stack: list[tuple[Any, str, int]] = [(value, where, 0)]
    while stack:
        v, w, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise GraphError(f"{w}: nested more than {MAX_DEPTH} levels deep")
        if isinstance(v, dict):
            if len(v) > MAX_ITEMS:
                raise GraphError(f"{w}: {len(v)} entries, expected at most {MAX_ITEMS}")
            for k, x in v.items():
                if rules and k in STATE_RULES:
                    STATE_RULES[k](x, f"{w}.{k}")
                stack.append((x, f"{w}.{k}", depth + 1))
        elif isinstance(v, list):
            if len(v) > MAX_ITEMS:
                raise GraphError(f"{w}: {len(v)} entries, expected at most {MAX_ITEMS}")
            stack.extend((x, f"{w}[{i}]", depth + 1) for i, x in enumerate(v))
        elif isinstance(v, int) and not isinstance(v, bool) and abs(v) >= 1 << 63:
            raise _reject(w, "an integer of at most 64 bits", v)


def _open_regular(path: Path) -> bytes:
    """At most ``MAX_GRAPH_BYTES + 1`` bytes of the regular file ``path`` (never waits on a FIFO or a device)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise GraphError(f"{path}: not a regular file; expected a predictive graph saved by psg-data (.json)")
        return fh.read(MAX_GRAPH_BYTES + 1)


def read_graph_file(path: Path) -> dict[str, Any]:
    """The parsed, checked content of the graph file ``path`` (see the module docstring).

    Raises:
        GraphError: one line naming the file and the field.
    """
    try:
        raw = _open_regular(path)
        if len(raw) > MAX_GRAPH_BYTES:
            raise GraphError(f"{path}: larger than {MAX_GRAPH_BYTES} bytes; expected a predictive graph file")
        d = json.loads(raw.decode("utf-8"))
    except GraphError:
        raise
    except RecursionError:
        raise GraphError(f"{path}: not a predictive graph (JSON nested too deeply)") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise GraphError(f"{path}: cannot read a predictive graph ({type(exc).__name__}: {exc})") from None
    if not isinstance(d, dict) or d.get("format") != GRAPH_FORMAT:
        got = d.get("format") if isinstance(d, dict) else type(d).__name__
        raise GraphError(f"{path}: format: expected {GRAPH_FORMAT!r}, got {str(got)[:40]!r}")
    v = d.get("version")
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= GRAPH_VERSION:
        raise GraphError(f"{path}: version: {v if isinstance(v, int) else str(v)[:40]!r}, this psg-data reads "
                         f"versions 1 to {GRAPH_VERSION}; upgrade psg-data for a newer file")
    try:
        check_graph_dict(d)
    except GraphError as exc:
        raise GraphError(f"{path}: malformed predictive graph: {exc}") from None
    return d  # type: ignore[no-any-return]


def _need(d: dict[str, Any], key: str, types: type | tuple[type, ...], expected: str, *, none_ok: bool = False) -> Any:
    v = d.get(key)
    if (v is None and not none_ok) or (v is not None and not isinstance(v, types)):
        raise _reject(key, expected, v)
    return v


def check_graph_dict(d: Any) -> None:
    """Refuse a parsed graph file of the wrong shape (after ``format`` and ``version``, checked by the loader).

    Raises:
        GraphError: ``FIELD: expected ..., got ...`` for the first field that does not fit.
    """
    if not isinstance(d, dict):
        raise _reject("file", "a JSON object", type(d).__name__)
    _walk(d, "", rules=False)
    layout = _need(d, "layout", dict, "an object (the scene layout)")
    _timezone(layout.get("timezone"), "layout.timezone")
    for key in ("estimator", "door_estimator"):
        spec = _need(d, key, dict, "an object {name, params} or null", none_ok=True)
        if spec is not None and (not isinstance(spec.get("name"), str) or not isinstance(spec.get("params", {}), dict)):
            raise _reject(key, "an object {name: string, params: object}", spec)
    edges = _need(d, "edges", list, "a list of [object_id, receptacle_id]")
    filters = _need(d, "filters", list, "a list of filter states")
    if len(edges) != len(filters):
        raise GraphError(f"filters: {len(filters)} states for {len(edges)} edges; expected one per edge")
    for i, e in enumerate(edges):
        if not (isinstance(e, list) and len(e) == 2 and all(isinstance(x, str) for x in e)):
            raise _reject(f"edges[{i}]", "[object_id, receptacle_id]", e)
    for i, f in enumerate(filters):
        if not isinstance(f, dict):
            raise _reject(f"filters[{i}]", "an object (a filter state)", f)
    _need(d, "new_edge", dict, "an object (a filter state) or null", none_ok=True)
    _check_doors(_need(d, "doors", dict, "an object door_id -> door model"))
    _need(d, "info", dict, "an object", none_ok=True)
    for key in ("estimator", "door_estimator", "filters", "new_edge", "doors"):
        _walk(d.get(key), key, rules=True)
    _check_grid(_need(d, "grid", dict, "an object {options[, arrays]}"))


def _check_doors(doors: dict[str, Any]) -> None:
    for door, v in doors.items():
        w = f"doors.{door}"
        if not isinstance(v, dict) or v.get("kind") not in ("prior", "estimator"):
            raise _reject(f"{w}.kind", "'prior' or 'estimator'", v.get("kind") if isinstance(v, dict) else v)
        if v["kind"] == "prior":
            if not _is_num(v.get("value")) or not 0.0 <= float(v["value"]) <= 1.0:
                raise _reject(f"{w}.value", "a probability in [0, 1]", v.get("value"))
            if v.get("last_t_s") is not None and not _is_num(v["last_t_s"]):
                raise _reject(f"{w}.last_t_s", "a finite time in seconds or null", v["last_t_s"])
        elif not isinstance(v.get("state"), dict):
            raise _reject(f"{w}.state", "an object (a filter state)", v.get("state"))


def _check_grid(grid: dict[str, Any]) -> None:
    if not isinstance(grid.get("options", {}), dict):
        raise _reject("grid.options", "an object", grid.get("options"))
    a = grid.get("arrays")
    if not a:
        return
    if not isinstance(a, dict):
        raise _reject("grid.arrays", "an object", a)
    shape = a.get("shape")
    if not (isinstance(shape, list) and len(shape) == 2 and all(isinstance(n, int) and not isinstance(n, bool)
                                                                 and n > 0 for n in shape)):
        raise _reject("grid.arrays.shape", "[rows, columns], two positive integers", shape)
    if shape[0] * shape[1] > MAX_GRID_CELLS:
        raise GraphError(f"grid.arrays.shape: {shape[0]} x {shape[1]} cells, expected at most {MAX_GRID_CELLS}")
    for key in ("resolution_m", "robot_radius_m"):
        if not _is_num(a.get(key)) or float(a[key]) < 0 or (key == "resolution_m" and float(a[key]) == 0):
            raise _reject(f"grid.arrays.{key}", "a finite positive number of metres", a.get(key))
    origin = a.get("origin_m")
    if not (isinstance(origin, list) and 2 <= len(origin) <= 3 and all(_is_num(x) for x in origin)):
        raise _reject("grid.arrays.origin_m", "2 or 3 finite numbers", origin)
    masks = [("static_obstacle", a.get("static_obstacle"))]
    for key in ("door_cells", "receptacle_cells"):
        if not isinstance(a.get(key), dict):
            raise _reject(f"grid.arrays.{key}", "an object id -> packed mask", a.get(key))
        masks += [(f"{key}.{k}", v) for k, v in a[key].items()]
    if len(masks) * shape[0] * shape[1] > MAX_GRID_TOTAL_CELLS:
        raise GraphError(f"grid.arrays: {len(masks)} masks of {shape[0]} x {shape[1]} cells, expected at most "
                         f"{MAX_GRID_TOTAL_CELLS} cells in all")
    for where, text in masks:
        if not isinstance(text, str) or len(text) > 4 * MAX_GRAPH_BYTES // 3 + 4:
            raise _reject(f"grid.arrays.{where}", "a packed mask (base64 text)", text)


def unpack_mask(text: str, shape: tuple[int, int], where: str = "mask") -> Any:
    """The boolean mask ``shape`` packed in ``text`` (base64 of zlib of packed bits), inflated to at
    most the bytes that shape needs (a longer stream is refused before it is inflated further).

    Raises:
        GraphError: not base64, not zlib, or more or fewer bytes than the shape needs.
    """
    need = (shape[0] * shape[1] + 7) // 8
    try:
        z = zlib.decompressobj()
        raw = z.decompress(base64.b64decode(text, validate=True), need)
        more = b"" if z.eof else z.decompress(z.unconsumed_tail, 1)
    except (binascii.Error, ValueError, zlib.error) as exc:
        raise GraphError(f"{where}: expected base64 of zlib-packed bits ({type(exc).__name__}: {exc})") from None
    if more:
        raise GraphError(f"{where}: inflates to more than the {need} bytes of a {shape[0]} x {shape[1]} mask")
    if not z.eof or len(raw) != need:
        raise GraphError(f"{where}: {len(raw)} bytes{'' if z.eof else ' (stream cut short)'}, expected {need} for "
                         f"a {shape[0]} x {shape[1]} mask")
    bits = np.unpackbits(np.frombuffer(raw, np.uint8))
    return bits[: shape[0] * shape[1]].reshape(shape).view(bool)  # 0 / 1 bytes: a view, no copy
