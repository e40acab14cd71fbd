"""Bresenham ray-tracing kernels of the ``method="ray"`` path (array in, array out).

One scan: :func:`scan_rays` plans its rays (sensor cell, end cells, squared region limits),
:func:`trace_rays` traces every cell of every ray with its region, :func:`scan_cells_ray` is
the public one-scan form. Many scans (the mapper's hot path, ``merge="per-scan"``):
:func:`scan_ends` plans a block of scans and :func:`scan_segments` turns each ray into a
run of free steps and a run of occupied steps, whose cells
:meth:`ScanSegments.flat_cells` generates as flat grid indices — the same cells, regions and
log odds, bit for bit, as tracing every cell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.mapping.bresenham import (
    MAX_SEGMENT_STEPS,
    IntArray,
    bresenham_rays,
    bresenham_segments,
    minor_steps,
)
from slamkit.mapping.inverse_model import (
    FREE,
    NO_INFORMATION,
    OCCUPIED,
    RegionArray,
    ResolvedModel,
    ray_region_limits,
)
from slamkit.mapping.occupancy.scans import check_ranges

__all__ = [
    "BLOCK_CELLS",
    "BLOCK_SCANS",
    "TAIL_MARGIN",
    "ScanEnds",
    "ScanRays",
    "ScanSegments",
    "scan_cells_ray",
    "scan_ends",
    "scan_rays",
    "scan_segments",
    "trace_rays",
]


# --------------------------------------------------------------------------------------------
# one scan → cells and regions
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ScanRays:
    """One scan's rays: sensor position, its lattice cell ``start (2,)``, the lattice cells
    ``end (B, 2)`` of the points at ``d_end`` (:func:`ray_extents`), and per ray the squared
    range limits of the regions: a traced cell whose centre lies at squared range
    ``r2 <= free2`` is free, else occupied if ``r2 < occ2``, else nothing."""

    x: float
    y: float
    start: IntArray
    end: IntArray
    free2: FloatArray
    occ2: FloatArray


def scan_rays(
    pose: FloatArray, readings: FloatArray, beams: FloatArray, model: ResolvedModel, res: float
) -> ScanRays:
    """The :class:`ScanRays` of one scan ``readings (B,)`` from sensor ``pose (3,)`` at
    ``beams (B,)``, on a lattice of ``res`` metres (checked inputs)."""
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    ang = th + beams
    d_end, free2, occ2 = ray_region_limits(readings, model)
    start = np.floor(np.array([y, x]) / res).astype(np.int64)
    end = np.empty((readings.size, 2), dtype=np.int64)
    end[:, 0] = np.floor((y + d_end * np.sin(ang)) / res)
    end[:, 1] = np.floor((x + d_end * np.cos(ang)) / res)
    return ScanRays(x, y, start, end, free2, occ2)


def _range2(
    rows: NDArray[Any],
    cols: NDArray[Any],
    cy: FloatArray | float,
    cx: FloatArray | float,
    res: float,
) -> FloatArray:
    """Squared range from the sensor of the centres of cells ``(rows, cols)`` (relative to a
    grid origin, broadcast), given ``cx = (col0 + 1/2) res - x`` and ``cy`` likewise. Both
    Bresenham paths compute it in exactly this order, so they classify cells identically."""
    r2: FloatArray = np.multiply(cols, res, dtype=np.float64)
    r2 += cx
    np.multiply(r2, r2, out=r2)
    dy: FloatArray = np.multiply(rows, res, dtype=np.float64)
    dy += cy
    np.multiply(dy, dy, out=dy)
    r2 += dy
    return r2


def trace_rays(
    rays: ScanRays, res: float, row0: int, col0: int
) -> tuple[IntArray, IntArray, RegionArray, IntArray]:
    """Bresenham cells of every ray, in coordinates relative to lattice cell ``(row0, col0)``,
    with their regions (0 where the cell centre lies beyond the ray's reach) and the number
    of steps of each ray (ray ``r`` has ``n_steps[r] + 1`` cells, in order)."""
    origin = np.array([row0, col0], dtype=np.int64)
    start = rays.start - origin
    cells = bresenham_rays(np.broadcast_to(start, rays.end.shape), rays.end - origin)
    counts = cells.n_steps + 1
    r2 = _range2(
        cells.rows, cells.cols, (row0 + 0.5) * res - rays.y, (col0 + 0.5) * res - rays.x, res
    )
    occupied = r2 < np.repeat(rays.occ2, counts)
    regions = np.where(r2 <= np.repeat(rays.free2, counts), FREE, 2 * occupied).astype(np.int8)
    return cells.rows, cells.cols, regions, cells.n_steps


def scan_cells_ray(
    pose: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    model: ResolvedModel,
    resolution: float,
) -> tuple[IntArray, RegionArray, IntArray]:
    """Bresenham path for one scan from sensor ``pose (3,)``: lattice ``cells (N, 2)``, their
    ``regions (N,)`` and the ``beam (N,)`` each came from. Each reading traces the cells from
    the sensor's cell to the cell at ``min(r_k + alpha/2, r_max)`` in integer arithmetic;
    each traced cell gets the inverse model's region from its centre's range and the ray's
    own reading. A cell appears once per ray that crosses it (see
    :meth:`LogOddsGrid.merge_scan`)."""
    p = as_array(pose, "pose", (3,))
    readings = check_ranges(ranges)
    beams = np.asarray(beam_angles, dtype=np.float64)
    rays = scan_rays(p, readings, beams, model, resolution)
    rows, cols, regions, n_steps = trace_rays(rays, resolution, 0, 0)
    ray = np.repeat(np.arange(n_steps.size, dtype=np.int64), n_steps + 1)
    keep = regions != NO_INFORMATION
    return np.stack([rows[keep], cols[keep]], axis=1), regions[keep], ray[keep]


# --------------------------------------------------------------------------------------------
# the Bresenham path for many scans at once (the mapper's hot path)
# --------------------------------------------------------------------------------------------

BLOCK_SCANS = 32
"""Scans whose rays are planned at once (per-ray arrays: small)."""
TAIL_MARGIN = 2
"""Steps tested exactly at the end of each ray: ``ceil(alpha / res)`` + this."""
BLOCK_CELLS = 1 << 16
"""Cells generated at once (then applied scan by scan): temporaries of a few MB whatever the
ranges, which stay in the caches; at least one scan at a time."""


@dataclass(frozen=True, eq=False)
class ScanEnds:
    """Rays of a block of ``S`` scans of ``B`` readings: sensor positions ``x, y (S, 1)``, the
    sensor's lattice cell ``start_row, start_col (S, 1)`` and the rays' end cells
    ``end_row, end_col (S, B)`` (lattice indices held in floats), the squared region limits
    ``free2, occ2 (S, B)`` (:func:`ray_region_limits`) and each scan's box of lattice cells
    ``lo, hi (S, 2)`` — every cell of its rays lies inside it."""

    x: FloatArray
    y: FloatArray
    start_row: FloatArray
    start_col: FloatArray
    end_row: FloatArray
    end_col: FloatArray
    free2: FloatArray
    occ2: FloatArray
    lo: IntArray
    hi: IntArray

    def select(self, k0: int, k1: int) -> ScanEnds:
        """Scans ``k0 .. k1 - 1``."""
        return ScanEnds(*(getattr(self, f)[k0:k1] for f in self.__dataclass_fields__))


def scan_ends(
    poses: FloatArray, readings: FloatArray, beams: FloatArray, model: ResolvedModel, res: float
) -> ScanEnds:
    """:class:`ScanEnds` of scans ``readings (S, B)`` from ``poses (S, 3)``: the same numbers,
    computed in the same order, as :func:`scan_rays` computes for one scan."""
    x, y = poses[:, 0:1], poses[:, 1:2]
    ang = poses[:, 2:3] + beams
    d_end, free2, occ2 = ray_region_limits(readings, model)
    start_row, start_col = np.floor(y / res), np.floor(x / res)
    end_row = np.floor((y + d_end * np.sin(ang)) / res)
    end_col = np.floor((x + d_end * np.cos(ang)) / res)
    lo = np.stack(
        [
            np.minimum(start_row[:, 0], end_row.min(axis=1, initial=np.inf)),
            np.minimum(start_col[:, 0], end_col.min(axis=1, initial=np.inf)),
        ],
        axis=1,
    ).astype(np.int64)
    hi = np.stack(
        [
            np.maximum(start_row[:, 0], end_row.max(axis=1, initial=-np.inf)),
            np.maximum(start_col[:, 0], end_col.max(axis=1, initial=-np.inf)),
        ],
        axis=1,
    ).astype(np.int64)
    return ScanEnds(x, y, start_row, start_col, end_row, end_col, free2, occ2, lo, hi)


@dataclass(frozen=True, eq=False)
class ScanSegments:
    """What a block of scans writes, as runs of Bresenham steps (:func:`bresenham_segments`):
    per scan ``2B + 2`` segments — the sensor's cell if it is free, the free steps of each
    ray, the sensor's cell if it is occupied, the occupied steps of each ray — so that each
    scan's cells come out as its free cells followed by its occupied cells. ``n_free (S,)``
    and ``n_occupied (S,)`` count them (with repeats)."""

    lengths: IntArray
    first: FloatArray
    slope: FloatArray
    major: FloatArray
    minor: FloatArray
    base: FloatArray
    n_free: IntArray
    n_occupied: IntArray

    def flat_cells(self, k0: int = 0, k1: int | None = None) -> IntArray:
        """The cells of scans ``k0 .. k1 - 1``, scan after scan (each: free, then occupied)."""
        part = slice(k0, k1)
        return bresenham_segments(
            self.lengths[part].reshape(-1),
            self.first[part].reshape(-1),
            self.slope[part].reshape(-1),
            self.major[part].reshape(-1),
            self.minor[part].reshape(-1),
            np.broadcast_to(self.base[part], self.lengths[part].shape).reshape(-1),
        )


def scan_segments(
    ends: ScanEnds, model: ResolvedModel, res: float, row0: int, col0: int, n_cols: int
) -> ScanSegments | None:
    """The free and occupied runs of every ray of a block of scans on a grid whose array cell
    ``(0, 0)`` is lattice cell ``(row0, col0)`` and whose rows hold ``n_cols`` cells (every ray
    inside it). ``None`` if a ray is too long for :func:`bresenham_segments`.

    Along a Bresenham ray the squared range of the cell centres grows strictly from step 1
    on: with ``e`` the offset of the start cell's centre from the sensor (each coordinate
    within half a cell) and step ``i`` moving one cell along the major axis and
    ``δ ∈ {0, 1}`` along the minor one, ``|c_{i+1}|² - |c_i|² = 2 c_i · step + |step|²
    >= 2i + 2δ q_i >= 2i`` cells². So the free steps (``r2 <= free2``) are ``1 .. F``, the
    occupied ones (``free2 < r2 < occ2``) the next ``O``, and the rest get nothing; only the
    sensor's own cell (step 0) needs its own test. ``F`` and ``O`` come from the exact test of
    the last few steps of each ray (the rest of the ray is free if the first of those is,
    because the increments are far larger than any rounding), and from the exact test of
    every step for the rare ray whose tail is not long enough.
    """
    sr = ends.start_row - row0  # (S, 1); rays are traced in array cells, like trace_rays
    sc = ends.start_col - col0
    d_row = ends.end_row - row0 - sr
    d_col = ends.end_col - col0 - sc
    a_row, a_col = np.abs(d_row), np.abs(d_col)
    col_major = a_col >= a_row
    n = np.maximum(a_row, a_col)
    if n.size and float(n.max()) >= MAX_SEGMENT_STEPS:
        return None
    slope = np.minimum(a_row, a_col) / np.maximum(n, 1.0)
    s_row, s_col = np.sign(d_row), np.sign(d_col)
    major_row = np.where(col_major, 0.0, s_row)
    major_col = np.where(col_major, s_col, 0.0)
    minor_row, minor_col = s_row - major_row, s_col - major_col
    cy = (row0 + 0.5) * res - ends.y
    cx = (col0 + 0.5) * res - ends.x
    per_ray = {
        "sr": sr, "sc": sc, "cy": cy, "cx": cx, "slope": slope, "free2": ends.free2,
        "occ2": ends.occ2, "major_row": major_row, "major_col": major_col,
        "minor_row": minor_row, "minor_col": minor_col,
    }  # fmt: skip

    def regions(
        steps: FloatArray, ray: tuple[Any, ...]
    ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """Free and occupied masks of ``steps (K, ...)`` of the rays ``ray`` (an index into
        the ``(S, B)`` rays). The steps run along the first axis so that NumPy's inner loops
        run over the rays, not over a handful of steps."""
        v = {k: np.broadcast_to(a, n.shape)[ray] for k, a in per_ray.items()}
        q = minor_steps(steps, v["slope"])
        rows = steps * v["major_row"]
        rows += v["sr"]
        rows += q * v["minor_row"]
        cols = steps * v["major_col"]
        cols += v["sc"]
        cols += q * v["minor_col"]
        r2 = _range2(rows, cols, v["cy"], v["cx"], res)
        free = r2 <= v["free2"]
        return free, ~free & (r2 < v["occ2"])

    # the last K steps of every ray, n - K + 1 .. n (those >= 1)
    tail = max(1, math.ceil(model.alpha / res) + TAIL_MARGIN)
    steps = n - np.arange(tail, dtype=np.float64)[:, None, None]  # (K, S, B)
    free, occupied = regions(np.maximum(steps, 0.0), (slice(None), slice(None)))
    valid = steps >= 1.0
    t0 = np.maximum(n - (tail - 1), 1.0)
    n_free = t0 - 1.0 + np.count_nonzero(free & valid, axis=0)
    n_occ = np.count_nonzero(occupied & valid, axis=0).astype(np.float64)
    recount = (t0 > 1.0) & ~free[tail - 1]
    if np.any(recount):  # a tail that does not reach the free steps: test every step
        rays = np.flatnonzero(recount)
        length = n.reshape(-1)[rays].astype(np.int64)  # steps 1 .. n of each, n >= 2
        end = np.cumsum(length)
        k0 = 0
        while k0 < rays.size:  # chunks of at most BLOCK_CELLS steps (at least one ray)
            k1 = max(k0 + 1, int(np.searchsorted(end, end[k0] - length[k0] + BLOCK_CELLS, "right")))
            counts = length[k0:k1]
            offset = np.cumsum(counts) - counts
            ray = np.unravel_index(np.repeat(rays[k0:k1], counts), n.shape)
            step = np.arange(1.0, counts.sum() + 1.0) - np.repeat(offset, counts)
            free_all, occ_all = regions(step[None], ray)
            n_free[np.unravel_index(rays[k0:k1], n.shape)] = np.add.reduceat(free_all[0], offset)
            n_occ[np.unravel_index(rays[k0:k1], n.shape)] = np.add.reduceat(occ_all[0], offset)
            k0 = k1
    # step 0: the sensor's cell, the same for every ray of a scan; occupied wins
    r2_0 = _range2(sr, sc, cy, cx, res)
    sensor = np.where(r2_0 <= ends.free2, FREE, np.where(r2_0 < ends.occ2, OCCUPIED, 0))
    sensor = sensor.max(axis=1, initial=NO_INFORMATION)

    n_scans, n_beams = n.shape
    width = 2 * n_beams + 2
    lengths = np.zeros((n_scans, width), dtype=np.int64)
    lengths[:, 0] = sensor == FREE
    lengths[:, 1 : n_beams + 1] = n_free
    lengths[:, n_beams + 1] = sensor == OCCUPIED
    lengths[:, n_beams + 2 :] = n_occ
    first = np.zeros((n_scans, width))
    first[:, 1 : n_beams + 1] = 1.0
    first[:, n_beams + 2 :] = n_free + 1.0

    def per_segment(per_ray: FloatArray) -> FloatArray:
        out = np.zeros((n_scans, width))
        out[:, 1 : n_beams + 1] = per_ray
        out[:, n_beams + 2 :] = per_ray
        return out

    return ScanSegments(
        lengths=lengths,
        first=first,
        slope=per_segment(slope),
        major=per_segment(major_row * n_cols + major_col),
        minor=per_segment(minor_row * n_cols + minor_col),
        base=sr * n_cols + sc,
        n_free=lengths[:, : n_beams + 1].sum(axis=1),
        n_occupied=lengths[:, n_beams + 1 :].sum(axis=1),
    )
