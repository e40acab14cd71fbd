"""Settings of occupancy-grid mapping with known poses."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from slamkit.errors import ConfigError
from slamkit.mapping.inverse_model import InverseSensorModel

__all__ = ["OccupancyMappingConfig"]


@dataclass(frozen=True)
class OccupancyMappingConfig:
    """Settings of occupancy-grid mapping with known poses (see
    :mod:`slamkit.mapping.occupancy`). Metres, degrees where named."""

    resolution: float = 0.05
    """Side of a grid cell [m]."""
    model: InverseSensorModel = field(default_factory=InverseSensorModel)
    """The inverse sensor model and the log-odds clamp."""
    method: Literal["ray", "cell"] = "ray"
    """``ray``: Bresenham per reading; ``cell``: per-cell model over the scan's window."""
    precompute: bool = False
    """``cell`` method: use the pre-computed polar model (sensor snapped to its cell centre)."""
    merge: Literal["per-scan", "per-reading"] = "per-scan"
    """``ray`` method: one update per cell and scan, or one per cell and reading."""
    beam_stride: int = 1
    """Use every n-th beam of a scan (sensor subsampling)."""
    scan_stride: int = 1
    """Use every n-th scan."""
    min_travel: float = 0.0
    """Skip a scan unless the robot moved this far [m] since the last scan used (or turned
    ``min_rotation_deg``); 0 with ``min_rotation_deg`` 0 uses every scan."""
    min_rotation_deg: float = 0.0
    """See ``min_travel`` [deg]."""
    min_change: float = 0.0
    """Cell-level selective updating: leave a cell alone when an update would change its
    probability by less than this (0 = always write)."""
    bounds: Literal["data", "grow"] = "data"
    """``data``: size the grid from all poses and ray ends first; ``grow``: grow as needed.
    Only :func:`~slamkit.mapping.occupancy.build_occupancy_map` (a batch over a whole log)
    can size from the data; the pipeline estimator sees one scan at a time and always grows
    (the cells are the same: every grid lies on one lattice anchored at the world origin)."""
    max_cells: int = 500_000_000
    """Refuse to allocate (or grow to) a grid of more cells than this (4 bytes each: 2 GB by
    default), with the size it would have had, instead of running out of memory."""
    margin: float = 1.0
    """Free border around the data bounds, and the least a growing grid adds [m]."""
    pose_source: Literal["truth", "odometry"] = "truth"
    """Where the known poses come from: the data set's true trajectory (interpolated at the
    scan times) or its odometry readings (a map that shows the odometry's drift)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise ConfigError(f"resolution: expected a number > 0, got {self.resolution!r}")
        for name in ("beam_stride", "scan_stride", "max_cells"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name}: expected an integer >= 1, got {getattr(self, name)}")
        for name in ("min_travel", "min_rotation_deg", "margin"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: expected a number >= 0, got {v!r}")
        if not (0.0 <= self.min_change < 1.0):
            raise ConfigError(
                f"min_change: expected a probability in [0, 1), got {self.min_change}"
            )
        if self.precompute and self.method != "cell":
            raise ConfigError("precompute: the pre-computed model belongs to method 'cell'")
