"""Settings of SEIF SLAM (:class:`SeifConfig`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from slamkit.errors import ConfigError
from slamkit.estimation.gps import check_gps_settings
from slamkit.mapping.ekf_mapping import association_probabilities

__all__ = ["SeifConfig"]


@dataclass(frozen=True)
class SeifConfig:
    """Settings of :class:`Seif`. Units: metres, radians."""

    max_active: int = 6
    """Most landmarks the robot stays linked to. A reading activates its landmark; beyond
    this many the least recently observed are deactivated by sparsification. Without ids it
    should hold a scan's landmarks: in ``landmark-clutter`` (~13 readings a scan) the
    default cuts the links to half of what was just seen, SEIF turns overconfident and
    true landmarks fall out of the gate; 20 associates as well as EKF-SLAM's nearest
    neighbour (measured in ``docs/estimators/ekf_slam.md``)."""
    relax_per_step: int = 10
    """Landmarks besides the robot and the active ones whose mean is relaxed per step (in
    turn, round robin): the amortised mean recovery."""
    relax_sweeps: int = 2
    """Gauss–Seidel sweeps over the robot and the active landmarks per step (they are
    strongly coupled, and the robot's mean is the estimate reported at every step)."""
    motion_cov_scale: float = 1.0
    """Multiplies the data set's control-noise covariance (>= 0)."""
    measurement_cov_scale: float = 1.0
    """Multiplies the landmark sensor's noise covariance (> 0)."""
    initial_capacity: int = 32
    """Landmarks the buffers hold before their first doubling."""
    prior_information: float = 1e12
    """Information of a pose prior given with zero covariance (the map frame): the
    information form needs a finite value; 1e12 = a standard deviation of 1 µm (rad)."""
    use_ids: bool = True
    """Use the landmark ids the readings carry when the sensor provides them
    (``LandmarkSensorSpec.identities``); ``-1`` readings are then associated with the
    existing landmarks but never start one (an id chosen here could collide with a later
    labelled one). ``False`` (or a sensor without identities) ignores every id and
    associates all readings (module docstring, *Data association*)."""
    gate_probability: float = 0.999
    """The χ² gate of a pairing: ``d² ≤ χ²_m(p)`` (13.8 for ``m = 2``)."""
    new_landmark_probability: float = 0.99999
    """An unpaired reading starts a landmark only if its ``d²`` to every candidate exceeds
    ``χ²_m(new_landmark_probability)`` (23.0 for ``m = 2``); between the two thresholds it
    is rejected rather than allowed to duplicate a landmark it just missed."""
    candidate_radius: float = 3.0
    """A landmark is a candidate for a scan's readings if its mean lies within this distance
    [m] of the point some reading places (inverse model at the mean pose); the others count
    as ``d² = ∞``. It must exceed the robot's position error plus the reading's (a few
    σ): landmarks beyond it cannot be re-found, and become duplicates."""
    max_candidates: int = 40
    """At most this many candidates per scan (nearest to a reading's point first): with
    :attr:`max_blanket` it bounds the cost of one scan's association."""
    blanket_hops: int = 1
    """Rings of links around the robot and the candidates in the blanket whose information
    gives their covariance: 1 = their Markov blanket (the active landmarks and the
    candidates' neighbours), each further ring the neighbours of the last. More rings:
    closer to the marginal, larger solves."""
    max_blanket: int = 120
    """Most landmarks in the blanket (candidates and the active ones first, then the rings
    in order, cut at this size): bounds the Cholesky factorisation per scan, a
    ``(3 + 2 · max_blanket)²`` matrix."""
    gps_lever_arm: tuple[float, float] = (0.0, 0.0)
    """Where the GPS antenna sits in the robot frame [m] (ahead, left): a fix measures
    ``t + R(θ) o`` and is an information update on the pose block
    (:mod:`slamkit.slam.seif.gps`). Used only when the data set's stream carries GPS fixes
    (its loader asked to fuse them); the same setting as EKF-SLAM's."""
    gps_gate_probability: float = 0.99
    """A fix whose ``d²`` (the pose's covariance from its blanket) exceeds ``χ²₂(p)`` (9.21)
    is refused as an outlier (multipath) and counted in ``gps_refused`` — EKF-SLAM's gate
    (``docs/estimators/gps.md``)."""

    def __post_init__(self) -> None:
        for name in ("max_active", "initial_capacity", "max_candidates", "max_blanket"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
        for name in ("relax_sweeps", "blanket_hops"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
        if not (isinstance(self.relax_per_step, int) and self.relax_per_step >= 0):
            raise ConfigError(
                f"relax_per_step: expected an integer >= 0, got {self.relax_per_step}"
            )
        if not (math.isfinite(self.motion_cov_scale) and self.motion_cov_scale >= 0):
            raise ConfigError(f"motion_cov_scale: expected >= 0, got {self.motion_cov_scale}")
        s = self.measurement_cov_scale
        if not (math.isfinite(s) and s > 0):
            raise ConfigError(f"measurement_cov_scale: expected > 0, got {s}")
        if not (math.isfinite(self.prior_information) and self.prior_information > 0):
            raise ConfigError(f"prior_information: expected > 0, got {self.prior_information}")
        association_probabilities(self.gate_probability, self.new_landmark_probability)
        arm = check_gps_settings(self.gps_lever_arm, self.gps_gate_probability)
        object.__setattr__(self, "gps_lever_arm", arm)
        r = self.candidate_radius
        if not (math.isfinite(r) and r > 0):
            raise ConfigError(f"candidate_radius: expected a number > 0, got {r}")
