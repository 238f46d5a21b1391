"""The corruption corpus: damaged recordings, frame folders and datasets built here from generated data.

Every case states what must happen and is checked the same way:

* ``error``: ``psg-data convert IN OUT`` exits 1 with exactly one ``error:`` line (no traceback)
  containing the expected text, and the file system is exactly as it was (no OUT, no OUT.partial);
* ``skip``: the conversion succeeds without the damaged frames (a warning says which), the output
  validates and every frame loads (the autouse fixture of tests/conftest.py), the input unchanged;
* ``ok``: a valid but unusual input converts with every frame;
* ``dataset``: ``psg-data validate`` exits 1 listing the problem, ``psg-data info`` and the loader
  either fail with one line / a FormatError or (damaged images only) leave image checks to the
  frame reads, which fail; nothing is written.

``test_corpus_size`` prints how many cases there are (at least 40).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from psg_data.cli.psg_data_cmd import main
from psg_data.errors import FormatError
from psg_data.loaders import open_dataset
from psg_data.loaders.raw._transforms import matrix_to_quat_xyzw
from tests.conftest import reseal_checksums, write_tiny_dataset
from tests.contract import assert_one_error, snapshot

from .conftest import CAMERA, images, pose, write_bag

N = 6  # frames per generated recording


@dataclass(frozen=True)
class Case:
    name: str
    build: Callable[[Path], list[str]]
    """Builds the input under the given folder; returns the arguments after ``convert`` (input first)."""
    kind: str
    match: str = ""
    frames: int | None = None


# -- byte-level damage ----------------------------------------------------------------------------------

def flip(path: Path, offset: int, n: int = 1, value: int | None = None) -> None:
    data = bytearray(path.read_bytes())
    offset %= len(data)
    for k in range(offset, min(offset + n, len(data))):
        data[k] = value if value is not None else data[k] ^ 0x5A
    path.write_bytes(bytes(data))


def truncate(path: Path, keep: float | int) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep) if isinstance(keep, float) else keep])


def storage(bag: Path) -> Path:
    return next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))


def sqlite_page_damage(bag: Path) -> None:
    """The first bytes of a page in the middle of a ROS 2 .db3 set to 0xff (a b-tree or overflow page)."""
    db = storage(bag)
    page = int.from_bytes(db.read_bytes()[16:18], "big") or 65536
    flip(db, page * (db.stat().st_size // page // 2), n=8, value=0xFF)


def jpeg_damage(how: str, frames: tuple[int, ...] = (2,)) -> Callable[[str, int, bytes], bytes]:
    def payload(topic: str, i: int, data: bytes) -> bytes:
        if i not in frames:
            return data
        if how == "truncate":
            return data[: len(data) // 2]
        if how == "sof":  # the frame header: SOF0 length field
            k = data.find(b"\xff\xc0")
            return data[:k + 2] + b"\x00\x01" + data[k + 4:]
        if how == "garbage":
            return bytes(np.random.default_rng(i).integers(0, 256, len(data), dtype=np.uint8))
        raise ValueError(how)
    return payload


def png_damage(how: str, frames: tuple[int, ...] = (3,)) -> Callable[[str, int, bytes], bytes]:
    def payload(topic: str, i: int, data: bytes) -> bytes:
        if i not in frames:
            return data
        b = bytearray(data)
        if how == "idat":
            b[b.find(b"IDAT") + 20] ^= 0x01  # one bit inside the compressed image data
            return bytes(b)
        if how == "truncate":
            return data[:-30]
        raise ValueError(how)
    return payload


# -- recordings -----------------------------------------------------------------------------------------

def bag(fmt: str = "ros1", name: str = "a", n: int = N, **kw: Any) -> Callable[[Path], Path]:
    def make(d: Path) -> Path:
        return write_bag(d / (f"{name}.bag" if fmt == "ros1" else f"{name}.mcap" if fmt == "mcap" else name),
                         "ros2-mcap" if fmt == "mcap" else fmt, n=n, **kw)
    return make


def damaged(make: Callable[[Path], Path], damage: Callable[[Path], None], *options: str) -> Callable[[Path], list[str]]:
    def build(d: Path) -> list[str]:
        p = make(d)
        damage(p)
        return [str(p), *options]
    return build


def plain(make: Callable[[Path], Path], *options: str) -> Callable[[Path], list[str]]:
    return lambda d: [str(make(d)), *options]


def bare_mcap(d: Path) -> Path:
    """A bare .mcap file (the storage file of a ROS 2 MCAP bag)."""
    b = write_bag(d / "tmpbag", "ros2-mcap", n=N)
    out = d / "a.mcap"
    shutil.move(str(storage(b)), out)
    shutil.rmtree(b)
    return out


def renamed(make: Callable[[Path], Path], name: str) -> Callable[[Path], Path]:
    def m(d: Path) -> Path:
        p = make(d)
        return p.rename(d / name)
    return m


def text_file(name: str, data: bytes) -> Callable[[Path], Path]:
    def m(d: Path) -> Path:
        (d / name).write_bytes(data)
        return d / name
    return m


def mixed_dir(d: Path) -> list[str]:
    recs = d / "recs"
    recs.mkdir()
    write_bag(recs / "good.bag", n=N)
    truncate(write_bag(recs / "bad.bag", n=N), 0.5)
    return [str(recs)]


def mixed_formats(d: Path) -> list[str]:
    recs = d / "recs"
    recs.mkdir()
    write_bag(recs / "a.bag", n=N)
    write_bag(recs / "b", "ros2-mcap", n=N)
    return [str(recs)]


def service_event_mcap(d: Path) -> list[str]:
    """A ROS 2 MCAP bag plus a service-event topic whose schema is the raw .srv text (as rosbag2 writes it)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    src = storage(write_bag(d / "src", "ros2-mcap", n=N))
    out = d / "svc.mcap"
    with open(src, "rb") as fi, open(out, "wb") as fo:
        reader = make_reader(fi)
        w = Writer(fo)
        w.start(profile="ros2", library="test")
        ids: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages():
            if channel.id not in ids:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = w.register_channel(channel.topic, channel.message_encoding, sid, channel.metadata)
            w.add_message(ids[channel.id], log_time=message.log_time, data=message.data,
                          publish_time=message.publish_time)
        sid = w.register_schema("example_interfaces/srv/AddTwoInts_Event", "ros2msg", b"int64 a\nint64 b\n---\nint64 sum\n")
        cid = w.register_channel("/add_two_ints/_service_event", "cdr", sid)
        w.add_message(cid, log_time=1, data=b"\x00\x01\x00\x00" + bytes(48), publish_time=1)
        w.finish()
    shutil.rmtree(d / "src")
    return [str(out)]


