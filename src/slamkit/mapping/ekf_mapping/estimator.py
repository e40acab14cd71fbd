"""The pipeline estimator :class:`EkfMapping`: EKF landmark mapping with known poses."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, KnownPose, LandmarkReadings
from slamkit.errors import InputError
from slamkit.estimation.contract import EstimatorOutput, InnovationLog, LandmarkIds, PoseEstimate
from slamkit.estimation.shell import EstimatorShell
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


class EkfMapping(EstimatorShell):
    """EKF landmark mapping with KNOWN poses, as an estimator of the pipeline.

    The robot's pose arrives through the stream as :class:`~slamkit.datasets.KnownPose`
    events (:func:`slamkit.pipeline.run` adds them from the data set's true trajectory, one
    at the head of every time stamp); the estimator never reads ``truth``. The landmark map
    is estimated from the :class:`~slamkit.datasets.LandmarkReadings` events with the
    block-diagonal EKF of :mod:`slamkit.mapping.ekf_mapping`; other events are ignored.
    :meth:`estimate` returns the known pose with a zero covariance.

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
        if dataset.truth.poses is None:
            raise InputError(
                f"EKF mapping with known poses needs the true trajectory; {dataset.name} has none"
            )
        super().__init__()
        self._config = config
        self._model = require_invertible(sensor.model())
        self._R = config.measurement_cov_scale * sensor.noise_cov
        m = self._model.dim
        self._gate = chi2_gate(m, config.gate_probability)
        self._new_gate = chi2_gate(m, config.new_landmark_probability)
        self._pose: FloatArray | None = None  # the latest KnownPose
        self._belief = LandmarkBelief.empty()
        self._ids_used = config.use_ids and sensor.identities
        self._log_t: list[FloatArray] = []
        self._log_ids: list[NDArray[np.int64]] = []
        self._log_status: list[NDArray[np.int64]] = []
        self._log_nis: list[FloatArray] = []

    name = "EKF mapping"

    def on_known_pose(self, event: KnownPose) -> None:
        self._pose = np.array(event.pose, dtype=np.float64)

    def on_landmarks(self, event: LandmarkReadings) -> None:
        pose = self._pose
        if pose is None:
            raise InputError(
                f"EKF mapping with known poses: no KnownPose before the readings at "
                f"t={event.t} (run it through slamkit.pipeline.run on a data set with a true "
                "trajectory, or give KnownPose events)"
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
        pose = np.zeros(3) if self._pose is None else self._pose.copy()
        return PoseEstimate(pose, np.zeros((3, 3)))

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
            landmark_numbering=LandmarkIds.DATASET if self._ids_used else LandmarkIds.OWN,
        )


def _cat(parts: Sequence[NDArray[Any]], dtype: type) -> NDArray[Any]:
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype=dtype)
