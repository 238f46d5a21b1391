"""Arrow schemas of every table of the psg-dataset format, version 2.

These schemas are the single source of truth: the writer casts to them, the validator checks
against them, and ``docs/FORMAT.md`` lists exactly their fields (a test keeps the two in step).
Each field carries a ``doc`` metadata entry; units and frames are part of the field names
(``stamp_ns``, ``T_world_camera``, ``extent_m``).
"""

from __future__ import annotations

from dataclasses import dataclass

import pyarrow as pa

__all__ = [
    "TableSpec",
    "TABLES",
    "REQUIRED_TABLES",
    "table_path",
    "COLOR_PATH_TEMPLATE",
    "DEPTH_PATH_TEMPLATE",
    "ARCHIVE_PATH_TEMPLATE",
    "ARCHIVE_MEMBER_TEMPLATES",
    "IMAGE_LAYOUTS",
    "COLUMNS_SINCE",
    "schema_for",
    "MANIFEST_NAME",
    "DOOR_STATES",
    "LABEL_CODES",
    "CODE_PRESENT",
    "CODE_ABSENT",
    "CODE_MISSING",
    "CODE_INVALID",
    "VISIBILITY_KINDS",
]

MANIFEST_NAME = "dataset.json"
"""File name of the manifest at the dataset root."""

COLOR_PATH_TEMPLATE = "images/{scan_id}/color/{frame_index:06d}.{ext}"
"""Relative path of a colour image (``ext`` is ``png`` or ``jpg``)."""

DEPTH_PATH_TEMPLATE = "images/{scan_id}/depth/{frame_index:06d}.png"
"""Relative path of a depth image (16-bit PNG, millimetres, 0 = invalid)."""

ARCHIVE_PATH_TEMPLATE = "images/{scan_id}.tar"
"""Relative path of a scan's image archive (``tar`` layout): an uncompressed POSIX ustar archive."""

ARCHIVE_MEMBER_TEMPLATES = ("color/{frame_index:06d}.{ext}", "depth/{frame_index:06d}.png")
"""Member names of a frame's colour and depth image inside its scan archive (extracting the archive
into ``images/<scan_id>/`` gives the ``files`` layout's paths)."""

IMAGE_LAYOUTS = ("tar", "files")
"""How images are stored: one tar archive per scan (default) or one file per image."""

DOOR_STATES = ("open", "closed", "unknown")
"""Allowed values of ``door_states.state``."""

CODE_PRESENT = 1
"""Label code: observed present (the object was seen on the receptacle)."""
CODE_ABSENT = 0
"""Label code: observed absent (the receptacle was seen and the object was not on it)."""
CODE_MISSING = -1
"""Label code: no observation (receptacle not seen, or presence could not be confirmed)."""
CODE_INVALID = -2
"""Label code: the receptacle is not a valid location of the object (not an edge of the graph)."""
LABEL_CODES = (CODE_PRESENT, CODE_ABSENT, CODE_MISSING, CODE_INVALID)
"""Allowed values of ``labels.code`` (the paper's privileged codes)."""
VISIBILITY_KINDS = ("receptacle", "object", "door")
"""Allowed values of ``visibility.kind``."""


def _f(name: str, type_: pa.DataType, doc: str, *, nullable: bool = False) -> pa.Field:
    return pa.field(name, type_, nullable=nullable, metadata={"doc": doc})


_VEC3 = pa.list_(pa.float64(), 3)
_MAT3 = pa.list_(pa.float64(), 9)
_MAT4 = pa.list_(pa.float64(), 16)


@dataclass(frozen=True)
class TableSpec:
    """One table of the format: its name, Arrow schema, primary key and foreign keys."""

    name: str
    schema: pa.Schema
    doc: str
    key: tuple[str, ...]
    references: tuple[tuple[str, str, str], ...] = ()
    """(column, referenced table, referenced column) triples checked by the validator."""
    required: bool = True

    @property
    def path(self) -> str:
        """Path of the table's Parquet file, relative to the dataset root."""
        return table_path(self.name)


def table_path(name: str) -> str:
    """Relative path of table ``name`` inside a dataset directory."""
    return f"tables/{name}.parquet"


_BOX_FIELDS = [
    _f("center_m", _VEC3, "box centre in the world frame, metres"),
    _f("extent_m", _VEC3, "full box side lengths along the box's own x, y, z axes, metres, > 0"),
    _f("rotation", _MAT3, "row-major 3x3 rotation world-from-box (orthonormal, det +1)"),
]

TABLES: dict[str, TableSpec] = {}


def _add(spec: TableSpec) -> None:
    TABLES[spec.name] = spec


