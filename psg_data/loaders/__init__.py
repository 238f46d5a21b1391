"""Reading canonical psg-datasets (and, in :mod:`psg_data.loaders.raw`, raw recordings)."""

from psg_data.loaders._dataset import Dataset, Scan, backproject, open_dataset
from psg_data.loaders._frame_view import FrameRecord, FrameView

__all__ = ["Dataset", "Scan", "FrameView", "FrameRecord", "backproject", "open_dataset"]
