"""Write the synthetic lab as a canonical psg-dataset (through :class:`DatasetWriter`)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from psg_data.schemas._records import ObjectInfo
from psg_data.synth._catalog import ObjectSpec
from psg_data.synth._model import LabConfig, LabModel, check_memory
from psg_data.synth._render import RenderedFrame

__all__ = ["build_lab", "rerender_frame", "object_description"]

log = logging.getLogger(__name__)


def object_description(o: ObjectSpec) -> str:
    """Description stored in the ``objects`` table: text, size (metres) and colour (hex sRGB)."""
    rgb = "".join(f"{int(round(c * 255)):02x}" for c in o.color)
    sx, sy, sz = o.size_m
    return f"{o.description}; {o.shape} {sx:.2f} x {sy:.2f} x {sz:.2f} m; colour #{rgb}"


def build_lab(out: str | Path, config: LabConfig | None = None, *, overwrite: bool = False,
              progress: Callable[..., Any] | None = None, lab: LabModel | None = None) -> Path:
    """Render the synthetic lab and write it as a psg-dataset at ``out``.

    Tables: cameras (one simulated D435), scans (split 'train' for the first ``train_days`` days,
    then 'test'), frames (PNG colour + 16-bit depth), rooms, receptacles, doors, door_states and
    schedule per scan, objects. The generator parameters are stored in the manifest ``extra``;
    the dense ground truth is reproducible with ``LabModel.from_dataset(ds).schedule.dense()``.
    With the ``steps-v2`` generator the full generative model (every entity's step process) is
    stored as ``generator/process.json`` (:func:`psg_data.synth.load_process`).

    Args:
        out: dataset directory to create.
        config: lab parameters (default :class:`LabConfig`).
        overwrite: replace an existing dataset.
        progress: called as ``progress(1, frames=total_frames_so_far)`` after every scan.
        lab: an already built :class:`LabModel` of ``config`` (saves re-planning).

    Raises:
        DatasetExistsError: ``out`` exists and ``overwrite`` is False.
        PsgDataError: the lab needs more memory than the machine has (see :func:`check_memory`).
    """
    check_memory(config or LabConfig())
    from psg_data.writers import DatasetWriter

    lab = lab or LabModel(config or LabConfig())
    cfg = lab.config
    L = lab.layout
    with DatasetWriter(out, name=Path(out).name, timezone=cfg.timezone, overwrite=overwrite,
                       extra=cfg.to_extra()) as w:
        w.add_camera(lab.camera)
        w.set_rooms(L.rooms)
        w.set_receptacles(L.receptacles)
        w.set_doors(L.doors)
        if L.openings:
            w.set_openings(L.openings)
        w.set_objects([ObjectInfo(o.name, o.name, object_description(o)) for o in L.objects])
        door_rows: list[dict[str, Any]] = []
        sched_rows: list[dict[str, Any]] = []
        n_frames = 0
        for plan in lab.scans:
            rend = lab.renderer(plan.state)
            with w.scan(plan.scan_id, source=f"psg_data.synth seed={cfg.seed}", split=plan.split) as s:
                for i, (stamp, T) in enumerate(zip(plan.stamps_ns, plan.poses)):
                    fr = rend.render(T, lab.camera, noise=cfg.noise, rng=lab.noise_rng(plan.index, i))
                    s.add_frame(int(stamp), T, fr.color, fr.depth_mm, lab.camera.camera_id)
            door_rows += [{"scan_id": plan.scan_id, "door_id": d, "state": "open" if o else "closed"}
                          for d, o in plan.state.doors_open.items()]
            sched_rows += [{"scan_id": plan.scan_id, "object_id": o, "receptacle_id": r}
                           for o, r in plan.state.objects.items()]
            n_frames += len(plan.poses)
            if progress is not None:
                progress(1, frames=n_frames)
        w.set_table("door_states", door_rows)
        w.set_table("schedule", sched_rows)
        process = getattr(lab.schedule, "process", None)
        if process is not None:  # steps-v2: the exact generative model, for the Bayes ceiling
            from psg_data.schemas._generator_model import PROCESS_FILE

            w.add_file(PROCESS_FILE, process.to_json().encode("utf-8"))
    log.info("synthetic lab: %d scans, seed %d", len(lab.scans), cfg.seed)
    return Path(out)


def rerender_frame(dataset: Any, scan_id: str, frame_index: int, *, noise: bool = True,
                   lab: LabModel | None = None) -> RenderedFrame:
    """Re-render a stored frame of a synthetic dataset from the lab model and the stored tables.

    The scene state comes from the dataset's ``schedule`` and ``door_states`` rows of the scan, the
    pose and intrinsics from its ``frames`` and ``cameras`` tables; with ``noise`` the same noise
    stream as at build time is used, so colour and depth equal the stored images.

    Args:
        dataset: an opened :class:`~psg_data.loaders.Dataset` written by :func:`build_lab`.
        scan_id: scan id.
        frame_index: frame index in the scan.
        noise: reproduce the sensor noise (False: noise-free depth and colour).
        lab: the dataset's :class:`LabModel` if already built.
    """
    from psg_data.synth._render import SceneState

    lab = lab or LabModel.from_dataset(dataset)
    sched = dataset.table("schedule").to_pylist()
    doors = dataset.table("door_states").to_pylist()
    state = SceneState({r["object_id"]: r["receptacle_id"] for r in sched if r["scan_id"] == scan_id},
                       {r["door_id"]: r["state"] == "open" for r in doors if r["scan_id"] == scan_id})
    scan = dataset.scan(scan_id)
    cam = dataset.cameras[str(scan.camera_ids[frame_index])]
    scan_index = dataset.scan_ids.index(scan_id)
    rng = lab.noise_rng(scan_index, frame_index)
    return lab.renderer(state).render(np.asarray(scan.poses[frame_index]), cam,
                                      noise=lab.config.noise if noise else None, rng=rng)
