"""A JSON-able summary of a dataset (what ``psg-data info`` prints)."""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

from psg_data.loaders._dataset import Dataset
from psg_data.schemas._tables import TABLES

__all__ = ["summarize"]


def _local(stamp_ns: int, tz: Any) -> str:
    return datetime.fromtimestamp(stamp_ns / 1e9, tz=timezone.utc).astimezone(tz).strftime("%Y-%m-%d %H:%M %a")


def summarize(ds: Dataset) -> dict[str, Any]:
    """Counts, time span (local time of the site), receptacles per room, door-state counts, size."""
    scans = ds.df("scans")
    frames = ds.table("frames")
    rooms = ds.df("rooms")
    recs = ds.df("receptacles")
    counts = [len(s) for s in ds.scans] or [0]  # (the loader's checks of the frames table run here)
    room_names = dict(zip(rooms["room_id"], rooms["name"]))
    per_room = recs.groupby("room_id").size().to_dict() if len(recs) else {}
    door_states = ds.df("door_states")["state"].value_counts().to_dict() if ds.has_table("door_states") else {}
    sched = ds.df("schedule") if ds.has_table("schedule") else None
    files = ds.df("files")
    tz = ds.info.tz
    start = int(scans["start_stamp_ns"].min()) if len(scans) else 0
    end = int(scans["end_stamp_ns"].max()) if len(scans) else 0
    return {
        "name": ds.info.name,
        "path": str(ds.root),
        "format": ds.info.format,
        "format_version": ds.info.format_version,
        "color_encoding": ds.info.color_encoding,
        "timezone": ds.info.timezone,
        "scans": int(len(scans)),
        "splits": ({str(k): int(v) for k, v in sorted(scans["split"].fillna("-").value_counts().items())}
                   if len(scans) else {}),
        "frames": int(frames.num_rows),
        "frames_per_scan_min": int(min(counts)),
        "frames_per_scan_max": int(max(counts)),
        "start_local": _local(start, tz) if len(scans) else "-",
        "end_local": _local(end, tz) if len(scans) else "-",
        "span_days": (end - start) / 86400e9,
        "cameras": [f"{c.camera_id} {c.width}x{c.height}" for c in ds.cameras.values()],
        "rooms": int(len(rooms)),
        "receptacles": int(len(recs)),
        "receptacles_per_room": {room_names.get(k, k): int(v) for k, v in sorted(per_room.items())},
        "doors": int(ds.table("doors").num_rows),
        "door_states": {str(k): int(v) for k, v in sorted(door_states.items())},
        "objects": int(ds.table("objects").num_rows),
        "schedule_rows": 0 if sched is None else int(len(sched)),
        "schedule_absent": 0 if sched is None else int(sched["receptacle_id"].isna().sum()),
        "extra_tables": [n for n in ds.table_names if n not in TABLES],
        "files": int(len(files)) + 2,
        "size_bytes": int(sum(p.stat().st_size for p in ds.root.rglob("*") if p.is_file())),
    }
