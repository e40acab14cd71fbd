"""GPS fixes in FastSLAM 1.0 and 2.0: a fix measures each particle's pose, never its map.

The measurement, the gate's threshold, the collection of fixes for the move into the GPS
frame, the counts and the path in the GPS frame are every filter's
(:mod:`slamkit.estimation.gps`); here is what a particle set does with them.

**Derivation.** FastSLAM factors the posterior as ``p(x_1:t | …) Π_j p(m_j | x_1:t, …)``.
A fix ``z = h(x_t) + n``, ``h(x) = t + R(θ) o`` (``o`` the lever arm), ``n ~ N(0, R)``,
depends on the pose alone, so given the path it says nothing about any landmark: every
particle's landmark EKFs stay as they are, and the fix enters only the path's particle
filter. Bayes' rule on the path gives each particle the factor ``p(z | x_t^[p])``:

* **FastSLAM 1.0** (poses sampled from the motion model, exact within a particle):
  ``w_p ← w_p N(z; h(x_p), R)``.
* **FastSLAM 2.0** keeps each particle's motion since its last scan as a Gaussian
  ``N(x̄_p, P_p)`` (:func:`~slamkit.slam.fastslam.proposal.fold_motion`). The fix is folded
  into that proposal as one more EKF measurement of the pose, linearised at ``x̄_p`` with
  ``H_p = ∂h/∂x`` (:func:`~slamkit.estimation.gps.antenna_measurements`)::

      L_p = H_p P_p H_pᵀ + R          (the fix's marginal covariance)
      K_p = P_p H_pᵀ L_p⁻¹,  x̄_p ← x̄_p + K_p ν_p,
      P_p ← (I − K_p H_p) P_p (I − K_p H_p)ᵀ + K_p R K_pᵀ      (Joseph form: stays PSD)

  and the weight takes the marginal likelihood with the pose integrated out,
  ``w_p ← w_p N(ν_p; 0, L_p)`` — the same chain rule as the readings' proposal. Nothing is
  sampled at the fix: the next scan's proposal starts from the updated Gaussian (the fix
  holds the pose as a control of zero length would), so it still covers all the motion
  since the last scan. Without motion since the scan (``P_p = 0``) this is 1.0's factor.

**The gate.** The predicted fix is the mixture ``Σ_p w_p N(h(x̄_p), L_p)``; its moments are
``h̄ = Σ w_p h_p`` and ``S = Σ w_p (L_p + (h_p − h̄)(h_p − h̄)ᵀ)`` (``L_p = R`` for exact poses),
and the fix is refused when ``d² = (z − h̄)ᵀ S⁻¹ (z − h̄)`` exceeds the threshold — the EKF's
test with the particles' spread in place of ``H Σ Hᵀ``. A refused fix changes no weight
(a multipath jump of 20 m would otherwise wipe out every particle but the nearest).

**The frame.** At the move into the GPS frame every particle — its pose and its whole map —
is moved rigidly by the fitted transform composed with its own draw of the fit's error
(:func:`frame_draws`): the particles carry the frame's uncertainty as the EKF's covariance
does (:func:`~slamkit.slam.ekf_slam.gps.add_frame_uncertainty`), as an error every position
of one particle shares.
"""

from __future__ import annotations

import numpy as np

from slamkit._validation import FloatArray
from slamkit.estimation.gps import FrameFit, antenna_measurements
from slamkit.geometry.angles import wrap_angle
from slamkit.slam.fastslam.particles import LOG_2PI

__all__ = ["fix_distance", "fix_update", "frame_draws", "move_gaussians", "move_poses"]


