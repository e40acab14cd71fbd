"""The settings of FastSLAM's measurement update (gates, new-landmark likelihood, misses) and
the default new-landmark threshold."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import as_covariance
from slamkit.errors import ConfigError
from slamkit.prob import chi2_gate

# --------------------------------------------------------------------------------------------
# Settings of the measurement update
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class UpdateSettings:
    """How readings are associated and landmarks kept (the estimator builds this from
    :class:`FastSlamConfig` and the data set's sensor).

    ``p0`` is the new-landmark likelihood threshold, a density in the units of the reading
    (1/(m·rad) for range-bearing, 1/m² for relative positions). ``use_ids``: take a reading's
    id (``>= 0``) as its landmark. ``prune``: remove landmarks started by unlabelled readings
    when their existence counter drops below zero. ``visible_min_range``,
    ``visible_max_range`` [m] and ``fov`` [rad, centred on the heading]: where the sensor
    sees a landmark (for the counters), measured from ``sensor_offset`` [m, robot frame:
    x forward, y left], where the sensor sits (readings are still given from the robot's
    origin; see :func:`predicted_visible`). ``min_range`` [m]: readings that place their landmark
    closer than this are skipped. ``first_unlabelled_id``: landmarks with ids at or above it
    were started by unlabelled readings (only those keep a counter and are pruned).
    ``hit_weight``: what a scan that updates a landmark adds to its counter (a miss
    subtracts 1).
    """

    p0: float
    use_ids: bool = True
    prune: bool = True
    visible_min_range: float = 0.0
    visible_max_range: float = math.inf
    fov: float = 2.0 * math.pi
    min_range: float = 0.0
    first_unlabelled_id: int = 0
    hit_weight: int = 1
    sensor_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        off = tuple(float(v) for v in self.sensor_offset)
        if len(off) != 2 or not all(math.isfinite(v) for v in off):
            raise ConfigError(f"sensor_offset: expected two finite numbers, got {off}")
        object.__setattr__(self, "sensor_offset", off)
        if not (isinstance(self.hit_weight, int) and self.hit_weight >= 1):
            raise ConfigError(f"hit_weight: expected an integer >= 1, got {self.hit_weight}")
        if not (self.p0 > 0 and math.isfinite(self.p0)):
            raise ConfigError(f"p0: expected a density > 0, got {self.p0}")
        if not 0 <= self.visible_min_range <= self.visible_max_range:
            raise ConfigError("visible ranges: expected 0 <= min <= max")
        if not self.fov > 0:
            raise ConfigError(f"fov: expected an angle > 0, got {self.fov}")
        if not (self.min_range >= 0 and math.isfinite(self.min_range)):
            raise ConfigError(f"min_range: expected a number >= 0, got {self.min_range}")

    @property
    def log_p0(self) -> float:
        return math.log(self.p0)


def default_p0(noise_cov: ArrayLike, probability: float = 0.999) -> float:
    """The density of ``N(0, R)`` at squared Mahalanobis distance ``χ²_m(probability)``:
    ``exp(-½ χ²) / sqrt(det(2π R))``.

    For a landmark whose position is certain and a particle at the true pose, ``Q = R``, and
    a reading then starts a new landmark exactly when it lies outside the ``probability``
    gate of every mapped landmark. A landmark still uncertain has a broader ``Q``, a lower
    peak density, and so a narrower effective gate."""
    R = as_covariance(noise_cov, "noise_cov")
    if not 0.0 < probability < 1.0:
        raise ConfigError(f"probability: expected a value in (0, 1), got {probability}")
    m = R.shape[0]
    d2 = chi2_gate(m, probability)
    _, logdet = np.linalg.slogdet(2.0 * np.pi * R)
    return float(math.exp(-0.5 * d2 - 0.5 * float(logdet)))
