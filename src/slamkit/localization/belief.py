"""Gaussian beliefs over the robot pose and the prediction step shared by every filter."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.geometry import wrap_angle
from slamkit.models import MotionModel, propagate_gaussian

__all__ = ["GaussianBelief", "predict"]


@dataclass(frozen=True)
class GaussianBelief:
    """``N(mean, cov)`` over a pose ``(x, y, theta)`` (or a longer state whose first three
    entries are the pose). The heading is kept wrapped; the covariance symmetric PSD."""

    mean: FloatArray
    cov: FloatArray

    def __post_init__(self) -> None:
        mean = as_array(self.mean, "belief mean", (None,)).copy()
        mean[2] = wrap_angle(mean[2])
        cov = as_covariance(self.cov, "belief cov", mean.size, semidefinite=True)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

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
    """
    if belief.mean.size == 3:
        mean, cov = propagate_gaussian(model, belief.mean, belief.cov, u, dt, control_cov)
        return GaussianBelief(mean, cov)
    G, V = model.jacobians(belief.mean[:3], u, dt)
    mean = belief.mean.copy()
    mean[:3] = model.apply(belief.mean[:3], u, dt)
    cov = belief.cov.copy()
    Q = np.asarray(control_cov, dtype=float)
    # Pose block, then the pose-map cross-covariance (rows and the mirrored columns).
    cov[:3, :3] = G @ belief.cov[:3, :3] @ G.T + V @ Q @ V.T
    cov[:3, 3:] = G @ belief.cov[:3, 3:]
    cov[3:, :3] = cov[:3, 3:].T
    return GaussianBelief(mean, cov)
