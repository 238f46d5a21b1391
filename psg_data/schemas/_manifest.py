"""The dataset manifest ``dataset.json`` read into a dataclass (cf. lerobot's ``info.json``)."""

from __future__ import annotations

import json
import logging
import re
import zoneinfo
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from psg_data.errors import FormatError
from psg_data.schemas._paths import inside_dataset, real_root

__all__ = ["DatasetInfo", "FORMAT_NAME", "FORMAT_VERSION", "read_manifest", "manifest_from_dict", "format_major",
           "parse_format_version"]

log = logging.getLogger(__name__)

FORMAT_NAME = "psg-dataset"
FORMAT_VERSION = "2.0"
"""``MAJOR.MINOR``: readers accept any minor of their major and refuse a newer major.

2.0 added the tar image layout (``frames`` columns ``color_offset`` ... ``depth_size``); this
release reads 1.x datasets too."""

COLOR_ENCODINGS = ("png", "jpeg")


@dataclass
class DatasetInfo:
    """Contents of ``dataset.json``.

    Attributes:
        name: dataset name.
        timezone: IANA timezone of the site (e.g. ``America/Toronto``), used for weekday and
            time-of-day; all stamps are UTC.
        color_encoding: ``png`` (lossless) or ``jpeg``.
        files_sha256: hex SHA-256 of ``tables/files.parquet``, which holds every other checksum.
        counts: number of rows per table plus ``images``.
        units: unit of every kind of quantity (fixed by the format, stored for readers).
        created_by: the software and version that wrote the dataset.
        extra: free-form provenance (converter config, generator parameters, ...).
    """

    name: str
    timezone: str
    color_encoding: str
    files_sha256: str = ""
    counts: dict[str, int] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=lambda: {
        "length": "m",
        "time": "int64 nanoseconds since the Unix epoch, UTC",
        "depth_image": "uint16 millimetres, 0 = invalid",
        "angles": "rad",
    })
    created_by: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    format: str = FORMAT_NAME
    format_version: str = FORMAT_VERSION

    def to_json(self) -> str:
        """The manifest as JSON text (``dataset.json``), with a final newline."""
        return json.dumps(asdict(self), indent=2, sort_keys=False) + "\n"

    @property
    def tz(self) -> zoneinfo.ZoneInfo:
        """The dataset's time zone (IANA ``timezone``)."""
        return zoneinfo.ZoneInfo(self.timezone)

    @property
    def major(self) -> int:
        """Major format version of the dataset."""
        return format_major(self.format_version)


_VERSION_RE = re.compile(r"(0|[1-9][0-9]*)\.(0|[1-9][0-9]*)")


def parse_format_version(version: object) -> tuple[int, int]:
    """``(major, minor)`` of a format version: a string ``MAJOR.MINOR`` (ValueError otherwise)."""
    m = _VERSION_RE.fullmatch(version) if isinstance(version, str) else None
    if m is None:
        raise ValueError(f"expected a string 'MAJOR.MINOR' (e.g. {FORMAT_VERSION!r}), got {version!r}")
    return int(m.group(1)), int(m.group(2))


def format_major(version: str) -> int:
    """Major number of a ``MAJOR.MINOR`` format version (ValueError if malformed)."""
    return parse_format_version(version)[0]


def _major(version: object, where: str) -> int:
    try:
        return format_major(version)  # type: ignore[arg-type]
    except ValueError as exc:
        raise FormatError(f"{where}: format_version: {exc}") from None


def manifest_from_dict(data: Any, where: str, *, warn_newer_minor: bool = True) -> DatasetInfo:
    """Build a :class:`DatasetInfo` from parsed JSON, checking format, version and fields.

    A newer minor version is read with a logged warning (``warn_newer_minor``; the validator reports
    it as a problem instead).
    """
    if not isinstance(data, dict):
        raise FormatError(f"{where}: expected a JSON object, got {type(data).__name__}")
    if data.get("format") != FORMAT_NAME:
        raise FormatError(f"{where}: format: expected {FORMAT_NAME!r}, got {data.get('format')!r}")
    version = data.get("format_version")
    if version is None:
        raise FormatError(f"{where}: format_version: missing, expected 'MAJOR.MINOR'")
    if _major(version, where) > _major(FORMAT_VERSION, where):
        raise FormatError(
            f"{where}: format_version: {version} is newer than this psg-data reads "
            f"({FORMAT_VERSION}); upgrade psg-data to a release that reads format {version.split('.')[0]}.x"
        )
    if _major(version, where) < 1:
        raise FormatError(f"{where}: format_version: {version}, expected 1.x or 2.x")
    if warn_newer_minor and parse_format_version(version) > parse_format_version(FORMAT_VERSION):
        log.warning("%s: format_version %s is a newer minor version than this psg-data knows (%s): what it "
                    "added is ignored; psg-data validate cannot check it", where, version, FORMAT_VERSION)
    known = {f.name for f in fields(DatasetInfo)}
    unknown = sorted(set(data) - known)
    if unknown:
        log.warning("%s: ignoring unknown manifest keys %s", where, ", ".join(unknown))
    for key in ("name", "timezone", "color_encoding"):
        if not isinstance(data.get(key), str) or not data.get(key):
            raise FormatError(f"{where}: {key}: missing or not a string")
    if data["color_encoding"] not in COLOR_ENCODINGS:
        raise FormatError(f"{where}: color_encoding: expected one of {COLOR_ENCODINGS}, got {data['color_encoding']!r}")
    try:
        zoneinfo.ZoneInfo(data["timezone"])
    except (zoneinfo.ZoneInfoNotFoundError, ValueError) as exc:
        raise FormatError(f"{where}: timezone: {data['timezone']!r} is not an IANA timezone name") from exc
    return DatasetInfo(**{k: v for k, v in data.items() if k in known})


def read_manifest(root: str | Path) -> DatasetInfo:
    """Read and check ``ROOT/dataset.json``.

    Raises:
        FormatError: missing or unreadable manifest, wrong format, newer major version.
    """
    path = Path(root) / "dataset.json"
    if not path.is_file():
        raise FormatError(f"{path}: missing manifest; is {root} a psg-dataset directory?")
    inside_dataset(real_root(root), "dataset.json", f"{root}: manifest")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FormatError(f"{path}: not valid JSON ({exc})") from exc
    return manifest_from_dict(data, str(path))
