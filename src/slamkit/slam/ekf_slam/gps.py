"""GPS fixes in EKF-SLAM: the antenna's position as a measurement of the pose, through the
χ² gate, and the one-off move of the filter's state into the GPS frame. The measurement, the
gate, the collection of fixes for the frame and the path in the GPS frame are every filter's
(:mod:`slamkit.estimation.gps`); here is what the EKF's state does with them.

**The update.** The EKF's state is additive, so ``H = [H_r, 0, …, 0]`` with ``H_r`` the
antenna's derivative (:func:`~slamkit.estimation.gps.antenna_measurement`), and
``H Σ = H_r Σ[0:3, :]`` needs the pose's three rows only: the update reads and writes the
covariance once, as a landmark update does (:func:`~slamkit.slam.ekf_slam.update.
gain_update_inplace`, the Joseph form).

**The frame.** The fit (:class:`~slamkit.estimation.gps.FrameFit`) moves the whole state
(:func:`move_state_inplace`: every position rotated and shifted, the heading turned, the
covariance ``J Σ Jᵀ``), and the fit's own uncertainty is added to the covariance as the
error every position shares (:func:`add_frame_uncertainty`).
"""

from __future__ import annotations

import math

import numpy as np

from slamkit._validation import FloatArray
from slamkit.estimation.gaussian import small_spd_inverse
from slamkit.estimation.gps import (
    ALIGN_MIN_FIXES,
    ALIGN_SPAN,
    GPS_COUNTS,
    REFUSED_SHARE,
    FrameAligner,
    GpsFrontEnd,
    antenna_measurement,
    gps_warnings,
)
from slamkit.slam.ekf_slam.update import gain_update_inplace

__all__ = [
    "ALIGN_MIN_FIXES",
    "ALIGN_SPAN",
    "GPS_COUNTS",
    "REFUSED_SHARE",
    "FrameAligner",
    "GpsFusion",
    "add_frame_uncertainty",
    "antenna_measurement",
    "gps_update_inplace",
    "gps_warnings",
    "move_state_inplace",
]


def gps_update_inplace(
    mean: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    lever: FloatArray,
    R: FloatArray,
    gate: float,
    scratch: FloatArray,
) -> tuple[float, bool]:
    """Update the active state (``mean (n,)``, ``cov (n, n)``, pose first) with the fix
    ``z (2,)`` of covariance ``R (2, 2)`` unless its ``d²`` exceeds ``gate``; returns
    ``(d², used)``. ``scratch`` holds at least ``n`` numbers."""
    h, Hr = antenna_measurement(mean[:3], lever)
    nu = z - h
    HS = Hr @ cov[:3, :]  # H Σ: the map's blocks of H are zero
    S = HS[:, :3] @ Hr.T + R
    S = 0.5 * (S + S.T)
    S_inv = small_spd_inverse(S, "ekf-slam gps update")
    assert S_inv is not None  # 2 × 2
    d2 = float(nu @ S_inv @ nu)
    if not d2 <= gate:
        return d2, False
    # slot 0: only the gain's "consider" branch and the symmetrised block read it, and the
    # block at 0 lies inside the pose block, symmetrised anyway.
    gain_update_inplace(mean, cov, 0, nu, HS, S, scratch)
    return d2, True


def _position_rows(n: int) -> FloatArray:
    """Index pairs ``(P, 2)`` of the positions in a state of size ``n``: pose, landmarks."""
    starts = np.concatenate(([0], np.arange(3, n, 2)))
    return np.stack([starts, starts + 1], axis=1)


def move_state_inplace(mean: FloatArray, cov: FloatArray, angle: float, shift: FloatArray) -> None:
    """Move the state into another frame: every position ``p ← R(angle) p + shift``, the
    heading ``θ ← θ + angle`` (wrapped), the covariance ``Σ ← J Σ Jᵀ`` with ``J`` block
    diagonal (``R(angle)`` for each position, 1 for the heading)."""
    n = mean.shape[0]
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    rows = _position_rows(n)
    pts = mean[rows]  # (P, 2)
    mean[rows] = pts @ rot.T + shift
    mean[2] = (mean[2] + angle + math.pi) % (2.0 * math.pi) - math.pi
    J = np.eye(n)
    for a, b in rows:
        J[a : b + 1, a : b + 1] = rot
    cov[:, :] = J @ cov @ J.T  # once per run: a dense product is fine
    cov[:, :] = 0.5 * (cov + cov.T)


def add_frame_uncertainty(cov: FloatArray, mean: FloatArray, centre: FloatArray,
                          frame_cov: FloatArray) -> None:  # fmt: skip
    """``Σ ← Σ + A Σ_T Aᵀ``: the fitted frame's error ``δT = (δc, δφ)`` (a shift at
    ``centre`` and a turn about it, covariance ``frame_cov (3, 3)``) moves every position
    ``p`` by ``δc + δφ S (p − centre)`` and the heading by ``δφ``, so ``A``'s rows are
    ``[I, S (p − centre)]`` for a position and ``[0, 0, 1]`` for the heading."""
    n = mean.shape[0]
    A = np.zeros((n, 3))
    rows = _position_rows(n)
    d = mean[rows] - centre  # (P, 2)
    A[rows[:, 0], 0] = 1.0
    A[rows[:, 1], 1] = 1.0
    A[rows[:, 0], 2] = -d[:, 1]  # S d = (−d_y, d_x)
    A[rows[:, 1], 2] = d[:, 0]
    A[2, 2] = 1.0
    cov += A @ frame_cov @ A.T


class GpsFusion(GpsFrontEnd):
    """EKF-SLAM's GPS fusion, one object the estimator holds when its stream has fixes: the
    shared front end (:class:`~slamkit.estimation.gps.GpsFrontEnd`: counts, the move into
    the GPS frame, the path) on the filter's state (module docstring)."""

    def fix(self, mean: FloatArray, cov: FloatArray, t: float, z: FloatArray,
            scratch: FloatArray) -> None:  # fmt: skip
        """The fix ``z`` at ``t`` on the active state: collected for the move into the GPS
        frame until that is done, then fused through the gate."""
        if not self.aligned:
            fit = self.collect(t, z, mean[:3])
            if fit is not None:
                move_state_inplace(mean, cov, fit.angle, fit.shift)
                add_frame_uncertainty(cov, mean, fit.centre, fit.cov)
            return
        _, used = gps_update_inplace(mean, cov, z, self.lever, self.noise_cov, self.gate,
                                     scratch)  # fmt: skip
        self.judged(used)
