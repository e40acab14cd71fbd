"""Grid-based Rao-Blackwellized particle filter SLAM (Grisetti, Stachniss & Burgard 2007):
particles with their own occupancy grids (tiles shared, copied on write), the improved
proposal from scan matching, adaptive resampling; the guard against odometry glitches and
the watch for lost loops."""

from slamkit.slam.grid_rbpf.config import GridRbpfConfig
from slamkit.slam.grid_rbpf.estimator import (
    FIELD_MARGIN,
    MATCH,
    RECOVERY_SEARCH,
    RESAMPLE_SHARE,
    TILE_CELLS,
    GridRbpf,
)
from slamkit.slam.grid_rbpf.guard import map_fit, relocate_on_map
from slamkit.slam.grid_rbpf.loops import LoopCheck, LoopWatch, particle_spread
from slamkit.slam.grid_rbpf.maps import TiledMap, TilePool, scan_cells
from slamkit.slam.grid_rbpf.proposal import (
    MODE_NOISE,
    MOTION_FLOOR,
    PROPOSAL_TEMPERATURE,
    STENCIL,
    STENCIL_SIGMAS,
    Scan,
    gaussian_proposal,
    mode_proposal,
    motion_covariance,
    motion_log_density,
    motion_proposal,
)

__all__ = [
    "FIELD_MARGIN",
    "MATCH",
    "MODE_NOISE",
    "MOTION_FLOOR",
    "PROPOSAL_TEMPERATURE",
    "RECOVERY_SEARCH",
    "RESAMPLE_SHARE",
    "STENCIL",
    "STENCIL_SIGMAS",
    "TILE_CELLS",
    "GridRbpf",
    "GridRbpfConfig",
    "LoopCheck",
    "LoopWatch",
    "Scan",
    "TilePool",
    "TiledMap",
    "gaussian_proposal",
    "map_fit",
    "mode_proposal",
    "motion_covariance",
    "motion_log_density",
    "motion_proposal",
    "particle_spread",
    "relocate_on_map",
    "scan_cells",
]
