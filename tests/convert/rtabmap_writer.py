"""A small writer of RTAB-Map databases for the tests: the tables, columns and blob layouts RTAB-Map
itself writes per schema version (see docs/RAW_FORMATS.md for the sources read), written with
``sqlite3``, numpy, zlib and OpenCV.

Versions: 0.17.0 (calibration as 18 float32 per camera), 0.18.0 (``CameraModel::serialize``
records, ``Node.env_sensors``) and 0.23.0 (``Data.depth_confidence``, ``GlobalDescriptor``,
``Admin.dictionary_index``). Everything but the tables the reader needs is left empty.
"""

from __future__ import annotations

import sqlite3
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

VERSIONS = ("0.17.0", "0.18.0", "0.23.0")

_NODE = {"0.17.0": "id INTEGER NOT NULL, map_id INTEGER NOT NULL, weight INTEGER, stamp FLOAT, pose BLOB, "
                   "ground_truth_pose BLOB, velocity BLOB, label TEXT, gps BLOB, time_enter DATE, PRIMARY KEY (id)"}
_NODE["0.18.0"] = _NODE["0.17.0"].replace("gps BLOB,", "gps BLOB, env_sensors BLOB,")
_NODE["0.23.0"] = _NODE["0.18.0"]
_DATA = {"0.17.0": "id INTEGER NOT NULL, image BLOB, depth BLOB, calibration BLOB, scan BLOB, scan_info BLOB, "
                   "ground_cells BLOB, obstacle_cells BLOB, empty_cells BLOB, cell_size FLOAT, view_point_x FLOAT, "
                   "view_point_y FLOAT, view_point_z FLOAT, user_data BLOB, time_enter DATE, PRIMARY KEY (id)"}
_DATA["0.18.0"] = _DATA["0.17.0"]
_DATA["0.23.0"] = _DATA["0.17.0"].replace("depth BLOB,", "depth BLOB, depth_confidence BLOB,")
_LINK = ("from_id INTEGER NOT NULL, to_id INTEGER NOT NULL, type INTEGER NOT NULL, information_matrix BLOB NOT NULL, "
         "transform BLOB, user_data BLOB, FOREIGN KEY (from_id) REFERENCES Node(id), "
         "FOREIGN KEY (to_id) REFERENCES Node(id)")
_ADMIN = ("version TEXT, preview_image BLOB, opt_cloud BLOB, opt_ids BLOB, opt_poses BLOB, opt_last_localization "
          "BLOB, opt_polygons_size INTEGER, opt_polygons BLOB, opt_tex_coords BLOB, opt_tex_materials BLOB, "
          "opt_map BLOB, opt_map_x_min FLOAT, opt_map_y_min FLOAT, opt_map_resolution FLOAT, {extra}time_enter DATE")
_OTHER = {
    "Word": "id INTEGER NOT NULL, descriptor_size INTEGER NOT NULL, descriptor BLOB NOT NULL, time_enter DATE, "
            "PRIMARY KEY (id)",
    "Feature": "node_id INTEGER NOT NULL, word_id INTEGER NOT NULL, pos_x FLOAT NOT NULL, pos_y FLOAT NOT NULL, "
               "size INTEGER NOT NULL, dir FLOAT NOT NULL, response FLOAT NOT NULL, octave INTEGER NOT NULL, "
               "depth_x FLOAT, depth_y FLOAT, depth_z FLOAT, descriptor_size INTEGER, descriptor BLOB",
    "Info": "STM_size INTEGER, last_sign_added INTEGER, process_mem_used INTEGER, database_mem_used INTEGER, "
            "dictionary_size INTEGER, parameters TEXT, time_enter DATE",
    "Statistics": "id INTEGER NOT NULL, stamp FLOAT, data BLOB, wm_state BLOB",
}
OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def schema_sql(version: str) -> str:
    """CREATE TABLE statements of ``version`` (columns as in RTAB-Map's DatabaseSchema of that version)."""
    tables = {"Node": _NODE[version], "Data": _DATA[version], "Link": _LINK, **_OTHER,
              "Admin": _ADMIN.format(extra="dictionary_index BLOB, " if version >= "0.20.0" else "")}
    if version >= "0.18.0":
        tables["Tag"] = ("node_id INTEGER NOT NULL, tag_id INTEGER NOT NULL, stamp FLOAT NOT NULL, "
                         "transform BLOB NOT NULL")
    if version >= "0.20.0":
        tables["GlobalDescriptor"] = "node_id INTEGER NOT NULL, type INTEGER NOT NULL, info BLOB, data BLOB NOT NULL"
    sql = "".join(f"CREATE TABLE {name} ({cols});\n" for name, cols in tables.items())
    return sql + ("CREATE UNIQUE INDEX IDX_Node_id on Node (id);\nCREATE INDEX IDX_Link_from_id on Link (from_id);\n"
                  "CREATE UNIQUE INDEX IDX_node_label on Node (label);\n"
                  f"INSERT INTO Admin(version) VALUES('{version}');\n")


def transform_blob(T: np.ndarray) -> bytes:
    """``Transform``: the top 3x4 of ``T``, row-major float32."""
    return np.asarray(T, "<f4")[:3, :].tobytes()


