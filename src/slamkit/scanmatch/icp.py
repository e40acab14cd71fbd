"""Point-to-point ICP for 2D scans, and the prepared reference shared with point-to-line ICP.

**Iteration.** From the current estimate ``T = (t, θ)`` the current points ``q_i`` are mapped
into the reference frame, ``q_i' = R(θ) q_i + t``, and each is paired with its nearest
reference point ``p_j(i)`` (a KD-tree built once per reference). Pairs farther apart than
``max_correspondence_distance`` are dropped, then only the ``trim_fraction`` closest of the
rest are kept (trimmed ICP). The new estimate minimises ``Σ |R q_i + t - p_i|²`` over the kept
pairs in closed form (2D Procrustes, the 2D case of the SVD solution):

    with centroids q̄, p̄ and centred points q̃_i = q_i - q̄, p̃_i = p_i - p̄,
    Σ |R q̃_i - p̃_i|² = const - 2 Σ p̃_iᵀ R q̃_i
                    = const - 2 (cos θ Σ q̃_i·p̃_i + sin θ Σ q̃_i × p̃_i),
    so  θ = atan2(Σ q̃_i × p̃_i, Σ q̃_i·p̃_i),   t = p̄ - R(θ) q̄,

with ``a × b = a_x b_y - a_y b_x``. The loop stops when the step between two estimates is below
both tolerances or the correspondences repeat (the next solution would be the same).

**Result.** ``pose`` is ``T_ref_cur`` (:mod:`slamkit.scanmatch.result`); the covariance and the
degeneracy test use the normal-distance model of :mod:`slamkit.scanmatch.covariance`, with
the reference normals estimated once in :func:`prepare_scan`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from slamkit._validation import FloatArray, as_array
from slamkit.backend import SEAM
from slamkit.errors import ConfigError, MatchError
from slamkit.scanmatch import kernels
from slamkit.scanmatch.covariance import (
    estimate_normals,
    line_jacobian,
    neighbour_table,
    normal_distance_covariance,
    require_constrained,
    scan_order_normals,
)
from slamkit.scanmatch.result import MatchResult, require_points

__all__ = [
    "IcpConfig",
    "PreparedScan",
    "icp",
    "point_to_point_step",
    "prepare_scan",
    "scan_tables_numpy",
    "validate_common",
]

MIN_REFERENCE_POINTS = 3
"""A reference scan needs at least this many points to define any surface."""


@dataclass(frozen=True, eq=False)
class PreparedScan:
    """A reference scan ready to be matched against many times.

    * ``points (M, 2)``: the reference points [m], read-only; for point-to-line ICP they must
      be in scan (beam) order, as :func:`~slamkit.scanmatch.scan_points` returns them;
    * ``tree``: a :class:`scipy.spatial.cKDTree` over ``points``, built on first use (the
      compiled point-to-line ICP of :mod:`slamkit.scanmatch.kernels` does not need one);
    * ``normals (M, 2)``: unit surface normals by principal components of each point's
      neighbourhood (``(0, 0)`` where ``has_normal`` is false), for the degeneracy test and
      the point-to-point covariance;
    * ``has_normal (M,)``: the point had enough neighbours for a normal;
    * ``gaps (M - 1,)``: ``|points[j + 1] - points[j]|`` [m], the spacing in scan order;
    * ``segment_normals (M - 1, 2)``: the unit normal of the segment from ``points[j]`` to
      ``points[j + 1]``, the tangent turned by +90° (``(0, 0)`` for coincident points).

    Build it with :func:`prepare_scan`.
    """

    points: FloatArray
    normals: FloatArray
    has_normal: NDArray[np.bool_]
    gaps: FloatArray
    segment_normals: FloatArray

    @cached_property
    def tree(self) -> cKDTree:
        """The KD-tree over ``points`` (built on the first access, then kept)."""
        return cKDTree(self.points, leafsize=8)


def scan_tables_numpy(
    points: FloatArray, window: int, max_spacing: float
) -> tuple[FloatArray, NDArray[np.bool_], FloatArray, FloatArray]:
    """``(normals (M, 2), has_normal (M,), gaps (M - 1,), segment_normals (M - 1, 2))`` of a
    scan in beam order (:func:`prepare_scan`): the normals of
    :func:`~slamkit.scanmatch.covariance.scan_order_normals`, the spacings and the unit
    normals of the segments between consecutive points (``(0, 0)`` for coincident ones).
    The path without numba and the oracle of :func:`slamkit.scanmatch.kernels.scan_tables`
    (the same ``has_normal``, the rest to 1e-9)."""
    normals, ok = scan_order_normals(points, window, max_spacing)
    gaps, seg_normals = _segments(points)
    return normals, ok, gaps, seg_normals


def _segments(points: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The spacings ``(M - 1,)`` of consecutive points and the unit normals ``(M - 1, 2)`` of
    the segments between them (the tangent turned by +90°; ``(0, 0)`` for coincident ones)."""
    tangent = np.diff(points, axis=0)
    gaps = np.hypot(tangent[:, 0], tangent[:, 1])
    inv = np.divide(1.0, gaps, out=np.zeros_like(gaps), where=gaps > 0.0)
    return gaps, np.column_stack([-tangent[:, 1] * inv, tangent[:, 0] * inv])


