"""Grid-based Rao-Blackwellized particle filter SLAM (Grisetti, Stachniss & Burgard 2007):
particles with their own occupancy grids (tiles shared, copied on write), the improved
proposal from scan matching, adaptive resampling."""

from slamkit.slam.grid_rbpf.config import GridRbpfConfig
from slamkit.slam.grid_rbpf.estimator import FIELD_MARGIN, GridRbpf
from slamkit.slam.grid_rbpf.maps import TiledMap, TilePool, scan_cells
from slamkit.slam.grid_rbpf.proposal import (
    STENCIL,
    Scan,
    gaussian_proposal,
    mode_proposal,
    motion_covariance,
    motion_log_density,
    motion_proposal,
)

__all__ = [
    "FIELD_MARGIN",
    "STENCIL",
    "GridRbpf",
    "GridRbpfConfig",
    "Scan",
    "TilePool",
    "TiledMap",
    "gaussian_proposal",
    "mode_proposal",
    "motion_covariance",
    "motion_log_density",
    "motion_proposal",
    "scan_cells",
]
