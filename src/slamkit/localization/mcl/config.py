"""The settings of the ``mcl`` estimator (:class:`MclConfig`) as frozen sections.

``MclConfig`` holds what every run uses (particle count, resampling, noise scales) and one
section per concern::

    MclConfig(
        n_particles=2000,
        start=StartConfig(uniform=True),          # global localization
        augmented=AugmentedConfig(alpha_fast=0.2),
        kld=KldConfig(epsilon=0.05),
        laser=LaserConfig(sigma_hit=0.2, beam_stride=4),
        snapshots=SnapshotConfig(every=50),
    )

In a TOML file the sections are nested tables (``[estimator.kld]``), in JSON nested
objects. Validation is declarative (:class:`slamkit.config.Section`): errors name the field
as ``section.field``. Units: metres and radians unless the name says degrees.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal

from slamkit.config import (
    Section,
    finite_above,
    finite_at_least,
    fraction,
    int_at_least,
    optional,
    setting,
)
from slamkit.errors import ConfigError

__all__ = [
    "AugmentedConfig",
    "KldConfig",
    "LaserConfig",
    "MclConfig",
    "SnapshotConfig",
    "StartConfig",
]


@dataclass(frozen=True)
class StartConfig(Section):
    """Where the particles start."""

    SECTION: ClassVar[str] = "start"

    uniform: bool = False
    """True: ignore any prior and start from particles uniform over the map (global
    localization). A data set without a prior always starts uniform."""
    prior_cov_scale: float = setting(1.0, finite_at_least(0.0), "a finite number >= 0")
    """Multiplies the prior covariance the start particles are drawn from (> 1: a broad
    prior, which tolerates a wrong prior mean)."""
    n_particles: int | None = setting(None, optional(int_at_least(1)), "an integer >= 1 or None")
    """Particles of a uniform start; ``None``: ``particles_per_m2`` times the area they are
    spread over (free space of the grid, or the landmarks' box), within [1000, 2·10⁶]. With
    KLD-sampling the set then shrinks towards what the posterior needs (after the first
    measurement: see :class:`~slamkit.localization.mcl.MonteCarloLocalization` for why it
    costs only that one update)."""
    particles_per_m2: float = setting(1700.0, finite_above(0.0), "a finite number > 0")
    """Density of a uniform start [1/m²] (headings uniform). A start this dense has about one
    particle per 10 cm × 10 cm × 20° of poses: sparser starts converged later, and only
    through random injections (measurements in docs/estimators/mcl.md). The first update
    scores them all; every later step works on the KLD-sized set."""


@dataclass(frozen=True)
class AugmentedConfig(Section):
    """Augmented MCL: inject random particles when the fast likelihood average drops below
    the slow one (recovers from kidnapping and from a wrong prior)."""

    SECTION: ClassVar[str] = "augmented"

    enabled: bool = True
    alpha_slow: float = setting(0.01, fraction(open_low=True), "a number in (0, 1]")
    """Rate of the slow likelihood average, per measurement update (0 < alpha_slow <
    alpha_fast <= 1)."""
    alpha_fast: float = setting(0.2, fraction(open_low=True), "a number in (0, 1]")
    """Rate of the fast likelihood average, per measurement update."""
    injection_sigmas: float = setting(8.0, finite_at_least(0.0), "a finite number >= 0")
    """Inject only once the fast average has dropped below the slow one by more than this
    many times its natural spread ``σ_f`` (:meth:`.Augmentation.tolerance`), then
    ``1 - w_fast / (w_slow e^{-k σ_f})`` of the particles (``k = 0``: Thrun's rule). The
    spread's distribution has heavy tails, so ``k`` is well above the deviations seen while
    tracking; a kidnapped robot's ratio falls by a factor ``1 - α_fast`` per update whatever
    ``σ_f``, so a large ``k`` delays the recovery by a few updates only (measurements in
    docs/estimators/mcl.md)."""
    injection_margin: float = setting(2.0, finite_at_least(0.0), "a finite number >= 0")
    """Landmark worlds: random particles (and a uniform start) are drawn from the landmarks'
    bounding box grown by this margin [m] (laser worlds: from the free cells of the map)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.alpha_slow < self.alpha_fast:
            raise ConfigError(
                f"augmented.alpha_slow, augmented.alpha_fast: expected alpha_slow < "
                f"alpha_fast, got {self.alpha_slow}, {self.alpha_fast}"
            )


@dataclass(frozen=True)
class KldConfig(Section):
    """KLD-sampling (Fox 2003): each resampling draws as many particles as the belief needs,
    many while it is spread out (global start, after a kidnapping), few once it has
    converged. Resampling itself is triggered as without KLD (``resample_threshold``, or an
    injection): KLD-sampling does not need to resample at every prediction, and doing so
    redraws a set of equal weights whenever several predictions come between two
    measurements (5 Hz odometry, 2 Hz ranges on Plaza 1), which only loses particles.
    ``enabled = False``: a fixed set of ``n_particles``, resampled by the low-variance
    scheme."""

    SECTION: ClassVar[str] = "kld"

    enabled: bool = True
    epsilon: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Bound on the Kullback-Leibler divergence between sample and posterior."""
    quantile: float = setting(0.99, fraction(open_low=True, open_high=True), "a number in (0, 1)")
    """``1 - δ``, the probability with which the bound holds."""
    bin_xy: float = setting(0.5, finite_above(0.0), "a finite number > 0")
    """Histogram bin size in x and y [m]."""
    bin_theta_deg: float = setting(10.0, finite_above(0.0), "a finite number > 0")
    """Histogram bin size in heading [deg]."""
    min_particles: int = setting(500, int_at_least(1), "an integer >= 1")
    """Never fewer particles than this."""
    max_particles: int = setting(20_000, int_at_least(1), "an integer >= 1")
    """Never more particles than this."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.max_particles < self.min_particles:
            raise ConfigError(
                f"kld.max_particles: expected >= kld.min_particles ({self.min_particles}), "
                f"got {self.max_particles}"
            )


@dataclass(frozen=True)
class LaserConfig(Section):
    """The likelihood-field laser model (:mod:`slamkit.maps.likelihood_field`)."""

    SECTION: ClassVar[str] = "laser"

    sigma_hit: float | None = setting(0.2, optional(finite_above(0.0)), "a number > 0 or None")
    """Standard deviation of a hit's end-point distance [m]. ``None``: derived from the data
    set, ``sqrt(measurement_cov_scale · (σ_r² + res²/3))`` with the laser's range noise
    ``σ_r`` and the map resolution (an end point and the wall it hits each lie anywhere in
    their cells: variance ``res²/6`` each). That is right for a particle at the true pose but
    far too sharp for a particle set, whose particles are never exactly there, and global
    localization with the derived value often did not converge (measurements in
    docs/estimators/mcl.md). The broader value also absorbs the correlation between
    neighbouring beams, which the model ignores."""
    z_hit: float = setting(0.95, finite_at_least(0.0), "a finite number >= 0")
    """Weight of the hit component."""
    z_rand: float = setting(0.05, finite_at_least(0.0), "a finite number >= 0")
    """Weight of the uniform random-reading component."""
    beam_stride: int = setting(4, int_at_least(1), "an integer >= 1")
    """Use every ``beam_stride``-th beam (neighbouring beams are strongly correlated, and the
    cost is linear in the number of beams)."""
    independent_beams: float | None = setting(
        4.5, optional(finite_above(0.0)), "a number > 0 or None"
    )
    """Temper each scan's likelihood so that it counts as this many independent readings,
    ``p(z | x)^e`` with ``e = min(1, independent_beams / B)`` for its ``B`` used beams (see
    :func:`.mcl_update_laser`); ``None``: no tempering (``e = 1``). The likelihood field
    scores beams as independent, but neighbouring beams' errors are not (same wall, same map
    cells, same pose error): untempered, every scan collapses the set onto one or a few
    particles, which then drift off the true pose and lose it. The default was chosen for a
    consistent NEES after convergence (measurements in docs/estimators/mcl.md)."""
    offset: tuple[float, float, float] | None = None
    """Pose of the laser in the robot frame: (forward [m], left [m], yaw [rad]); ``None``: the
    data set's :attr:`~slamkit.datasets.LaserSpec.mounting` (a bag's base-to-laser
    transform), so that scans land where the mapping estimators, which use it too, put the
    walls of a saved map."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.z_hit + self.z_rand <= 0:
            raise ConfigError("laser.z_hit, laser.z_rand: expected numbers >= 0, not both 0")


@dataclass(frozen=True)
class SnapshotConfig(Section):
    """Copies of the particle set kept for plots and animations (besides the initial set
    whenever any are kept)."""

    SECTION: ClassVar[str] = "snapshots"

    every: int = setting(0, int_at_least(0), "an integer >= 0")
    """Keep a copy every this many measurement updates (0: never)."""
    times: tuple[float, ...] = ()
    """Keep a copy at the first measurement update at or after each of these times [s]."""


@dataclass(frozen=True)
class MclConfig(Section):
    """Settings of :class:`~slamkit.localization.mcl.MonteCarloLocalization`."""

    n_particles: int = setting(2000, int_at_least(1), "an integer >= 1")
    """Particles when the data set gives a prior pose (tracking), and the fixed set size
    without KLD-sampling."""
    resample_threshold: float = setting(0.5, fraction(), "a fraction in [0, 1]")
    """Resample (low variance) when the effective sample size ``1/Σw²`` falls below this
    fraction of the number of particles; 1 = after every update, 0 = only for injections.
    Resampling is done just before the next prediction, so the estimate after a measurement
    is always that of the weighted set."""
    motion_cov_scale: float = setting(1.0, finite_at_least(0.0), "a finite number >= 0")
    """Multiplies the data set's nominal control-noise covariance (> 1 helps a particle set
    cover unmodelled motion)."""
    measurement_cov_scale: float = setting(1.0, finite_above(0.0), "a finite number > 0")
    """Multiplies the measurement noise covariances (standard deviations by the square
    root): the landmark sensor's, and the laser's range noise when ``laser.sigma_hit`` is
    derived."""
    on_weight_underflow: Literal["skip", "raise"] = "skip"
    """What to do when a measurement leaves every particle with zero weight: ``"skip"``
    drops that measurement (keeps the predicted weights) and reports it in the
    diagnostics; ``"raise"`` raises :class:`~slamkit.errors.ConvergenceError`."""
    record_innovations: bool = True
    """Landmark readings: keep every used reading's NIS against the particle mean and
    covariance before the update (see :func:`.landmark_innovations`) in the output's
    :class:`~slamkit.estimation.contract.InnovationLog`, as the EKF does."""
    start: StartConfig = field(default_factory=StartConfig)
    augmented: AugmentedConfig = field(default_factory=AugmentedConfig)
    kld: KldConfig = field(default_factory=KldConfig)
    laser: LaserConfig = field(default_factory=LaserConfig)
    snapshots: SnapshotConfig = field(default_factory=SnapshotConfig)
