"""Readers of raw recordings: ROS 1 / ROS 2 bags and MCAP files (rosbags), frame folders (TUM RGB-D,
ScanNet), side files, image decoding and the TF tree.
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
from psg_data.loaders.raw._transforms import PoseSeries, TfBuffer, make_transform, matrix_to_quat_xyzw
from psg_data.loaders.raw._wire import CompressedFields, TfSample, parse_compressed_image, parse_tf_message

__all__ = [
    "RECORDING_FORMATS", "RosRecording", "find_recordings", "recording_format", "CompressedFields",
    "parse_compressed_image", "parse_tf_message", "TfSample",
    "FolderRecording", "folder_format", "read_scannet_folder", "read_tum_folder", "read_tum_poses",
    "decode_color_image", "decode_compressed_color", "decode_compressed_depth", "decode_depth_image",
    "inspect_encoded", "make_compressed_depth",
    "SideData", "read_side_files",
    "PoseSeries", "TfBuffer", "make_transform", "matrix_to_quat_xyzw",
]
