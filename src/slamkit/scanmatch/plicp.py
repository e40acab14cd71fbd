"""Point-to-line ICP (PLICP) for 2D scans, after Censi, "An ICP variant using a point-to-line
metric", ICRA 2008.

**Correspondences.** The reference points must be in scan order (as
:func:`~slamkit.scanmatch.scan_points` returns them): consecutive points are neighbours on a
surface unless they are farther apart than ``max_gap`` (a range discontinuity: an edge, a door,
dropped beams). Each current point, mapped by the estimate ``T`` into the reference frame as
``q'_i``, takes its nearest reference point ``j1`` (a KD-tree query; compiled, the exact
search by bearing of :mod:`slamkit.scanmatch.kernels`) and the closer of ``j1 - 1`` and
``j1 + 1`` among those joined to ``j1`` by a segment no longer than ``max_gap``; ``j2``. Its
error is the distance from ``q'_i`` to the line through ``p_j1`` and ``p_j2``,
``e_i = n_iᵀ (q'_i - p_j1)`` with ``n_i`` the unit normal of the segment. Pairs farther than
``max_correspondence_distance`` from ``p_j1`` are dropped, then the rest are trimmed: those with
``|e_i|`` above ``outlier_multiplier`` times the median ``|e|`` (but never below
``outlier_floor``), then all but the ``trim_fraction`` smallest.

**The step** (Censi's closed form). With ``x = (t_x, t_y, cos θ, sin θ)`` the mapped point is
linear in ``x``, so each error is ``e_i = φ_iᵀ x - b_i`` with

    φ_i = (n_x, n_y, n_x q_x + n_y q_y, n_y q_x - n_x q_y),   b_i = n_iᵀ p_j1,

and the problem is ``min Σ (φ_iᵀ x - b_i)²`` subject to ``x_3² + x_4² = 1``. With ``M = Σ φ_i
φ_iᵀ`` and ``v = Σ φ_i b_i`` split into 2×2 blocks ``M = [[A, B], [Bᵀ, D]]``, ``v = (v_t,
v_c)``, the Lagrange conditions with multiplier ``λ`` on ``|c|² = 1`` (``c = (x_3, x_4)``) are

    A t + B c = v_t,   Bᵀ t + (D + λ I) c = v_c.

Eliminating ``t = A⁻¹ (v_t - B c)`` leaves ``(S + λ I) c = h`` with the Schur complement
``S = D - Bᵀ A⁻¹ B`` and ``h = v_c - Bᵀ A⁻¹ v_t``. As ``(S + λI)⁻¹ = (adj S + λ I) / p(λ)`` with
``p(λ) = λ² + tr(S) λ + det S`` and ``adj [[a, b], [b, d]] = [[d, -b], [-b, a]]``, the
constraint ``|c|² = 1`` becomes, with ``k = adj(S) h``,

    p(λ)² - (|h|² λ² + 2 hᵀk λ + |k|²) = 0,

a polynomial of degree 4 in ``λ``:

    λ⁴ + 2τ λ³ + (τ² + 2δ - |h|²) λ² + 2(τδ - hᵀk) λ + (δ² - |k|²),   τ = tr S, δ = det S.

The minimum is at its largest real root (there ``S + λI`` is positive semi-definite; the other
roots are saddles or maxima on the circle). It lies in ``(-s_min, |h| - s_min]``, ``s_min`` the
smaller eigenvalue of ``S``; above it the polynomial is positive. :func:`largest_real_root`
finds it by Newton's method on ``1/|c(λ)| - 1`` (concave and increasing there, so Newton from
the left converges monotonically), then ``c = (adj S + λ I) h / p(λ)``, ``θ = atan2(c_2, c_1)``
and ``t`` as above.

**Stopping.** When the correspondences (``j1``, ``j2`` and the kept set) repeat those of the
previous iteration the next step would reproduce the last solution, so the loop stops; it also
stops on a step below both tolerances.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.backend import SEAM, writable
from slamkit.errors import ConfigError, MatchError
from slamkit.scanmatch import kernels
from slamkit.scanmatch.covariance import (
    degenerate_error,
    line_jacobian,
    normalised_min_eigenvalue,
    point_to_line_covariance,
)
from slamkit.scanmatch.icp import PreparedScan, prepare_scan, validate_common
from slamkit.scanmatch.result import MatchResult, require_points

__all__ = [
    "PlIcpConfig",
    "lagrange_quartic",
    "largest_real_root",
    "plicp",
    "plicp_loop_numpy",
    "point_to_line_step",
]


@dataclass(frozen=True)
class PlIcpConfig:
    """Settings of point-to-line ICP (:func:`plicp`).

    * ``max_iterations``: correspondence rounds before ``MatchError("no_convergence")``
      (default 50);
    * ``max_correspondence_distance`` [m]: a current point farther than this from its nearest
      reference point (at the current estimate) is not paired (default 1.0);
    * ``max_gap`` [m]: consecutive reference points farther apart than this are not joined by
      a segment — a range discontinuity (default 0.5);
    * ``outlier_multiplier``: keep pairs whose line distance is at most this times the median
      line distance (default 3.0) ...
    * ``outlier_floor`` [m]: ... or at most this, whichever is larger (default 0.005);
    * ``trim_fraction`` in ``(0, 1]``: of those, keep this fraction with the smallest line
      distances (default 0.95);
    * ``min_correspondences``, ``min_points``, ``translation_tolerance`` [m],
      ``rotation_tolerance`` [rad], ``min_eigenvalue``: as in
      :class:`~slamkit.scanmatch.icp.IcpConfig` (defaults 10, 10, 1e-4 m, 1e-4 rad, 0.01).
    """

    max_iterations: int = 50
    max_correspondence_distance: float = 1.0
    max_gap: float = 0.5
    outlier_multiplier: float = 3.0
    outlier_floor: float = 0.005
    trim_fraction: float = 0.95
    min_correspondences: int = 10
    min_points: int = 10
    translation_tolerance: float = 1e-4
    rotation_tolerance: float = 1e-4
    min_eigenvalue: float = 0.01

    def __post_init__(self) -> None:
        validate_common(self)
        for field in ("max_gap", "outlier_multiplier", "outlier_floor"):
            v = getattr(self, field)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"PlIcpConfig.{field}: expected a finite number > 0, got {v!r}")


_NOT_SPANNED = "plicp: the line normals do not span the plane (translation unconstrained)"


_DEFAULT = PlIcpConfig()


def lagrange_quartic(S: FloatArray, h: FloatArray) -> FloatArray:
    """Coefficients ``(5,)``, highest power first, of the degree-4 polynomial in ``λ`` whose
    real roots are the multipliers of ``min cᵀ S c - 2 hᵀ c`` subject to ``|c| = 1`` (module
    docstring), for a symmetric ``S (2, 2)`` and ``h (2,)``."""
    a, b, d = float(S[0, 0]), float(S[0, 1]), float(S[1, 1])
    h0, h1 = float(h[0]), float(h[1])
    tau, delta = a + d, a * d - b * b
    k0, k1 = d * h0 - b * h1, -b * h0 + a * h1
    hh, hk, kk = h0 * h0 + h1 * h1, h0 * k0 + h1 * k1, k0 * k0 + k1 * k1
    return np.array(
        [1.0, 2.0 * tau, tau * tau + 2.0 * delta - hh, 2.0 * (tau * delta - hk), delta**2 - kk]
    )


def largest_real_root(s11: float, s12: float, s22: float, h1: float, h2: float) -> float:
    """The largest real root of :func:`lagrange_quartic` for ``S = [[s11, s12], [s12, s22]]``
    and ``h = (h1, h2)``: the multiplier ``λ`` of the minimum.

    Newton's method on ``ψ(λ) = 1/|c(λ)| - 1`` with ``|c(λ)|² = Σ g_k² / (e_k + λ)²`` in the
    eigenbasis of ``S`` (eigenvalues ``e_1 <= e_2``, ``g = Vᵀ h``), started where ``ψ <= 0``:
    ``ψ`` is concave and increasing on ``(-e_1, ∞)``, so the iterates increase monotonically
    to the root. In the "hard case" (``g_1 = 0`` and ``|c(-e_1)| < 1``) the answer is
    ``-e_1``."""
    # Eigen-decomposition of the symmetric 2×2 S in closed form.
    mid, rad = 0.5 * (s11 + s22), math.hypot(0.5 * (s11 - s22), s12)
    e1, e2 = mid - rad, mid + rad
    phi = 0.5 * math.atan2(2.0 * s12, s11 - s22)  # direction of the larger eigenvalue e2
    v2x, v2y = math.cos(phi), math.sin(phi)
    g2 = h1 * v2x + h2 * v2y
    g1 = -h1 * v2y + h2 * v2x  # component along the eigenvector of e1
    norm_h = math.hypot(h1, h2)
    scale = max(abs(e1), abs(e2), norm_h, 1e-300)
    eps = 1e-12 * scale  # λ is known to rounding of the problem's scale, not of λ itself
    # |c| = 1 needs |h| / (e1 + λ) >= 1 >= |h| / (e2 + λ) (|c| lies between the two), so
    # λ ∈ [|h| - e2, |h| - e1]; start at the left end, kept right of the pole at -e1.
    lam = max(norm_h - e2, -e1 + eps)
    for _ in range(60):
        u1, u2 = e1 + lam, e2 + lam
        c2 = (g1 / u1) ** 2 + (g2 / u2) ** 2
        if c2 <= 1.0 and lam <= -e1 + eps and abs(g1) <= eps:
            return -e1  # hard case: no pole at -e1 and |c| < 1 already there
        norm_c = math.sqrt(c2)
        psi = 1.0 / norm_c - 1.0
        # d|c|²/dλ = -2 Σ g_k² / u_k³,  so  dψ/dλ = Σ (g_k² / u_k³) / |c|³
        dpsi = (g1 * g1 / u1**3 + g2 * g2 / u2**3) / (c2 * norm_c)
        if not dpsi > 0.0:
            return lam
        step = -psi / dpsi
        lam += step
        if abs(step) <= eps:
            return lam
    return lam


def point_to_line_step(
    current: FloatArray, reference: FloatArray, normals: FloatArray
) -> FloatArray:
    """The pose ``(x, y, θ)`` minimising ``Σ (n_iᵀ (R(θ) q_i + t - p_i))²`` exactly, for
    ``current (m, 2)`` points ``q``, reference points ``p (m, 2)`` on the lines and unit
    ``normals (m, 2)`` (Censi's closed form, module docstring); a zero normal drops its row
    (its reference point must still be finite). Raises
    ``MatchError("degenerate")`` when the normals do not span the plane (``A`` singular)."""
    m = current.shape[0]
    phi = np.empty((m, 4))
    phi[:, :2] = normals
    phi[:, 2] = np.einsum("ij,ij->i", normals, current)
    phi[:, 3] = normals[:, 1] * current[:, 0] - normals[:, 0] * current[:, 1]
    b = np.einsum("ij,ij->i", normals, reference)
    (m00, m01, m02, m03), (_, m11, m12, m13), (_, _, m22, m23), (_, _, _, m33) = (
        phi.T @ phi
    ).tolist()
    vt0, vt1, vc0, vc1 = (phi.T @ b).tolist()
    det_a = m00 * m11 - m01 * m01
    if not det_a > 1e-12 * (m00 + m11) ** 2:
        raise MatchError(_NOT_SPANNED, "degenerate")
    # A⁻¹ = [[m11, -m01], [-m01, m00]] / det A;  B = [[m02, m03], [m12, m13]]
    i00, i01, i11 = m11 / det_a, -m01 / det_a, m00 / det_a
    k00, k01 = i00 * m02 + i01 * m12, i00 * m03 + i01 * m13  # A⁻¹ B
    k10, k11 = i01 * m02 + i11 * m12, i01 * m03 + i11 * m13
    s11 = m22 - (m02 * k00 + m12 * k10)  # S = D - Bᵀ A⁻¹ B
    s12 = m23 - (m02 * k01 + m12 * k11)
    s22 = m33 - (m03 * k01 + m13 * k11)
    h1 = vc0 - (k00 * vt0 + k10 * vt1)  # h = v_c - (A⁻¹ B)ᵀ v_t
    h2 = vc1 - (k01 * vt0 + k11 * vt1)
    lam = largest_real_root(s11, s12, s22, h1, h2)
    # c = (adj S + λ I) h / p(λ); only its direction is needed (p(λ) > 0 at the minimum)
    c0 = (s22 + lam) * h1 - s12 * h2
    c1 = -s12 * h1 + (s11 + lam) * h2
    if c0 == 0.0 and c1 == 0.0:  # h = 0: no rotation is preferred; keep cos θ = 1
        c0 = 1.0
    theta = math.atan2(c1, c0)
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    # t = A⁻¹ (v_t - B c)
    r0 = vt0 - (m02 * cos_t + m03 * sin_t)
    r1 = vt1 - (m12 * cos_t + m13 * sin_t)
    return np.array([i00 * r0 + i01 * r1, i01 * r0 + i11 * r1, theta])


_LoopOutput = tuple[int, int, int, FloatArray, FloatArray, float]


def plicp_loop_numpy(
    ref: PreparedScan, q: FloatArray, pose: FloatArray, cfg: PlIcpConfig, joined: NDArray[np.bool_]
) -> _LoopOutput:
    """The correspondence loop and the covariance in NumPy, from ``pose = (x, y, θ)``: the
    path without numba and the oracle of :func:`slamkit.scanmatch.kernels.plicp_loop` (the
    same arguments in other packaging, the same outputs, the pose to 1e-9 m/rad and the
    covariance to 1e-9 of its largest entry: BLAS sums the step's products in another
    order; see there). ``joined (M - 1,)``: the segments no longer than ``max_gap`` and not
    of zero length."""
    P = ref.points
    m_ref = P.shape[0]
    n_cur = q.shape[0]
    # One lookup table indexed by the nearest point j1 (row m_ref: "no point within range"),
    # columns [prev point | next point | prev normal | next normal | point]: the scan
    # neighbours of j1 and the normals of the segments to them where a segment exists and is
    # no longer than max_gap; else a point so far away that it never wins and fails the
    # validity test (and a zero normal).
    far = 1e12
    table = np.zeros((m_ref + 1, 10))
    table[:, 0:4] = far
    table[m_ref, 8:10] = far
    table[1:m_ref, 0:2][joined] = P[:-1][joined]
    table[: m_ref - 1, 2:4][joined] = P[1:][joined]
    table[1:m_ref, 4:6][joined] = ref.segment_normals[joined]
    table[: m_ref - 1, 6:8][joined] = ref.segment_normals[joined]
    table[:m_ref, 8:10] = P
    twice = np.array([[1.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 1.0]])  # q' -> (q', q')
    pair_sum = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0]])
    tx, ty, th = float(pose[0]), float(pose[1]), float(pose[2])
    seen: set[bytes] = set()  # every correspondence set met so far
    it = n_keep = 0
    no_cov = np.zeros((3, 3))
    keep = valid = use_next = np.zeros(n_cur, dtype=bool)
    j1 = np.full(n_cur, m_ref, dtype=np.intp)
    for it in range(1, cfg.max_iterations + 1):
        c, s = math.cos(th), math.sin(th)
        moved = q @ np.array([[c, s], [-s, c]])  # rows R q_i
        moved += (tx, ty)
        _, j1 = ref.tree.query(moved, k=1, distance_upper_bound=cfg.max_correspondence_distance)
        rows = table.take(j1, axis=0)
        d = rows[:, 0:4] - moved @ twice  # (prev - q', next - q')
        d *= d
        d2 = d @ pair_sum  # squared distances to the prev, next point
        d_prev, d_next = d2[:, 0], d2[:, 1]
        use_next = d_next < d_prev
        valid = np.minimum(d_prev, d_next) < far  # j1 found and joined to a neighbour
        a = rows[:, 8:10]
        normals = np.where(use_next[:, None], rows[:, 6:8], rows[:, 4:6])
        err = np.abs(np.einsum("ij,ij->i", normals, moved - a))
        err = np.where(valid, err, np.inf)
        # Trimming by order statistics of one sorted copy: the median of the valid errors,
        # the adaptive limit, then the trim fraction of those within it.
        order = np.sort(err)
        n_valid = int(np.count_nonzero(valid))
        thr = -1.0
        if n_valid:
            limit = max(
                cfg.outlier_multiplier * float(order[(n_valid - 1) // 2]), cfg.outlier_floor
            )
            n_lim = int(np.searchsorted(order, limit, side="right"))
            n_t = math.ceil(cfg.trim_fraction * n_lim)
            thr = float(order[n_t - 1]) if n_t else -1.0
        keep = err <= thr
        n_keep = int(np.count_nonzero(keep))
        out = (np.array([tx, ty, th]), no_cov)
        if n_keep < cfg.min_correspondences:
            return (kernels.TOO_FEW, it, n_keep, *out, 0.0)
        if it == 1:
            lam = _min_eigenvalue_numpy(ref, q, j1, keep, th)
            if lam < 0.5 * cfg.min_eigenvalue:
                return (kernels.DEGENERATE_START, it, n_keep, *out, lam)
        stamp = j1.tobytes() + use_next.tobytes() + keep.tobytes()
        if stamp in seen:
            break  # pairs met before: the steps would repeat (a cycle)
        seen.add(stamp)
        # Dropped pairs get a zero normal, which zeroes their rows in the step's sums.
        try:
            new = point_to_line_step(q, a, normals * keep[:, None])
        except MatchError:
            return (kernels.DEGENERATE_STEP, it, n_keep, *out, 0.0)
        dth = math.remainder(float(new[2]) - th, 2.0 * math.pi)
        small = (
            math.hypot(float(new[0]) - tx, float(new[1]) - ty) < cfg.translation_tolerance
            and abs(dth) < cfg.rotation_tolerance
        )
        tx, ty, th = float(new[0]), float(new[1]), th + dth
        if small:
            break
    else:
        return (kernels.NO_CONVERGENCE, it, n_keep, np.array([tx, ty, th]), no_cov, 0.0)
    th = math.remainder(th, 2.0 * math.pi)
    pose = np.array([tx, ty, th])
    lam = _min_eigenvalue_numpy(ref, q, j1, keep, th)
    if lam < cfg.min_eigenvalue:
        return (kernels.DEGENERATE_END, it, n_keep, pose, no_cov, lam)
    j1v = j1[valid]
    j2 = np.where(use_next[valid], j1v + 1, j1v - 1)
    cov = point_to_line_covariance(q[valid], P[j1v], P[j2], j1v, j2, m_ref, pose, keep[valid])
    return (kernels.CONVERGED, it, n_keep, pose, cov, 0.0)


def _min_eigenvalue_numpy(
    ref: PreparedScan, q: FloatArray, j1: NDArray[np.intp], keep: NDArray[np.bool_], th: float
) -> float:
    """The normalised Hessian's smallest eigenvalue over the kept pairs whose nearest
    reference point has a normal, at heading ``th``."""
    j = np.minimum(j1, ref.points.shape[0] - 1)
    has = ref.has_normal[j] & keep
    return normalised_min_eigenvalue(line_jacobian(q[has], ref.normals[j[has]], th), q[has])


def _loop_compiled(
    ref: PreparedScan, q: FloatArray, pose: FloatArray, cfg: PlIcpConfig, joined: NDArray[np.bool_]
) -> _LoopOutput:
    """:func:`plicp_loop_numpy`'s arguments as :func:`slamkit.scanmatch.kernels.plicp_loop`
    takes them."""
    initial = np.array([float(pose[0]), float(pose[1]), float(pose[2])])
    out: _LoopOutput = kernels.plicp_loop(
        ref.points, ref.segment_normals, joined, ref.has_normal, ref.normals, writable(q),
        initial, _settings_values(cfg),
    )  # fmt: skip
    return out


@functools.lru_cache(maxsize=64)
def _settings_values(cfg: PlIcpConfig) -> FloatArray:
    """``cfg``'s numbers in the order of :class:`slamkit.scanmatch.kernels.PlicpSettings`
    (read-only; one array per config)."""
    values = np.array(
        [
            cfg.max_iterations, cfg.max_correspondence_distance, cfg.outlier_multiplier,
            cfg.outlier_floor, cfg.trim_fraction, cfg.min_correspondences,
            cfg.translation_tolerance, cfg.rotation_tolerance, cfg.min_eigenvalue,
        ],
        dtype=np.float64,
    )  # fmt: skip
    values.flags.writeable = False
    return values


_plicp_loop = SEAM.pair(compiled=_loop_compiled, oracle=plicp_loop_numpy)
"""The loop, compiled under numba, else in NumPy (:mod:`slamkit.backend`)."""


def plicp(
    reference: ArrayLike | PreparedScan,
    current: ArrayLike,
    initial: ArrayLike = (0.0, 0.0, 0.0),
    config: PlIcpConfig | None = None,
) -> MatchResult:
    """Register ``current (K, 2)`` points (current sensor frame, metres) to ``reference``
    (``(M, 2)`` points in the reference frame **in scan order**, or a :class:`PreparedScan`
    of them) by point-to-line ICP from ``initial = T_ref_cur`` guess ``(x, y, θ)``.

    Returns a :class:`~slamkit.scanmatch.MatchResult` (``method="plicp"``; ``score`` and
    ``inlier_fraction`` are the fraction of current points kept at the end; the covariance is
    Censi's implicit-function estimate for the final point-to-line problem, the range noise
    estimated from the residuals: :func:`slamkit.scanmatch.covariance.point_to_line_covariance`).
    Raises ``MatchError`` with reason ``"too_few_points"``, ``"too_few_correspondences"``,
    ``"degenerate"`` or ``"no_convergence"``; ``ShapeError``/``NonFiniteError`` for
    malformed arrays.

    With numba installed the loop runs compiled (:mod:`slamkit.scanmatch.kernels`), else
    :func:`plicp_loop_numpy`, with the same results to rounding (:mod:`slamkit.backend`).
    """
    cfg = _DEFAULT if config is None else config
    ref = reference if isinstance(reference, PreparedScan) else prepare_scan(reference)
    q = require_points(as_array(current, "current points", (None, 2)), cfg.min_points, "current")
    x0 = as_array(initial, "initial pose", (3,))
    joined = (ref.gaps <= cfg.max_gap) & (ref.gaps > 0.0)
    status, it, n_keep, pose, cov, lam = _plicp_loop(ref, q, x0, cfg, joined)
    if status == kernels.TOO_FEW:
        raise MatchError(
            f"plicp: {n_keep} correspondences after trimming at iteration {it}; at least "
            f"{cfg.min_correspondences} are needed",
            "too_few_correspondences",
        )
    if status == kernels.DEGENERATE_START:
        raise degenerate_error(lam, 0.5 * cfg.min_eigenvalue, "plicp")
    if status == kernels.DEGENERATE_STEP:
        raise MatchError(_NOT_SPANNED, "degenerate")
    if status == kernels.NO_CONVERGENCE:
        raise MatchError(
            f"plicp: no convergence within {cfg.max_iterations} iterations",
            "no_convergence",
        )
    if status == kernels.DEGENERATE_END:
        raise degenerate_error(lam, cfg.min_eigenvalue, "plicp")
    frac = n_keep / q.shape[0]
    return MatchResult(pose, cov, frac, frac, it, "plicp")