def export_folder_single_bag(d: Path) -> list[str]:
    """One bag of an export folder whose side files are broken: converting the bag alone ignores them."""
    recs = d / "recs"
    recs.mkdir()
    write_bag(recs / "a.bag", n=N)
    (recs / "schedule.csv").write_text("scan_id,object_id,receptacle_id\nscan_999,mug,table\n")
    (recs / "site.json").write_text("{ not json")
    return [str(recs / "a.bag")]


# -- frame folders --------------------------------------------------------------------------------------

def tum(*, jpeg: bool = False, intrinsics: str | None = "fx fy cx cy", damage: Callable[[Path], None] | None = None,
        ) -> Callable[[Path], list[str]]:
    def build(d: Path) -> list[str]:
        f = d / "fr1"
        (f / "rgb").mkdir(parents=True)
        (f / "depth").mkdir()
        rgb, dep, gt = ["# color"], ["# depth"], ["# timestamp tx ty tz qx qy qz qw"]
        for i in range(N):
            t = f"1305031102.{175304 + 33333 * i:06d}"
            c, dm = images(i, 0)
            ext = "jpg" if jpeg else "png"
            cv2.imwrite(str(f / "rgb" / f"{t}.{ext}"), cv2.cvtColor(c, cv2.COLOR_RGB2BGR))
            cv2.imwrite(str(f / "depth" / f"{t}.png"), (dm.astype(np.uint32) * 5).clip(0, 65535).astype(np.uint16))
            rgb.append(f"{t} rgb/{t}.{ext}")
            dep.append(f"{t} depth/{t}.png")
            T = pose(i, 0)
            gt.append(f"{t} " + " ".join(f"{v:.17g}" for v in [*T[:3, 3], *matrix_to_quat_xyzw(T[:3, :3])]))
        (f / "rgb.txt").write_text("\n".join(rgb) + "\n")
        (f / "depth.txt").write_text("\n".join(dep) + "\n")
        (f / "groundtruth.txt").write_text("\n".join(gt) + "\n")
        if intrinsics is not None:
            vals = {"fx": CAMERA.fx, "fy": CAMERA.fy, "cx": CAMERA.cx, "cy": CAMERA.cy}
            (f / "intrinsics.txt").write_text(" ".join(str(vals.get(t, t)) for t in intrinsics.split()) + "\n")
        if damage is not None:
            damage(f)
        return [str(f)]
    return build