_add(TableSpec(
    "cameras",
    pa.schema([
        _f("camera_id", pa.string(), "unique camera id"),
        _f("width", pa.int32(), "image width, pixels"),
        _f("height", pa.int32(), "image height, pixels"),
        _f("fx", pa.float64(), "focal length x, pixels"),
        _f("fy", pa.float64(), "focal length y, pixels"),
        _f("cx", pa.float64(), "principal point x, pixels (OpenCV: pixel centres at integers)"),
        _f("cy", pa.float64(), "principal point y, pixels"),
        _f("distortion_model", pa.string(), "'none', 'plumb_bob' (OpenCV k1 k2 p1 p2 k3) or 'equidistant'"),
        _f("distortion_coeffs", pa.list_(pa.float64()), "distortion coefficients of the model, may be empty"),
        _f("depth_scale_m", pa.float64(), "metres per unit of the stored depth image (0.001: millimetres)"),
        _f("frame_id", pa.string(), "optical frame name in the source recording", nullable=True),
    ]),
    "Pinhole intrinsics of every camera (colour and depth are registered: one camera).",
    key=("camera_id",),
))

_add(TableSpec(
    "scans",
    pa.schema([
        _f("scan_id", pa.string(), "unique scan (mapping session) id"),
        _f("start_stamp_ns", pa.int64(), "first frame stamp, int64 UTC nanoseconds"),
        _f("end_stamp_ns", pa.int64(), "last frame stamp, int64 UTC nanoseconds, >= start"),
        _f("source", pa.string(), "source recording (file name) or generator", nullable=True),
        _f("split", pa.string(), "declared split: 'train', 'val', 'test' or null", nullable=True),
    ]),
    "One row per scan (mapping session), ordered by start time.",
    key=("scan_id",),
))

_add(TableSpec(
    "frames",
    pa.schema([
        _f("scan_id", pa.string(), "scan this frame belongs to"),
        _f("frame_index", pa.int32(), "0-based index of the frame within its scan"),
        _f("stamp_ns", pa.int64(), "capture time, int64 UTC nanoseconds, increasing within a scan"),
        _f("camera_id", pa.string(), "camera that took the frame"),
        _f("T_world_camera", _MAT4, "row-major 4x4 camera-to-world pose (OpenCV camera axes), metres"),
        _f("color_path", pa.string(), "relative path of the colour image, or of the scan archive holding it"),
        _f("depth_path", pa.string(), "relative path of the depth image, or of the scan archive holding it"),
        _f("color_offset", pa.int64(), "byte offset of the colour image inside color_path; null: the whole file",
           nullable=True),
        _f("color_size", pa.int64(), "byte length of the colour image inside color_path; null: the whole file",
           nullable=True),
        _f("depth_offset", pa.int64(), "byte offset of the depth image inside depth_path; null: the whole file",
           nullable=True),
        _f("depth_size", pa.int64(), "byte length of the depth image inside depth_path; null: the whole file",
           nullable=True),
    ]),
    "One row per RGB-D frame; each image is a file, or a byte range of its scan's archive.",
    key=("scan_id", "frame_index"),
    references=(("scan_id", "scans", "scan_id"), ("camera_id", "cameras", "camera_id")),
))

_add(TableSpec(
    "rooms",
    pa.schema([
        _f("room_id", pa.string(), "unique room id"),
        _f("name", pa.string(), "human-readable room name"),
        _f("floor_polygon_m", pa.list_(pa.list_(pa.float64(), 2)),
           "floor outline as (x, y) vertices in the world frame, metres, counter-clockwise", nullable=True),
    ]),
    "Rooms of the site.",
    key=("room_id",),
))

_add(TableSpec(
    "receptacles",
    pa.schema([
        _f("receptacle_id", pa.string(), "unique receptacle id"),
        _f("name", pa.string(), "human-readable name"),
        _f("category", pa.string(), "furniture category (table, shelf, counter, ...)", nullable=True),
        _f("room_id", pa.string(), "room the receptacle stands in"),
        *_BOX_FIELDS,
    ]),
    "Receptacles (static furniture objects rest on) as oriented boxes in the world frame.",
    key=("receptacle_id",),
    references=(("room_id", "rooms", "room_id"),),
))

_add(TableSpec(
    "doors",
    pa.schema([
        _f("door_id", pa.string(), "unique door id"),
        _f("name", pa.string(), "human-readable name"),
        _f("room_a", pa.string(), "first room the door joins"),
        _f("room_b", pa.string(), "second room the door joins"),
        *_BOX_FIELDS,
    ]),
    "Doors between rooms, their doorway as an oriented box in the world frame.",
    key=("door_id",),
    references=(("room_a", "rooms", "room_id"), ("room_b", "rooms", "room_id")),
))

