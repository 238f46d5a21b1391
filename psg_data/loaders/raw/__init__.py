"""Readers of raw recordings: ROS 1 / ROS 2 bags and MCAP files (rosbags), frame folders (TUM RGB-D,
ScanNet), side files, image decoding and the TF tree; and the long-term state files of the public real
benchmarks (time-value text, per-minute index files).
"""

from psg_data.loaders.raw._bag import RECORDING_FORMATS, RosRecording, find_recordings, recording_format
from psg_data.loaders.raw._folders import (
    FolderRecording,
    folder_format,
    read_scannet_folder,
    read_tum_folder,
    read_tum_poses,
)
from psg_data.loaders.raw._images import (
    decode_color_image,
    decode_compressed_color,
    decode_compressed_depth,
    decode_depth_image,
    inspect_encoded,
    make_compressed_depth,
)
from psg_data.loaders.raw._side import SideData, read_side_files
from psg_data.loaders.raw._state_benchmarks import (
    StateBenchmark,
    StatePeriod,
    read_door_benchmark,
    read_room_presence_benchmark,
)
from psg_data.loaders.raw._state_files import read_minute_index, read_names, read_time_value
from psg_data.loaders.raw._transforms import PoseSeries, TfBuffer, make_transform, matrix_to_quat_xyzw
from psg_data.loaders.raw._wire import CompressedFields, TfSample, parse_compressed_image, parse_tf_message

__all__ = [
    "RECORDING_FORMATS", "RosRecording", "find_recordings", "recording_format", "CompressedFields",
    "parse_compressed_image", "parse_tf_message", "TfSample",
    "FolderRecording", "folder_format", "read_scannet_folder", "read_tum_folder", "read_tum_poses",
    "decode_color_image", "decode_compressed_color", "decode_compressed_depth", "decode_depth_image",
    "inspect_encoded", "make_compressed_depth",
    "SideData", "read_side_files",
    "StateBenchmark", "StatePeriod", "read_door_benchmark", "read_room_presence_benchmark", "read_time_value",
    "read_minute_index", "read_names",
    "PoseSeries", "TfBuffer", "make_transform", "matrix_to_quat_xyzw",
]