_scan_tables = SEAM.pair(compiled=kernels.scan_tables, oracle=scan_tables_numpy)
"""A scan's tables, compiled under numba, else in NumPy (:mod:`slamkit.backend`)."""


def prepare_scan(
    points: ArrayLike,
    *,
    ordered: bool = True,
    normal_neighbours: int = 7,
    normal_radius: float = 0.5,
) -> PreparedScan:
    """A :class:`PreparedScan` of reference ``points (M, 2)`` [m] (copied): the scan-order
    gaps and segment normals, and point normals by principal components of
    ``normal_neighbours`` points: when ``ordered`` (a scan) the points centred on each in scan
    order, no consecutive two more than ``normal_radius`` [m] apart; else (any point cloud)
    its nearest neighbours within ``normal_radius`` (found with the KD-tree, which is then
    kept; for a scan it is built on first use). Fewer than 3 points raise
    ``MatchError("too_few_points")``. With numba the tables of a scan are computed by
    :func:`slamkit.scanmatch.kernels.scan_tables`, else by :func:`scan_tables_numpy`, the
    same numbers to rounding."""
    pts = require_points(
        as_array(points, "reference points", (None, 2)), MIN_REFERENCE_POINTS, "reference"
    ).copy()
    if int(normal_neighbours) != normal_neighbours or normal_neighbours < 3:
        raise ConfigError(f"normal_neighbours: expected an integer >= 3, got {normal_neighbours!r}")
    if not (math.isfinite(normal_radius) and normal_radius > 0):
        raise ConfigError(f"normal_radius: expected a finite number > 0 [m], got {normal_radius!r}")
    pts.flags.writeable = False
    tree = None
    if ordered:
        normals, ok, gaps, seg_normals = _scan_tables(
            pts, int(normal_neighbours), float(normal_radius)
        )
    else:
        tree = cKDTree(pts, leafsize=8)
        table = neighbour_table(pts, tree, int(normal_neighbours))
        normals, ok = estimate_normals(pts, table, float(normal_radius))
        gaps, seg_normals = _segments(pts)
    for arr in (normals, ok, gaps, seg_normals):
        arr.flags.writeable = False
    scan = PreparedScan(pts, normals, ok, gaps, seg_normals)
    if tree is not None:
        scan.__dict__["tree"] = tree  # the cache of the `tree` property: built already
    return scan


