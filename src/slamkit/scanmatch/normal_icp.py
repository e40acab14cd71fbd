"""Point-to-normal ICP against an unordered point cloud (a local map of several scans).

Point-to-line ICP (:mod:`slamkit.scanmatch.plicp`) pairs a point with the segment between
two neighbouring *beams* of one reference scan, so it needs a reference in scan order. A
local map merged from several scans has no scan order; its surface is known instead through
normals estimated once per map point from its nearest neighbours (principal components,
:func:`~slamkit.scanmatch.covariance.estimate_normals`). The error of a current point
``q_i`` paired with map point ``p_j`` of normal ``n_j`` is its distance to the tangent line
there,

    e_i(x) = n_jᵀ (R(θ) q_i + t − p_j),       x = (t_x, t_y, θ),

and one Gauss-Newton step solves ``(Σ w_i J_iᵀ J_i) δ = −Σ w_i J_i e_i`` with ``J_i =
[n_x, n_y, n_jᵀ R'(θ) q_i]`` (:func:`~slamkit.scanmatch.covariance.line_jacobian`). The
weights are Huber's, ``w = min(1, k σ̂ / |e|)`` with ``σ̂`` the robust scale ``1.4826 ·
median |e|``, which lets a few wrong pairs (a door opened, a person walking by) pull with a
bounded force instead of a squared one. Pairs farther apart than
``max_correspondence_distance`` are not made; the correspondences are searched again after
every step (the normals stay those of the map). It stops when a step is below the
tolerances or when the correspondences repeat an earlier iterate's (the steps from there
would cycle between the same few sets).

The covariance is ``σ̂² H⁻¹`` of the last step (the normal-distance model, as for
point-to-point ICP); a map whose Hessian leaves a direction unconstrained raises
``MatchError("degenerate")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from slamkit._validation import FloatArray, as_array
from slamkit.backend import writable
from slamkit.errors import ConfigError, CovarianceError, MatchError
from slamkit.geometry.pose2 import transform_points
from slamkit.scanmatch.covariance import require_constrained
from slamkit.scanmatch.nearest import CELL_SIDE, NearestGrid
from slamkit.scanmatch.normal_terms import pair_terms
from slamkit.scanmatch.result import MatchResult, require_points

__all__ = ["NormalCloud", "NormalIcpConfig", "normal_icp", "surface_fit"]


@dataclass(frozen=True, eq=False)
class NormalCloud:
    """Reference points ``(M, 2)`` with unit normals ``(M, 2)`` (build with :meth:`build`),
    and the search for their nearest neighbours (:meth:`nearest`). The arrays are treated as
    read-only."""

    points: FloatArray
    normals: FloatArray

    @classmethod
    def build(cls, points: ArrayLike, normals: ArrayLike) -> NormalCloud:
        pts = as_array(points, "reference points", (None, 2))
        nrm = as_array(normals, "reference normals", (pts.shape[0], 2))
        return cls(pts, nrm)

    @cached_property
    def tree(self) -> cKDTree:
        """A KD-tree over the points (built on first use)."""
        return cKDTree(self.points, leafsize=8)

    def nearest(self, x: FloatArray, bound: float) -> NDArray[np.intp]:
        """The index of the point nearest each of ``x (K, 2)`` strictly within ``bound``
        [m], ``M`` where none is: ``self.tree.query(x, k=1, distance_upper_bound=bound)[1]``
        to the index, by a grid (:class:`~slamkit.scanmatch.nearest.NearestGrid`, one per
        bound, built on first use), several times faster on ICP's small batches."""
        grids = self.__dict__.setdefault("_grids", {})  # the frozen dataclass's cache
        grid = grids.get(bound)
        if grid is None:
            grid = NearestGrid(self.points, CELL_SIDE * bound)
            grids[bound] = grid
        return grid.query(x, bound)