def compress_data(a: np.ndarray) -> bytes:
    """``compressData2``: zlib of the matrix bytes, then int32 rows, cols, OpenCV type (1 channel)."""
    types = {np.dtype(np.int32): 4, np.dtype(np.float32): 5, np.dtype(np.uint8): 0}
    a2 = np.atleast_2d(a)
    return zlib.compress(a2.tobytes()) + struct.pack("<3i", a2.shape[0], a2.shape[1], types[a2.dtype])


def camera_blob(version: str, fx: float, fy: float, cx: float, cy: float, w: int, h: int, local: np.ndarray,
                D: tuple[float, ...] = ()) -> bytes:
    """One camera's ``Data.calibration``: 18 float32 before 0.18.0, else ``CameraModel::serialize``."""
    if version < "0.18.0":
        return np.array([fx, fy, cx, cy, w, h, *np.asarray(local)[:3, :].ravel()], "<f4").tobytes()
    major, minor, patch = (int(v) for v in version.split("."))
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "<f8")
    P = np.array([[fx, 0, cx, 0], [0, fy, cy, 0], [0, 0, 1, 0]], "<f8")
    R = np.eye(3, dtype="<f8")
    hdr = struct.pack("<11i", major, minor, patch, 0, w, h, 9, len(D), 9, 12, 12)
    return hdr + K.tobytes() + np.array(D, "<f8").tobytes() + R.tobytes() + P.tobytes() + transform_blob(local)


def _vle(values: list[int]) -> bytes:
    """RVL's variable-length nibble code, 8 nibbles per little-endian int32 word, first nibble on top."""
    nibbles: list[int] = []
    for v in values:
        while True:
            nib = v & 7
            v >>= 3
            nibbles.append(nib | (8 if v else 0))
            if not v:
                break
    nibbles += [0] * (-len(nibbles) % 8)
    words = np.array(nibbles, np.uint32).reshape(-1, 8) << np.arange(28, -1, -4, dtype=np.uint32)
    return np.bitwise_or.reduce(words, axis=1).astype("<u4").tobytes()


def rvl_blob(depth: np.ndarray) -> bytes:
    """RTAB-Map's ``.rvl`` depth: ``DEPTHRVL``, uint32 cols, rows, then the RVL code of the uint16 pixels."""
    flat = np.asarray(depth, np.uint16).ravel().astype(np.int64)
    values, prev, i, n = [], 0, 0, flat.size
    while i < n:
        j = i
        while j < n and flat[j] == 0:
            j += 1
        k = j
        while k < n and flat[k] != 0:
            k += 1
        values += [j - i, k - j]
        for v in flat[j:k]:
            delta = int(v) - prev
            values.append((delta << 1) ^ (delta >> 31))
            prev = int(v)
        i = k
    return b"DEPTHRVL" + struct.pack("<2I", depth.shape[1], depth.shape[0]) + _vle(values)


def float_depth_blob(depth_mm: np.ndarray) -> bytes:
    """A 32FC1 depth (metres) as RTAB-Map stores it: the float bytes as an 8-bit 4-channel PNG."""
    import cv2

    m = (np.asarray(depth_mm, np.float32) / 1000.0).astype("<f4")
    ok, png = cv2.imencode(".png", m.view(np.uint8).reshape(m.shape[0], m.shape[1], 4))
    assert ok
    return png.tobytes()


@dataclass
class Node:
    id: int
    map_id: int
    stamp_s: float
    pose: np.ndarray | None
    """Base-to-world (odometry) pose, 4x4."""
    image: bytes | None = None
    depth: bytes | None = None
    calibration: bytes | None = None
    label: str | None = None


@dataclass
class Link:
    from_id: int
    to_id: int
    type: int
    transform: np.ndarray
    information: np.ndarray = field(default_factory=lambda: np.eye(6) * 1e4)


def write_database(path: Path, version: str, nodes: list[Node], links: list[Link],
                   optimized: dict[int, np.ndarray] | None = None) -> Path:
    """Write an RTAB-Map database; links are stored both ways, as RTAB-Map does."""
    con = sqlite3.connect(path)
    con.executescript(schema_sql(version))
    for n in nodes:
        con.execute("INSERT INTO Node(id, map_id, weight, stamp, pose, label) VALUES(?,?,?,?,?,?)",
                    (n.id, n.map_id, 0, n.stamp_s, None if n.pose is None else transform_blob(n.pose), n.label))
        if n.image is not None or n.depth is not None or n.calibration is not None:
            con.execute("INSERT INTO Data(id, image, depth, calibration) VALUES(?,?,?,?)",
                        (n.id, n.image, n.depth, n.calibration))
    for lk in links:
        for a, b, T in ((lk.from_id, lk.to_id, lk.transform), (lk.to_id, lk.from_id, np.linalg.inv(lk.transform))):
            con.execute("INSERT INTO Link(type, information_matrix, transform, user_data, from_id, to_id) "
                        "VALUES(?,?,?,?,?,?)", (lk.type, np.asarray(lk.information, "<f8").tobytes(),
                                                transform_blob(T), None, a, b))
    if optimized:
        ids = np.array(sorted(optimized), np.int32)
        poses = np.concatenate([np.asarray(optimized[i], "<f4")[:3, :].ravel() for i in ids]).astype(np.float32)
        con.execute("UPDATE Admin SET opt_ids=?, opt_poses=?", (compress_data(ids[None, :]),
                                                                compress_data(poses[None, :])))
    con.commit()
    con.close()
    return path
