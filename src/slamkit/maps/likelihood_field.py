"""The likelihood-field laser model (Probabilistic Robotics, section 6.4).

Instead of casting a ray per beam and particle, the model projects each beam's end point into
the map and scores it by the distance ``d`` to the nearest obstacle:

    p(z_k | x, m) = z_hit · N(d; 0, sigma_hit²) + z_rand / max_range

Readings at (or beyond) ``max_range`` carry no information and are left out, which is the
usual choice for this model (a "max range" reading says little about where the wall is).
End points that fall outside the map, or into cells whose occupancy is unknown, get the
largest distance found in the map, so they score about ``z_rand / max_range``.

The distance map is computed once per map by a Euclidean distance transform
(:func:`scipy.ndimage.distance_transform_edt`) and turned into a table of ``log p`` per cell,
with a one-cell border holding the "outside" value. Scoring ``P`` particles against ``B``
beams is then an affine map of the beam end points (one small matrix product per block of
particles), a conversion to integer cell indices, and one gather from that table: no
trigonometry and no ``exp`` or ``log`` per particle and beam.
"""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import field as dataclass_field

import numpy as np
from numpy.typing import ArrayLike
from scipy.ndimage import distance_transform_edt

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.errors import InputError
from slamkit.maps import FREE_THRESHOLD, OCCUPIED_THRESHOLD, OccupancyGrid

__all__ = [
    "LikelihoodField",
    "beam_log_likelihood",
    "interpolate_distance",
    "log_likelihood",
    "usable_beams",
]

# Particles are scored in blocks so that the (block, B) temporaries stay in cache: 2^15
# elements is 256 kB per float64 buffer. Measured for 10⁵ particles × 180 beams on the 2-core
# development machine: 2^12 → 100 ms, 2^13 → 72, 2^14 → 60, 2^15 → 55, 2^16 → 54, 2^17 → 54
# (but 2^17 was 1.3× slower than 2^15 for 2·10⁴ × 45).
_BLOCK_ELEMENTS = 1 << 15


