"""Map representations: point landmarks, wall segments and occupancy grids."""

from slamkit.maps.types import (
    FREE_THRESHOLD,
    OCCUPIED_THRESHOLD,
    UNKNOWN,
    LandmarkMap,
    OccupancyGrid,
    SegmentMap,
)

__all__ = [
    "FREE_THRESHOLD",
    "OCCUPIED_THRESHOLD",
    "UNKNOWN",
    "LandmarkMap",
    "OccupancyGrid",
    "SegmentMap",
]
