"""Converting raw recordings (ROS 1 / ROS 2 bags, MCAP, TUM RGB-D and ScanNet folders) into psg-datasets."""

from psg_data.convert._config import CONVERT_SETTINGS, ConvertConfig, load_config
from psg_data.convert._pipeline import ConversionReport, convert, plan_sources
from psg_data.convert._scan import SKIP_REASONS, discover_topics

__all__ = ["ConvertConfig", "CONVERT_SETTINGS", "load_config", "ConversionReport", "convert", "plan_sources",
           "SKIP_REASONS", "discover_topics"]
