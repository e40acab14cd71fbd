"""Laser range finders: ray casting in segment worlds and occupancy grids, and a simulator.

Conventions:

* ``poses (..., 3)`` are sensor poses ``(x, y, theta)``; ``beam_angles (B,)`` are measured
  from the sensor heading, counter-clockwise positive (radians). Ranges come back as
  ``(..., B)``: every pose against every beam.
* A range equal to ``max_range`` means **no return**: nothing was hit within ``max_range``.
  Real hits beyond ``max_range`` are reported as ``max_range`` too.
* Segment casting returns the distance to the nearest intersection with any segment (end
  points included; a ray lying along a segment does not hit it). Grid casting returns the
  distance to the point where the ray *enters* the first cell whose occupancy probability is
  ``>= occupied_threshold`` (0 when the ray starts inside one); leaving the grid is no hit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.errors import InputError, ShapeError
from slamkit.maps.types import OCCUPIED_THRESHOLD, OccupancyGrid, SegmentMap

__all__ = ["LaserScanner", "cast_rays_grid", "cast_rays_segments", "scan_points"]

# Largest number of (ray, segment) pairs held in memory at once by cast_rays_segments; each
# pair costs a handful of float64 temporaries, so this bounds the working set to ~100 MB.
_PAIRS_PER_BLOCK = 1 << 20


def _as_beams(beam_angles: ArrayLike) -> FloatArray:
    beams = as_array(beam_angles, "beam_angles", (None,))
    if beams.size == 0:
        raise ShapeError("beam_angles: expected at least one beam, got none")
    return beams


def _as_segments(segments: SegmentMap | ArrayLike) -> FloatArray:
    if isinstance(segments, SegmentMap):
        return segments.segments
    return as_array(segments, "segments", (None, 2, 2))


def _rays(poses: ArrayLike, beams: FloatArray) -> tuple[tuple[int, ...], FloatArray, FloatArray]:
    """Batch shape, ray origins ``(R, 2)`` and unit directions ``(R, 2)``, R = N·B."""
    p = as_array(poses, "poses", (..., 3))
    batch = p.shape[:-1]
    flat = p.reshape(-1, 3)
    ang = (flat[:, 2:3] + beams[None, :]).ravel()
    origin = np.repeat(flat[:, :2], beams.size, axis=0)
    direction = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    return batch, origin, direction


def cast_rays_segments(
    poses: ArrayLike,
    beam_angles: ArrayLike,
    segments: SegmentMap | ArrayLike,
    max_range: float,
) -> FloatArray:
    """Ranges ``(..., B)`` from each pose along each beam to the nearest segment.

    ``segments`` is a :class:`SegmentMap` or an array ``(S, 2, 2)`` of end points. Rays that
    hit nothing within ``max_range`` return ``max_range``. Work is split into blocks of at
    most ~10⁶ (ray, segment) pairs, so memory stays bounded for any number of poses.
    """
    beams = _as_beams(beam_angles)
    seg = _as_segments(segments)
    rmax = as_positive(max_range, "max_range")
    batch, origin, direction = _rays(poses, beams)
    n_rays, n_seg = origin.shape[0], seg.shape[0]
    out = np.full(n_rays, rmax)
    if n_rays == 0 or n_seg == 0:
        return out.reshape(*batch, beams.size)

    a = seg[:, 0, :]
    e = seg[:, 1, :] - seg[:, 0, :]
    seg_block = min(n_seg, _PAIRS_PER_BLOCK)
    ray_block = max(1, _PAIRS_PER_BLOCK // seg_block)
    for r0 in range(0, n_rays, ray_block):
        rs = slice(r0, r0 + ray_block)
        ox, oy = origin[rs, 0:1], origin[rs, 1:2]
        dx, dy = direction[rs, 0:1], direction[rs, 1:2]
        best = out[rs].copy()
        for s0 in range(0, n_seg, seg_block):
            ss = slice(s0, s0 + seg_block)
            ex, ey = e[None, ss, 0], e[None, ss, 1]
            wx, wy = a[None, ss, 0] - ox, a[None, ss, 1] - oy
            # o + t d = a + s e  =>  t d - s e = w,  w = a - o. Crossing with e and with d:
            #   t = (w × e) / (d × e),   s = (w × d) / (d × e),   a × b = a_x b_y - a_y b_x
            denom = dx * ey - dy * ex
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (wx * ey - wy * ex) / denom
                s = (wx * dy - wy * dx) / denom
            hit = (denom != 0.0) & (t >= 0.0) & (s >= 0.0) & (s <= 1.0)
            best = np.minimum(best, np.where(hit, t, np.inf).min(axis=1))
        out[rs] = best
    return out.reshape(*batch, beams.size)


def cast_rays_grid(
    poses: ArrayLike,
    beam_angles: ArrayLike,
    grid: OccupancyGrid,
    max_range: float,
    occupied_threshold: float = OCCUPIED_THRESHOLD,
) -> FloatArray:
    """Ranges ``(..., B)`` from each pose along each beam to the first occupied grid cell.

    Cells with probability ``>= occupied_threshold`` are obstacles. All rays are traversed
    at once by an Amanatides–Woo grid walk: each step moves every live ray into the next cell
    it crosses, so the distance reported is the exact distance to the boundary where the ray
    enters the first occupied cell. Rays starting outside the grid are first clipped to it;
    rays that leave the grid or pass ``max_range`` return ``max_range``. On an exact corner
    crossing the ray steps in x first, so it cannot slip between diagonal neighbours.
    """
    if not isinstance(grid, OccupancyGrid):
        raise InputError(f"grid: expected an OccupancyGrid, got {type(grid).__name__}")
    beams = _as_beams(beam_angles)
    rmax = as_positive(max_range, "max_range")
    batch, origin, direction = _rays(poses, beams)
    threshold = float(as_array(occupied_threshold, "occupied_threshold", ()))
    occ = grid.occupied(threshold)
    rows, cols = grid.shape
    res = grid.resolution
    n_rays = origin.shape[0]
    t_hit = np.full(n_rays, np.inf)  # in cell units (metres / resolution)

    # Work in cell units: the grid is the box [0, cols) × [0, rows).
    gx = (origin[:, 0] - grid.origin_xy[0]) / res
    gy = (origin[:, 1] - grid.origin_xy[1]) / res
    dx, dy = direction[:, 0], direction[:, 1]
    t_max_range = rmax / res

    # Slab clipping of each ray to the grid box: t in [t_enter, t_exit].
    def slab(g: FloatArray, d: FloatArray, size: int) -> tuple[FloatArray, FloatArray]:
        moving = d != 0.0
        safe = np.where(moving, d, 1.0)
        ta, tb = (0.0 - g) / safe, (size - g) / safe
        inside = (g >= 0.0) & (g < size)
        lo = np.where(moving, np.minimum(ta, tb), np.where(inside, -np.inf, np.inf))
        hi = np.where(moving, np.maximum(ta, tb), np.where(inside, np.inf, -np.inf))
        return lo, hi

    x_lo, x_hi = slab(gx, dx, cols)
    y_lo, y_hi = slab(gy, dy, rows)
    t_enter = np.maximum(0.0, np.maximum(x_lo, y_lo))
    t_exit = np.minimum(x_hi, y_hi)
    idx = np.flatnonzero((t_enter < t_exit) & (t_enter <= t_max_range))

    def first_cell(g: FloatArray, d: FloatArray, t0: FloatArray, size: int) -> NDArray[np.int64]:
        q = g + t0 * d
        i = np.floor(q)
        # A start exactly on a cell boundary belongs, for a ray moving towards lower
        # indices, to the cell below that boundary.
        i = np.where((d < 0.0) & (q == i), i - 1.0, i)
        return np.clip(i, 0, size - 1).astype(np.int64)

    def axis_setup(
        g: FloatArray, d: FloatArray, i: NDArray[np.int64]
    ) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
        step = np.sign(d).astype(np.int64)
        moving = d != 0.0
        safe = np.where(moving, d, 1.0)
        boundary = np.where(d > 0.0, i + 1.0, i.astype(np.float64))
        t_next = np.where(moving, (boundary - g) / safe, np.inf)  # next boundary crossing
        t_delta = np.where(moving, 1.0 / np.abs(safe), np.inf)  # between crossings
        return step, t_next, t_delta

    t_cur = t_enter[idx]
    gx_i, gy_i, dx_i, dy_i = gx[idx], gy[idx], dx[idx], dy[idx]
    ix = first_cell(gx_i, dx_i, t_cur, cols)
    iy = first_cell(gy_i, dy_i, t_cur, rows)
    sx, tnx, tdx = axis_setup(gx_i, dx_i, ix)
    sy, tny, tdy = axis_setup(gy_i, dy_i, iy)

    while idx.size:
        hit = occ[iy, ix]
        t_hit[idx[hit]] = t_cur[hit]
        # step every live ray across its nearest cell boundary
        go_x = tnx <= tny
        t_cur = np.where(go_x, tnx, tny)
        ix = ix + np.where(go_x, sx, 0)
        iy = iy + np.where(go_x, 0, sy)
        tnx = np.where(go_x, tnx + tdx, tnx)
        tny = np.where(go_x, tny, tny + tdy)
        live = ~hit & (ix >= 0) & (ix < cols) & (iy >= 0) & (iy < rows) & (t_cur <= t_max_range)
        idx, t_cur, ix, iy = idx[live], t_cur[live], ix[live], iy[live]
        sx, sy, tnx, tny, tdx, tdy = sx[live], sy[live], tnx[live], tny[live], tdx[live], tdy[live]

    ranges = np.minimum(t_hit * res, rmax)
    return ranges.reshape(*batch, beams.size)


@dataclass(frozen=True, eq=False)
class LaserScanner:
    """A planar laser range finder with Gaussian range noise.

    ``beam_angles (B,)`` (rad, from the sensor heading, counter-clockwise), ``max_range``
    (m, > 0) and ``range_sigma`` (m, >= 0) the standard deviation of the range noise. A
    reading equal to ``max_range`` means no return. The beam array is copied and made
    read-only.
    """

    beam_angles: FloatArray
    max_range: float
    range_sigma: float

    def __post_init__(self) -> None:
        beams = _as_beams(self.beam_angles).copy()
        beams.flags.writeable = False
        object.__setattr__(self, "beam_angles", beams)
        object.__setattr__(self, "max_range", as_positive(self.max_range, "max_range"))
        object.__setattr__(
            self, "range_sigma", as_positive(self.range_sigma, "range_sigma", allow_zero=True)
        )

    @classmethod
    def from_fov(
        cls, fov_rad: float, n_beams: int, max_range: float, range_sigma: float
    ) -> LaserScanner:
        """``n_beams`` beams spread evenly over a field of view of ``fov_rad`` centred on the
        heading: from ``-fov/2`` to ``+fov/2`` inclusive. A full circle (``fov >= 2 pi``)
        uses ``-pi + 2 pi k / n`` so that no beam is duplicated; one beam looks straight ahead.
        """
        fov = as_positive(fov_rad, "fov_rad")
        n = int(n_beams)
        if n != n_beams or n < 1:
            raise InputError(f"n_beams: expected an integer >= 1, got {n_beams!r}")
        if n == 1:
            beams = np.zeros(1)
        elif fov >= 2.0 * np.pi - 1e-12:
            beams = -np.pi + 2.0 * np.pi * np.arange(n) / n
        else:
            beams = np.linspace(-fov / 2.0, fov / 2.0, n)
        return cls(beams, max_range, range_sigma)

    @property
    def n_beams(self) -> int:
        return int(self.beam_angles.size)

    def expected_ranges(
        self,
        poses: ArrayLike,
        world: SegmentMap | OccupancyGrid | ArrayLike,
        *,
        occupied_threshold: float = OCCUPIED_THRESHOLD,
    ) -> FloatArray:
        """Noise-free ranges ``(..., B)`` from sensor poses ``(..., 3)`` in ``world`` (a
        :class:`SegmentMap`, an ``(S, 2, 2)`` segment array or an :class:`OccupancyGrid`)."""
        if isinstance(world, OccupancyGrid):
            return cast_rays_grid(
                poses, self.beam_angles, world, self.max_range, occupied_threshold
            )
        return cast_rays_segments(poses, self.beam_angles, world, self.max_range)

    def simulate(
        self,
        poses: ArrayLike,
        world: SegmentMap | OccupancyGrid | ArrayLike,
        rng: np.random.Generator,
        *,
        occupied_threshold: float = OCCUPIED_THRESHOLD,
    ) -> FloatArray:
        """Noisy scans ``(..., B)``: true range plus ``N(0, range_sigma²)`` per beam, clipped to
        ``[0, max_range]``. Beams without a return read exactly ``max_range`` (no noise); a
        noisy hit pushed past ``max_range`` also reads ``max_range``."""
        true = self.expected_ranges(poses, world, occupied_threshold=occupied_threshold)
        noise = rng.standard_normal(true.shape) * self.range_sigma
        noisy = np.clip(true + noise, 0.0, self.max_range)
        return np.where(true >= self.max_range, self.max_range, noisy)


def scan_points(
    ranges: FloatArray,
    beam_angles: FloatArray,
    max_range: float,
    *,
    min_range: float = 0.0,
) -> FloatArray:
    """The end points ``(M, 2)`` of the beams that returned, in the sensor frame.

    A beam returned when ``min_range < r < max_range`` and ``r`` is finite (``r >=
    max_range`` is the "no return" convention of :class:`~slamkit.datasets.LaserScan`).
    """
    r = as_array(ranges, "ranges", (None,), finite=False)
    a = as_array(beam_angles, "beam_angles", (r.size,))
    keep = np.isfinite(r) & (r > min_range) & (r < max_range)
    rk = r[keep]
    ak = a[keep]
    return np.column_stack([rk * np.cos(ak), rk * np.sin(ak)])