@dataclass(frozen=True, eq=False)
class LikelihoodField:
    """A map prepared for the likelihood-field model.

    ``distances (rows, cols)`` holds, per cell of ``grid``, the distance in metres from the
    cell's centre to the centre of the nearest occupied cell (cells of unknown occupancy and,
    implicitly, everything outside the grid hold the largest distance in the map). Build one
    with :meth:`from_grid`. Parameters:

    * ``sigma_hit`` (m, > 0): standard deviation of the end-point distance of a true hit;
      it should cover the range noise *and* the map's discretisation.
    * ``z_hit``, ``z_rand`` (>= 0, not both 0): mixture weights of a hit and of a random
      reading uniform on ``[0, max_range)``.
    * ``max_range`` (m, > 0): readings ``>= max_range`` mean no return and are ignored.

    The arrays are treated as read-only; fields compare by identity (``eq=False``).
    """

    grid: OccupancyGrid
    distances: FloatArray
    sigma_hit: float
    z_hit: float = 0.95
    z_rand: float = 0.05
    max_range: float = 30.0
    _table: FloatArray = dataclass_field(init=False, repr=False)
    """``log p`` per cell on the grid padded by one cell of "outside" value, flattened."""

    def __post_init__(self) -> None:
        if not isinstance(self.grid, OccupancyGrid):
            raise InputError(f"grid: expected an OccupancyGrid, got {type(self.grid).__name__}")
        dist = as_array(self.distances, "distances", self.grid.shape)
        if np.any(dist < 0):
            raise InputError("distances: expected values >= 0")
        sigma = as_positive(self.sigma_hit, "sigma_hit")
        z_hit = as_positive(self.z_hit, "z_hit", allow_zero=True)
        z_rand = as_positive(self.z_rand, "z_rand", allow_zero=True)
        if not z_hit + z_rand > 0:
            raise InputError("z_hit and z_rand: expected at least one of them > 0")
        max_range = as_positive(self.max_range, "max_range")
        object.__setattr__(self, "distances", dist)
        object.__setattr__(self, "sigma_hit", sigma)
        object.__setattr__(self, "z_hit", z_hit)
        object.__setattr__(self, "z_rand", z_rand)
        object.__setattr__(self, "max_range", max_range)
        rows, cols = self.grid.shape
        padded = np.full((rows + 2, cols + 2), self.log_p(self.outside_distance))
        padded[1:-1, 1:-1] = self.log_p(dist)
        padded.flags.writeable = False
        object.__setattr__(self, "_table", padded.ravel())

    @classmethod
    def from_grid(
        cls,
        grid: OccupancyGrid,
        sigma_hit: float,
        z_hit: float = 0.95,
        z_rand: float = 0.05,
        max_range: float = 30.0,
        *,
        occupied_threshold: float = OCCUPIED_THRESHOLD,
        free_threshold: float = FREE_THRESHOLD,
    ) -> LikelihoodField:
        """Compute the distance map of ``grid`` and build the field.

        Cells with probability ``>= occupied_threshold`` are obstacles; cells above
        ``free_threshold`` that are not obstacles are unknown and get the largest distance.
        A map without any obstacle gives every cell the diagonal of the map as distance.
        """
        if not isinstance(grid, OccupancyGrid):
            raise InputError(f"grid: expected an OccupancyGrid, got {type(grid).__name__}")
        occupied = grid.occupied(occupied_threshold)
        if occupied.any():
            # EDT measures, for every non-zero cell, the distance to the nearest zero cell.
            dist = distance_transform_edt(~occupied, sampling=grid.resolution)
        else:
            rows, cols = grid.shape
            dist = np.full(grid.shape, np.hypot(rows, cols) * grid.resolution)
        dist = np.asarray(dist, dtype=np.float64)
        unknown = ~occupied & ~grid.free(free_threshold)
        if unknown.any():
            dist = np.where(unknown, dist.max(), dist)
        return cls(grid, dist, sigma_hit, z_hit, z_rand, max_range)

    @property
    def outside_distance(self) -> float:
        """The distance (m) given to end points outside the grid: the largest in the map."""
        return float(self.distances.max())

    def log_p(self, d: ArrayLike) -> FloatArray:
        """``log(z_hit N(d; 0, sigma_hit²) + z_rand / max_range)`` of distances ``d``, computed
        with ``logaddexp`` so that neither term underflows."""
        dd = np.asarray(d, dtype=np.float64)
        s = self.sigma_hit
        with np.errstate(divide="ignore"):  # log(0) = -inf for a zero mixture weight
            log_hit = np.log(self.z_hit) - 0.5 * (dd / s) ** 2 - np.log(s * np.sqrt(2 * np.pi))
            log_rand = np.log(self.z_rand / self.max_range)
        out: FloatArray = np.logaddexp(log_hit, log_rand)
        return out


def _as_field(field_: LikelihoodField) -> LikelihoodField:
    if not isinstance(field_, LikelihoodField):
        raise InputError(f"field: expected a LikelihoodField, got {type(field_).__name__}")
    return field_


def _select_beams(
    field_: LikelihoodField, ranges: ArrayLike, beam_angles: ArrayLike, beam_stride: int
) -> tuple[FloatArray, FloatArray]:
    """The ranges and angles of every ``beam_stride``-th beam that has a return."""
    r = as_array(ranges, "ranges", (None,))
    a = as_array(beam_angles, "beam_angles", (r.size,))
    stride = int(beam_stride)
    if stride != beam_stride or stride < 1:
        raise InputError(f"beam_stride: expected an integer >= 1, got {beam_stride!r}")
    if np.any(r < 0):
        raise InputError(f"ranges: expected values >= 0, got minimum {float(r.min())}")
    r, a = r[::stride], a[::stride]
    keep = r < field_.max_range
    return r[keep], a[keep]


def usable_beams(
    field: LikelihoodField, ranges: ArrayLike, beam_angles: ArrayLike, beam_stride: int = 1
) -> int:
    """How many beams :func:`log_likelihood` scores: every ``beam_stride``-th beam whose
    range is below ``max_range``."""
    r, _ = _select_beams(_as_field(field), ranges, beam_angles, beam_stride)
    return int(r.size)