@dataclass(frozen=True)
class NormalIcpConfig:
    """Settings of :func:`normal_icp`.

    * ``max_iterations``: Gauss-Newton steps before ``MatchError("no_convergence")`` (30);
    * ``max_correspondence_distance`` [m]: farther pairs are not made (0.5);
    * ``huber_k``: the Huber threshold in robust standard deviations (1.5);
    * ``min_correspondences``, ``min_points``: fewer raise ``MatchError`` (10, 10);
    * ``translation_tolerance`` [m], ``rotation_tolerance`` [rad]: stop when a step is
      smaller than both (1e-4, 1e-4);
    * ``min_eigenvalue``: the degeneracy threshold of
      :func:`~slamkit.scanmatch.covariance.require_constrained` (0.01; not applied with a
      prior);
    * ``noise_floor`` [m]: the least robust residual scale ``σ̂`` (0.005): a map point laid
      down from a scan with its own noise is never exactly on the surface, and without a
      floor a near-perfect fit would claim an information without bound.
    """

    max_iterations: int = 30
    max_correspondence_distance: float = 0.5
    huber_k: float = 1.5
    min_correspondences: int = 10
    min_points: int = 10
    translation_tolerance: float = 1e-4
    rotation_tolerance: float = 1e-4
    min_eigenvalue: float = 0.01
    noise_floor: float = 0.005

    def __post_init__(self) -> None:
        for name in ("max_iterations", "min_correspondences", "min_points"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
                raise ConfigError(f"NormalIcpConfig.{name}: expected an integer >= 1, got {v!r}")
        for name in (
            "noise_floor",
            "max_correspondence_distance",
            "huber_k",
            "translation_tolerance",
            "rotation_tolerance",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(
                    f"NormalIcpConfig.{name}: expected a finite number > 0, got {v!r}"
                )
        if not (math.isfinite(self.min_eigenvalue) and self.min_eigenvalue >= 0):
            raise ConfigError(
                "NormalIcpConfig.min_eigenvalue: expected a number >= 0, got "
                f"{self.min_eigenvalue!r}"
            )


def normal_icp(
    reference: NormalCloud,
    current: ArrayLike,
    initial: ArrayLike = (0.0, 0.0, 0.0),
    config: NormalIcpConfig | None = None,
    *,
    prior_information: ArrayLike | None = None,
    prior_pose: ArrayLike | None = None,
) -> MatchResult:
    """Register ``current (K, 2)`` points (sensor frame, metres) to the map ``reference`` (a
    :class:`NormalCloud`, e.g. :meth:`slamkit.scanmatch.point_map.PointMap.near`) from
    ``initial = T_ref_cur``.

    Returns a :class:`~slamkit.scanmatch.MatchResult` (``method="normal-icp"``; ``score`` and
    ``inlier_fraction``: the fraction of current points paired at the end). Raises
    ``MatchError`` (``"too_few_points"``, ``"too_few_correspondences"``, ``"degenerate"``,
    ``"no_convergence"``), ``ShapeError``/``NonFiniteError`` for malformed arrays.

    ``prior_information (3, 3)``: the information (inverse covariance) of a prior on the
    pose at ``x₀ = prior_pose`` (default: ``initial``), e.g. from odometry. The steps then
    minimise the posterior ``Σ w e² / σ̂² + (x − x₀)ᵀ Λ (x − x₀)`` (the heading difference
    wrapped), so a direction the map leaves unconstrained (a corridor) keeps the prior
    instead of sliding, no match is refused as degenerate, and the covariance returned is
    the posterior's ``(H/σ̂² + Λ)⁻¹``. A ``prior_pose`` apart from ``initial`` lets the
    search start from a better guess than the prior's mean (the last match moved by the
    wheels, say) while the prior stays an independent measurement.
    """
    cfg = NormalIcpConfig() if config is None else config
    q = require_points(as_array(current, "current points", (None, 2)), cfg.min_points, "current")
    x0 = as_array(initial, "initial pose", (3,))
    lam = None
    x_prior = x0 if prior_pose is None else as_array(prior_pose, "prior pose", (3,))
    if prior_information is not None:
        lam = as_array(prior_information, "prior information", (3, 3))
        _require_prior(lam)
    # The arrays as the kernels take them (C-ordered, writable): converted once, not per
    # step; the rotation below keeps ``q`` itself (the BLAS product of its own layout).
    P, normals = writable(reference.points), writable(reference.normals)
    qc = writable(q)
    tx, ty, th = float(x0[0]), float(x0[1]), float(x0[2])
    converged = False
    seen: set[bytes] = set()  # every correspondence set met so far
    it = 0
    jac = np.zeros((0, 3))
    jw = np.zeros((0, 3))
    qk = np.zeros((0, 2))
    sigma = 0.0
    n_pairs = 0
    for it in range(1, cfg.max_iterations + 1):
        c, s = math.cos(th), math.sin(th)
        moved = q @ np.array([[c, s], [-s, c]])
        moved += (tx, ty)
        j = reference.nearest(moved, cfg.max_correspondence_distance)
        terms = pair_terms(
            moved, qc, j, P, normals, th, cfg.huber_k, cfg.noise_floor, cfg.min_correspondences
        )
        n_pairs = terms.n_pairs
        if n_pairs < cfg.min_correspondences:
            raise MatchError(
                f"normal-icp: {n_pairs} correspondences within "
                f"{cfg.max_correspondence_distance} m at iteration {it}; at least "
                f"{cfg.min_correspondences} are needed",
                "too_few_correspondences",
            )
        if terms.stamp in seen:  # the pairs of an earlier iterate: the steps would cycle
            converged = True
            break
        seen.add(terms.stamp)
        qk, e, jac, jw, sigma = terms.current, terms.e, terms.jac, terms.jw, terms.sigma
        if it == 1 and lam is None:
            require_constrained(jac, qk, cfg.min_eigenvalue, "normal-icp")
        h = jw.T @ jac
        g = jw.T @ e
        if lam is not None:  # the prior, in the same units: divide the data term by σ̂²
            dx = np.array(
                [tx - x_prior[0], ty - x_prior[1], math.remainder(th - x_prior[2], 2.0 * math.pi)]
            )
            h = h / (sigma * sigma) + lam
            g = g / (sigma * sigma) + lam @ dx
        try:
            delta = -np.linalg.solve(h, g)
        except np.linalg.LinAlgError:
            raise MatchError("normal-icp: singular normal equations", "degenerate") from None
        tx += float(delta[0])
        ty += float(delta[1])
        th += float(delta[2])
        if (
            math.hypot(float(delta[0]), float(delta[1])) < cfg.translation_tolerance
            and abs(float(delta[2])) < cfg.rotation_tolerance
        ):
            converged = True
            break
    if not converged:
        raise MatchError(
            f"normal-icp: no convergence within {cfg.max_iterations} iterations",
            "no_convergence",
        )
    if lam is None:
        require_constrained(jac, qk, cfg.min_eigenvalue, "normal-icp")
        cov = sigma * sigma * np.linalg.solve(jw.T @ jac, np.eye(3))
    else:
        cov = np.linalg.solve((jw.T @ jac) / (sigma * sigma) + lam, np.eye(3))
    cov = 0.5 * (cov + cov.T)
    frac = n_pairs / q.shape[0]
    pose = np.array([tx, ty, math.remainder(th, 2.0 * math.pi)])
    return MatchResult(pose, cov, frac, frac, it, "normal-icp")


def _require_prior(lam: FloatArray) -> None:
    """``CovarianceError`` unless ``lam (3, 3)`` (finite) is symmetric (``np.allclose(lam,
    lam.T)``) and positive semi-definite (``np.linalg.eigvalsh`` of its symmetric part has
    no eigenvalue below zero): the same verdict, without NumPy's calls for a clear case.

    Symmetry: ``isclose``'s test ``|a − b| <= 1e-8 + 1e-5 |b|`` on Python floats is NumPy's
    own float64 arithmetic. Definiteness: when the leading minors of the symmetric part
    ``S`` (computed here, each to within ~1e-14 ‖S‖ᵏ) all exceed 1e-12 ‖S‖ᵏ (Frobenius
    norm), ``S`` is positive definite (Sylvester) with ``λ_min ≥ det S / ‖S‖² > 1e-12 ‖S‖``,
    far above the error of LAPACK's eigenvalues (a small multiple of 1e-16 ‖S‖): eigvalsh
    could not find one below zero. Anything less clear is left to eigvalsh itself.
    """
    a = lam.tolist()
    symmetric = all(
        abs(a[i][k] - a[k][i]) <= 1e-8 + 1e-5 * abs(a[k][i]) for i in range(3) for k in range(3)
    )
    if symmetric:
        s00, s11, s22 = (0.5 * (a[i][i] + a[i][i]) for i in range(3))
        s01, s02, s12 = (0.5 * (a[i][k] + a[k][i]) for i, k in ((0, 1), (0, 2), (1, 2)))
        norm = math.sqrt(
            s00 * s00 + s11 * s11 + s22 * s22 + 2.0 * (s01 * s01 + s02 * s02 + s12 * s12)
        )
        minor2 = s00 * s11 - s01 * s01
        det = (
            s00 * (s11 * s22 - s12 * s12)
            - s01 * (s01 * s22 - s12 * s02)
            + s02 * (s01 * s12 - s11 * s02)
        )
        if s00 > 1e-12 * norm and minor2 > 1e-12 * norm**2 and det > 1e-12 * norm**3:
            return
        if not np.linalg.eigvalsh(0.5 * (lam + lam.T))[0] < 0:
            return
    raise CovarianceError(
        "prior information: expected a symmetric positive semi-definite 3x3 matrix"
    )


def surface_fit(
    reference: NormalCloud,
    current: ArrayLike,
    pose: ArrayLike,
    tolerance: float = 0.05,
    reach: float = 0.2,
) -> float:
    """The fraction of ``current (K, 2)`` points (sensor frame) that ``pose = T_ref_cur``
    puts within ``tolerance`` [m] of the map's surface: nearer than that, along its normal,
    to the tangent line of their nearest map point, that point within ``reach`` [m].

    A check of a match that does not trust the match's own residuals: a scan turned the
    wrong way still pairs its points within the matcher's correspondence distance and can
    converge with a small robust scale on the few walls it got right, but most of its
    points then lie off every surface. Points far from any map point (new ground) count as
    off the surface too, so compare fits of the same scan, or set a low bar.
    """
    q = as_array(current, "current points", (None, 2))
    x = as_array(pose, "pose", (3,))
    if q.shape[0] == 0 or reference.points.shape[0] == 0:
        return 0.0
    moved = transform_points(x, q)
    j = reference.nearest(moved, reach)
    ok = j < reference.points.shape[0]
    jk = j[ok]
    e = np.einsum("ij,ij->i", reference.normals[jk], moved[ok] - reference.points[jk])
    return float(np.count_nonzero(np.abs(e) <= tolerance)) / q.shape[0]
