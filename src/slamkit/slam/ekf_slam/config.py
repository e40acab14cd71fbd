"""Settings of EKF-SLAM (:class:`EkfSlamConfig`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from slamkit.errors import ConfigError
from slamkit.estimation.gps import check_gps_settings
from slamkit.mapping.ekf_mapping import association_probabilities

__all__ = ["EkfSlamConfig"]


@dataclass(frozen=True)
class EkfSlamConfig:
    """Settings of :class:`EkfSlam`. Units: metres, radians, m² for covariance traces."""

    motion_cov_scale: float = 1.0
    """Multiplies the data set's nominal control-noise covariance ``Q`` (>= 0)."""
    measurement_cov_scale: float = 1.0
    """Multiplies the landmark sensor's noise covariance ``R`` (> 0)."""
    use_ids: bool = True
    """Use the landmark ids the readings carry when the sensor provides them
    (``LandmarkSensorSpec.identities``); ``-1`` readings are then associated with the
    existing landmarks but never start one, so that an id chosen here cannot collide with a
    later labelled one. ``False`` (or a sensor without identities) ignores every id and
    associates all readings."""
    association: Literal["nn", "jcbb"] = "nn"
    """Data association of unlabelled readings. ``"nn"``: greedy global nearest neighbour
    in Mahalanobis distance (pairs taken by increasing ``d²`` inside the gate, one reading
    per landmark and scan). ``"jcbb"``: joint compatibility branch and bound over the scan
    (:func:`~slamkit.slam.ekf_slam.jcbb`), which respects that every prediction shares the
    robot's error."""
    gate_probability: float = 0.999
    """The individual (and, for JCBB, joint) χ² gate: ``d² ≤ χ²_m(p)`` (13.8 for ``m = 2``;
    JCBB's ``p`` pairs: ``χ²_{mp}(p)``)."""
    new_landmark_probability: float = 0.99999
    """An unmatched reading starts a feature only if its ``d²`` to EVERY landmark exceeds
    ``χ²_m(new_landmark_probability)`` (23.0 for ``m = 2``); between the two thresholds it
    is rejected rather than allowed to duplicate a landmark it just missed."""
    provisional_trace: float | None = 0.05
    """Provisional feature list [m²]: a new feature is in the state (predicted, tracked and
    associated like any landmark) but its readings update only the feature itself — the
    Schmidt (consider) update, so the robot and the map are untouched — until it is known
    well enough: the trace of its *measurement-only* covariance ``(Σₖ H_kᵀ R⁻¹ H_k)⁻¹``
    (``H_k = ∂h/∂m`` of each of its readings; the covariance it would have if the robot's
    poses at its sightings were known) falls below this; then it joins the map. One reading
    at range ``r`` gives ``L_z R L_zᵀ``, trace ``σ_r² + r² σ_b²`` (0.041 m² at 5 m,
    0.054 m² at 6 m with σ_r = 0.1 m, σ_b = 2°), so the default confirms a feature at its
    second sighting, or first within 5 m — a single reading is never enough, as the test
    runs after an update. Not the marginal ``Σ_ff``, which can never fall below the robot's
    own position variance: after some drift no feature would be confirmed and the map would
    stop growing. Not ``Σ_ff`` conditioned on the current pose either: that includes the
    motion noise since the last sighting, so with long control steps many features would
    stay provisional to the end (``docs/estimators/ekf_slam.md``). ``None``: features join
    the map at their first reading."""
    min_feature_spacing: float = 1.0
    """Spatial spread of the features [m]: an unmatched reading starts a feature only if the
    landmark it places is at least this far from every landmark of the state (provisional
    ones included) and from the features the same scan starts; else it is counted in
    ``not_selected`` (:mod:`slamkit.slam.ekf_slam.selection`). ``0``: no such test. The
    default is below the closest pair of true landmarks in Victoria Park (1.5 m) and the
    simulated worlds (1.2 m); how it was chosen: ``docs/estimators/ekf_slam.md``."""
    max_misses: int | None = 3
    """A provisional feature predicted inside the sensor's field of view and range (with a
    3σ margin) but not matched in this many consecutive scans is removed from the state
    (clutter, a spurious reading). ``None``: never."""
    miss_probability: float | None = 0.001
    """If set, the consecutive misses that remove a provisional feature are not
    ``max_misses`` but as many as a real landmark, detected as often as the map's confirmed
    landmarks are when predicted in view, would be missed in a row with at most this
    probability (:func:`~slamkit.slam.ekf_slam.provisional.miss_limit`): one miss where the
    sensor sees every landmark in view, more where it sees few. A sensor without a finite
    range (``max_range``, ``detection_range``) states no view in which a detection rate
    means anything (MRCLAM's camera: every landmark counts as in view at every scan):
    ``max_misses`` applies there. ``None``: ``max_misses`` everywhere. The default (how it
    was chosen: ``docs/estimators/ekf_slam.md``) gives one or two misses on the simulated
    worlds (``p_D ≈ 0.999``), twelve on Victoria Park (``p_D ≈ 0.45``)."""
    max_misses_confirmed: int | None = None
    """The same for confirmed landmarks (``None``, the default: a confirmed landmark is
    kept — real landmarks are occluded, and removing one throws away its correlations)."""
    min_range: float = 0.0
    """Readings that place their landmark closer than this to the sensor [m] are skipped
    (a range-bearing EKF linearisation is wrong within a few σ_range of the sensor)."""
    jcbb_max_nodes: int = 20_000
    """Node budget of one JCBB search; when exhausted the best hypothesis so far is used and
    ``jcbb_incomplete`` counts it."""
    initial_capacity: int = 32
    """Landmarks the state buffers hold before their first doubling."""
    check_every: int | None = 50
    """Every this many time steps the whole covariance is tested for positive
    semi-definiteness (:func:`~slamkit.estimation.gaussian.check_covariance`: a Cholesky
    factorisation, ``O(n³)``, eigenvalues when it fails). The pose block is tested at every
    step, and the cheap checks (positive innovation covariance, finite gain, non-negative
    diagonal) run on every update regardless. ``None``: the pose block and the cheap checks
    only. With the default the checks take about 2 % of a run's time on ``landmark-loop``
    and ``landmark-loop-closure`` (``docs/estimators/ekf_slam.md``)."""
    record_innovations: bool = True
    """Keep the NIS of every map update in the output's :class:`InnovationLog`."""
    gps_lever_arm: tuple[float, float] = (0.0, 0.0)
    """Where the GPS antenna sits in the robot frame [m] (ahead, left): a fix measures
    ``t + R(θ) o`` (:mod:`slamkit.slam.ekf_slam.gps`). Used only when the data set's stream
    carries GPS fixes (its loader asked to fuse them)."""
    gps_gate_probability: float = 0.99
    """A fix whose ``d² = νᵀ S⁻¹ ν`` exceeds ``χ²₂(p)`` (9.21) is refused as an outlier
    (multipath) and counted in ``gps_refused`` — the graph's gate
    (``docs/estimators/gps.md``)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.motion_cov_scale) and self.motion_cov_scale >= 0):
            raise ConfigError(
                f"motion_cov_scale: expected a number >= 0, got {self.motion_cov_scale}"
            )
        if not (math.isfinite(self.measurement_cov_scale) and self.measurement_cov_scale > 0):
            raise ConfigError(
                f"measurement_cov_scale: expected a number > 0, got {self.measurement_cov_scale}"
            )
        if self.association not in ("nn", "jcbb"):
            raise ConfigError(f"association: expected 'nn' or 'jcbb', got {self.association!r}")
        association_probabilities(self.gate_probability, self.new_landmark_probability)
        t = self.provisional_trace
        if t is not None and not (math.isfinite(t) and t > 0):
            raise ConfigError(f"provisional_trace: expected a number > 0 or None, got {t}")
        for name in ("max_misses", "max_misses_confirmed", "check_every"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1 or None, got {v!r}")
        if not (math.isfinite(self.min_feature_spacing) and self.min_feature_spacing >= 0):
            raise ConfigError(
                f"min_feature_spacing: expected a number >= 0, got {self.min_feature_spacing}"
            )
        v = self.miss_probability
        if v is not None and not 0.0 < v < 1.0:
            raise ConfigError(f"miss_probability: expected 0 < p < 1 or None, got {v}")
        if not (math.isfinite(self.min_range) and self.min_range >= 0):
            raise ConfigError(f"min_range: expected a number >= 0, got {self.min_range}")
        arm = check_gps_settings(self.gps_lever_arm, self.gps_gate_probability)
        object.__setattr__(self, "gps_lever_arm", arm)
        for name in ("jcbb_max_nodes", "initial_capacity"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"{name}: expected an integer >= 1, got {v!r}")
