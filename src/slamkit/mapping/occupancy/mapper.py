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
    from its second cell on (:func:`_scan_segments`), so each ray is free up to some step,
    occupied for a few steps, then silent, and only the sensor's cell and the last few cells
    of each ray need the region test; the cells themselves are then generated as flat grid
    indices for blocks of scans at once (:func:`~slamkit.mapping.bresenham.bresenham_segments`)
    and applied scan by scan (:meth:`LogOddsGrid.apply_free_occupied`). It gives the same
    cells, regions and log odds, bit for bit, as tracing every cell.

The two paths agree on which cells a scan makes free or occupied except where the per-cell
model's beam width fills the gaps between diverging rays (``tests/test_occupancy.py`` holds
them to ≥ 98 % of the touched cells on a simulated scan).

Computational options (the notes' list): beam subsampling (``beam_stride``), scan
subsampling (``scan_stride``), selective updating — at scan level (``min_travel``,
``min_rotation_deg``: a scan taken before the robot has moved that far brings no significant
new information and is skipped) and at cell level (``min_change``: a cell whose probability
would move by less than this, e.g. one clamped at "free" and seen free again, is not written)
— the pre-computed model above, and the grid size: ``bounds="data"`` sizes the grid once to
the box of all poses and all ray ends actually used (``+ margin``); ``bounds="grow"`` starts
from the first scan and grows (by at least ``margin``) whenever a scan reaches past the edge.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.config import config_to_dict
from slamkit.datasets.stream import Dataset, Event, LaserScan, LaserSpec, Odometry
from slamkit.errors import ConfigError, InputError, NonFiniteError, ShapeError
from slamkit.estimation.contract import EstimatorOutput, PoseEstimate
from slamkit.geometry.angles import wrap_angle
from slamkit.mapping.bresenham import (
    MAX_SEGMENT_STEPS,
    bresenham_rays,
    bresenham_segments,
    minor_steps,
)
from slamkit.mapping.grid import LogOddsGrid, lattice_cells
from slamkit.mapping.inverse_model import (
    FREE,
    NO_INFORMATION,
    OCCUPIED,
    InverseSensorModel,
    RegionArray,
    ResolvedModel,
    classify_cells,
    nearest_beam,
    ray_extents,
    ray_region_limits,
)
from slamkit.maps import OccupancyGrid

__all__ = [
    "MappingStats",
    "OccupancyMapResult",
    "OccupancyMapper",
    "OccupancyMapping",
    "OccupancyMappingConfig",
    "PolarTable",
    "build_occupancy_map",
    "check_ranges",
    "data_bounds",
    "known_pose_at",
    "laser_scans",
    "polar_table",
    "scan_bounds",
    "scan_cells_cell",
    "scan_cells_ray",
    "scan_cells_table",
    "scan_poses",
]

log = logging.getLogger(__name__)
log.addHandler(logging.NullHandler())

IntArray = NDArray[np.int64]
Progress = Callable[[int, int], None]
"""``progress(done, total)`` in scans; called at most about a hundred times per map (after
every ~1 % of the scans, or every block of scans traced at once if that is more)."""

_MAX_TABLE_CELLS = 8_000_000  # largest pre-computed model (cells around the sensor)
_POSE_TIME_TOL = 1e-9  # [s] a scan time within this of a true pose's time uses that pose


# --------------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OccupancyMappingConfig:
    """Settings of occupancy-grid mapping with known poses (module docstring). Metres,
    degrees where named."""

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
    """``data``: size the grid from all poses and ray ends first; ``grow``: grow as needed."""
    margin: float = 1.0
    """Free border around the data bounds, and the least a growing grid adds [m]."""
    pose_source: Literal["truth", "odometry"] = "truth"
    """Where the known poses come from: the data set's true trajectory (interpolated at the
    scan times) or its odometry readings (a map that shows the odometry's drift)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise ConfigError(f"resolution: expected a number > 0, got {self.resolution!r}")
        for name in ("beam_stride", "scan_stride"):
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


# --------------------------------------------------------------------------------------------
# input: range readings
# --------------------------------------------------------------------------------------------


def check_ranges(
    ranges: ArrayLike, *, first_scan: int = 0, times: ArrayLike | None = None
) -> FloatArray:
    """``ranges (B,)`` (one scan) or ``(S, B)`` as float64, every reading a finite number
    ``>= 0`` [m]; a reading ``>= max range`` is the "no return" mark. A NaN or infinite
    reading raises :class:`~slamkit.errors.NonFiniteError`, a negative one
    :class:`~slamkit.errors.InputError`, naming the scan (``first_scan`` + its row, and its
    time if ``times (S,)`` is given), the beam and the value. Two reductions over the array
    when all is well (NaN propagates through ``min``); the culprit is searched only on
    failure."""
    R = np.asarray(ranges, dtype=np.float64)
    if R.ndim not in (1, 2):
        raise ShapeError(f"ranges: expected (B,) or (S, B), got shape {R.shape}")
    if R.size == 0:
        return R
    low, high = float(R.min()), float(R.max())
    if low >= 0.0 and high < math.inf:
        return R
    rows = R.reshape(-1, R.shape[-1])
    non_finite = ~np.isfinite(rows)
    bad = non_finite | (rows < 0.0)
    k, j = divmod(int(np.argmax(bad)), rows.shape[1])
    where = f"scan {first_scan + k}"
    if times is not None:
        where += f" (t={float(np.asarray(times, dtype=np.float64).reshape(-1)[k]):.6f} s)"
    message = (
        f"{where}, beam {j}: expected a finite range >= 0 m (a reading at the max range "
        f"means no return), got {float(rows[k, j])}"
    )
    raise (NonFiniteError if non_finite[k, j] else InputError)(message)


# --------------------------------------------------------------------------------------------
# one scan → cells and regions (array in, array out)
# --------------------------------------------------------------------------------------------


def _unit(angles: FloatArray) -> tuple[FloatArray, FloatArray]:
    return np.cos(angles), np.sin(angles)


@dataclass(frozen=True, eq=False)
class _ScanRays:
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


def _scan_rays(
    pose: FloatArray, readings: FloatArray, beams: FloatArray, model: ResolvedModel, res: float
) -> _ScanRays:
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    ang = th + beams
    d_end, free2, occ2 = ray_region_limits(readings, model)
    start = np.floor(np.array([y, x]) / res).astype(np.int64)
    end = np.empty((readings.size, 2), dtype=np.int64)
    end[:, 0] = np.floor((y + d_end * np.sin(ang)) / res)
    end[:, 1] = np.floor((x + d_end * np.cos(ang)) / res)
    return _ScanRays(x, y, start, end, free2, occ2)


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


def _trace(
    rays: _ScanRays, res: float, row0: int, col0: int
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
    rays = _scan_rays(p, readings, beams, model, resolution)
    rows, cols, regions, n_steps = _trace(rays, resolution, 0, 0)
    ray = np.repeat(np.arange(n_steps.size, dtype=np.int64), n_steps + 1)
    keep = regions != NO_INFORMATION
    return np.stack([rows[keep], cols[keep]], axis=1), regions[keep], ray[keep]


# --------------------------------------------------------------------------------------------
# the Bresenham path for many scans at once (the mapper's hot path)
# --------------------------------------------------------------------------------------------

_BLOCK_SCANS = 32  # scans whose rays are planned at once (per-ray arrays: small)
_TAIL_MARGIN = 2  # steps tested exactly at the end of each ray: ceil(alpha / res) + this
_BLOCK_CELLS = 1 << 16  # cells generated at once (then applied scan by scan): temporaries of
# a few MB whatever the ranges, which stay in the caches; at least one scan at a time


@dataclass(frozen=True, eq=False)
class _ScanEnds:
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

    def select(self, k0: int, k1: int) -> _ScanEnds:
        """Scans ``k0 .. k1 - 1``."""
        return _ScanEnds(*(getattr(self, f)[k0:k1] for f in self.__dataclass_fields__))


def _scan_ends(
    poses: FloatArray, readings: FloatArray, beams: FloatArray, model: ResolvedModel, res: float
) -> _ScanEnds:
    """:class:`_ScanEnds` of scans ``readings (S, B)`` from ``poses (S, 3)``: the same numbers,
    computed in the same order, as :func:`_scan_rays` computes for one scan."""
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
    return _ScanEnds(x, y, start_row, start_col, end_row, end_col, free2, occ2, lo, hi)


@dataclass(frozen=True, eq=False)
class _ScanSegments:
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


def _scan_segments(
    ends: _ScanEnds, model: ResolvedModel, res: float, row0: int, col0: int, n_cols: int
) -> _ScanSegments | None:
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
    sr = ends.start_row - row0  # (S, 1); rays are traced in array cells, like _trace
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
    tail = max(1, math.ceil(model.alpha / res) + _TAIL_MARGIN)
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
        while k0 < rays.size:  # chunks of at most _BLOCK_CELLS steps (at least one ray)
            k1 = max(
                k0 + 1, int(np.searchsorted(end, end[k0] - length[k0] + _BLOCK_CELLS, "right"))
            )
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

    return _ScanSegments(
        lengths=lengths,
        first=first,
        slope=per_segment(slope),
        major=per_segment(major_row * n_cols + major_col),
        minor=per_segment(minor_row * n_cols + minor_col),
        base=sr * n_cols + sc,
        n_free=lengths[:, : n_beams + 1].sum(axis=1),
        n_occupied=lengths[:, n_beams + 1 :].sum(axis=1),
    )


def _window_points(
    pose: FloatArray, beam_angles: FloatArray, d_end: FloatArray, beta: float
) -> FloatArray:
    """Sensor position and the ends of every beam and of its ±beta/2 edges ``(3B + 1, 2)``."""
    x, y, th = pose
    ang = th + np.concatenate([beam_angles - beta / 2, beam_angles, beam_angles + beta / 2])
    d = np.tile(d_end, 3)
    c, s = _unit(ang)
    return np.concatenate([[[x, y]], np.stack([x + d * c, y + d * s], axis=-1)])


def scan_cells_cell(
    pose: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    model: ResolvedModel,
    resolution: float,
) -> tuple[IntArray, RegionArray]:
    """Per-cell path: the lattice ``cells (N, 2)`` the scan says something about and their
    ``regions (N,)``, each cell once. Every cell of the window (the box around the sensor
    and the ends of all beams and beam edges, plus one cell) is classified by
    :func:`~slamkit.mapping.inverse_model.classify_cells` from its centre's range and
    bearing."""
    p = np.asarray(pose, dtype=np.float64)
    beams = np.asarray(beam_angles, dtype=np.float64)
    readings = check_ranges(ranges)
    _, d_end = ray_extents(readings, model)
    pts = _window_points(p, beams, d_end, min(model.beta, math.pi))
    lo = lattice_cells(pts.min(axis=0), resolution) - 1
    hi = lattice_cells(pts.max(axis=0), resolution) + 1
    rows = np.arange(lo[0], hi[0] + 1)
    cols = np.arange(lo[1], hi[1] + 1)
    dx = (cols + 0.5) * resolution - p[0]
    dy = (rows + 0.5) * resolution - p[1]
    r = np.hypot(dx[None, :], dy[:, None])
    phi = wrap_angle(np.arctan2(dy[:, None], dx[None, :]) - p[2])
    regions = classify_cells(r, phi, readings, beams, model)
    ir, ic = np.nonzero(regions)
    return np.stack([rows[ir], cols[ic]], axis=1), regions[ir, ic]


_TABLE_BINS = 4096  # bearing bins of the pre-computed model (0.088° each)


@dataclass(frozen=True, eq=False)
class PolarTable:
    """The pre-computed inverse-model geometry around a sensor sitting at a cell centre:
    every lattice offset ``(drow, dcol)`` within ``radius``, with the range ``r`` [m] and
    world bearing ``psi`` [rad] of that cell's centre. The offsets are grouped into
    ``n_bins`` equal bins of world bearing (``bin_start`` indexes each bin's first offset) and
    sorted by range within a bin, so a scan reads, bin by bin, only the offsets within reach
    of the beams that bin's bearings belong to. Independent of the heading (a scan's
    bearings are ``psi - theta``), so one table serves every scan."""

    resolution: float
    radius: float
    n_bins: int
    offsets: NDArray[np.int32]
    r: FloatArray
    psi: FloatArray
    bin_start: IntArray
    keys: FloatArray
    """``bin * key_scale + r``: increasing, so one ``searchsorted`` finds every bin's prefix."""
    key_scale: float

    def __len__(self) -> int:
        return int(self.r.size)

    @property
    def nbytes(self) -> int:
        arrays = (self.offsets, self.r, self.psi, self.bin_start, self.keys)
        return int(sum(a.nbytes for a in arrays))


@functools.lru_cache(maxsize=4)
def polar_table(resolution: float, radius: float, n_bins: int = _TABLE_BINS) -> PolarTable:
    """The :class:`PolarTable` for ``resolution`` and ``radius``, built once and cached."""
    n = math.ceil(radius / resolution) + 1
    if (2 * n + 1) ** 2 > _MAX_TABLE_CELLS * 4 / math.pi:
        raise ConfigError(
            f"pre-computed model: {radius:.1f} m at {resolution} m would hold "
            f"~{math.pi * n * n:.2e} cells; lower model.max_range or use precompute=false"
        )
    k = np.arange(-n, n + 1)
    drow, dcol = np.meshgrid(k, k, indexing="ij")
    r_all = np.hypot(drow, dcol) * resolution
    keep = r_all <= radius + resolution
    r = r_all[keep]
    psi = np.arctan2(drow[keep], dcol[keep]).astype(np.float64)
    width = 2.0 * math.pi / n_bins
    bins = np.minimum(((psi + math.pi) / width).astype(np.int64), n_bins - 1)
    order = np.lexsort((r, bins))
    scale = 2.0 * (radius + resolution) + 1.0
    offsets = np.stack([drow[keep], dcol[keep]], axis=1)[order].astype(np.int32)
    bin_start = np.searchsorted(bins[order], np.arange(n_bins + 1)).astype(np.int64)
    keys = bins[order] * scale + r[order]
    return PolarTable(
        resolution, radius, n_bins, offsets, r[order], psi[order], bin_start, keys, scale
    )


def scan_cells_table(
    table: PolarTable,
    pose: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    model: ResolvedModel,
) -> tuple[IntArray, RegionArray]:
    """Per-cell path with the pre-computed model: like :func:`scan_cells_cell` with the
    sensor snapped to the centre of its cell. For each bearing bin, the beams nearest to its
    two edges bound which beams its cells can belong to (a bin is narrower than half the beam
    spacing of any laser here); only the bin's offsets within the longer of those beams'
    reach are classified."""
    p = np.asarray(pose, dtype=np.float64)
    beams = np.asarray(beam_angles, dtype=np.float64)
    readings = check_ranges(ranges)
    _, d_end = ray_extents(readings, model)
    width = 2.0 * math.pi / table.n_bins
    edges = -math.pi + width * np.arange(table.n_bins + 1) - p[2]
    k_edge, d_edge = nearest_beam(wrap_angle(edges), beams)
    ok = d_edge <= 0.5 * model.beta + width
    reach = np.where(ok, d_end[k_edge], -1.0)
    limit = np.maximum(reach[:-1], reach[1:])  # per bin: its edges' beams
    stops = np.searchsorted(
        table.keys, np.arange(table.n_bins) * table.key_scale + limit, side="right"
    )
    starts = table.bin_start[:-1]
    counts = np.maximum(stops - starts, 0)
    first = np.cumsum(counts) - counts
    idx = np.repeat(starts - first, counts) + np.arange(int(counts.sum()))
    phi = wrap_angle(table.psi[idx] - p[2])
    regions = classify_cells(table.r[idx], phi, readings, beams, model)
    keep = regions != NO_INFORMATION
    centre = lattice_cells(p[:2], table.resolution)
    return table.offsets[idx[keep]].astype(np.int64) + centre, regions[keep]


def scan_bounds(
    poses: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    model: ResolvedModel,
) -> tuple[float, float, float, float]:
    """``(xmin, ymin, xmax, ymax)`` of every sensor position and every ray end actually used
    (``min(r_k + alpha/2, r_max)``) over scans ``ranges (S, B)`` from ``poses (S, 3)``, widened
    by the beam width's spread at the longest ray. Works through the scans in blocks, so
    memory stays small for long logs."""
    P = as_array(poses, "poses", (None, 3))
    R = as_array(ranges, "ranges", (P.shape[0], None), finite=False)
    check_ranges(R)
    beams = np.asarray(beam_angles, dtype=np.float64)
    lo = np.full(2, np.inf)
    hi = np.full(2, -np.inf)
    longest = 0.0
    for s0 in range(0, P.shape[0], 512):
        p = P[s0 : s0 + 512]
        _, d_end = ray_extents(R[s0 : s0 + 512], model)
        longest = max(longest, float(d_end.max(initial=0.0)))
        ang = p[:, 2:3] + beams[None, :]
        ex = p[:, 0:1] + d_end * np.cos(ang)
        ey = p[:, 1:2] + d_end * np.sin(ang)
        lo = np.minimum(lo, [min(ex.min(), p[:, 0].min()), min(ey.min(), p[:, 1].min())])
        hi = np.maximum(hi, [max(ex.max(), p[:, 0].max()), max(ey.max(), p[:, 1].max())])
    spread = longest * math.sin(min(model.beta, math.pi) / 2.0)
    return (
        float(lo[0] - spread),
        float(lo[1] - spread),
        float(hi[0] + spread),
        float(hi[1] + spread),
    )


# --------------------------------------------------------------------------------------------
# known poses
# --------------------------------------------------------------------------------------------


def known_pose_at(times: ArrayLike, poses: ArrayLike, t: ArrayLike) -> FloatArray:
    """Poses ``(..., 3)`` at times ``t`` from a trajectory ``times (N,)``, ``poses (N, 3)``:
    the recorded pose where a time matches (to 1 ns), else linear interpolation of the
    position and of the wrapped heading difference between the two neighbours. A time
    outside the trajectory raises :class:`InputError`."""
    T = as_array(times, "trajectory times", (None,))
    P = as_array(poses, "trajectory poses", (T.size, 3))
    q = np.asarray(t, dtype=np.float64)
    if T.size == 0:
        raise InputError("known poses: the trajectory is empty")
    if np.any(q < T[0] - _POSE_TIME_TOL) or np.any(q > T[-1] + _POSE_TIME_TOL):
        raise InputError(
            f"known poses: times {float(q.min()):.6g}..{float(q.max()):.6g} s reach outside "
            f"the trajectory's {T[0]:.6g}..{T[-1]:.6g} s"
        )
    hi = np.clip(np.searchsorted(T, q, side="left"), 0, T.size - 1)
    lo = np.clip(hi - 1, 0, T.size - 1)
    exact_hi = np.abs(T[hi] - q) <= _POSE_TIME_TOL
    span = T[hi] - T[lo]
    w = np.where(span > 0, (q - T[lo]) / np.where(span > 0, span, 1.0), 1.0)
    w = np.where(exact_hi, 1.0, np.clip(w, 0.0, 1.0))
    xy = P[lo, :2] + w[..., None] * (P[hi, :2] - P[lo, :2])
    th = wrap_angle(P[lo, 2] + w * wrap_angle(P[hi, 2] - P[lo, 2]))
    return np.concatenate([xy, th[..., None]], axis=-1)


def laser_scans(dataset: Dataset) -> tuple[FloatArray, FloatArray]:
    """Scan times ``(S,)`` and ranges ``(S, B)`` of a data set."""
    scans = [ev for ev in dataset.events if isinstance(ev, LaserScan)]
    if not scans:
        raise InputError(f"data set {dataset.name!r} has no laser scans")
    times = np.array([ev.t for ev in scans], dtype=np.float64)
    return times, np.stack([ev.ranges for ev in scans])


def _odometry_at(dataset: Dataset, times: FloatArray) -> FloatArray:
    """The latest odometry pose at or before each scan time."""
    odo = [ev for ev in dataset.events if isinstance(ev, Odometry)]
    if not odo:
        raise InputError(f"pose_source 'odometry': data set {dataset.name!r} has no odometry")
    t_odo = np.array([ev.t for ev in odo])
    idx = np.searchsorted(t_odo, times, side="right") - 1
    if np.any(idx < 0):
        raise InputError("pose_source 'odometry': a scan comes before the first odometry reading")
    return np.stack([odo[i].pose for i in idx])


def scan_poses(dataset: Dataset, times: FloatArray, source: str) -> FloatArray:
    """Known sensor poses ``(S, 3)`` at the scan ``times``: the true trajectory (mapping with
    known poses) or the odometry (see :class:`OccupancyMappingConfig.pose_source`)."""
    if source == "odometry":
        return _odometry_at(dataset, times)
    truth = dataset.truth
    if truth.times is None or truth.poses is None:
        raise InputError(
            f"occupancy mapping with known poses needs the true trajectory, which data set "
            f"{dataset.name!r} does not have (use pose_source='odometry')"
        )
    return known_pose_at(truth.times, truth.poses, times)


def data_bounds(
    dataset: Dataset, config: OccupancyMappingConfig
) -> tuple[float, float, float, float]:
    """:func:`scan_bounds` of the scans ``config`` would use from ``dataset`` (scan and beam
    strides applied), at the poses of ``config.pose_source``."""
    if dataset.laser is None:
        raise InputError(f"occupancy mapping needs laser scans; {dataset.name!r} has none")
    times, ranges = laser_scans(dataset)
    used = slice(None, None, config.scan_stride)
    poses = scan_poses(dataset, times[used], config.pose_source)
    beams = dataset.laser.beam_angles[:: config.beam_stride]
    model = config.model.resolve(config.resolution, beams, dataset.laser.max_range)
    return scan_bounds(poses, ranges[used, :: config.beam_stride], beams, model)


# --------------------------------------------------------------------------------------------
# the mapper: grid + model + statistics
# --------------------------------------------------------------------------------------------


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
                xmin - m, ymin - m, xmax + m, ymax + m, config.resolution, self.model.l0
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
        rays = _scan_rays(pose, readings, self.beam_angles, self.model, res)
        # A Bresenham line stays inside the box of its end cells: check the box, not cells.
        lo = np.minimum(rays.start, rays.end.min(axis=0))
        hi = np.maximum(rays.start, rays.end.max(axis=0))
        grid = self._ensure(lo, hi)
        rows, cols, regions, _ = _trace(rays, res, grid.row0, grid.col0)
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
        scans in blocks of :data:`_BLOCK_SCANS`; the cells of a block's scans are traced in
        one pass (:func:`_scan_segments`), then applied scan by scan
        (:meth:`LogOddsGrid.apply_free_occupied`). A scan that reaches past the grid first
        grows it (and the rest of the block is planned again on the new grid), or, with
        fixed bounds, takes the per-scan path that cuts its rays at the edge."""
        res = self.config.resolution
        total = 0
        k = 0
        while k < poses.shape[0]:
            stop = min(poses.shape[0], k + _BLOCK_SCANS)
            ends = _scan_ends(poses[k:stop], readings[k:stop], self.beam_angles, self.model, res)
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
        self, poses: FloatArray, readings: FloatArray, ends: _ScanEnds, grid: LogOddsGrid
    ) -> int:
        """Trace and apply scans (with their :class:`_ScanEnds`) whose rays all lie inside
        ``grid``."""
        cols = grid.shape[1]
        seg = _scan_segments(ends, self.model, self.config.resolution, grid.row0, grid.col0, cols)
        if seg is None:  # rays too long for the segment form: the general path, scan by scan
            return sum(self._integrate_one(p, r) for p, r in zip(poses, readings, strict=True))
        counts = (seg.n_free + seg.n_occupied).tolist()
        n_free = seg.n_free.tolist()
        n = 0
        k0 = 0
        while k0 < len(counts):  # generate up to _BLOCK_CELLS cells (at least a scan) at once
            k1, cells = k0 + 1, counts[k0]
            while k1 < len(counts) and cells + counts[k1] <= _BLOCK_CELLS:
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


# --------------------------------------------------------------------------------------------
# whole data set
# --------------------------------------------------------------------------------------------


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
    """Map ``dataset``'s laser scans from known poses (module docstring).

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
    every = max(_BLOCK_SCANS, -(-total // 100))
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


# --------------------------------------------------------------------------------------------
# the estimator
# --------------------------------------------------------------------------------------------


class OccupancyMapping:
    """Occupancy-grid mapping **with known poses**, as a pipeline estimator.

    This estimator deliberately reads the data set's *true trajectory*
    (``dataset.truth.times/poses``) in its constructor — mapping with known poses is defined
    as being given the poses — and uses the pose at each scan's time stamp to integrate the
    scan (interpolated between true poses if a scan falls between them). Its
    :meth:`estimate` therefore reports the known pose (its trajectory error is zero by
    construction); its product is the map, returned by :meth:`finish` as
    ``EstimatorOutput(grid=...)``. With ``pose_source="odometry"`` it uses the odometry
    readings instead and reports those (a map that shows the odometry's drift).
    """

    def __init__(
        self, dataset: Dataset, config: OccupancyMappingConfig, rng: np.random.Generator
    ) -> None:
        if dataset.laser is None:
            raise InputError(f"occupancy mapping needs laser scans; {dataset.name!r} has none")
        self._config = config
        self._source = config.pose_source
        truth = dataset.truth
        self._times: FloatArray | None = None
        self._poses: FloatArray | None = None
        if self._source == "truth":
            if truth.times is None or truth.poses is None or truth.times.size == 0:
                raise InputError(
                    f"occupancy mapping with known poses needs the true trajectory, which "
                    f"data set {dataset.name!r} does not have (use pose_source='odometry')"
                )
            self._times = truth.times.copy()
            self._poses = truth.poses.copy()
        bounds = data_bounds(dataset, config) if config.bounds == "data" else None
        self._mapper = OccupancyMapper(dataset.laser, config, bounds)
        self._t = dataset.start_time
        start = dataset.initial_pose if dataset.initial_pose is not None else np.zeros(3)
        self._odometry: FloatArray = np.asarray(start, dtype=np.float64)

    def _pose(self, t: float) -> FloatArray:
        if self._times is not None and self._poses is not None:
            t_clamped = min(max(t, float(self._times[0])), float(self._times[-1]))
            return known_pose_at(self._times, self._poses, t_clamped)
        return self._odometry

    def handle(self, event: Event) -> None:
        self._t = event.t
        if isinstance(event, Odometry):
            self._odometry = np.asarray(event.pose, dtype=np.float64)
        elif isinstance(event, LaserScan):
            if self._times is not None and self._poses is not None:
                pose = known_pose_at(self._times, self._poses, event.t)
            else:
                pose = self._odometry
            self._mapper.offer(pose, event.ranges)

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(self._pose(self._t))

    def finish(self) -> EstimatorOutput:
        grid = self._mapper.occupancy_grid()
        stats = self._mapper.stats.as_dict()
        stats["pose_source"] = self._source
        stats["grid_shape"] = list(grid.shape)
        return EstimatorOutput(grid=grid, diagnostics={"mapping": stats})
