"""The pipeline estimator :class:`EkfMapping`: EKF landmark mapping with known poses."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, Event, LandmarkReadings
from slamkit.errors import InputError
from slamkit.estimation.contract import EstimatorOutput, InnovationLog, PoseEstimate
from slamkit.mapping.ekf_mapping.beliefs import LandmarkBelief
from slamkit.mapping.ekf_mapping.config import EkfMappingConfig
from slamkit.mapping.ekf_mapping.inputs import require_invertible
from slamkit.mapping.ekf_mapping.readings import (
    DISCARDED,
    INITIALISED,
    TOO_CLOSE,
    UPDATED,
    process_readings_unchecked,
)
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.prob import chi2_gate

__all__ = ["EkfMapping"]


class EkfMapping:
    """EKF landmark mapping with KNOWN poses, as an estimator of the pipeline.

    The robot pose at each event is read from ``dataset.truth`` by time stamp — the one
    estimator allowed to do so, because mapping with known poses assumes exactly that. The
    landmark map is estimated from the :class:`~slamkit.datasets.LandmarkReadings` events with
    the block-diagonal EKF of :mod:`slamkit.mapping.ekf_mapping`; every other event only moves
    the current time. :meth:`estimate` returns the known pose with a zero covariance.

    Works with any landmark sensor whose model has an inverse (``"range-bearing"``,
    ``"position"``); range-only and bearing-only sensors raise :class:`InputError` (a single
    reading does not locate a landmark).
    """

    def __init__(
        self, dataset: Dataset, config: EkfMappingConfig, rng: np.random.Generator
    ) -> None:
        sensor = dataset.landmark_sensor
        if sensor is None:
            raise InputError(f"EKF mapping needs a landmark sensor; {dataset.name} has none")
        if not isinstance(sensor.model(), InvertibleLandmarkModel):
            raise InputError(
                f"EKF mapping cannot use the {sensor.kind!r} sensor of {dataset.name}: one "
                "reading does not locate a landmark, so a first sighting cannot be "
                "initialised (use range-bearing or position readings)"
            )
        truth = dataset.truth
        if truth.times is None or truth.poses is None or truth.times.size == 0:
            raise InputError(
                f"EKF mapping with known poses needs the true trajectory; {dataset.name} has none"
            )
        self._config = config
        self._model = require_invertible(sensor.model())
        self._R = config.noise_scale * sensor.noise_cov
        m = self._model.dim
        self._gate = chi2_gate(m, config.gate_probability)
        self._new_gate = chi2_gate(m, config.new_landmark_probability)
        self._times = truth.times
        self._poses = truth.poses
        self._pose = truth.poses[0].copy()
        self._belief = LandmarkBelief.empty()
        self._log_t: list[FloatArray] = []
        self._log_ids: list[NDArray[np.int64]] = []
        self._log_status: list[NDArray[np.int64]] = []
        self._log_nis: list[FloatArray] = []

    def _pose_at(self, t: float) -> FloatArray | None:
        i = int(np.searchsorted(self._times, t))
        best: int | None = None
        for j in (i - 1, i):
            if 0 <= j < self._times.size and (
                best is None or abs(self._times[j] - t) < abs(self._times[best] - t)
            ):
                best = j
        if best is None or abs(self._times[best] - t) > self._config.pose_time_tolerance:
            return None
        return self._poses[best]

    def handle(self, event: Event) -> None:
        pose = self._pose_at(event.t)
        if pose is not None:
            self._pose = pose.copy()
        if not isinstance(event, LandmarkReadings):
            return
        if pose is None:
            raise InputError(
                f"EKF mapping with known poses: no true pose within "
                f"{self._config.pose_time_tolerance:g} s of the readings at t={event.t}"
            )
        z = np.asarray(event.z, dtype=np.float64)
        ids = np.asarray(event.ids, dtype=np.int64)
        if not self._config.use_ids:
            ids = np.full(ids.shape, -1, dtype=np.int64)
        # The Dataset validated z and the constructor R and the model: call the kernel.
        self._belief, outcome = process_readings_unchecked(
            self._belief,
            pose,
            z,
            ids,
            self._R,
            self._model,
            self._gate,
            self._new_gate,
            self._config.min_range,
        )
        self._log_t.append(np.full(ids.size, float(event.t)))
        self._log_ids.append(outcome.landmark_ids)
        self._log_status.append(outcome.status)
        self._log_nis.append(outcome.nis)

    def estimate(self) -> PoseEstimate:
        """The known (true) pose at the current time, with a zero covariance."""
        return PoseEstimate(self._pose.copy(), np.zeros((3, 3)))

    @property
    def belief(self) -> LandmarkBelief:
        """The current map belief (block-diagonal form)."""
        return self._belief

    def reading_log(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading handled so far, in stream order: ``(times, landmark ids, status)``;
        the id is the landmark the reading updated or started, ``-1`` if it was rejected;
        status codes as in :class:`ReadingsOutcome`."""
        return (
            _cat(self._log_t, np.float64),
            _cat(self._log_ids, np.int64),
            _cat(self._log_status, np.int64),
        )

    def finish(self) -> EstimatorOutput:
        times, ids, status = self.reading_log()
        nis = _cat(self._log_nis, np.float64)
        upd = status == UPDATED
        log = InnovationLog(
            times=times[upd],
            nis=nis[upd],
            dof=np.full(int(upd.sum()), self._model.dim, dtype=np.int64),
            landmark_ids=ids[upd],
        )
        diagnostics: dict[str, Any] = {
            "known_poses": True,
            "n_landmarks": len(self._belief),
            "n_readings": int(status.size),
            "n_updates": int(upd.sum()),
            "n_new_landmarks": int(np.count_nonzero(status == INITIALISED)),
            "n_rejected": int(np.count_nonzero(status == DISCARDED)),
            "n_too_close": int(np.count_nonzero(status == TOO_CLOSE)),
            "mean_nis": float(nis[upd].mean()) if upd.any() else None,
        }
        return EstimatorOutput(
            landmarks=self._belief.to_landmark_estimate(),
            innovations=log,
            diagnostics=diagnostics,
        )


def _cat(parts: Sequence[NDArray[Any]], dtype: type) -> NDArray[Any]:
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype=dtype)