def nth_listed(f: Path, listing: str, k: int = 2) -> Path:
    rows = [ln.split() for ln in (f / listing).read_text().splitlines() if ln and not ln.startswith("#")]
    return f / rows[k][1]


def edit_line(listing: str, k: int, new: str) -> Callable[[Path], None]:
    def damage(f: Path) -> None:
        lines = (f / listing).read_text().splitlines()
        data_rows = [j for j, ln in enumerate(lines) if ln and not ln.startswith("#")]
        lines[data_rows[k]] = new if "{}" not in new else new.format(lines[data_rows[k]])
        (f / listing).write_text("\n".join(lines) + "\n")
    return damage


def scannet(pose_text: str | None = None, intrinsic_text: str | None = None) -> Callable[[Path], list[str]]:
    def build(d: Path) -> list[str]:
        f = d / "scene0000_00"
        for sub in ("color", "depth", "pose", "intrinsic"):
            (f / sub).mkdir(parents=True)
        K = np.eye(4)
        K[0, 0], K[1, 1], K[0, 2], K[1, 2] = CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy
        np.savetxt(f / "intrinsic" / "intrinsic_depth.txt", K)
        if intrinsic_text is not None:
            (f / "intrinsic" / "intrinsic_depth.txt").write_text(intrinsic_text)
        for i in range(N):
            c, dm = images(i, 0)
            cv2.imwrite(str(f / "color" / f"{i}.jpg"), cv2.cvtColor(c, cv2.COLOR_RGB2BGR))
            cv2.imwrite(str(f / "depth" / f"{i}.png"), dm)
            np.savetxt(f / "pose" / f"{i}.txt", pose(i, 0))
        if pose_text is not None:
            (f / "pose" / "2.txt").write_text(pose_text)
        return [str(f)]
    return build