def _sensor_poses(poses: FloatArray, sensor_offset: ArrayLike | None) -> tuple[FloatArray, float]:
    """Sensor positions ``(P, 2)``, headings ``(P,)`` come back separately with the yaw
    offset (rad) to add to every beam."""
    if sensor_offset is None:
        return poses, 0.0
    off = as_array(sensor_offset, "sensor_offset", (3,))
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    out = poses.copy()
    # x_sensor = x_robot ⊕ offset: the offset (forward, left) rotated by the robot heading.
    out[:, 0] = poses[:, 0] + c * off[0] - s * off[1]
    out[:, 1] = poses[:, 1] + s * off[0] + c * off[1]
    return out, float(off[2])


def log_likelihood(
    field: LikelihoodField,
    poses: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    sensor_offset: ArrayLike | None = None,
    beam_stride: int = 1,
) -> FloatArray:
    """``log p(z | x_i, m)`` ``(P,)`` of one scan for every pose ``x_i`` in ``poses (P, 3)``.

    The scan is ``ranges (B,)`` at ``beam_angles (B,)`` (radians from the sensor heading,
    counter-clockwise). ``sensor_offset = (forward, left, yaw)`` is the sensor's pose in the
    robot frame (``None``: the sensor sits at the robot's origin). Every ``beam_stride``-th
    beam is used; readings ``>= field.max_range`` are skipped. Beams are treated as
    independent, so the result is the sum of the per-beam ``log p``.

    Vectorised over particles × beams: for a block of particles the end points in cell units
    are ``g = A_p V``, with ``A_p = [cos θ, -sin θ, (x - x0)/res + 1]`` (one row per particle
    and axis) and ``V = [r cos α, r sin α, res]ᵀ / res`` (one column per beam); the cell is
    ``floor(g)`` and its ``log p`` is read from the padded table by one flat index.
    """
    f = _as_field(field)
    p = as_array(poses, "poses", (None, 3))
    r, a = _select_beams(f, ranges, beam_angles, beam_stride)
    n = p.shape[0]
    out = np.zeros(n)
    if n == 0 or r.size == 0:
        return out
    sensor, yaw = _sensor_poses(p, sensor_offset)
    grid = f.grid
    rows, cols = grid.shape
    width = cols + 2  # of the padded table
    res = grid.resolution
    reach = f.max_range / res + 2.0  # cells; an end point is never farther from its sensor

    # Beam end points in the sensor frame, in cells: V (3, B). The third row carries the
    # particle's own offset through the matrix product.
    b = r.size
    V = np.empty((3, b))
    V[0] = r * np.cos(a + yaw) / res
    V[1] = r * np.sin(a + yaw) / res
    V[2] = 1.0
    # Per particle: cell coordinates of the sensor, +1 for the padding border. A sensor far
    # outside the map is pulled to `reach` cells outside it: all its end points stay outside
    # either way, and the indices stay small integers.
    c, s = np.cos(sensor[:, 2]), np.sin(sensor[:, 2])
    gx0 = np.clip((sensor[:, 0] - grid.origin_xy[0]) / res + 1.0, -reach, cols + 2 + reach)
    gy0 = np.clip((sensor[:, 1] - grid.origin_xy[1]) / res + 1.0, -reach, rows + 2 + reach)
    Ax = np.column_stack([c, -s, gx0])  # gx = cos θ vx - sin θ vy + gx0
    Ay = np.column_stack([s, c, gy0])  # gy = sin θ vx + cos θ vy + gy0

    block = max(1, _BLOCK_ELEMENTS // b)
    m = min(block, n)
    gx = np.empty((m, b))
    gy = np.empty((m, b))
    # Cell indices in int32: converting to it is ~3x cheaper than to int64, and every index
    # is small (the sensor positions were clipped to `reach` cells outside the map).
    ix = np.empty((m, b), dtype=np.int32)
    iy = np.empty((m, b), dtype=np.int32)
    logp = np.empty((m, b))
    table = f._table
    last_col = float(width - 1)
    for start in range(0, n, block):
        stop = min(start + block, n)
        k = stop - start
        bx, by, bix, biy, bl = gx[:k], gy[:k], ix[:k], iy[:k], logp[:k]
        np.matmul(Ax[start:stop], V, out=bx)
        np.matmul(Ay[start:stop], V, out=by)
        # Column: clipped into [0, width-1] so that it can never wrap into the next row;
        # columns 0 and width-1 are the "outside" border. On values >= 0 the conversion to
        # int (truncation) is the floor.
        np.clip(bx, 0.0, last_col, out=bx)
        np.copyto(bix, bx, casting="unsafe")
        # Row: truncation is the floor for rows >= 0 and gives 0 (the border) for rows in
        # (-1, 0), which is where floor's -1 would be "outside" too. Rows need no clip: a
        # row below 0 or past the last makes the flat index fall off the table, which
        # take(mode="clip") maps to its first or last entry — both on the border.
        np.copyto(biy, by, casting="unsafe")
        np.multiply(biy, width, out=biy)
        np.add(biy, bix, out=biy)  # flat index = row * width + column
        np.take(table, biy, out=bl, mode="clip")
        np.sum(bl, axis=1, out=out[start:stop])
    return out


def beam_log_likelihood(
    field: LikelihoodField,
    pose: ArrayLike,
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    sensor_offset: ArrayLike | None = None,
    beam_stride: int = 1,
) -> FloatArray:
    """``log p`` of each used beam ``(B_used,)`` for a single pose ``(3,)`` (for plots and
    diagnosis; :func:`log_likelihood` is the sum of these)."""
    f = _as_field(field)
    p = as_array(pose, "pose", (3,))
    r, a = _select_beams(f, ranges, beam_angles, beam_stride)
    sensor, yaw = _sensor_poses(p[None, :], sensor_offset)
    ang = sensor[0, 2] + yaw + a
    end = sensor[0, :2] + r[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    cells = f.grid.world_to_cell(end)
    inside = f.grid.contains(cells)
    d = np.full(r.size, f.outside_distance)
    d[inside] = f.distances[cells[inside, 0], cells[inside, 1]]
    return f.log_p(d)


def interpolate_distance(
    field: LikelihoodField, points: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """The distance map interpolated at world points ``(N, 2)``, and its gradient ``(N, 2)``.

    ``field.distances`` holds values at cell centres; between the four centres around a
    point, at fractions ``(a, b)`` of a cell along x and y,

        d = (1-a)(1-b) d00 + a(1-b) d01 + (1-a) b d10 + a b d11,
        ∂d/∂x = ((1-b)(d01 - d00) + b(d11 - d10)) / res,
        ∂d/∂y = ((1-a)(d10 - d00) + a(d11 - d01)) / res,

    with ``d_rc`` the centre ``r`` rows up and ``c`` columns right (bilinear interpolation;
    the gradient is that of the interpolant, continuous inside each square of centres).
    Centres outside the grid read :attr:`LikelihoodField.outside_distance`, so a point far
    outside gets that value and a zero gradient. This is the smooth field for gradient-based
    scan-to-map registration; :func:`log_likelihood` keeps the faster nearest-cell lookup.
    """
    f = _as_field(field)
    p = as_array(points, "points", (None, 2))
    grid = f.grid
    rows, cols = grid.shape
    res = grid.resolution
    # Cell-centre coordinates; far points are pulled to two cells outside (still outside).
    u = np.clip((p[:, 0] - grid.origin_xy[0]) / res - 0.5, -2.0, cols + 1.0)
    v = np.clip((p[:, 1] - grid.origin_xy[1]) / res - 0.5, -2.0, rows + 1.0)
    c0f, r0f = np.floor(u), np.floor(v)
    a, b = u - c0f, v - r0f
    c0, r0 = c0f.astype(np.int64), r0f.astype(np.int64)
    outside = f.outside_distance

    def corner(dr: int, dc: int) -> FloatArray:
        r, c = r0 + dr, c0 + dc
        inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        val = np.full(r.shape, outside)
        val[inside] = f.distances[r[inside], c[inside]]
        return val

    d00, d01, d10, d11 = corner(0, 0), corner(0, 1), corner(1, 0), corner(1, 1)
    d = (1 - a) * (1 - b) * d00 + a * (1 - b) * d01 + (1 - a) * b * d10 + a * b * d11
    grad = np.empty((p.shape[0], 2))
    grad[:, 0] = ((1 - b) * (d01 - d00) + b * (d11 - d10)) / res
    grad[:, 1] = ((1 - a) * (d10 - d00) + a * (d11 - d01)) / res
    return d, grad
