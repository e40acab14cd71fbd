"""Dead reckoning: integrate the motion model from the start, propagating the covariance.

No measurement is used, so the covariance grows without bound (``C ← A C Aᵀ + B Q Bᵀ``). It is
the baseline every filter must beat, and the simplest example of the :class:`Estimator`
protocol (see :mod:`slamkit.estimation.contract`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset
from slamkit.errors import ConfigError, InputError
from slamkit.estimation.belief import GaussianBelief, predict_unchecked
from slamkit.estimation.contract import EstimatorOutput, PoseEstimate
from slamkit.estimation.gaussian import check_covariance
from slamkit.estimation.shell import EstimatorShell

__all__ = ["DeadReckoning", "DeadReckoningConfig"]


@dataclass(frozen=True)
class DeadReckoningConfig:
    """Settings of :class:`DeadReckoning`."""

    motion_cov_scale: float = 1.0
    """Multiplies the data set's nominal control-noise covariance (1 = trust it as given)."""

    def __post_init__(self) -> None:
        if not self.motion_cov_scale >= 0:
            raise ConfigError(
                f"motion_cov_scale: expected a number >= 0, got {self.motion_cov_scale}"
            )


class DeadReckoning(EstimatorShell):
    """Integrates :class:`Control` or :class:`Odometry` events; ignores everything else."""

    name = "dead reckoning"

    def __init__(
        self, dataset: Dataset, config: DeadReckoningConfig, rng: np.random.Generator
    ) -> None:
        if dataset.motion is None:
            raise InputError(f"dead reckoning needs a motion model; {dataset.name} has none")
        self._motion = dataset.motion
        self._Q = config.motion_cov_scale * dataset.motion.noise_cov
        start = dataset.initial_pose if dataset.initial_pose is not None else np.zeros(3)
        self._belief = GaussianBelief.from_pose(start, dataset.initial_cov)
        self._steps = 0
        super().__init__()

    def on_control(self, u: FloatArray, dt: float) -> None:
        # The Dataset validated u and dt, MotionSpec the noise: no re-checks per step.
        self._belief = predict_unchecked(self._belief, u, dt, self._motion.model, self._Q)
        self._steps += 1

    def after_event(self, step: int) -> None:
        # the check every Gaussian filter shares (a prediction can only carry a bad
        # covariance forward, or overflow)
        check_covariance(self._belief.cov, "dead reckoning")

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(self._belief.pose, self._belief.pose_cov)

    def finish(self) -> EstimatorOutput:
        return EstimatorOutput(diagnostics={"motion_steps": self._steps})