YEAR = 365 * 86400 * 10**9
RECORDINGS = [
    Case("ros1 truncated to half", damaged(bag(), lambda p: truncate(p, 0.5)), "error",
         "unreadable or truncated recording"),
    Case("ros1 last byte cut", damaged(bag(), lambda p: truncate(p, p.stat().st_size - 1)), "error",
         "unreadable or truncated recording"),
    Case("ros1 zero-length", damaged(bag(), lambda p: truncate(p, 0)), "error", "zero-byte file"),
    Case("ros1 bag header flipped", damaged(bag(), lambda p: flip(p, 20, 8)), "error",
         "unreadable or truncated recording"),
    Case("ros1 index flipped", damaged(bag(), lambda p: flip(p, -60, 8, 0xFF)), "error",
         "unreadable or truncated recording"),
    Case("ros1 image payload flipped in the file", damaged(bag(color="jpeg"),
         lambda p: flip(p, _nth(p.read_bytes(), b"\xff\xd8\xff", 2) + 3, 2, 0)), "skip", "frame at stamp", N - 1),
    Case("ros2 sqlite3 page damaged mid-file", damaged(bag("ros2-sqlite3"), sqlite_page_damage), "error",
         "unreadable or truncated recording"),
    Case("ros2 sqlite3 truncated", damaged(bag("ros2-sqlite3"), lambda p: truncate(storage(p), 0.5)), "error",
         "unreadable or truncated recording"),
    Case("ros2 mcap truncated", damaged(bag("ros2-mcap"), lambda p: truncate(storage(p), 0.5)), "error",
         "unreadable or truncated recording"),
    Case("ros2 mcap magic flipped", damaged(bag("ros2-mcap"), lambda p: flip(storage(p), 1, 4)), "error",
         "unreadable or truncated recording"),
    Case("ros2 metadata.yaml garbage", damaged(bag("ros2-mcap"), lambda p: (p / "metadata.yaml").write_text(
        "rosbag2_bagfile_information: [\nstorage_identifier: mcap\n")), "error", "unreadable or truncated recording"),
    Case("bare mcap record flipped", damaged(bare_mcap, lambda p: flip(p, 9, 16, 0xFF)), "error",
         "unreadable or truncated recording"),
    Case("mcap named .bag", plain(renamed(bare_mcap, "x.bag")), "error", "unreadable or truncated recording"),
    Case("text file named .bag", plain(text_file("notes.bag", b"not a bag\n")), "error",
         "unreadable or truncated recording"),
    Case("text file named .mcap", plain(text_file("notes.mcap", b"not an mcap\n" * 4)), "error",
         "unreadable or truncated recording"),
    Case("no CameraInfo", plain(bag(info=False)), "error", "no sensor_msgs/CameraInfo topic"),
    Case("no TF at all", plain(bag(tf=False, tf_static=False)), "error", "no pose source"),
    Case("NaN TF everywhere", plain(bag(nan_pose_at=-1)), "ok", "", N),  # -1 matches no frame: control case
    Case("NaN TF at one frame", plain(bag(nan_pose_at=2)), "skip", "", N - 1),
    Case("out-of-order frame beyond the buffer", plain(bag(n=30, late={2: 3 * 10**9})), "skip", "", 29),
    Case("log time 1 year after the stamps", plain(bag(log_lag_ns=YEAR)), "ok", "", N),
    Case("camera latency 1.5 s", plain(bag(image_latency_ns=1_500_000_000)), "ok", "", N),
    Case("colour and depth sizes differ", plain(bag(depth_size=(16, 12))), "error", "depth is 16x12 but colour is 32x24"),
    Case("unknown colour encoding", plain(bag(color="yuv422")), "error", "unknown colour image encoding 'yuv422'"),
    Case("unknown depth encoding", plain(bag(depth="mono8")), "error", "unknown depth image encoding"),
    Case("jpeg frame header damaged", plain(bag(color="jpeg", payload=jpeg_damage("sof"))), "skip", "frame at stamp", N - 1),
    Case("jpeg truncated", plain(bag(color="jpeg", payload=jpeg_damage("truncate"))), "skip", "frame at stamp", N - 1),
    Case("compressedDepth png bit flipped in IDAT", plain(bag(color="jpeg", depth="compressedDepth",
                                                              payload=png_damage("idat"))), "skip", "frame at stamp", N - 1),
    Case("compressedDepth png truncated", plain(bag(depth="compressedDepth", payload=png_damage("truncate"))),
         "skip", "frame at stamp", N - 1),
    Case("every jpeg truncated", plain(bag(color="jpeg", payload=jpeg_damage("truncate", tuple(range(N))))),
         "error", "every frame has a damaged image"),
    Case("one damaged jpeg with --strict", plain(bag(color="jpeg", payload=jpeg_damage("truncate")), "--strict"),
         "error", "refused by --strict"),
    Case("jpeg bytes that are not an image", plain(bag(color="jpeg", payload=jpeg_damage("garbage"))), "skip", "frame at stamp",
         N - 1),
    Case("directory with one truncated recording", mixed_dir, "error", "bad.bag: unreadable or truncated recording"),
    Case("directory mixing ROS 1 and ROS 2", mixed_formats, "error", "directory mixes recording formats"),
    Case("depth stamps 0.55 s off", plain(bag(depth_stamp_offset_ns=550_000_000)), "error",
         "no depth image within sync_tolerance_s"),
    Case("/tf stamps 100 s off", plain(bag(tf_stamp_offset_ns=100 * 10**9)), "error", "no pose within max_pose_gap_s"),
    Case("service-event schema in an mcap", service_event_mcap, "ok", "", N),
    Case("one bag of an export folder with broken side files", export_folder_single_bag, "ok", "", N),
    Case("tum truncated png", tum(damage=lambda f: truncate(nth_listed(f, "depth.txt"), 0.6)), "skip", "frame at stamp", N - 1),
    Case("tum jpeg cut before EOI", tum(jpeg=True, damage=lambda f: truncate(nth_listed(f, "rgb.txt"), 0.7)),
         "skip", "frame at stamp", N - 1),
    Case("tum listed image missing", tum(damage=lambda f: nth_listed(f, "rgb.txt").unlink()), "error",
         "listed image not found"),
    Case("tum short rgb.txt row", tum(damage=edit_line("rgb.txt", 1, "1305031102.2")), "error",
         "expected 'timestamp filename', got 1 value(s)"),
    Case("tum non-numeric pose value", tum(damage=edit_line("groundtruth.txt", 1, "1305031102.2 0 0 x 0 0 0 1")),
         "error", "groundtruth.txt:3: expected 'tx ty tz qx qy qz qw' as numbers"),
    Case("tum NaN intrinsics", tum(intrinsics="nan fy cx cy"), "error", "intrinsics.txt: expected 'fx fy cx cy'"),
    Case("tum zero focal length", tum(intrinsics="0 fy cx cy"), "error", "intrinsics.txt: fx: focal length 0.0"),
    Case("tum principal point outside", tum(intrinsics="fx fy 400 cy"), "error", "intrinsics.txt: cx: principal point"),
    Case("tum non-numeric intrinsics", tum(intrinsics="fx fy cx abc"), "error", "intrinsics.txt: expected"),
    Case("tum rgb.txt not text", tum(damage=lambda f: (f / "rgb.txt").write_bytes(b"\xff\xfe\x00garbage")), "error",
         "rgb.txt: not a text file"),
    Case("scannet non-numeric pose", scannet(pose_text="1 0 0 0\n0 1 0 0\n0 0 1 zero\n0 0 0 1\n"), "error",
         "2.txt: expected a 4x4 camera-to-world matrix as numbers"),
    Case("scannet 3-value intrinsic file", scannet(intrinsic_text="1 2 3\n"), "error",
         "expected 'fx fy cx cy' or a 3x3/4x4 intrinsic matrix, got 3 values"),
]


