"""What the SLAM estimators share: the ids they give their own landmarks, the readings of a
scan, the Jacobians of one reading and the per-reading log they keep.

Used by :mod:`slamkit.slam.ekf_slam` and :mod:`slamkit.slam.seif` (both Gaussian filters
over ``(x_r, m_1, …, m_L)`` with a 5-column reading Jacobian).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import LandmarkReadings
from slamkit.errors import NonFiniteError, ShapeError
from slamkit.estimation.contract import InnovationLog
from slamkit.estimation.gaussian import measure_unchecked
from slamkit.models import LandmarkModel
from slamkit.models.measurement import LandmarkModelBase

__all__ = ["OWN_ID_BASE", "NisRecord", "ReadingLog", "reading_jacobians", "scan_readings"]

OWN_ID_BASE = 1_000_000
"""Ids the estimator gives the features it names itself (readings without ids) start here,
so that they never alias a data set's landmark ids: evaluation matches maps by id, and a
feature numbered 3 by the filter is not the data set's landmark 3."""


def reading_jacobians(
    model: LandmarkModel, pose: FloatArray, landmark: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(h (m,), H_r (m, 3), H_j (m, 2))`` for one pose and one landmark.

    slamkit's point-landmark models depend on the landmark only through ``m − t`` (world
    frame) and ``θ`` — moving pose and landmark by the same offset changes no reading — so
    ``∂h/∂m = −∂h/∂t``: the landmark Jacobian is minus the first two columns of the pose
    Jacobian, which the fused single-reading kernel already gives. (Checked against
    ``model.jacobians`` in the tests.) Other models are asked for both."""
    if isinstance(model, LandmarkModelBase):
        h, Hr = measure_unchecked(model, pose, landmark)
        return h, Hr, -Hr[:, :2]
    h = np.asarray(model.predict(pose, landmark), dtype=np.float64)
    Hr, Hj = model.jacobians(pose, landmark)
    return h, np.asarray(Hr, dtype=np.float64), np.asarray(Hj, dtype=np.float64)


def scan_readings(
    event: LandmarkReadings, m: int, use_ids: bool
) -> tuple[FloatArray, NDArray[np.int64]]:
    """A scan's readings ``(K, m)``, checked (shape, finite), and the ids to use: the
    event's, or all ``-1`` when ids are not used."""
    z = np.asarray(event.z, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != m:
        raise ShapeError(f"readings at t={event.t}: expected shape (K, {m}), got {z.shape}")
    if not np.isfinite(z).all():
        raise NonFiniteError(f"readings at t={event.t}: NaN or inf values")
    if not use_ids:
        return z, np.full(z.shape[0], -1, dtype=np.int64)
    return z, np.asarray(event.ids, dtype=np.int64)


class ReadingLog:
    """Every reading an estimator handled, in order: its time, the id of the landmark it
    updated or started (``-1`` if none) and its status
    (:class:`~slamkit.estimation.readings.ReadingStatus`)."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.ids: list[int] = []
        self.statuses: list[int] = []

    def add(self, t: float, landmark_id: int, status: int) -> None:
        """Record one reading."""
        self.times.append(t)
        self.ids.append(landmark_id)
        self.statuses.append(status)

    def arrays(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """``(times, landmark ids, statuses)`` as arrays (copies)."""
        return (
            np.asarray(self.times, dtype=np.float64),
            np.asarray(self.ids, dtype=np.int64),
            np.asarray(self.statuses, dtype=np.int64),
        )


class NisRecord:
    """The normalised innovation squared ``νᵀ S⁻¹ ν`` of every map update, with its time and
    landmark id: the estimator's :class:`~slamkit.estimation.contract.InnovationLog`."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.nis: list[float] = []
        self.ids: list[int] = []

    def add(self, t: float, nis: float, landmark_id: int) -> None:
        """Record one update."""
        self.times.append(t)
        self.nis.append(nis)
        self.ids.append(landmark_id)

    def log(self, dof: int) -> InnovationLog:
        """The record as an :class:`~slamkit.estimation.contract.InnovationLog` of readings
        with ``dof`` components."""
        nis = np.asarray(self.nis, dtype=float)
        return InnovationLog(
            times=np.asarray(self.times, dtype=float),
            nis=nis,
            dof=np.full(nis.size, dof, dtype=np.int64),
            landmark_ids=np.asarray(self.ids, dtype=np.int64),
        )
