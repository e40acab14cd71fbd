"""The mapper: a log-odds grid, the resolved inverse model and the statistics of a run; it
selects scans (scan stride, motion) and integrates them by the ray or the per-cell path."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.datasets.stream import LaserSpec
from slamkit.errors import ShapeError
from slamkit.geometry.angles import wrap_angle
from slamkit.mapping.bresenham import IntArray
from slamkit.mapping.grid import LogOddsGrid
from slamkit.mapping.inverse_model import RegionArray
from slamkit.mapping.occupancy.cells import (
    PolarTable,
    polar_table,
    scan_cells_cell,
    scan_cells_table,
)
from slamkit.mapping.occupancy.config import OccupancyMappingConfig
from slamkit.mapping.occupancy.rays import (
    BLOCK_CELLS,
    BLOCK_SCANS,
    ScanEnds,
    scan_ends,
    scan_rays,
    scan_segments,
    trace_rays,
)
from slamkit.mapping.occupancy.scans import check_ranges
from slamkit.maps import OccupancyGrid

__all__ = ["MappingStats", "OccupancyMapper"]


@dataclass
class MappingStats:
    """What a mapping run did. ``cell_updates`` counts cell writes (a cell updated by 100
    scans counts 100 times); ``seconds`` is the time spent integrating scans."""

    scans_seen: int = 0
    scans_used: int = 0
    scans_skipped_stride: int = 0
    scans_skipped_motion: int = 0
    readings_used: int = 0
    cell_updates: int = 0
    grid_growths: int = 0
    seconds: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        out = dict(self.__dict__)
        out["cell_updates_per_second"] = (
            self.cell_updates / self.seconds if self.seconds > 0 else None
        )
        return out


class OccupancyMapper:
    """Integrates scans taken from known poses into a :class:`LogOddsGrid`.

    ``laser`` gives the beam angles and the sensor's max range; ``bounds`` (``xmin, ymin,
    xmax, ymax``) fixes the grid (``+ margin``; readings beyond it are cut); ``None`` starts
    with the first scan's box and grows whenever a scan reaches past the edge.
    :meth:`offer` applies scan subsampling and motion-based selective updating;
    :meth:`integrate` always updates. :meth:`offer_many` and :meth:`integrate_many` do the
    same for many scans in order (same map, same statistics), several times faster than one
    call per scan because the Bresenham path then traces blocks of scans at once.
    """

    def __init__(
        self,
        laser: LaserSpec,
        config: OccupancyMappingConfig,
        bounds: tuple[float, float, float, float] | None = None,
    ) -> None:
        self.config = config
        self.n_beams = laser.n_beams
        """Readings per scan (every beam of the laser; the beam stride picks from them)."""
        self.beam_angles = laser.beam_angles[:: config.beam_stride].copy()
        self.model = config.model.resolve(config.resolution, self.beam_angles, laser.max_range)
        self.stats = MappingStats()
        self._margin_cells = math.ceil(config.margin / config.resolution)
        self.grid: LogOddsGrid | None = None
        self._fixed = bounds is not None
        if bounds is not None:
            xmin, ymin, xmax, ymax = bounds
            m = config.margin
            self.grid = LogOddsGrid.covering(
                xmin - m,
                ymin - m,
                xmax + m,
                ymax + m,
                config.resolution,
                self.model.l0,
                max_cells=config.max_cells,
            )
        self._table: PolarTable | None = None
        if config.precompute:
            self._table = polar_table(config.resolution, self.model.r_max + self.model.alpha)
        self._last_pose: FloatArray | None = None

    def _moved_enough(self, pose: FloatArray, last: FloatArray | None) -> bool:
        cfg = self.config
        if last is None or (cfg.min_travel <= 0 and cfg.min_rotation_deg <= 0):
            return True
        dist = math.hypot(pose[0] - last[0], pose[1] - last[1])
        turn = abs(float(wrap_angle(pose[2] - last[2])))
        return (cfg.min_travel > 0 and dist >= cfg.min_travel) or (
            cfg.min_rotation_deg > 0 and turn >= math.radians(cfg.min_rotation_deg)
        )

    def _select(self, poses: FloatArray) -> NDArray[np.bool_]:
        """Which of the next scans, taken from ``poses (S, 3)``, scan subsampling and
        motion-based selective updating let through (counted in the statistics). Depends only
        on the poses of the scans used before, so it can be decided before any is mapped."""
        used = np.zeros(poses.shape[0], dtype=bool)
        last = self._last_pose
        for k in range(poses.shape[0]):
            seen = self.stats.scans_seen
            self.stats.scans_seen += 1
            if seen % self.config.scan_stride != 0:
                self.stats.scans_skipped_stride += 1
            elif not self._moved_enough(poses[k], last):
                self.stats.scans_skipped_motion += 1
            else:
                used[k] = True
                last = poses[k]
        return used

    def _checked(
        self, poses: ArrayLike, ranges: ArrayLike, first_scan: int
    ) -> tuple[FloatArray, FloatArray]:
        """Poses ``(S, 3)`` and ranges ``(S, B)`` checked: shapes, one reading per beam of the
        laser (before the beam stride), finite poses, finite non-negative readings
        (:func:`check_ranges`, naming scan ``first_scan + k``)."""
        P = as_array(poses, "poses", (None, 3))
        R = np.asarray(ranges, dtype=np.float64)
        if R.ndim != 2 or R.shape[0] != P.shape[0]:
            raise ShapeError(
                f"scans: expected ranges (S, B) for {P.shape[0]} poses, got shape {R.shape}"
            )
        if R.shape[1] != self.n_beams:
            raise ShapeError(
                f"scan {first_scan}: expected {self.n_beams} ranges (the laser's beams), "
                f"got {R.shape[1]}"
            )
        return P, check_ranges(R, first_scan=first_scan)

    def offer(self, pose: ArrayLike, ranges: ArrayLike) -> bool:
        """Integrate the scan unless scan subsampling or selective updating skips it;
        returns whether it was used. Bad input raises before anything is counted."""
        readings = np.asarray(ranges, dtype=np.float64)
        if readings.ndim != 1:
            raise ShapeError(f"scan: expected ranges (B,), got shape {readings.shape}")
        return bool(self.offer_many(as_array(pose, "pose", (3,))[None], readings[None])[0])

    def offer_many(self, poses: ArrayLike, ranges: ArrayLike) -> NDArray[np.bool_]:
        """:meth:`offer` for scans ``ranges (S, B)`` taken from ``poses (S, 3)``, in order (the
        same map and statistics as ``S`` calls, several times faster: the scans used are traced
        in blocks); returns which scans were used ``(S,)``. Errors number the scans in the
        order they were offered (``stats.scans_seen`` before the call, + row)."""
        P, R = self._checked(poses, ranges, self.stats.scans_seen)
        used = self._select(P)
        if np.any(used):
            self._integrate_checked(P[used], R[used])
        return used

    def _ensure(self, lo: IntArray, hi: IntArray) -> LogOddsGrid:
        """The grid, created or grown to hold lattice cells lo..hi (never grown when the
        mapper was given fixed bounds: cells beyond them are dropped)."""
        if self.grid is None:
            m = self._margin_cells
            self.grid = LogOddsGrid(
                self.config.resolution,
                int(lo[0]) - m,
                int(lo[1]) - m,
                int(hi[0] - lo[0]) + 1 + 2 * m,
                int(hi[1] - lo[1]) + 1 + 2 * m,
                self.model.l0,
                max_cells=self.config.max_cells,
            )
        elif not self._fixed and self.grid.grow_to_cells(lo, hi, self._margin_cells):
            self.stats.grid_growths += 1
        return self.grid

    def _ray_flat(
        self, pose: FloatArray, readings: FloatArray
    ) -> tuple[IntArray, RegionArray, tuple[int, int, int, int] | None]:
        """Flat indices and regions of the scan's ray cells, and the box of array cells
        holding them (None if the scan reaches past fixed bounds and was cut)."""
        res = self.config.resolution
        rays = scan_rays(pose, readings, self.beam_angles, self.model, res)
        # A Bresenham line stays inside the box of its end cells: check the box, not cells.
        lo = np.minimum(rays.start, rays.end.min(axis=0))
        hi = np.maximum(rays.start, rays.end.max(axis=0))
        grid = self._ensure(lo, hi)
        rows, cols, regions, _ = trace_rays(rays, res, grid.row0, grid.col0)
        n_rows, n_cols = grid.shape
        flat = rows * n_cols + cols
        if not grid.contains_cells(lo, hi):  # fixed bounds that this scan reaches past
            inside = (rows >= 0) & (rows < n_rows) & (cols >= 0) & (cols < n_cols)
            return flat[inside], regions[inside], None
        box = (
            int(lo[0]) - grid.row0,
            int(lo[1]) - grid.col0,
            int(hi[0]) - grid.row0,
            int(hi[1]) - grid.col0,
        )
        return flat, regions, box

    def _cell_flat(self, pose: FloatArray, readings: FloatArray) -> tuple[IntArray, RegionArray]:
        if self._table is not None:
            cells, regions = scan_cells_table(
                self._table, pose, readings, self.beam_angles, self.model
            )
        else:
            cells, regions = scan_cells_cell(
                pose, readings, self.beam_angles, self.model, self.config.resolution
            )
        if cells.shape[0] == 0:
            return np.empty(0, dtype=np.int64), regions
        grid = self._ensure(cells.min(axis=0), cells.max(axis=0))
        flat, inside = grid.flat_index(cells)
        if not np.all(inside):
            flat, regions = flat[inside], regions[inside]
        return flat, regions

    def integrate(self, pose: ArrayLike, ranges: ArrayLike) -> int:
        """Update the grid with one scan from ``pose``; returns the number of cells written."""
        p = as_array(pose, "pose", (3,))
        readings = np.asarray(ranges, dtype=np.float64)
        if readings.ndim != 1:
            raise ShapeError(f"scan: expected ranges (B,), got shape {readings.shape}")
        return self.integrate_many(p[None], readings[None])

    def integrate_many(self, poses: ArrayLike, ranges: ArrayLike) -> int:
        """Update the grid with scans ``ranges (S, B)`` from ``poses (S, 3)``, in order — the
        same as ``S`` calls of :meth:`integrate`; returns the number of cells written. Errors
        number the scans in the order they were integrated (``stats.scans_used`` before the
        call, + row)."""
        P, R = self._checked(poses, ranges, self.stats.scans_used)
        return self._integrate_checked(P, R)

    def _integrate_checked(self, P: FloatArray, ranges: FloatArray) -> int:
        """:meth:`integrate_many` of checked scans (all beams, before the beam stride)."""
        tic = time.perf_counter()
        R = ranges[:, :: self.config.beam_stride]
        cfg = self.config
        if cfg.method == "ray" and cfg.merge == "per-scan" and cfg.min_change == 0.0:
            n = self._ray_scans(P, R)
        else:
            n = sum(self._integrate_one(P[k], R[k]) for k in range(P.shape[0]))
        self.stats.scans_used += P.shape[0]
        self.stats.readings_used += R.size
        self.stats.cell_updates += n
        self.stats.seconds += time.perf_counter() - tic
        if P.shape[0]:
            self._last_pose = P[-1].copy()
        return n

    def _integrate_one(self, pose: FloatArray, readings: FloatArray) -> int:
        """One scan by the general paths (any method, merge and selective updating)."""
        cfg = self.config
        box = None
        if cfg.method == "ray":
            flat, regions, box = self._ray_flat(pose, readings)
        else:
            flat, regions = self._cell_flat(pose, readings)
        if self.grid is None or flat.size == 0:
            return 0
        if cfg.method == "ray" and cfg.merge == "per-reading":
            return self.grid.apply_readings(flat, regions, self.model, cfg.min_change)
        if cfg.method == "ray":
            return self.grid.apply_scan(flat, regions, self.model, cfg.min_change, box)
        # the per-cell paths give every cell once already
        return self.grid.apply(flat, self.model.delta(regions), self.model, cfg.min_change)

    def _ray_scans(self, poses: FloatArray, readings: FloatArray) -> int:
        """The hot path (Bresenham, one update per cell and scan, no cell-level selection):
        scans in blocks of :data:`BLOCK_SCANS`; the cells of a block's scans are traced in
        one pass (:func:`scan_segments`), then applied scan by scan
        (:meth:`LogOddsGrid.apply_free_occupied`). A scan that reaches past the grid first
        grows it (and the rest of the block is planned again on the new grid), or, with
        fixed bounds, takes the per-scan path that cuts its rays at the edge."""
        res = self.config.resolution
        total = 0
        k = 0
        while k < poses.shape[0]:
            stop = min(poses.shape[0], k + BLOCK_SCANS)
            ends = scan_ends(poses[k:stop], readings[k:stop], self.beam_angles, self.model, res)
            grid = self._ensure(ends.lo[0], ends.hi[0]) if self.grid is None else self.grid
            rows, cols = grid.shape
            inside = (
                (ends.lo[:, 0] >= grid.row0)
                & (ends.lo[:, 1] >= grid.col0)
                & (ends.hi[:, 0] < grid.row0 + rows)
                & (ends.hi[:, 1] < grid.col0 + cols)
            )
            j = 0
            while j < stop - k:
                if inside[j]:
                    rest = inside[j:]
                    run = rest.size if rest.all() else int(rest.argmin())  # to the first False
                    part = slice(k + j, k + j + run)
                    block = ends.select(j, j + run)
                    total += self._trace_block(poses[part], readings[part], block, grid)
                    j += run
                elif self._fixed:
                    total += self._integrate_one(poses[k + j], readings[k + j])
                    j += 1
                else:  # grow, then plan the rest of the block on the new grid
                    self._ensure(ends.lo[j], ends.hi[j])
                    break
            k += j
        return total

    def _trace_block(
        self, poses: FloatArray, readings: FloatArray, ends: ScanEnds, grid: LogOddsGrid
    ) -> int:
        """Trace and apply scans (with their :class:`ScanEnds`) whose rays all lie inside
        ``grid``."""
        cols = grid.shape[1]
        seg = scan_segments(ends, self.model, self.config.resolution, grid.row0, grid.col0, cols)
        if seg is None:  # rays too long for the segment form: the general path, scan by scan
            return sum(self._integrate_one(p, r) for p, r in zip(poses, readings, strict=True))
        counts = (seg.n_free + seg.n_occupied).tolist()
        n_free = seg.n_free.tolist()
        n = 0
        k0 = 0
        while k0 < len(counts):  # generate up to BLOCK_CELLS cells (at least a scan) at once
            k1, cells = k0 + 1, counts[k0]
            while k1 < len(counts) and cells + counts[k1] <= BLOCK_CELLS:
                cells += counts[k1]
                k1 += 1
            flat = seg.flat_cells(k0, k1)
            start = 0
            for k in range(k0, k1):
                if counts[k]:
                    n += grid.apply_free_occupied(
                        flat[start : start + counts[k]], n_free[k], self.model
                    )
                start += counts[k]
            k0 = k1
        return n

    def occupancy_grid(self) -> OccupancyGrid:
        """The current map (an all-unknown 1 × 1 grid before the first scan)."""
        return self.log_odds_grid().to_occupancy_grid()

    def log_odds_grid(self) -> LogOddsGrid:
        """The working grid (an all-prior 1 × 1 grid before the first scan)."""
        if self.grid is None:
            return LogOddsGrid(self.config.resolution, 0, 0, 1, 1, self.model.l0)
        return self.grid
