"""The systematic errors of the odometry and the laser's mounting, by least squares over the
laser's matched relative motions.

**The model.** A differential drive reports per step the wheel distances ``d_L``, ``d_R``
through its assumed radii and wheel base ``b``: ``d = (d_R + d_L) / 2``, ``a = (d_R - d_L) /
b``. When both radii are off by the same factor and the base by another, the true step is
``d_true = c_t d`` and ``a_true = c_r a`` with

    c_t = r_true / r_assumed,        c_r = (r_true / r_assumed) · (b_assumed / b_true),

so with the odometry's relative errors ``ε_r = r_assumed / r_true - 1`` and ``ε_b =
b_assumed / b_true - 1`` (the convention of :class:`~slamkit.sim.OdometryErrorModel`: the
reported distance is ``(1 + ε_r)`` times the true one, the reported turn ``(1 + ε_r) / (1 +
ε_b)`` times), ``ε_r = 1 / c_t - 1`` and ``ε_b = c_r / c_t - 1``. The data sets hold pose
increments, not wheel ticks, so the step is rewritten as ``(rot1, trans, rot2)`` and
corrected as ``(c_r rot1, c_t trans, c_r rot2)`` — exact for straight steps and turns on
the spot, and to second order in the step's turn on arcs.

The corrected steps integrate to the robot's motion ``T_Ra_Rb(c)`` between keyframe scans
``a`` and ``b``; the laser sits at ``M = (m_x, m_y, m_θ)`` on the robot, so it moves by

    T̂_La_Lb = M⁻¹ ⊕ T_Ra_Rb(c) ⊕ M,

whose position is ``R(m_θ)ᵀ [t_R + (R(φ) - I) m]`` (``φ`` the turn): ``m_θ`` shows in the
direction of straight travel, ``(m_x, m_y)`` only in turns (the lever arm swings), and the
scales in both. The residual of pair ``p`` is ``r_p = between(T̂_La_Lb, T_La_Lb)`` (the
match against the prediction, in the predicted laser frame), whitened by its covariance
``S_p`` (the matcher's plus the odometry noise's, :mod:`slamkit.calibration.noise`), and
``(c_t, c_r, M)`` minimise ``Σ_p r_pᵀ S_p⁻¹ r_p`` (``scipy.optimize.least_squares``, a
trust-region Gauss-Newton). Pairs beyond the χ²(3) 99.9 % bound are trimmed and the fit
repeated. The parameters' covariance is ``(Jᵀ J)⁻¹`` of the whitened problem, scaled by
``χ² / dof`` when that exceeds 1 (noise the weights under-state).

**What is identifiable.** From pose increments only the two scales: the mean radius scale
``c_t`` and the ratio ``c_r`` (radius over base); separate left and right radii would need
the wheels' own distances. The laser gives the scale (it measures metres); its yaw needs
straight travel, its position needs turns — a robot that never turns leaves ``(m_x, m_y)``
undetermined (their standard deviations say so). With ``fit_mounting=False`` the mounting
is held at the data set's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from slamkit._validation import FloatArray
from slamkit.calibration.noise import CHI2_3_999, TRIM_ROUNDS
from slamkit.errors import ConvergenceError
from slamkit.geometry.pose2 import between, compose, inverse
from slamkit.models import integrate_odometry, signed_odometry_steps

__all__ = [
    "SystematicFit",
    "corrected_steps",
    "fit_systematic",
    "pair_residuals",
]

PARAMETERS = ("translation_scale", "rotation_scale", "mount_x", "mount_y", "mount_yaw")


def corrected_steps(
    steps: FloatArray, translation_scale: float, rotation_scale: float
) -> FloatArray:
    """``(c_r rot1, c_t trans, c_r rot2)`` of the signed form
    (:func:`~slamkit.models.signed_odometry_steps`) of odometry steps ``(S, 3)``: the steps
    the wheels would have reported with the right radii and base (a backward step rolls the
    same wheels backward, scaled alike)."""
    u = signed_odometry_steps(steps)
    return np.column_stack(
        [rotation_scale * u[:, 0], translation_scale * u[:, 1], rotation_scale * u[:, 2]]
    )


def pair_residuals(
    steps: FloatArray,
    first: NDArray[np.int64],
    last: NDArray[np.int64],
    T_laser: FloatArray,
    params: FloatArray,
) -> FloatArray:
    """``r (P, 3)``: ``between(T̂_La_Lb, T_La_Lb)`` for ``params = (c_t, c_r, m_x, m_y,
    m_θ)`` (the module docstring)."""
    u = corrected_steps(steps, float(params[0]), float(params[1]))
    X = integrate_odometry(np.zeros(3), u)
    M = np.asarray(params[2:5], dtype=np.float64)
    predicted = compose(compose(inverse(M), between(X[first], X[last])), M)
    return between(predicted, T_laser)


@dataclass(frozen=True)
class SystematicFit:
    """The fitted ``(c_t, c_r, m_x, m_y, m_θ)`` with their covariance ``cov (5, 5)`` (the
    mounting's rows zero when it was held), the errors ``ε_r``, ``ε_b`` of the odometry
    (:class:`~slamkit.sim.OdometryErrorModel`'s convention) with standard deviations, the
    pairs used and trimmed, and the whitened ``χ² / dof`` before any scaling."""

    params: FloatArray
    cov: FloatArray
    fit_mounting: bool
    used: int
    trimmed: int
    chi2_per_dof: float

    @property
    def translation_scale(self) -> float:
        return float(self.params[0])

    @property
    def rotation_scale(self) -> float:
        return float(self.params[1])

    @property
    def mounting(self) -> tuple[float, float, float]:
        return (float(self.params[2]), float(self.params[3]), float(self.params[4]))

    @property
    def stds(self) -> FloatArray:
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))

    def wheel_errors(self) -> tuple[float, float, float, float]:
        """``(ε_r, σ(ε_r), ε_b, σ(ε_b))`` by the delta method: ``ε_r = 1/c_t - 1``,
        ``ε_b = c_r/c_t - 1``."""
        ct, cr = self.translation_scale, self.rotation_scale
        J = np.array([[-1.0 / ct**2, 0.0], [-cr / ct**2, 1.0 / ct]])
        C = J @ self.cov[:2, :2] @ J.T
        return 1.0 / ct - 1.0, float(np.sqrt(C[0, 0])), cr / ct - 1.0, float(np.sqrt(C[1, 1]))

    def as_dict(self) -> dict[str, object]:
        er, ser, eb, seb = self.wheel_errors()
        std = self.stds
        return {
            "values": {n: float(v) for n, v in zip(PARAMETERS, self.params, strict=True)},
            "stds": {n: float(v) for n, v in zip(PARAMETERS, std, strict=True)},
            "mounting_fitted": self.fit_mounting,
            "wheel_radius_error": er,
            "wheel_radius_error_std": ser,
            "wheel_base_error": eb,
            "wheel_base_error_std": seb,
            "pairs_used": self.used,
            "pairs_trimmed": self.trimmed,
            "chi2_per_dof": self.chi2_per_dof,
            "covariance": self.cov.tolist(),
        }


def _whitener(cov: FloatArray) -> FloatArray:
    """``L⁻¹`` with ``L Lᵀ = cov`` for each ``(P, 3, 3)``: ``L⁻¹ r`` has unit covariance."""
    L = np.linalg.cholesky(cov)
    return np.linalg.inv(L)  # 3 × 3 blocks: one small triangular inverse per pair


def fit_systematic(
    steps: FloatArray,
    first: NDArray[np.int64],
    last: NDArray[np.int64],
    T_laser: FloatArray,
    cov: FloatArray,
    start: FloatArray,
    *,
    fit_mounting: bool = True,
) -> SystematicFit:
    """The least-squares ``(c_t, c_r, M)`` of the module docstring, from ``start (5,)``, the
    pairs weighted by ``cov (P, 3, 3)`` (their residuals' covariance). With
    ``fit_mounting=False`` the mounting stays at ``start[2:]``."""
    start = np.asarray(start, dtype=np.float64)
    W = _whitener(cov)
    n_free = 5 if fit_mounting else 2
    keep = np.ones(first.size, dtype=bool)
    x = start[:n_free].copy()

    def full(v: FloatArray) -> FloatArray:
        return v if fit_mounting else np.concatenate([v, start[2:]])

    def whitened(v: FloatArray, mask: NDArray[np.bool_]) -> FloatArray:
        r = pair_residuals(steps, first[mask], last[mask], T_laser[mask], full(v))
        return np.einsum("pij,pj->pi", W[mask], r)

    res = None
    for round_ in range(TRIM_ROUNDS + 1):
        if int(keep.sum()) * 3 <= n_free:
            raise ConvergenceError(
                f"calibration: {int(keep.sum())} pairs left after trimming; too few for "
                f"{n_free} parameters"
            )
        res = least_squares(lambda v, m=keep: whitened(v, m).ravel(), x, method="trf",
                            x_scale=np.r_[1.0, 1.0, 0.1, 0.1, 0.1][:n_free])  # fmt: skip
        x = res.x
        if round_ == TRIM_ROUNDS:
            break
        new_keep = np.sum(whitened(x, np.ones(first.size, dtype=bool)) ** 2, axis=1) <= CHI2_3_999
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    assert res is not None
    r = whitened(x, keep).ravel()
    dof = max(r.size - n_free, 1)
    chi2 = float(r @ r) / dof
    JtJ = res.jac.T @ res.jac
    free_cov = np.linalg.pinv(JtJ) * max(chi2, 1.0)
    out_cov = np.zeros((5, 5))
    out_cov[:n_free, :n_free] = free_cov
    return SystematicFit(
        params=full(x),
        cov=out_cov,
        fit_mounting=fit_mounting,
        used=int(keep.sum()),
        trimmed=int((~keep).sum()),
        chi2_per_dof=chi2,
    )
