"""Map representations: point landmarks, wall segments and occupancy grids."""

from slamkit.maps.types import UNKNOWN, LandmarkMap, OccupancyGrid, SegmentMap

__all__ = ["UNKNOWN", "LandmarkMap", "OccupancyGrid", "SegmentMap"]