_add(TableSpec(
    "openings",
    pa.schema([
        _f("opening_id", pa.string(), "unique opening id"),
        _f("name", pa.string(), "human-readable name"),
        _f("room_a", pa.string(), "first room the opening joins"),
        _f("room_b", pa.string(), "second room the opening joins"),
        *_BOX_FIELDS,
    ]),
    "Doorless passages between rooms (always traversable), as oriented boxes in the world frame.",
    key=("opening_id",),
    references=(("room_a", "rooms", "room_id"), ("room_b", "rooms", "room_id")),
    required=False,
))

_add(TableSpec(
    "door_states",
    pa.schema([
        _f("scan_id", pa.string(), "scan during which the state holds"),
        _f("door_id", pa.string(), "door"),
        _f("state", pa.string(), "'open', 'closed' or 'unknown'"),
    ]),
    "Ground-truth door state per scan and door.",
    key=("scan_id", "door_id"),
    references=(("scan_id", "scans", "scan_id"), ("door_id", "doors", "door_id")),
))

_add(TableSpec(
    "objects",
    pa.schema([
        _f("object_id", pa.string(), "unique object id"),
        _f("name", pa.string(), "object name (e.g. 'redmug')"),
        _f("description", pa.string(), "free-text description", nullable=True),
    ]),
    "Semi-static objects tracked in the dataset.",
    key=("object_id",),
))

_add(TableSpec(
    "schedule",
    pa.schema([
        _f("scan_id", pa.string(), "scan"),
        _f("object_id", pa.string(), "object"),
        _f("receptacle_id", pa.string(), "receptacle holding the object during the scan; null = absent",
           nullable=True),
    ]),
    "Ground-truth schedule: where each object was during each scan.",
    key=("scan_id", "object_id"),
    references=(("scan_id", "scans", "scan_id"), ("object_id", "objects", "object_id"),
                ("receptacle_id", "receptacles", "receptacle_id")),
))

_add(TableSpec(
    "files",
    pa.schema([
        _f("path", pa.string(), "relative path of a file of the dataset (every file but dataset.json and this table)"),
        _f("size_bytes", pa.int64(), "file size, bytes"),
        _f("sha256", pa.string(), "hex SHA-256 of the file content"),
    ]),
    "Checksums of every file; dataset.json records the checksum of this table.",
    key=("path",),
))

_add(TableSpec(
    "labels",
    pa.schema([
        _f("scan_id", pa.string(), "scan (mapping session)"),
        _f("object_id", pa.string(), "semi-static object (or door, for door-state edges)"),
        _f("receptacle_id", pa.string(), "receptacle (or door state 'open'/'closed', for door-state edges)"),
        _f("stamp_ns", pa.int64(), "observation time: the scan's start_stamp_ns, int64 UTC nanoseconds"),
        _f("code", pa.int8(), "1 present, 0 absent, -1 not observed, -2 receptacle not valid for the object"),
        _f("source", pa.string(), "label source: 'gt', 'privileged', 'noisy:P_M,P_F', 'observed' or 'detections:FILE'"),
    ]),
    "Observation codes of every (scan, object, receptacle) per label source.",
    key=("source", "scan_id", "object_id", "receptacle_id"),
    references=(("scan_id", "scans", "scan_id"),),
    required=False,
))

_add(TableSpec(
    "visibility",
    pa.schema([
        _f("scan_id", pa.string(), "scan (mapping session)"),
        _f("kind", pa.string(), "'receptacle' (its top surface), 'object' (its box) or 'door' (its doorway)"),
        _f("id", pa.string(), "receptacle_id, object_id or door_id"),
        _f("seen_fraction", pa.float64(), "fraction of the surface samples seen in at least one frame, [0, 1]"),
        _f("pixels", pa.float64(), "largest per-frame image area of the seen part of the surface, pixels"),
        _f("frames_seen", pa.int32(), "frames in which part of the surface was seen"),
        _f("visible", pa.bool_(), "seen_fraction and pixels reach the visibility thresholds"),
    ]),
    "What each scan saw of every receptacle top surface (and object box when known), from the depth images.",
    key=("scan_id", "kind", "id"),
    references=(("scan_id", "scans", "scan_id"),),
    required=False,
))

REQUIRED_TABLES: tuple[str, ...] = tuple(name for name, spec in TABLES.items() if spec.required)

COLUMNS_SINCE: dict[str, dict[str, int]] = {
    "frames": {"color_offset": 2, "color_size": 2, "depth_offset": 2, "depth_size": 2},
}
"""Columns added by a format major version (table -> column -> major): older datasets lack them."""


def schema_for(name: str, major: int) -> pa.Schema:
    """Schema of table ``name`` in datasets of format major version ``major`` (1 or 2)."""
    schema = TABLES[name].schema
    newer = [c for c, since in COLUMNS_SINCE.get(name, {}).items() if since > major]
    for col in newer:
        schema = schema.remove(schema.get_field_index(col))
    return schema
