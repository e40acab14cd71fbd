"""Settings of EKF landmark mapping with known poses."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamkit.errors import ConfigError
from slamkit.mapping.ekf_mapping.association import association_probabilities

__all__ = ["EkfMappingConfig"]


@dataclass(frozen=True)
class EkfMappingConfig:
    """Settings of :class:`EkfMapping` (EKF landmark mapping with known poses)."""

    measurement_cov_scale: float = 1.0
    """Multiplies the sensor's measurement-noise covariance ``R`` (1 = trust the data set)."""
    use_ids: bool = True
    """Use the landmark ids the readings carry. False ignores them and associates every
    reading by nearest neighbour (to test data association on labelled data)."""
    gate_probability: float = 0.999
    """Association gate: an unlabelled reading may update a landmark only if
    ``νᵀ S⁻¹ ν ≤ χ²_m(gate_probability)`` (``m`` = reading dimension; 13.8 for ``m = 2``)."""
    new_landmark_probability: float = 0.99999
    """A reading matching no landmark starts a new one only if ``νᵀ S⁻¹ ν`` to EVERY landmark
    exceeds ``χ²_m(new_landmark_probability)`` (23.0 for ``m = 2``); between the two
    thresholds it is rejected, to avoid duplicating a landmark. Must be ≥ gate_probability."""
    min_range: float = 0.0
    """Readings that place their landmark closer than this to the sensor (m) are skipped.
    0 uses every reading. Near the sensor the EKF's linearisation of a range-bearing model
    fails: a reading at range ``r ≲ 3 σ_range`` initialises a landmark whose lateral
    variance ``(r σ_bearing)²`` is far too small, so its NEES grows without bound (the
    measured effect is in ``docs/estimators/mapping.md``). The relative-position model is
    linear and needs no such limit."""

    def __post_init__(self) -> None:
        if not (self.measurement_cov_scale > 0 and np.isfinite(self.measurement_cov_scale)):
            raise ConfigError(
                f"measurement_cov_scale: expected a number > 0, got {self.measurement_cov_scale}"
            )
        association_probabilities(self.gate_probability, self.new_landmark_probability)
        if not (self.min_range >= 0 and np.isfinite(self.min_range)):
            raise ConfigError(f"min_range: expected a number >= 0, got {self.min_range}")
