"""Mapping with known poses: occupancy grids (log-odds, α/β inverse laser model, Bresenham).

* :mod:`~slamkit.mapping.logodds` — logit/expit, the log-odds update and its clamp;
* :mod:`~slamkit.mapping.inverse_model` — the inverse laser model and its regions;
* :mod:`~slamkit.mapping.bresenham` — integer ray tracing, one ray or many at once;
* :mod:`~slamkit.mapping.grid` — the growable log-odds grid on a world-anchored lattice;
* :mod:`~slamkit.mapping.occupancy` (a package) — per-scan update paths,
  :func:`build_occupancy_map` and the :class:`OccupancyMapping` estimator;
* :mod:`~slamkit.mapping.ekf_mapping` (a package) — EKF landmark mapping with known poses
  (imported by path, not re-exported here);
* :mod:`~slamkit.mapping.quality` — occupied/free/unknown fractions, entropy, map agreement.
"""

from slamkit.mapping.bresenham import RayCells, bresenham_line, bresenham_rays
from slamkit.mapping.grid import LogOddsGrid, lattice_cells
from slamkit.mapping.inverse_model import (
    FREE,
    NO_INFORMATION,
    OCCUPIED,
    InverseSensorModel,
    ResolvedModel,
    classify_cells,
    nearest_beam,
    ray_extents,
)
from slamkit.mapping.logodds import clamp_log_odds, expit, log_odds_update, logit
from slamkit.mapping.occupancy import (
    MappingStats,
    OccupancyMapper,
    OccupancyMapping,
    OccupancyMappingConfig,
    OccupancyMapResult,
    PolarTable,
    build_occupancy_map,
    known_pose_at,
    polar_table,
    scan_bounds,
    scan_cells_cell,
    scan_cells_ray,
    scan_cells_table,
)
from slamkit.mapping.quality import (
    MapQuality,
    even_odd_agreement,
    map_agreement,
    map_entropy,
    map_quality,
    occupied_precision_recall,
)

__all__ = [
    "FREE",
    "NO_INFORMATION",
    "OCCUPIED",
    "InverseSensorModel",
    "LogOddsGrid",
    "MapQuality",
    "MappingStats",
    "OccupancyMapResult",
    "OccupancyMapper",
    "OccupancyMapping",
    "OccupancyMappingConfig",
    "PolarTable",
    "RayCells",
    "ResolvedModel",
    "bresenham_line",
    "bresenham_rays",
    "build_occupancy_map",
    "clamp_log_odds",
    "classify_cells",
    "even_odd_agreement",
    "expit",
    "known_pose_at",
    "lattice_cells",
    "log_odds_update",
    "logit",
    "map_agreement",
    "map_entropy",
    "map_quality",
    "nearest_beam",
    "occupied_precision_recall",
    "polar_table",
    "ray_extents",
    "scan_bounds",
    "scan_cells_cell",
    "scan_cells_ray",
    "scan_cells_table",
]
