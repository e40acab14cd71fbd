"""Least-squares localization: a static (single-shot) fix at every landmark event.

:class:`LeastSquaresLocalization` does not filter: every :class:`LandmarkReadings` event with
enough readings of known landmarks is solved on its own by
:func:`~slamkit.localization.static.localize_from_readings`, and the estimate becomes that fix
and its covariance. Between fixes it keeps the last fix, or — with
``predict_between`` and a data set that has a motion model — dead-reckons from it with
:func:`~slamkit.estimation.belief.predict`, so the covariance grows until the next fix
replaces it. Events whose geometry does not determine the pose are *refused* (counted) and
leave the estimate unchanged.

:func:`snapshot_errors` runs the same static solver over every landmark event of a data set
with a true trajectory and returns the per-event errors — the natural score of data sets of
independent snapshots such as ``mrclam-snapshots``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, LandmarkReadings
from slamkit.errors import ConfigError, GeometryError, InputError
from slamkit.estimation.belief import GaussianBelief, predict
from slamkit.estimation.contract import EstimatorOutput, PoseEstimate
from slamkit.estimation.shell import EstimatorShell
from slamkit.eval import associate, nees, pose_errors
from slamkit.localization.static import (
    MAX_CONDITION,
    MIN_READINGS,
    UNIFORM_HEADING_VARIANCE,
    PoseFix,
    localize_from_readings,
)
from slamkit.maps import LandmarkMap

__all__ = [
    "LeastSquaresConfig",
    "LeastSquaresLocalization",
    "SnapshotErrors",
    "snapshot_errors",
]


@dataclass(frozen=True)
class LeastSquaresConfig:
    """Settings of :class:`LeastSquaresLocalization`."""

    predict_between: bool = True
    """Dead-reckon from the last fix with the data set's motion model between fixes (when it
    has one); otherwise hold the last fix unchanged."""
    motion_cov_scale: float = 1.0
    """Multiplies the data set's nominal control-noise covariance when dead-reckoning."""
    max_condition: float = MAX_CONDITION
    """Refuse a fix when the Jacobi-scaled normal matrix has a larger condition number."""
    unknown_position_sigma: float = 1e3
    """Standard deviation (m) of the reported position before the first fix when the data set
    has no prior (the reported pose is then the origin with a uniform heading)."""

    def __post_init__(self) -> None:
        if not self.motion_cov_scale >= 0:
            raise ConfigError(
                f"motion_cov_scale: expected a number >= 0, got {self.motion_cov_scale}"
            )
        if not self.max_condition > 1:
            raise ConfigError(f"max_condition: expected a number > 1, got {self.max_condition}")
        if not (np.isfinite(self.unknown_position_sigma) and self.unknown_position_sigma > 0):
            raise ConfigError(
                "unknown_position_sigma: expected a finite number > 0, got "
                f"{self.unknown_position_sigma}"
            )


def _check_dataset(dataset: Dataset) -> tuple[Any, LandmarkMap]:
    if dataset.landmark_sensor is None or dataset.known_landmarks is None:
        raise InputError(
            f"least-squares localization needs a landmark sensor and known landmarks; "
            f"{dataset.name} lacks "
            + ("a landmark sensor" if dataset.landmark_sensor is None else "a landmark map")
        )
    return dataset.landmark_sensor, dataset.known_landmarks


class LeastSquaresLocalization(EstimatorShell):
    """A static least-squares fix at every landmark event (see the module docstring).

    ``finish()`` reports ``fixes`` (events solved), ``refused`` (degenerate geometry),
    ``not_converged`` (Gauss–Newton hit its iteration limit; the fix is not used),
    ``too_few_readings`` (fewer usable readings than the sensor kind needs),
    ``motion_steps`` and ``mean_iterations`` of the solved events.
    """

    name = "least squares"

    def __init__(
        self, dataset: Dataset, config: LeastSquaresConfig, rng: np.random.Generator
    ) -> None:
        self._sensor, self._map = _check_dataset(dataset)
        self._config = config
        self._motion = dataset.motion if config.predict_between else None
        self._Q = None if self._motion is None else config.motion_cov_scale * self._motion.noise_cov
        if dataset.initial_pose is not None:
            self._belief = GaussianBelief.from_pose(dataset.initial_pose, dataset.initial_cov)
        else:
            s2 = config.unknown_position_sigma**2
            self._belief = GaussianBelief(np.zeros(3), np.diag([s2, s2, UNIFORM_HEADING_VARIANCE]))
        self._need = MIN_READINGS[self._sensor.kind]
        super().__init__()
        self._counts = {
            "fixes": 0,
            "refused": 0,
            "not_converged": 0,
            "too_few_readings": 0,
            "motion_steps": 0,
        }
        self._iterations = 0

    def on_control(self, u: FloatArray, dt: float) -> None:
        if self._motion is not None and self._Q is not None:
            self._belief = predict(self._belief, u, dt, self._motion.model, self._Q)
            self._counts["motion_steps"] += 1

    def on_landmarks(self, event: LandmarkReadings) -> None:
        if int(np.count_nonzero(np.asarray(event.ids) >= 0)) < self._need:
            self._counts["too_few_readings"] += 1
            return
        try:
            fix = localize_from_readings(
                event.z,
                event.ids,
                self._sensor,
                self._map,
                max_condition=self._config.max_condition,
            )
        except GeometryError:
            self._counts["refused"] += 1
            return
        if not fix.converged:
            self._counts["not_converged"] += 1
            return
        self._belief = GaussianBelief(fix.pose, fix.cov)
        self._counts["fixes"] += 1
        self._iterations += fix.iterations

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(self._belief.pose, self._belief.pose_cov)

    def finish(self) -> EstimatorOutput:
        diagnostics: dict[str, Any] = dict(self._counts)
        fixes = self._counts["fixes"]
        diagnostics["mean_iterations"] = self._iterations / fixes if fixes else 0.0
        return EstimatorOutput(diagnostics=diagnostics)


