"""GPS fixes in SEIF: an information update on the pose block, through the χ² gate, and the
one-off move of ``(Ω, ξ, μ)`` into the GPS frame. The measurement, the gate's threshold, the
collection of fixes for the frame and the path in the GPS frame are every filter's
(:mod:`slamkit.estimation.gps`).

**The update.** A fix measures ``h(x) = t + R(θ) o`` of the pose alone (``H = [H_r, 0, …]``,
``H_r`` :func:`~slamkit.estimation.gps.antenna_measurement`'s Jacobian). Linearised at the
running mean ``μ_r``, ``z ≈ h(μ_r) + H_r (x_r − μ_r)``, so as every SEIF measurement::

    Ω_rr += H_rᵀ R⁻¹ H_r          ξ_r += H_rᵀ R⁻¹ (ν + H_r μ_r),   ν = z − h(μ_r)

Only the 3 × 3 pose block and the pose's 3 entries of ``ξ`` change: no link is made, so the
matrix stays as sparse as it was. The running mean then moves by the usual amortised
relaxation.

**The gate.** ``d² = νᵀ (H_r Σ_rr H_rᵀ + R)⁻¹ ν`` with ``Σ_rr`` the pose's covariance from the
information over its Markov blanket (the robot and the active landmarks, as the association
recovers it), refused above ``χ²₂(p)``.

**The frame.** The move ``μ' = J μ + c`` (``J`` the rotation on every position and 1 on the
heading; ``c`` the shift on every position and the angle on the heading) is linear, so the
Gaussian's information moves exactly: ``Ω' = J⁻ᵀ Ω J⁻¹ = J Ω Jᵀ`` (``J`` orthogonal) and
``ξ' = Ω' μ' = J Ω Jᵀ (J μ + c) = J ξ + Ω' c`` — no mean recovery needed. The fit's own
error, which EKF-SLAM adds to its covariance as an error every position shares, is left out
here: in information form it would link every landmark to every other (the Woodbury
correction of a rank-3 covariance term over the whole state). With σ = 1 m fixes over 50 m
it is ~0.1 m and ~0.005 rad, so SEIF starts in the GPS frame that much more sure of itself.
"""

from __future__ import annotations

import math

import numpy as np

from slamkit._validation import FloatArray
from slamkit.estimation.gps import antenna_measurement

__all__ = ["fix_distance", "gps_information_update", "move_information"]


def fix_distance(
    mu_r: FloatArray, pose_cov: FloatArray, z: FloatArray, lever: FloatArray, R: FloatArray
) -> float:
    """``d²`` of the fix ``z (2,)`` for the pose mean ``mu_r (3,)`` with covariance
    ``pose_cov (3, 3)`` (module docstring)."""
    h, H = antenna_measurement(mu_r, lever)
    S = H @ pose_cov @ H.T + R
    nu = z - h
    return float(nu @ np.linalg.solve(S, nu))


def gps_information_update(
    Om: FloatArray, xi: FloatArray, mu: FloatArray, z: FloatArray, lever: FloatArray,
    R_inv: FloatArray,
) -> None:  # fmt: skip
    """Add the fix ``z``'s information to the pose block of ``Ω`` and ``ξ`` (in place),
    linearised at the running mean ``mu[:3]`` (module docstring)."""
    h, H = antenna_measurement(mu[:3], lever)
    HtRi = H.T @ R_inv
    Om[:3, :3] += HtRi @ H
    xi[:3] += HtRi @ (z - h + H @ mu[:3])


def move_information(
    Om: FloatArray, xi: FloatArray, mu: FloatArray, n: int, angle: float, shift: FloatArray
) -> None:
    """Move the first ``n`` entries of ``(Ω, ξ, μ)`` (pose, then landmarks) into another
    frame, ``p ← R(angle) p + shift`` for every position, ``θ ← θ + angle`` (in place;
    module docstring)."""
    c, s = math.cos(angle), math.sin(angle)
    J = np.eye(n)
    C = np.zeros(n)
    for a in [0, *range(3, n, 2)]:
        J[a : a + 2, a : a + 2] = [[c, -s], [s, c]]
        C[a : a + 2] = shift
    C[2] = angle
    O = J @ Om[:n, :n] @ J.T  # once per run: a dense product is fine
    O = 0.5 * (O + O.T)
    xi[:n] = J @ xi[:n] + O @ C
    mu[:n] = J @ mu[:n] + C
    Om[:n, :n] = O
