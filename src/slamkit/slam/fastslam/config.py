"""The FastSLAM estimator's config and what it derives from a data set's sensor and motion
specs."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, LandmarkSensorSpec, MotionSpec
from slamkit.errors import ConfigError, InputError
from slamkit.estimation.gps import check_gps_settings
from slamkit.models import Ackermann, MotionModel
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.slam.common import OWN_ID_BASE
from slamkit.slam.fastslam.settings import UpdateSettings, default_p0

# --------------------------------------------------------------------------------------------
# The estimators
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FastSlamConfig:
    """Settings of :class:`FastSlam1` and :class:`FastSlam2` (one config for both: every
    setting means the same in either, and which proposal is used is the estimator's name).
    Units: metres, radians."""

    n_particles: int = 100
    """Number of particles (paths with their maps)."""
    resample_threshold: float = 0.5
    """Resample (low variance) when the effective sample size ``1/Σw²`` falls below this
    fraction of the particles; resampling is done just before the next motion, so the
    estimate and the map after a scan are those of the weighted set."""
    p0: float | None = None
    """New-landmark likelihood threshold: an unlabelled reading whose best likelihood
    ``N(ν; 0, Q)`` in a particle is below ``p0`` starts a new landmark there, and the
    particle's weight is multiplied by ``p0``. A density in the reading's units
    (1/(m·rad) for range-bearing, 1/m² for positions). ``None``: :func:`default_p0` of the
    (scaled) sensor noise at ``new_landmark_probability``."""
    new_landmark_probability: float = 0.99999
    """Used when ``p0`` is None: ``p0`` is the density of ``N(0, R)`` at the edge of this
    χ² gate (m = 2: 0.99999 → squared Mahalanobis distance 23.0, the same threshold as
    :attr:`~slamkit.mapping.ekf_mapping.EkfMappingConfig.new_landmark_probability`). On
    "five-features" without ids (50 particles, seeds 0-5, both versions) 0.999 (13.8) left a
    duplicate of the first landmark at the loop closure in 4 of 12 runs, 0.99999 in none."""
    use_ids: bool = True
    """Use the landmark ids readings carry (known correspondences). False ignores them and
    associates every reading by maximum likelihood."""
    prune: bool = True
    """Remove landmarks started by unlabelled readings when their existence counter falls
    below zero (see the module docstring)."""
    motion_cov_scale: float = 1.0
    """Multiplies the data set's control-noise covariance (> 1 spreads the particles more)."""
    measurement_cov_scale: float = 1.0
    """Multiplies the sensor's noise covariance (its standard deviations by the square root),
    as every ``*_cov_scale`` setting of slamkit does."""
    prior_cov_scale: float = 1.0
    """The particles start from ``N(initial_pose, prior_cov_scale · initial_cov)``; without a
    prior in the data set, all at the origin (the map then defines the frame)."""
    min_range: float = 0.0
    """Readings that place their landmark closer than this [m] are skipped (see
    :attr:`~slamkit.mapping.ekf_mapping.EkfMappingConfig.min_range`)."""
    estimate: Literal["mean", "best"] = "mean"
    """The pose reported after each step: the weighted mean of the particles (circular mean
    of the heading) or the pose of the particle with the largest weight. The covariance is
    the particles' weighted covariance about their mean in both cases."""
    initial_capacity: int = 8
    """Landmark slots per particle to start with; doubled whenever a particle needs more."""
    hit_weight: int = 1
    """What one scan that updates a landmark adds to its existence counter (a scan that
    predicted it visible but did not read it subtracts 1): a landmark survives if it is read
    in more than ``1 / (1 + hit_weight)`` of the scans that should see it. "Should see it"
    cannot know occlusion (a tree behind another) nor a detector that misses a tree now and
    then: raise it for such sensors. Clutter, read once, still dies after ``hit_weight + 1``
    misses, but a duplicate made at a loop closure, read now and then, may live (measurements
    on five-features and Victoria Park in ``docs/estimators/fastslam.md``)."""
    miss_max_range: float | None = None
    """A missed landmark counts against its existence only when predicted closer than this
    [m]. None: the sensor's detection range (:attr:`LandmarkSensorSpec.reach
    <slamkit.datasets.stream.LandmarkSensorSpec.reach>`: its ``detection_range`` or else its
    ``max_range``) — on Victoria Park, where trees beyond ~40 m are seldom detected though
    the laser reaches 80 m, the loader measures 38 m from the laser
    (:func:`~slamkit.datasets.stream.measured_detection_range`)."""
    miss_fov_margin: float = 0.0
    """... and only when predicted this far [rad] inside the field of view's edges."""
    sensor_offset: tuple[float, float] | None = None
    """Where the landmark sensor sits in the robot frame [m] (x forward, y left): ranges and
    the field of view of the miss test above are measured from there. None: the data set's
    (its landmark sensor's ``offset``; Victoria Park's laser is 3.78 m ahead of and 0.5 m
    left of the rear axle). Judging misses from the axle there counts the trees beside the
    cab as missed at every scan, and the map loses them (``docs/estimators/fastslam.md``)."""
    n_snapshots: int = 6
    """Copies of the particle poses and weights kept for the plots (``particles.png``) when
    neither ``snapshot_every`` nor ``snapshot_times`` is set: the start, the end and states
    between them evenly spaced in measurement updates, chosen as the run goes without
    knowing its length (:class:`~slamkit.estimation.contract.SpreadSnapshots`). 0: none."""
    snapshot_every: int = 0
    """Keep a snapshot every this many measurement updates (0: not by count), plus the
    initial set (as :class:`~slamkit.localization.mcl.MclConfig`)."""
    snapshot_times: tuple[float, ...] = ()
    """Keep a snapshot at the first measurement update at or after each of these times [s]."""
    gps_lever_arm: tuple[float, float] = (0.0, 0.0)
    """Where the GPS antenna sits in the robot frame [m] (ahead, left): a fix measures
    ``t + R(θ) o`` of each particle's pose and enters its weight (and 2.0's proposal;
    :mod:`slamkit.slam.fastslam.gps`). Used only when the data set's stream carries GPS
    fixes (its loader asked to fuse them); the same setting as EKF-SLAM's."""
    gps_gate_probability: float = 0.99
    """A fix whose ``d²`` against the particles' predicted fix exceeds ``χ²₂(p)`` (9.21) is
    refused as an outlier (multipath) and counted in ``gps_refused`` — EKF-SLAM's gate
    (``docs/estimators/gps.md``)."""

    def __post_init__(self) -> None:
        if not self.n_particles >= 1:
            raise ConfigError(f"n_particles: expected an integer >= 1, got {self.n_particles}")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ConfigError(
                f"resample_threshold: expected a fraction in [0, 1], got {self.resample_threshold}"
            )
        if self.p0 is not None and not (self.p0 > 0 and math.isfinite(self.p0)):
            raise ConfigError(f"p0: expected a density > 0 or None, got {self.p0}")
        if not 0.0 < self.new_landmark_probability < 1.0:
            raise ConfigError(
                "new_landmark_probability: expected a probability in (0, 1), got "
                f"{self.new_landmark_probability}"
            )
        for name in ("motion_cov_scale", "prior_cov_scale", "min_range"):
            v = getattr(self, name)
            if not (v >= 0 and math.isfinite(v)):
                raise ConfigError(f"{name}: expected a number >= 0, got {v}")
        if not (self.measurement_cov_scale > 0 and math.isfinite(self.measurement_cov_scale)):
            raise ConfigError(
                f"measurement_cov_scale: expected a number > 0, got {self.measurement_cov_scale}"
            )
        if self.estimate not in ("mean", "best"):
            raise ConfigError(f"estimate: expected 'mean' or 'best', got {self.estimate!r}")
        if not self.initial_capacity >= 1:
            raise ConfigError(
                f"initial_capacity: expected an integer >= 1, got {self.initial_capacity}"
            )
        if not self.hit_weight >= 1:
            raise ConfigError(f"hit_weight: expected an integer >= 1, got {self.hit_weight}")
        if self.miss_max_range is not None and not self.miss_max_range > 0:
            raise ConfigError(
                f"miss_max_range: expected a range > 0 or None, got {self.miss_max_range}"
            )
        if not 0.0 <= self.miss_fov_margin < math.pi:
            raise ConfigError(
                f"miss_fov_margin: expected an angle in [0, π), got {self.miss_fov_margin}"
            )
        if self.sensor_offset is not None:
            off = tuple(float(v) for v in self.sensor_offset)
            if len(off) != 2 or not all(math.isfinite(v) for v in off):
                raise ConfigError(f"sensor_offset: expected two finite numbers or None, got {off}")
            object.__setattr__(self, "sensor_offset", off)
        if not (self.n_snapshots >= 0 and self.snapshot_every >= 0):
            raise ConfigError(
                "n_snapshots and snapshot_every: expected integers >= 0, got "
                f"{self.n_snapshots} and {self.snapshot_every}"
            )
        arm = check_gps_settings(self.gps_lever_arm, self.gps_gate_probability)
        object.__setattr__(self, "gps_lever_arm", arm)
        if not all(math.isfinite(t) for t in self.snapshot_times):
            raise ConfigError(f"snapshot_times: expected finite times, got {self.snapshot_times}")


def sensor_offset_of(dataset: Dataset) -> tuple[float, float]:
    """Where the data set's landmark sensor sits in the robot frame [m]
    (:attr:`LandmarkSensorSpec.offset <slamkit.datasets.stream.LandmarkSensorSpec.offset>`;
    the robot's origin without a sensor)."""
    sensor = dataset.landmark_sensor
    return (0.0, 0.0) if sensor is None else sensor.offset


def steering_limit(motion: MotionModel) -> float | None:
    """The largest steering angle [rad] a sampled Ackermann control may have (None: another
    model, nothing to limit).

    :class:`~slamkit.models.Ackermann` is defined for ``|α| < π/2`` and while the encoder
    wheel is off the centre of rotation (``tan α < L / H``). Control noise is Gaussian, so
    with 100 particles and tens of thousands of controls (Victoria Park: σ = 0.3 rad per
    25-ms sample) some draws fall outside; like a real steering rack, the draw saturates at
    99 % of the limit (such a particle turns sharply and loses its weight at the next scan)
    instead of stopping the run."""
    if not isinstance(motion, Ackermann):
        return None
    return 0.99 * motion.max_steering


def update_settings(
    dataset: Dataset, sensor: LandmarkSensorSpec, config: FastSlamConfig, R: FloatArray
) -> UpdateSettings:
    """The measurement-update settings of a run: from the config and what the sensor's spec
    says (its range limits, field of view, detection range and mounting), with ``R`` the
    scaled reading covariance. Nothing here looks at the data set's events."""
    p0 = config.p0 if config.p0 is not None else default_p0(R, config.new_landmark_probability)
    # Landmarks the filter numbers itself (readings without ids) start at OWN_ID_BASE
    # when the readings' ids are used, so that they never alias a data set's id (an
    # online filter cannot look ahead for the largest id); all are its own otherwise.
    first_unlabelled = OWN_ID_BASE if config.use_ids else 0
    offset = sensor_offset_of(dataset) if config.sensor_offset is None else config.sensor_offset
    miss_range = config.miss_max_range
    if miss_range is None:
        miss_range = sensor.reach  # the sensor's detection range (its spec says)
    fov = min(float(sensor.fov), 2.0 * math.pi)
    if fov < 2.0 * math.pi:
        fov = max(fov - 2.0 * config.miss_fov_margin, 1e-9)
    return UpdateSettings(
        p0=p0,
        use_ids=config.use_ids,
        prune=config.prune,
        visible_min_range=sensor.min_range,
        visible_max_range=min(sensor.max_range, miss_range),
        fov=fov,
        hit_weight=config.hit_weight,
        sensor_offset=offset,
        min_range=config.min_range,
        first_unlabelled_id=first_unlabelled,
    )


def check_dataset(
    dataset: Dataset, name: str
) -> tuple[MotionSpec, LandmarkSensorSpec, InvertibleLandmarkModel]:
    """The motion spec, landmark sensor and its model a FastSLAM run needs, or an
    :class:`~slamkit.errors.InputError` naming what the data set lacks."""
    if dataset.motion is None:
        raise InputError(f"{name} needs a motion model; data set {dataset.name!r} has none")
    sensor = dataset.landmark_sensor
    if sensor is None:
        raise InputError(f"{name} needs a landmark sensor; data set {dataset.name!r} has none")
    model = sensor.model()
    if not isinstance(model, InvertibleLandmarkModel) or model.dim != 2:
        raise InputError(
            f"{name} cannot use the {sensor.kind!r} sensor of {dataset.name!r}: one "
            "reading must locate a landmark (use range-bearing or position readings)"
        )
    return dataset.motion, sensor, model
