"""The psg-dataset format: Arrow schemas, the manifest, typed records and validation."""

from psg_data.schemas._manifest import FORMAT_NAME, FORMAT_VERSION, DatasetInfo, read_manifest
from psg_data.schemas._records import Box, CameraIntrinsics, Door, Frame, ObjectInfo, Opening, Receptacle, Room
from psg_data.schemas._streams import EdgeKey, EdgeStream
from psg_data.schemas._tables import (
    ARCHIVE_PATH_TEMPLATE,
    COLOR_PATH_TEMPLATE,
    DEPTH_PATH_TEMPLATE,
    DOOR_STATES,
    MANIFEST_NAME,
    REQUIRED_TABLES,
    TABLES,
    TableSpec,
    schema_for,
    table_path,
)

__all__ = [
    "FORMAT_NAME", "FORMAT_VERSION", "DatasetInfo", "read_manifest",
    "Box", "CameraIntrinsics", "Door", "Opening", "Frame", "ObjectInfo", "Receptacle", "Room",
    "COLOR_PATH_TEMPLATE", "DEPTH_PATH_TEMPLATE", "DOOR_STATES", "MANIFEST_NAME", "REQUIRED_TABLES",
    "TABLES", "TableSpec", "table_path", "schema_for", "ARCHIVE_PATH_TEMPLATE", "EdgeKey", "EdgeStream",
]