@dataclass(frozen=True)
class IcpConfig:
    """Settings of point-to-point ICP (:func:`icp`).

    * ``max_iterations``: correspondence rounds before giving up with
      ``MatchError("no_convergence")`` (default 100);
    * ``max_correspondence_distance`` [m]: a current point farther than this from every
      reference point (at the current estimate) is not paired (default 1.0);
    * ``trim_fraction`` in ``(0, 1]``: of the pairs within that distance, keep this fraction
      with the smallest distances (default 0.9);
    * ``min_correspondences``: fewer kept pairs raise ``MatchError("too_few_correspondences")``
      (default 10; at least 4, enough for a covariance);
    * ``min_points``: a current scan with fewer points raises ``MatchError("too_few_points")``
      (default 10);
    * ``translation_tolerance`` [m], ``rotation_tolerance`` [rad]: stop when one step moves the
      estimate by less than both (defaults 1e-4 m, 1e-4 rad);
    * ``min_eigenvalue``: raise ``MatchError("degenerate")`` when the smallest eigenvalue of the
      normalised normal-distance Hessian (:mod:`slamkit.scanmatch.covariance`; dimensionless,
      at most 2) is below this at the solution, or below half of it at the initial guess (a
      corridor is caught before the estimate drifts along it) (default 0.01).
    """

    max_iterations: int = 100
    max_correspondence_distance: float = 1.0
    trim_fraction: float = 0.9
    min_correspondences: int = 10
    min_points: int = 10
    translation_tolerance: float = 1e-4
    rotation_tolerance: float = 1e-4
    min_eigenvalue: float = 0.01

    def __post_init__(self) -> None:
        validate_common(self)


def validate_common(config: object) -> None:
    """Check the settings shared by :class:`IcpConfig` and the point-to-line config (the same
    field names); raise :class:`~slamkit.errors.ConfigError` naming the field."""
    name = type(config).__name__
    for field, low in (("max_iterations", 1), ("min_correspondences", 4), ("min_points", 4)):
        v = getattr(config, field)
        if not isinstance(v, int) or isinstance(v, bool) or v < low:
            raise ConfigError(f"{name}.{field}: expected an integer >= {low}, got {v!r}")
    for field in ("max_correspondence_distance", "translation_tolerance", "rotation_tolerance"):
        v = getattr(config, field)
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ConfigError(f"{name}.{field}: expected a finite number > 0, got {v!r}")
    frac = config.trim_fraction  # type: ignore[attr-defined]
    if not (isinstance(frac, int | float) and 0.0 < frac <= 1.0):
        raise ConfigError(f"{name}.trim_fraction: expected a number in (0, 1], got {frac!r}")
    lam = config.min_eigenvalue  # type: ignore[attr-defined]
    if not (isinstance(lam, int | float) and 0.0 <= lam < 2.0):
        raise ConfigError(f"{name}.min_eigenvalue: expected a number in [0, 2), got {lam!r}")


def point_to_point_step(current: FloatArray, reference: FloatArray) -> FloatArray:
    """The pose ``(x, y, θ)`` minimising ``Σ |R(θ) q_i + t - p_i|²`` for paired points
    ``current (m, 2)`` (``q``) and ``reference (m, 2)`` (``p``), in closed form (module
    docstring). Needs ``m >= 2`` distinct points for a unique answer."""
    q_mean = current.mean(axis=0)
    p_mean = reference.mean(axis=0)
    qc = current - q_mean
    pc = reference - p_mean
    dot = float(np.einsum("ij,ij->", qc, pc))
    cross = float(np.dot(qc[:, 0], pc[:, 1]) - np.dot(qc[:, 1], pc[:, 0]))
    theta = math.atan2(cross, dot)
    c, s = math.cos(theta), math.sin(theta)
    tx = p_mean[0] - (c * q_mean[0] - s * q_mean[1])
    ty = p_mean[1] - (s * q_mean[0] + c * q_mean[1])
    return np.array([tx, ty, theta])


def _trim(dist: FloatArray, valid: NDArray[np.bool_], fraction: float) -> NDArray[np.bool_]:
    """``valid`` restricted to the ``fraction`` of its entries with the smallest ``dist``."""
    n_valid = int(np.count_nonzero(valid))
    if fraction >= 1.0 or n_valid == 0:
        return valid
    n_keep = max(1, math.ceil(fraction * n_valid))
    if n_keep >= n_valid:
        return valid
    threshold = np.partition(dist[valid], n_keep - 1)[n_keep - 1]
    return valid & (dist <= threshold)


