"""Occupancy-grid mapping with known poses: log-odds Bayes filter per cell.

Given the robot's poses (here: the data set's true trajectory, or its odometry), every laser
scan updates the log odds of the cells it says something about (see
:mod:`slamkit.mapping.logodds` for the update and :mod:`slamkit.mapping.inverse_model` for
the α/β inverse sensor model). Two update paths compute which cells a scan touches:

``method="cell"``
    the per-cell model: every cell in the scan's window (the box around the sensor and the
    ends of all its beams) gets its range and bearing from the sensor, its nearest beam and
    one of the three regions — vectorised over the window's cells. With ``precompute=True``
    the range and world bearing of every cell offset around the sensor are computed once and
    reused by every scan (the notes' "measurement model pre-caching"); the sensor is then
    snapped to its cell centre, which moves it by at most ``resolution/√2``.
``method="ray"`` (default)
    Bresenham ray tracing: each range reading traces its own ray from the sensor's cell to
    the cell at ``min(r_k + alpha/2, r_max)`` in integer arithmetic
    (:mod:`slamkit.mapping.bresenham`), all beams of a scan at once. Each traced cell falls
    in the inverse model's regions by its centre's range and the ray's own reading: free up
    to ``r_k - alpha/2``, occupied beyond (never for a max-range reading), compared as
    squared ranges. ``merge="per-scan"`` applies the cells the readings of one scan touched
    as one update per cell (occupied wins, like the per-cell model); ``merge="per-reading"``
    adds one update per (cell, reading) pair, so the cells near the robot that many rays
    cross get many free updates per scan.

    With ``merge="per-scan"`` and no cell-level selection (the default) the mapper takes a
    faster road to the same map: the squared range of the cell centres grows along a ray
    from its second cell on (:func:`~slamkit.mapping.occupancy.rays.scan_segments`), so each
    ray is free up to some step, occupied for a few steps, then silent, and only the sensor's
    cell and the last few cells of each ray need the region test; the cells themselves are
    then generated as flat grid indices for blocks of scans at once
    (:func:`~slamkit.mapping.bresenham.bresenham_segments`) and applied scan by scan
    (:meth:`LogOddsGrid.apply_free_occupied`). It gives the same cells, regions and log odds,
    bit for bit, as tracing every cell.

The two paths agree on which cells a scan makes free or occupied except where the per-cell
model's beam width fills the gaps between diverging rays (``tests/mapping/test_occupancy.py`` holds
them to ≥ 98 % of the touched cells on a simulated scan).

Computational options (the notes' list): beam subsampling (``beam_stride``), scan
subsampling (``scan_stride``), selective updating — at scan level (``min_travel``,
``min_rotation_deg``: a scan taken before the robot has moved that far brings no significant
new information and is skipped) and at cell level (``min_change``: a cell whose probability
would move by less than this, e.g. one clamped at "free" and seen free again, is not written)
— the pre-computed model above, and the grid size: ``bounds="data"`` sizes the grid once to
the box of all poses and all ray ends actually used (``+ margin``); ``bounds="grow"`` starts
from the first scan and grows (by at least ``margin``) whenever a scan reaches past the edge.

The package:

* :mod:`~slamkit.mapping.occupancy.config` — :class:`OccupancyMappingConfig`;
* :mod:`~slamkit.mapping.occupancy.scans` — range checks, scans and their known poses from a
  data set, the box the scans reach (:func:`scan_bounds`, :func:`data_bounds`);
* :mod:`~slamkit.mapping.occupancy.rays` — the Bresenham kernels of ``method="ray"``, one
  scan and blocks of scans;
* :mod:`~slamkit.mapping.occupancy.cells` — the per-cell inverse-model path of
  ``method="cell"`` and its pre-computed polar table;
* :mod:`~slamkit.mapping.occupancy.mapper` — :class:`OccupancyMapper` (grid, selection of
  scans, the update paths) and :class:`MappingStats`;
* :mod:`~slamkit.mapping.occupancy.build` — :func:`build_occupancy_map` over a data set;
* :mod:`~slamkit.mapping.occupancy.estimator` — the pipeline estimator
  :class:`OccupancyMapping`;
* :mod:`~slamkit.mapping.occupancy.along_path` — :func:`dataset_on_path`: the known poses
  from any trajectory (a run's TUM file), scans outside its span dropped and counted.
"""

from slamkit.mapping.occupancy.along_path import PathCoverage, dataset_on_path
from slamkit.mapping.occupancy.build import OccupancyMapResult, Progress, build_occupancy_map
from slamkit.mapping.occupancy.cells import (
    PolarTable,
    polar_table,
    scan_cells_cell,
    scan_cells_table,
)
from slamkit.mapping.occupancy.config import OccupancyMappingConfig
from slamkit.mapping.occupancy.estimator import OccupancyMapping
from slamkit.mapping.occupancy.mapper import MappingStats, OccupancyMapper
from slamkit.mapping.occupancy.rays import scan_cells_ray
from slamkit.mapping.occupancy.scans import (
    check_ranges,
    data_bounds,
    known_pose_at,
    laser_scans,
    scan_bounds,
    scan_poses,
    sensor_poses,
)

__all__ = [
    "MappingStats",
    "OccupancyMapResult",
    "OccupancyMapper",
    "OccupancyMapping",
    "OccupancyMappingConfig",
    "PathCoverage",
    "PolarTable",
    "Progress",
    "build_occupancy_map",
    "check_ranges",
    "data_bounds",
    "dataset_on_path",
    "known_pose_at",
    "laser_scans",
    "polar_table",
    "scan_bounds",
    "scan_cells_cell",
    "scan_cells_ray",
    "scan_cells_table",
    "scan_poses",
    "sensor_poses",
]
