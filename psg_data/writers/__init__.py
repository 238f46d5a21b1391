"""Writing psg-datasets: :class:`DatasetWriter` is used by every producer (synth, convert)."""

from psg_data.writers._add_tables import add_tables
from psg_data.writers._dataset_writer import JPEG_QUALITY, PNG_LEVEL, DatasetWriter, ScanWriter, sha256_file, to_arrow

__all__ = ["add_tables", "DatasetWriter", "ScanWriter", "sha256_file", "to_arrow", "PNG_LEVEL", "JPEG_QUALITY"]