def _inv_logdet2(S: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Inverses and log-determinants of SPD 2×2 matrices ``(..., 2, 2)`` in closed form."""
    a, b, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
    det = a * d - b * b
    inv = np.empty_like(S)
    inv[..., 0, 0] = d / det
    inv[..., 1, 1] = a / det
    inv[..., 0, 1] = inv[..., 1, 0] = -b / det
    return inv, np.log(det)


def _marginals(
    means: FloatArray, covs: FloatArray | None, lever: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``h_p (P, 2)``, ``H_p (P, 2, 3)`` and ``L_p = H_p P_p H_pᵀ + R (P, 2, 2)``."""
    h, H = antenna_measurements(means, lever)
    if covs is None:
        L = np.broadcast_to(R, (means.shape[0], 2, 2)).copy()
    else:
        L = H @ covs @ np.swapaxes(H, -1, -2) + R
        L = 0.5 * (L + np.swapaxes(L, -1, -2))
    return h, H, L


def fix_distance(
    means: FloatArray, covs: FloatArray | None, weights: FloatArray, z: FloatArray,
    lever: FloatArray, R: FloatArray,
) -> float:  # fmt: skip
    """``d²`` of the fix ``z (2,)`` against the particles' predicted fix (module docstring:
    the gate) for poses ``means (P, 3)`` (with covariances ``covs (P, 3, 3)`` for 2.0's
    Gaussians, ``None`` for exact poses) and normalised ``weights (P,)``."""
    h, _, L = _marginals(means, covs, lever, R)
    hbar = weights @ h
    d = h - hbar
    S = np.einsum("p,pij->ij", weights, L) + np.einsum("p,pi,pj->ij", weights, d, d)
    nu = z - hbar
    return float(nu @ np.linalg.solve(S, nu))


def fix_update(
    means: FloatArray, covs: FloatArray | None, z: FloatArray, lever: FloatArray, R: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray | None]:  # fmt: skip
    """The fix ``z`` on each particle (module docstring): ``(log-likelihoods (P,), means,
    covariances)`` — the means and covariances updated (new arrays) when ``covs`` is given,
    ``means`` itself and ``None`` for exact poses."""
    h, H, L = _marginals(means, covs, lever, R)
    L_inv, logdet = _inv_logdet2(L)
    nu = z - h
    maha = np.einsum("pi,pij,pj->p", nu, L_inv, nu)
    loglik = -0.5 * (maha + logdet + 2.0 * LOG_2PI)
    if covs is None:
        return loglik, means, None
    Ht = np.swapaxes(H, -1, -2)
    K = covs @ Ht @ L_inv  # (P, 3, 2)
    new_means = means + np.einsum("pij,pj->pi", K, nu)
    new_means[:, 2] = wrap_angle(new_means[:, 2])
    A = np.eye(3) - K @ H
    new_covs = A @ covs @ np.swapaxes(A, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    return loglik, new_means, 0.5 * (new_covs + np.swapaxes(new_covs, -1, -2))


def frame_draws(fit: FrameFit, n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Each particle's move into the GPS frame, ``p ← R(angle_p) p + shift_p``: the fit
    composed with a draw ``(δc, δφ) ~ N(0, fit.cov)`` of its error (a shift at the centre
    ``c`` and a turn about it): ``angle_p = φ + δφ``,
    ``shift_p = c + δc + R(δφ)(shift − c)``. Returns ``angles (n,)``, ``shifts (n, 2)``."""
    d = rng.multivariate_normal(np.zeros(3), fit.cov, n, method="eigh")
    c, s = np.cos(d[:, 2]), np.sin(d[:, 2])
    r = fit.shift - fit.centre
    shifts = fit.centre + d[:, :2]
    shifts[:, 0] += c * r[0] - s * r[1]
    shifts[:, 1] += s * r[0] + c * r[1]
    return fit.angle + d[:, 2], shifts


def move_poses(poses: FloatArray, angles: FloatArray, shifts: FloatArray) -> FloatArray:
    """Poses ``(P, 3)`` moved, each by its own rigid transform (a new array)."""
    c, s = np.cos(angles), np.sin(angles)
    out = np.empty_like(poses)
    out[:, 0] = c * poses[:, 0] - s * poses[:, 1] + shifts[:, 0]
    out[:, 1] = s * poses[:, 0] + c * poses[:, 1] + shifts[:, 1]
    out[:, 2] = wrap_angle(poses[:, 2] + angles)
    return out


def move_gaussians(
    means: FloatArray, covs: FloatArray, angles: FloatArray, shifts: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Pose Gaussians ``(P, 3)``, ``(P, 3, 3)`` moved: means as :func:`move_poses`,
    ``P ← J P Jᵀ`` with ``J = diag(R(angle_p), 1)``."""
    J = np.zeros((angles.shape[0], 3, 3))
    J[:, 0, 0] = J[:, 1, 1] = np.cos(angles)
    J[:, 1, 0] = np.sin(angles)
    J[:, 0, 1] = -J[:, 1, 0]
    J[:, 2, 2] = 1.0
    moved = J @ covs @ np.swapaxes(J, -1, -2)
    return move_poses(means, angles, shifts), 0.5 * (moved + np.swapaxes(moved, -1, -2))
