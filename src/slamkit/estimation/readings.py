"""What became of each landmark reading: the status codes that the landmark estimators (EKF
mapping, EKF-SLAM, SEIF) record per reading, and the association codes of their data
association. Both are ``IntEnum``: they compare equal to the plain integers stored in the
estimators' ``int64`` status arrays."""

from __future__ import annotations

from enum import IntEnum

__all__ = ["AssociationCode", "ReadingStatus"]


class ReadingStatus(IntEnum):
    """The fate of one reading in a landmark estimator."""

    UPDATED = 0
    """It updated a mapped landmark."""
    INITIALISED = 1
    """It started a new landmark."""
    DISCARDED = 2
    """Data association rejected it (ambiguous or outside every gate); it was not used."""
    TOO_CLOSE = 3
    """It places its landmark closer than the sensor's ``min_range``; it was not used."""
    TRACKED = 4
    """It updated a provisional feature only (EKF-SLAM's feature list), not the state."""


class AssociationCode(IntEnum):
    """What data association returns instead of a landmark index (indices are ``>= 0``)."""

    NEW = -1
    """The reading starts a new landmark."""
    REJECTED = -2
    """The reading is ambiguous (between the gate and the new-landmark threshold)."""
