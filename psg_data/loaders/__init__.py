"""Reading canonical psg-datasets (and, in :mod:`psg_data.loaders.raw`, raw recordings)."""

from psg_data.loaders._dataset import Dataset, Scan, backproject, open_dataset

__all__ = ["Dataset", "Scan", "backproject", "open_dataset"]
