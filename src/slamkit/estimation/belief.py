"""Gaussian beliefs over the robot pose and the prediction step shared by every filter."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import ShapeError
from slamkit.geometry import wrap_angle
from slamkit.models import MotionModel, propagate_gaussian_unchecked

__all__ = ["GaussianBelief", "predict", "predict_unchecked"]


@dataclass(frozen=True)
class GaussianBelief:
    """``N(mean, cov)`` over a pose ``(x, y, theta)`` (or a longer state whose first three
    entries are the pose). The heading is kept wrapped; the covariance symmetric PSD.

    The public constructor validates (shape, finiteness, symmetric PSD). Filter steps build
    their results with :meth:`trusted`, which skips the eigenvalue check: their maths keeps
    the covariance PSD, and checking a large covariance at every step would cost more than
    the step itself.
    """

    mean: FloatArray
    cov: FloatArray

    def __post_init__(self) -> None:
        mean = as_array(self.mean, "belief mean", (None,)).copy()
        if mean.size < 3:
            raise ShapeError(f"belief mean: expected at least a pose (3 values), got {mean.size}")
        mean[2] = wrap_angle(mean[2])
        cov = as_covariance(self.cov, "belief cov", mean.size, semidefinite=True)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

    @classmethod
    def trusted(cls, mean: FloatArray, cov: FloatArray) -> GaussianBelief:
        """A belief from arrays a filter step computed: no copies, no checks (internal)."""
        obj = object.__new__(cls)
        object.__setattr__(obj, "mean", mean)
        object.__setattr__(obj, "cov", cov)
        return obj

    @classmethod
    def from_pose(cls, pose: ArrayLike, cov: ArrayLike | None = None) -> GaussianBelief:
        """A belief at ``pose``; ``cov`` defaults to zero (the start is known exactly)."""
        p = as_array(pose, "pose", (3,))
        return cls(p, np.zeros((3, 3)) if cov is None else np.asarray(cov, dtype=float))

    @property
    def pose(self) -> FloatArray:
        return self.mean[:3]

    @property
    def pose_cov(self) -> FloatArray:
        return self.cov[:3, :3]


def predict(
    belief: GaussianBelief,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    control_cov: ArrayLike,
) -> GaussianBelief:
    """The motion (prediction) step: ``mean ← g(mean, u, dt)``,
    ``cov ← G cov Gᵀ + V Q Vᵀ`` with ``G = ∂g/∂x``, ``V = ∂g/∂u`` at the old mean.

    This is also one step of dead reckoning. Only the pose block is touched when the state is
    longer than the pose (landmarks do not move), so the cost stays linear in its size.
    Validates ``u`` and ``control_cov``; estimators that validated them once call
    :func:`predict_unchecked` in their loops.
    """
    u_arr = as_array(u, "u", (model.control_dim,))
    Q = as_covariance(control_cov, "control_cov", model.control_dim, semidefinite=True)
    return predict_unchecked(belief, u_arr, dt, model, Q)


def predict_unchecked(
    belief: GaussianBelief,
    u: FloatArray,
    dt: float,
    model: MotionModel,
    control_cov: FloatArray,
) -> GaussianBelief:
    """:func:`predict` without validating ``u`` and ``control_cov`` (see there)."""
    if belief.mean.size == 3:
        mean, cov = propagate_gaussian_unchecked(model, belief.mean, belief.cov, u, dt, control_cov)
        return GaussianBelief.trusted(mean, cov)
    pose = belief.mean[:3]
    G, V = model.jacobians(pose, u, dt)
    mean = belief.mean.copy()
    mean[:3] = model.apply(pose, u, dt)
    cov = belief.cov.copy()
    # Pose block, then the pose-map cross-covariance (rows and the mirrored columns).
    P_rr = G @ belief.cov[:3, :3] @ G.T + V @ control_cov @ V.T
    cov[:3, :3] = 0.5 * (P_rr + P_rr.T)
    cov[:3, 3:] = G @ belief.cov[:3, 3:]
    cov[3:, :3] = cov[:3, 3:].T
    return GaussianBelief.trusted(mean, cov)
