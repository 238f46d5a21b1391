"""psg_data.synth: the built-in synthetic three-room lab (geometry, schedules, renderer, detections).

Main entry points:
    LabModel(LabConfig(seed=...))        geometry, dense ground-truth schedule, scan plans, renderer
    load_process(dataset)                the stored generative model of a steps-v2 dataset (exact posterior)
    build_lab(out, config)               write the lab as a canonical psg-dataset
    rerender_frame(dataset, scan, i)     re-render a stored frame with per-pixel instance ids
    write_detections(ds_or_lab, path)    simulated scene-graph detections (Parquet)
    HouseModel(HouseConfig(seed=...))    a procedural multi-room house (the navigation benchmark's scenes)
    build_house(out, config)             write a house as a psg-dataset (no images; hourly steps)
    transition_test(process, paths, ...) chi-square test of a week's transitions against a model
"""

from __future__ import annotations

from psg_data.schemas._generator_model import PROCESS_FILE, EntityProcess, StepProcess, load_process
from psg_data.synth._build import build_lab, object_description, rerender_frame
from psg_data.synth._catalog import CONFUSABLE, FURNITURE, OBJECTS, FurnitureSpec, ObjectSpec
from psg_data.synth._house_build import HOUSE_GENERATOR, HouseConfig, HouseModel, build_house
from psg_data.synth._house_layout import HouseLayout, HouseObject, HouseParams, make_house
from psg_data.synth._house_process import HouseProcessParams, house_process, shifted_objects
from psg_data.synth._house_shift import transition_test
from psg_data.synth._lab_process import ProcessParams, StepSchedule
from psg_data.synth._lab_schedule import LabSchedule
from psg_data.synth._layout import (
    DOOR_ID0,
    ID_CEILING,
    ID_FLOOR,
    ID_NONE,
    OBJECT_ID0,
    RECEPTACLE_ID0,
    WALL_ID0,
    Instance,
    LabLayout,
    make_layout,
)
from psg_data.synth._model import GENERATORS, SYNTH_VERSION, LabConfig, LabModel, ScanPlan, camera_pose
from psg_data.synth._perception import DETECTIONS_SCHEMA, detect, write_detections
from psg_data.synth._process import ForwardBelief, llm_schedules, sample_entity
from psg_data.synth._raw_export import RAW_EXPORT_FORMATS, export_raw
from psg_data.synth._render import DepthNoise, LabRenderer, RenderedFrame, SceneState, d435_intrinsics
from psg_data.synth._schedule import SHIFTS, WEEKDAYS, DenseSchedule, EntityModel, HourPattern, Timeline, WeekPattern
from psg_data.synth.persistence_benchmark import BENCHMARK_FEATURES, PersistenceBenchmark, make_persistence_benchmark

__all__ = [
    "LabConfig", "LabModel", "ScanPlan", "camera_pose", "SYNTH_VERSION", "GENERATORS",
    "StepSchedule", "ProcessParams", "StepProcess", "EntityProcess", "ForwardBelief", "load_process", "llm_schedules",
    "sample_entity", "PROCESS_FILE",
    "LabLayout", "Instance", "make_layout",
    "ID_NONE", "ID_FLOOR", "ID_CEILING", "WALL_ID0", "DOOR_ID0", "RECEPTACLE_ID0", "OBJECT_ID0",
    "LabSchedule", "DenseSchedule", "EntityModel", "HourPattern", "WeekPattern", "Timeline", "SHIFTS", "WEEKDAYS",
    "DepthNoise", "LabRenderer", "RenderedFrame", "SceneState", "d435_intrinsics",
    "build_lab", "rerender_frame", "object_description",
    "write_detections", "detect", "DETECTIONS_SCHEMA",
    "OBJECTS", "FURNITURE", "CONFUSABLE", "ObjectSpec", "FurnitureSpec",
    "export_raw", "RAW_EXPORT_FORMATS",
    "make_persistence_benchmark", "PersistenceBenchmark", "BENCHMARK_FEATURES",
    "HouseConfig", "HouseModel", "HouseLayout", "HouseObject", "HouseParams", "HouseProcessParams", "build_house",
    "make_house", "house_process", "shifted_objects", "transition_test", "HOUSE_GENERATOR",
]