def _nth(data: bytes, pat: bytes, k: int) -> int:
    i = -1
    for _ in range(k + 1):
        i = data.find(pat, i + 1)
    assert i >= 0
    return i


@pytest.mark.parametrize("case", RECORDINGS, ids=[c.name for c in RECORDINGS])
def test_recording(tmp_path: Path, case: Case) -> None:
    d = tmp_path / "in"
    d.mkdir()
    args = case.build(d)
    before = snapshot(tmp_path)
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["convert", *args, str(out), "-q"])
    if case.kind == "error":
        assert_one_error(r, case.match)
        assert snapshot(tmp_path) == before
        return
    assert r.exit_code == 0, (r.output, r.exception)
    assert "Traceback" not in r.output
    assert f", {case.frames} frames" in r.stdout, r.stdout
    if case.kind == "skip":
        assert "skipped" in r.stdout and case.match in r.stderr, r.output  # e.g. recording: topic: frame at stamp
    after = snapshot(tmp_path)
    assert {k: v for k, v in after.items() if not k.startswith("out")} == before  # the input untouched


# -- datasets -------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class DatasetCase:
    name: str
    damage: Callable[[Path], None]
    match: str
    """In the validate output and (if ``info``) in the one error line of ``info`` and the loader's error."""
    info: bool = True
    """Whether the tables are damaged (info and opening fail); else only reading the images fails."""


