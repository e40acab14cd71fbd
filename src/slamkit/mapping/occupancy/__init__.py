"""Occupancy-grid mapping with known poses (being split into a package)."""

from slamkit.mapping.occupancy.mapper import *  # noqa: F403
from slamkit.mapping.occupancy.mapper import __all__  # noqa: F401
