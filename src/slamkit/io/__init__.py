"""Reading and writing results: TUM trajectories, JSON, atomic output folders."""

from slamkit.io.folders import atomic_folder, write_json
from slamkit.io.tum import format_tum, read_tum, write_tum

__all__ = ["atomic_folder", "format_tum", "read_tum", "write_json", "write_tum"]