def _table(name: str) -> str:
    return f"tables/{name}.parquet"


def edit_table(name: str, fn: Callable[[pa.Table], pa.Table]) -> Callable[[Path], None]:
    """Rewrite table ``name`` with ``fn`` and re-seal its checksum, so the content check under test
    answers (a table that no longer fits its checksum is refused for that first: tests/format)."""
    def damage(root: Path) -> None:
        p = root / _table(name)
        pq.write_table(fn(pq.read_table(p)), p)
        reseal_checksums(root)
    return damage


def edit_manifest(**changes: Any) -> Callable[[Path], None]:
    def damage(root: Path) -> None:
        m = json.loads((root / "dataset.json").read_text())
        for k, v in changes.items():
            if v is None:
                m.pop(k, None)
            else:
                m[k] = v
        (root / "dataset.json").write_text(json.dumps(m))
    return damage


def _set(t: pa.Table, col: str, values: list) -> pa.Table:
    i = t.schema.get_field_index(col)
    return t.set_column(i, t.schema.field(col), pa.array(values, t.schema.field(col).type))


def _nan_pose(t: pa.Table) -> pa.Table:
    T = t.column("T_world_camera").to_pylist()
    T[1] = [float("nan")] * 16
    return _set(t, "T_world_camera", T)


def _image_range(root: Path, kind: str, k: int = 1) -> tuple[Path, int, int]:
    t = pq.read_table(root / _table("frames")).to_pylist()[k]
    return root / t[f"{kind}_path"], t[f"{kind}_offset"] or 0, t[f"{kind}_size"] or (root / t[f"{kind}_path"]).stat().st_size


