"""psg_data.labeling: visibility, privileged / perception labels, noise, error rates and label tables.

Main entry points:
    label_dataset(root, "privileged")        compute labels and store them in the dataset
    compute_labels(ds, source)               the same without writing (returns a LabelGrid)
    label_streams(ds, source) / load_label_streams(ds)   EdgeStream objects for estimators
    compute_visibility(ds)                   what each scan saw of every receptacle top surface
    observe_doors(ds)                        door visibility and open/closed state read from the depth
    error_rates(labels, gt)                  P_M / P_F with confidence intervals
    read_any_detections(ds, path)            detections from a table or ConceptGraphs / Spark-DSG / HOV-SG graphs
"""

from psg_data.labeling._association import (
    AssociationParams,
    PerceptionInfo,
    associate_objects,
    match_boxes,
    max_weight_matching,
    perception_labels,
)
from psg_data.labeling._codes import (
    ErrorRates,
    LabelGrid,
    binomial_interval,
    error_rates,
    ground_truth,
    inject_noise,
    privileged_codes,
    schedule_support,
    valid_mask,
)
from psg_data.labeling._detections import DETECTION_COLUMNS, Detections, read_detections
from psg_data.labeling._doors import (
    DOOR_EDGE_STATES,
    DoorObservations,
    DoorParams,
    DoorwaySamples,
    door_ground_truth,
    door_label_grid,
    door_visibility_from_table,
    doorway_samples,
    is_door_row,
    observe_doors,
)
from psg_data.labeling._geometry import (
    SurfaceSamples,
    box_iou,
    box_iou_matrix,
    box_surface_samples,
    convex_polygon_intersection,
    is_yaw_only,
    polygon_area,
    top_face_samples,
)
from psg_data.labeling._pipeline import (
    LabelResult,
    LabelSummary,
    SourceSpec,
    compute_labels,
    grid_streams,
    label_dataset,
    label_streams,
    load_label_streams,
    parse_source,
    summarize,
)
from psg_data.labeling._scene_graph_export import (
    EXPORT_FORMATS,
    export_scene_graphs,
    representable,
    write_detections_table,
)
from psg_data.labeling._scene_graphs import (
    DETECTION_FORMATS,
    SceneGraphMapping,
    Vocabulary,
    detect_format,
    load_mapping,
    read_any_detections,
    read_scene_graphs,
    vocabulary,
)
from psg_data.labeling._statistics import visibility_statistics
from psg_data.labeling._visibility import (
    SurfaceVisibility,
    VisibilityParams,
    compute_visibility,
    surface_visibility,
    visibility_matrix,
)

__all__ = [
    "AssociationParams", "PerceptionInfo", "associate_objects", "match_boxes", "max_weight_matching",
    "perception_labels",
    "ErrorRates", "LabelGrid", "binomial_interval", "error_rates", "ground_truth", "inject_noise", "privileged_codes",
    "schedule_support", "valid_mask",
    "DETECTION_COLUMNS", "Detections", "read_detections",
    "DOOR_EDGE_STATES", "DoorObservations", "DoorParams", "DoorwaySamples", "door_ground_truth", "door_label_grid",
    "door_visibility_from_table", "doorway_samples", "is_door_row", "observe_doors",
    "SurfaceSamples", "box_iou", "box_iou_matrix", "box_surface_samples", "convex_polygon_intersection",
    "is_yaw_only", "polygon_area", "top_face_samples",
    "LabelResult", "LabelSummary", "SourceSpec", "compute_labels", "grid_streams", "label_dataset", "label_streams",
    "load_label_streams", "parse_source", "summarize",
    "DETECTION_FORMATS", "EXPORT_FORMATS", "SceneGraphMapping", "Vocabulary", "detect_format", "export_scene_graphs",
    "load_mapping", "read_any_detections", "read_scene_graphs", "representable", "vocabulary", "write_detections_table",
    "SurfaceVisibility", "VisibilityParams", "compute_visibility", "surface_visibility", "visibility_matrix",
    "visibility_statistics",
]