@dataclass(frozen=True)
class SnapshotErrors:
    """Per-event errors of static fixes against the true poses at the same times.

    ``times (N,)`` of the solved events, ``errors (N, 3)`` = fix − truth as
    ``(dx, dy, wrapped dθ)`` (:func:`~slamkit.eval.pose_errors`), ``nees (N,)`` of each
    error under its fix's covariance, ``refused_times`` of the events that were refused
    (degenerate, too few readings, or not converged).
    """

    times: FloatArray
    errors: FloatArray
    nees: FloatArray
    refused_times: FloatArray

    @property
    def position_errors(self) -> FloatArray:
        """Euclidean position error of each fix (m)."""
        return np.asarray(np.hypot(self.errors[:, 0], self.errors[:, 1]), dtype=float)

    @property
    def heading_errors(self) -> FloatArray:
        """Absolute heading error of each fix (rad)."""
        return np.abs(self.errors[:, 2])

    def summary(self) -> dict[str, Any]:
        """Median, 90th percentile and maximum of the position (m) and heading (rad) errors,
        the mean NEES and the counts — JSON-able."""
        out: dict[str, Any] = {
            "solved": int(self.times.size),
            "refused": int(self.refused_times.size),
        }
        for name, vals in (("position", self.position_errors), ("heading", self.heading_errors)):
            if vals.size:
                out[name] = {
                    "median": float(np.median(vals)),
                    "p90": float(np.percentile(vals, 90)),
                    "max": float(vals.max()),
                }
        if self.nees.size:
            out["mean_nees"] = float(self.nees.mean())
        return out


def snapshot_errors(
    dataset: Dataset, *, max_condition: float = MAX_CONDITION, max_dt: float = 0.0
) -> SnapshotErrors:
    """Solve every landmark event of ``dataset`` on its own and compare with the truth.

    Each :class:`LandmarkReadings` event is localized by
    :func:`~slamkit.localization.static.localize_from_readings` and compared with the true
    pose at the same time (within ``max_dt`` seconds). For range-only sensors the heading of
    a fix is not determined, so compare only the position errors. Raises
    :class:`~slamkit.errors.InputError` if the data set has no landmark sensor, no known
    landmarks or no true trajectory, or an event has no true pose within ``max_dt``.
    """
    sensor, landmarks = _check_dataset(dataset)
    truth = dataset.truth
    if truth.times is None or truth.poses is None:
        raise InputError(f"snapshot errors need a true trajectory; {dataset.name} has none")
    need = MIN_READINGS[sensor.kind]
    times: list[float] = []
    fixes: list[PoseFix] = []
    refused: list[float] = []
    for ev in dataset.of_type(LandmarkReadings):
        assert isinstance(ev, LandmarkReadings)
        if int(np.count_nonzero(np.asarray(ev.ids) >= 0)) < need:
            refused.append(ev.t)
            continue
        try:
            fix = localize_from_readings(
                ev.z, ev.ids, sensor, landmarks, max_condition=max_condition
            )
        except GeometryError:
            refused.append(ev.t)
            continue
        if not fix.converged:
            refused.append(ev.t)
            continue
        times.append(ev.t)
        fixes.append(fix)
    t = np.asarray(times, dtype=float)
    ia, ib = associate(t, truth.times, max_dt)
    if ia.size != t.size:
        raise InputError(
            f"snapshot errors: {t.size - ia.size} event(s) have no true pose within {max_dt} s"
        )
    poses = np.array([f.pose for f in fixes]).reshape(-1, 3)
    covs = np.array([f.cov for f in fixes]).reshape(-1, 3, 3)
    err = pose_errors(poses, truth.poses[ib])
    return SnapshotErrors(t, err, nees(err, covs) if t.size else np.zeros(0), np.asarray(refused))