def damage_image(kind: str, how: str) -> Callable[[Path], None]:
    def damage(root: Path) -> None:
        p, off, size = _image_range(root, kind)
        if how == "flip":
            flip(p, off + size // 2, 1)
        else:  # the image's tail zeroed: a truncated image within an intact archive
            flip(p, off + size * 2 // 3, size - size * 2 // 3, 0)
    return damage


DATASETS = [
    DatasetCase("missing cameras table", lambda r: (r / _table("cameras")).unlink(), "missing table"),
    DatasetCase("cameras without fx", edit_table("cameras", lambda t: t.drop_columns(["fx"])), "fx: missing column"),
    DatasetCase("frames without T_world_camera", edit_table("frames", lambda t: t.drop_columns(["T_world_camera"])),
                "T_world_camera: missing column"),
    DatasetCase("frames with a column of the wrong type", edit_table("frames", lambda t: _set(
        t.drop_columns(["stamp_ns"]).append_column("stamp_ns", pa.array(["x"] * t.num_rows)), "stamp_ns",
        ["x"] * t.num_rows)), "stamp_ns"),
    DatasetCase("duplicate frame rows", edit_table("frames", lambda t: pa.concat_tables([t, t.slice(0, 1)])),
                "duplicate key"),
    DatasetCase("NaN pose", edit_table("frames", _nan_pose), "T_world_camera"),
    DatasetCase("frames of an unknown scan", edit_table("frames", lambda t: _set(
        t, "scan_id", ["scan_404"] + t.column("scan_id").to_pylist()[1:])), "dangling id 'scan_404'"),
    DatasetCase("frames of an unknown camera", edit_table("frames", lambda t: _set(
        t, "camera_id", ["nocam"] + t.column("camera_id").to_pylist()[1:])), "dangling id 'nocam'"),
    DatasetCase("duplicate scan ids", edit_table("scans", lambda t: pa.concat_tables([t, t.slice(0, 1)])),
                "duplicate key"),
    DatasetCase("format_version 2 (a number)", edit_manifest(format_version=2), "format_version"),
    DatasetCase("format_version 2.7", edit_manifest(format_version="2.7"), "format_version: 2.7 is newer", info=False),
    DatasetCase("format_version 3.0", edit_manifest(format_version="3.0"), "format_version: 3.0 is newer"),
    DatasetCase("format_version 'two'", edit_manifest(format_version="two"), "format_version"),
    DatasetCase("manifest without color_encoding", edit_manifest(color_encoding=None), "color_encoding"),
    DatasetCase("manifest not JSON", lambda r: (r / "dataset.json").write_text("{ nope"), "dataset.json"),
    DatasetCase("frames table truncated", lambda r: truncate(r / _table("frames"), 0.5), "frames.parquet"),
    DatasetCase("png image bit flipped in its archive", damage_image("depth", "flip"), "CRC mismatch", info=False),
    DatasetCase("png image cut in its archive", damage_image("color", "cut"), "corrupt PNG", info=False),
]


@pytest.mark.parametrize("case", DATASETS, ids=[c.name for c in DATASETS])
def test_dataset(tmp_path: Path, case: DatasetCase) -> None:
    root = write_tiny_dataset(tmp_path / "ds", scans=2, frames=3)
    case.damage(root)
    before = snapshot(tmp_path)
    r = CliRunner().invoke(main, ["validate", str(root)])
    assert r.exit_code == 1 and case.match in r.stdout, r.output
    assert_one_error(r, "problem(s), listed above")
    r = CliRunner().invoke(main, ["info", str(root)])
    if case.info:
        assert_one_error(r, case.match if "manifest" not in case.name else None)
        with pytest.raises(FormatError):
            _load_everything(root)
    else:
        assert r.exit_code == 0, r.output
        if "image" in case.name:
            with pytest.raises(FormatError, match="missing or unreadable (colour|depth) image"):
                _load_everything(root)
        else:
            _load_everything(root)  # a newer minor version is read (what it adds is ignored)
    assert snapshot(tmp_path) == before


def _load_everything(root: Path) -> None:
    with open_dataset(root) as ds:
        _ = (ds.cameras, ds.rooms, ds.receptacles, ds.doors, ds.objects)
        for scan in ds.scans:
            for _fr in scan.frames(prefetch=0):
                pass


def test_jpeg_dataset_truncated_image_rejected_by_validate_and_loader(tmp_path: Path) -> None:
    root = write_tiny_dataset(tmp_path / "ds", scans=1, frames=3, color_encoding="jpeg", image_layout="files")
    p, _, size = _image_range(root, "color")
    p.write_bytes(p.read_bytes()[: size * 2 // 3])  # OpenCV decodes this without complaint
    r = CliRunner().invoke(main, ["validate", "--no-checksums", str(root)])
    assert r.exit_code == 1 and "corrupt JPEG: truncated" in r.stdout, r.output
    with pytest.raises(FormatError, match="corrupt: truncated"):
        _load_everything(root)


N_CASES = len(RECORDINGS) + len(DATASETS) + 1  # + the JPEG dataset case


@pytest.mark.parametrize("n", [N_CASES], ids=[f"{N_CASES}-cases-{len(RECORDINGS)}-recordings-{len(DATASETS) + 1}-datasets"])
def test_corpus_size(n: int) -> None:
    print(f"corruption corpus: {n} cases ({len(RECORDINGS)} recordings and frame folders, {len(DATASETS) + 1} datasets)")
    assert n >= 40
