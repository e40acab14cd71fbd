"""A whole data set mapped at once: :func:`build_occupancy_map` and its result."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from slamkit._validation import FloatArray
from slamkit.config import config_to_dict
from slamkit.datasets.stream import Dataset
from slamkit.errors import InputError
from slamkit.mapping.grid import LogOddsGrid
from slamkit.mapping.occupancy.config import OccupancyMappingConfig
from slamkit.mapping.occupancy.mapper import MappingStats, OccupancyMapper
from slamkit.mapping.occupancy.rays import BLOCK_SCANS
from slamkit.mapping.occupancy.scans import check_ranges, laser_scans, scan_bounds, scan_poses
from slamkit.maps import OccupancyGrid

__all__ = ["OccupancyMapResult", "Progress", "build_occupancy_map"]

log = logging.getLogger(__name__)
log.addHandler(logging.NullHandler())

Progress = Callable[[int, int], None]
"""``progress(done, total)`` in scans; called at most about a hundred times per map (after
every ~1 % of the scans, or every block of scans traced at once if that is more)."""


@dataclass(frozen=True)
class OccupancyMapResult:
    """A map built by :func:`build_occupancy_map`: the probability ``grid``, the mapper's
    ``log_odds`` grid, the statistics, the resolved config (JSON-able), the poses of the
    scans used ``(S, 3)`` and the bounds the grid was sized for."""

    grid: OccupancyGrid
    log_odds: LogOddsGrid
    stats: MappingStats
    config: dict[str, Any]
    poses: FloatArray
    bounds: tuple[float, float, float, float] | None


def build_occupancy_map(
    dataset: Dataset,
    config: OccupancyMappingConfig | None = None,
    progress: Progress | None = None,
    *,
    scans: Sequence[int] | slice | None = None,
    bounds: tuple[float, float, float, float] | None = None,
) -> OccupancyMapResult:
    """Map ``dataset``'s laser scans from known poses (see :mod:`slamkit.mapping.occupancy`).

    ``scans`` selects scans by index (e.g. ``slice(0, None, 2)`` for the even ones);
    ``bounds`` fixes the grid's box (e.g. to build two maps on the same grid) instead of
    taking it from the data (``bounds="data"``) or growing it (``"grow"``).
    """
    cfg = config if config is not None else OccupancyMappingConfig()
    if dataset.laser is None:
        raise InputError(f"occupancy mapping needs laser scans; {dataset.name!r} has none")
    times, ranges = laser_scans(dataset)
    check_ranges(ranges, times=times)  # numbered as the data set's scans
    if scans is not None:
        pick = (
            np.arange(times.size)[scans]
            if isinstance(scans, slice)
            else np.asarray(scans, dtype=np.int64)
        )
        times, ranges = times[pick], ranges[pick]
        if times.size == 0:
            raise InputError("occupancy mapping: the scan selection is empty")
    poses = scan_poses(dataset, times, cfg.pose_source)
    if bounds is None and cfg.bounds == "data":
        used = slice(None, None, cfg.scan_stride)
        beams = dataset.laser.beam_angles[:: cfg.beam_stride]
        model = cfg.model.resolve(cfg.resolution, beams, dataset.laser.max_range)
        bounds = scan_bounds(poses[used], ranges[used, :: cfg.beam_stride], beams, model)
    mapper = OccupancyMapper(dataset.laser, cfg, bounds)
    total = times.size
    every = max(BLOCK_SCANS, -(-total // 100))
    chosen = np.zeros(total, dtype=bool)
    for k0 in range(0, total, every):  # the scans between two progress reports at once
        k1 = min(total, k0 + every)
        chosen[k0:k1] = mapper.offer_many(poses[k0:k1], ranges[k0:k1])
        if progress is not None:
            progress(k1, total)
    grid = mapper.occupancy_grid()
    log.debug("mapped %s: %s", dataset.name, mapper.stats)
    return OccupancyMapResult(
        grid=grid,
        log_odds=mapper.log_odds_grid(),
        stats=mapper.stats,
        config=config_to_dict(cfg),
        poses=poses[chosen],
        bounds=bounds,
    )