def icp(
    reference: ArrayLike | PreparedScan,
    current: ArrayLike,
    initial: ArrayLike = (0.0, 0.0, 0.0),
    config: IcpConfig | None = None,
) -> MatchResult:
    """Register ``current (K, 2)`` points (current sensor frame, metres) to ``reference``
    (``(M, 2)`` points in the reference frame, or a :class:`PreparedScan` of them) by
    point-to-point ICP from ``initial = T_ref_cur`` guess ``(x, y, θ)``.

    Returns a :class:`~slamkit.scanmatch.MatchResult` (``method="icp"``; ``score`` and
    ``inlier_fraction`` are the fraction of current points kept at the end). Raises
    ``MatchError`` with reason ``"too_few_points"``, ``"too_few_correspondences"``,
    ``"degenerate"`` or ``"no_convergence"``; ``ShapeError``/``NonFiniteError`` for malformed
    arrays.
    """
    cfg = IcpConfig() if config is None else config
    ref = reference if isinstance(reference, PreparedScan) else prepare_scan(reference)
    q = require_points(as_array(current, "current points", (None, 2)), cfg.min_points, "current")
    x0 = as_array(initial, "initial pose", (3,))
    P = ref.points
    m_ref = P.shape[0]
    tx, ty, th = float(x0[0]), float(x0[1]), float(x0[2])
    seen: set[bytes] = set()  # every correspondence set met so far
    keep = np.zeros(q.shape[0], dtype=bool)
    j = np.zeros(q.shape[0], dtype=np.intp)
    converged = False
    it = 0
    for it in range(1, cfg.max_iterations + 1):
        c, s = math.cos(th), math.sin(th)
        moved = q @ np.array([[c, s], [-s, c]])  # rows R q_i
        moved += (tx, ty)
        dist, j = ref.tree.query(moved, k=1, distance_upper_bound=cfg.max_correspondence_distance)
        keep = _trim(dist, j < m_ref, cfg.trim_fraction)
        n_keep = int(np.count_nonzero(keep))
        if n_keep < cfg.min_correspondences:
            raise MatchError(
                f"icp: {n_keep} correspondences within "
                f"{cfg.max_correspondence_distance} m at iteration {it}; at least "
                f"{cfg.min_correspondences} are needed",
                "too_few_correspondences",
            )
        jk = np.where(keep, j, -1)
        if it == 1:
            has = keep & ref.has_normal[np.where(keep, j, 0)]
            jac = line_jacobian(q[has], ref.normals[j[has]], th)
            require_constrained(jac, q[has], 0.5 * cfg.min_eigenvalue, "icp")
        stamp = jk.tobytes()
        if stamp in seen:
            converged = True  # pairs met before: the steps would repeat (a cycle)
            break
        seen.add(stamp)
        new = point_to_point_step(q[keep], P[j[keep]])
        dth = math.remainder(float(new[2]) - th, 2.0 * math.pi)
        small = (
            math.hypot(float(new[0]) - tx, float(new[1]) - ty) < cfg.translation_tolerance
            and abs(dth) < cfg.rotation_tolerance
        )
        tx, ty, th = float(new[0]), float(new[1]), th + dth
        if small:
            converged = True
            break
    if not converged:
        raise MatchError(
            f"icp: no convergence within {cfg.max_iterations} iterations (last step above "
            f"{cfg.translation_tolerance} m / {cfg.rotation_tolerance} rad)",
            "no_convergence",
        )
    th = math.remainder(th, 2.0 * math.pi)
    # Covariance and degeneracy from the normal distances at the reference normals, over all
    # pairs within range (the scale) and the kept ones (the Hessian).
    valid = (j < m_ref) & ref.has_normal[np.minimum(j, m_ref - 1)]
    jv = j[valid]
    normals = ref.normals[jv]
    qv = q[valid]
    jac = line_jacobian(qv, normals, th)
    kept = keep[valid]
    require_constrained(jac[kept], qv[kept], cfg.min_eigenvalue, "icp")
    c, s = math.cos(th), math.sin(th)
    moved = qv @ np.array([[c, s], [-s, c]]) + np.array([tx, ty])
    residuals = np.einsum("ij,ij->i", normals, moved - P[jv])
    cov = normal_distance_covariance(jac, residuals, kept)
    frac = float(np.count_nonzero(keep)) / q.shape[0]
    return MatchResult(np.array([tx, ty, th]), cov, frac, frac, it, "icp")
