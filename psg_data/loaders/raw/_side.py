"""Side files of a recordings directory: the site (rooms, receptacle and door boxes, objects),
door states, the ground-truth schedule and the scan list.

Layout (see docs/RAW_FORMATS.md)::

    recordings/
      site.json             # or site.yaml: name, timezone, cameras, rooms, receptacles, doors, objects
                            #   (and optionally openings: doorless passages, boxes like doors; and
                            #   operating_hours: "09:00-17:00", the daily hours the dataset is scored in)
      door_states.csv       # scan_id,door_id,state           (or .json / .yaml: a list of rows)
      schedule.csv          # scan_id,object_id,receptacle_id (empty receptacle_id = absent)
      scans.csv             # scan_id,recording,split         (optional)
      scan_000.bag | scan_000/ | scan_000.mcap ...

Every table may also be its own ``{table}.csv|json|yaml`` file; a table given twice is an error.
In CSV, list columns (``center_m``, ``extent_m``, ``rotation``, ``floor_polygon_m``) hold JSON arrays;
boxes may instead use ``center_x,center_y,center_z,extent_x,extent_y,extent_z[,yaw_rad]`` columns.
"""

from __future__ import annotations

import csv
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from psg_data._geometry import yaw_rotation
from psg_data._settings import Text, TimeZone, check_settings
from psg_data.errors import ConversionError

__all__ = ["SideData", "read_side_files", "SIDE_TABLES", "SITE_NAMES"]

SIDE_TABLES = ("rooms", "receptacles", "doors", "openings", "objects", "door_states", "schedule", "scans")
SITE_NAMES = ("site.json", "site.yaml", "site.yml")
_EXTS = (".csv", ".json", ".yaml", ".yml")
_LIST_COLS = ("center_m", "extent_m", "rotation", "floor_polygon_m")


@dataclass
class SideData:
    """Everything the side files say. ``tables`` maps a table name to rows (dicts)."""

    name: str | None = None
    timezone: str | None = None
    operating_hours: str | None = None
    """Daily local hours the site is scored in (``09:00-17:00``; stored in the manifest's ``extra``)."""
    cameras: dict[str, str] = field(default_factory=dict)
    """Optical frame id in the recordings -> camera_id."""
    tables: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)
    sources: dict[str, str] = field(default_factory=dict)
    """Table name -> file it was read from."""

    def scan_rows(self) -> dict[str, dict[str, Any]]:
        """Recording name (file or directory name, with or without suffix) -> scans.csv row."""
        out: dict[str, dict[str, Any]] = {}
        for r in self.tables.get("scans", []):
            rec = str(r.get("recording") or r["scan_id"])
            out[rec] = r
            out[Path(rec).stem] = r
        return out


def _load_structured(path: Path) -> Any:
    try:
        text = path.read_text(encoding="utf-8")
        if path.suffix == ".json":
            return json.loads(text)
        from ruamel.yaml import YAML

        return YAML(typ="safe").load(text)
    except Exception as exc:  # json / yaml errors
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ConversionError(f"{path}: cannot parse {path.suffix[1:].upper()} ({first})") from exc


def _num_list(value: str, path: Path, line: int, col: str) -> Any:
    try:
        return json.loads(value)
    except json.JSONDecodeError:
        try:
            return [float(v) for v in value.replace(";", " ").replace(",", " ").split()]
        except ValueError as exc:
            raise ConversionError(f"{path}:{line}: {col}: expected a JSON array of numbers, got {value!r}") from exc


def _read_csv(path: Path) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        for line, row in enumerate(reader, start=2):
            out: dict[str, Any] = {}
            for k, v in row.items():
                if k is None:
                    raise ConversionError(f"{path}:{line}: more values than header columns")
                k = k.strip()
                v = None if v is None or v.strip() == "" else v.strip()
                out[k] = _num_list(v, path, line, k) if (k in _LIST_COLS and v is not None) else v
            if "center_x" in out:
                try:
                    out["center_m"] = [float(out.pop(f"center_{a}")) for a in "xyz"]
                    out["extent_m"] = [float(out.pop(f"extent_{a}")) for a in "xyz"]
                    yaw = out.pop("yaw_rad", None)
                    out.setdefault("rotation", yaw_rotation(float(yaw or 0.0)).reshape(9).tolist())
                except (KeyError, TypeError, ValueError) as exc:
                    raise ConversionError(f"{path}:{line}: box columns: expected numbers in center_x..z and "
                                          f"extent_x..z ({exc})") from exc
            rows.append(out)
    return rows


def _read_table_file(path: Path) -> list[dict[str, Any]]:
    if path.suffix == ".csv":
        return _read_csv(path)
    data = _load_structured(path)
    if not isinstance(data, list) or not all(isinstance(r, dict) for r in data):
        raise ConversionError(f"{path}: expected a list of objects (one per row)")
    return [dict(r) for r in data]


_HOURS = re.compile(r"^\d{1,2}(:\d{2})?-\d{1,2}(:\d{2})?(,\d{1,2}(:\d{2})?-\d{1,2}(:\d{2})?)*$")


def _hours_text(value: Any, path: Path) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or not _HOURS.match(value.replace(" ", "")):
        raise ConversionError(f"{path}: operating_hours: expected local hour ranges like \"09:00-17:00\", got "
                              f"{value!r}")
    return value.replace(" ", "")


def read_side_files(directory: str | Path | None) -> SideData:
    """Read the side files in ``directory`` (missing files mean empty tables).

    Raises:
        ConversionError: unparsable file, a table given twice, or a malformed site file.
    """
    side = SideData()
    if directory is None:
        return side
    d = Path(directory)
    if not d.is_dir():
        return side
    site_files = [d / n for n in SITE_NAMES if (d / n).is_file()]
    if len(site_files) > 1:
        raise ConversionError(f"{d}: both {site_files[0].name} and {site_files[1].name}; expected one site file")
    sources: dict[str, Path] = {}
    if site_files:
        path = site_files[0]
        site = _load_structured(path)
        if not isinstance(site, dict):
            raise ConversionError(f"{path}: expected an object with keys name, timezone, rooms, receptacles, ...")
        side.files.append(path.name)
        check_settings({"name": Text(), "timezone": TimeZone()}, {k: site.get(k) for k in ("name", "timezone")},
                       str(path), ConversionError)
        side.name = site.get("name")
        side.timezone = site.get("timezone")
        side.operating_hours = _hours_text(site.get("operating_hours"), path)
        for cam in site.get("cameras") or []:
            if not isinstance(cam, dict) or "camera_id" not in cam or "frame_id" not in cam:
                raise ConversionError(f"{path}: cameras: expected objects with camera_id and frame_id")
            side.cameras[str(cam["frame_id"]).lstrip("/")] = str(cam["camera_id"])
        for name in SIDE_TABLES:
            if name in site and site[name] is not None:
                rows = site[name]
                if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
                    raise ConversionError(f"{path}: {name}: expected a list of objects (one per row)")
                side.tables[name] = [dict(r) for r in rows]
                sources[name] = path
    for name in SIDE_TABLES:
        for ext in _EXTS:
            path = d / f"{name}{ext}"
            if not path.is_file():
                continue
            if name in sources:
                raise ConversionError(f"{path}: table {name!r} is also given in {sources[name].name}; expected "
                                      f"it once")
            side.tables[name] = _read_table_file(path)
            sources[name] = path
            side.files.append(path.name)
    for rows in side.tables.values():
        for r in rows:
            if "extent_m" in r and "rotation" not in r:
                r["rotation"] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    side.sources = {k: str(v) for k, v in sources.items()}
    return side
