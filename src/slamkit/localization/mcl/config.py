"""The settings of the ``mcl`` estimator (:class:`MclConfig`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from slamkit.errors import ConfigError

__all__ = ["MclConfig"]


@dataclass(frozen=True)
class MclConfig:
    """Settings of :class:`~slamkit.localization.mcl.MonteCarloLocalization`. Units:
    metres, radians unless the name says degrees."""

    n_particles: int = 2000
    """Particles when the data set gives a prior pose (tracking), and the fixed set size
    without KLD-sampling."""
    n_particles_global: int | None = None
    """Particles of a uniform start when there is no prior (global localization); ``None``:
    ``global_particles_per_m2`` times the area they are spread over (free space of the grid,
    or the landmarks' box), within [1000, 2·10⁶]. With KLD-sampling the set then shrinks
    towards what the posterior needs (after the first measurement: see
    :class:`~slamkit.localization.mcl.MonteCarloLocalization` for why it costs only that
    one update)."""
    global_particles_per_m2: float = 1700.0
    """Density of a uniform start [1/m²] (particles per square metre, headings uniform).
    A start this dense has about one particle per 10 cm × 10 cm × 20° of poses: sparser
    starts converged later, and only through random injections (measurements in
    docs/estimators/mcl.md). The first update scores them all; every later step works on
    the KLD-sized set."""
    global_start: bool = False
    """True: ignore any prior and start from particles uniform over the map."""
    prior_cov_scale: float = 1.0
    """Multiplies the prior covariance the start particles are drawn from (> 1: a broad
    prior, which tolerates a wrong prior mean)."""
    resample_threshold: float = 0.5
    """Resample (low variance) when the effective sample size ``1/Σw²`` falls below this
    fraction of the number of particles; 1 = after every update, 0 = only for injections.
    Resampling is done just before the next prediction, so the estimate after a measurement
    is always that of the weighted set."""
    motion_cov_scale: float = 1.0
    """Multiplies the data set's nominal control-noise covariance (> 1 helps a particle set
    cover unmodelled motion)."""
    augmented: bool = True
    """Augmented MCL: inject random particles when the fast likelihood average drops below
    the slow one (recovers from kidnapping and from a wrong prior)."""
    alpha_slow: float = 0.01
    """Rate of the slow likelihood average, per measurement update (0 < alpha_slow <
    alpha_fast <= 1)."""
    alpha_fast: float = 0.2
    """Rate of the fast likelihood average, per measurement update."""
    injection_sigmas: float = 8.0
    """Augmented MCL: inject only once the fast average has dropped below the slow one by
    more than this many times its natural spread ``σ_f`` (:meth:`.Augmentation.tolerance`),
    then ``1 - w_fast / (w_slow e^{-k σ_f})`` of the particles (``k = 0``: Thrun's rule).
    The spread's distribution has heavy tails, so ``k`` is well above the deviations seen
    while tracking; a kidnapped robot's ratio falls by a factor ``1 - α_fast`` per update
    whatever ``σ_f``, so a large ``k`` delays the recovery by a few updates only
    (measurements in docs/estimators/mcl.md)."""
    injection_margin: float = 2.0
    """Landmark worlds: random particles are drawn from the landmarks' bounding box grown by
    this margin [m] (laser worlds: from the free cells of the map)."""
    kld: bool = True
    """KLD-sampling (Fox 2003): each resampling draws as many particles as the belief needs,
    many while it is spread out (global start, after a kidnapping), few once it has
    converged. Resampling itself is triggered as without KLD (``resample_threshold``, or an
    injection): KLD-sampling does not need to resample at every prediction, and doing so
    redraws a set of equal weights whenever several predictions come between two
    measurements (5 Hz odometry, 2 Hz ranges on Plaza 1), which only loses particles.
    False: a fixed set of ``n_particles``, resampled by the low-variance scheme."""
    kld_epsilon: float = 0.05
    """KLD-sampling: bound on the Kullback-Leibler divergence between sample and posterior."""
    kld_quantile: float = 0.99
    """KLD-sampling: ``1 - δ``, the probability with which the bound holds."""
    kld_bin_xy: float = 0.5
    """KLD-sampling: histogram bin size in x and y [m]."""
    kld_bin_theta_deg: float = 10.0
    """KLD-sampling: histogram bin size in heading [deg]."""
    kld_min_particles: int = 500
    """KLD-sampling: never fewer particles than this."""
    kld_max_particles: int = 20_000
    """KLD-sampling: never more particles than this."""
    sigma_hit: float | None = 0.2
    """Likelihood field: standard deviation of a hit's end-point distance [m]. ``None``:
    derived from the data set, ``sqrt(measurement_cov_scale · (σ_r² + res²/3))`` with the
    laser's range noise ``σ_r`` and the map resolution (an end point and the wall it hits
    each lie anywhere in their cells: variance ``res²/6`` each). That is right for a particle
    at the true pose but far too sharp for a particle set, whose particles are never exactly
    there, and global localization with the derived value often did not converge
    (measurements in docs/estimators/mcl.md). The broader value also absorbs the
    correlation between neighbouring beams, which the model ignores."""
    z_hit: float = 0.95
    """Likelihood field: weight of the hit component."""
    z_rand: float = 0.05
    """Likelihood field: weight of the uniform random-reading component."""
    beam_stride: int = 4
    """Use every ``beam_stride``-th laser beam (neighbouring beams are strongly correlated,
    and the cost is linear in the number of beams)."""
    laser_independent_beams: float | None = 4.5
    """Laser: temper each scan's likelihood so that it counts as this many independent
    readings, ``p(z | x)^e`` with ``e = min(1, laser_independent_beams / B)`` for its ``B``
    used beams (see :func:`.mcl_update_laser`); ``None``: no tempering (``e = 1``).
    The likelihood field scores beams as independent, but neighbouring beams' errors are
    not (same wall, same map cells, same pose error): untempered, every scan collapses the
    set onto one or a few particles, which then drift off the true pose and lose it. The
    default was chosen for a consistent NEES after convergence (measurements in
    docs/estimators/mcl.md)."""
    laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Pose of the laser in the robot frame: (forward [m], left [m], yaw [rad])."""
    measurement_cov_scale: float = 1.0
    """Multiplies the measurement noise covariances (standard deviations by the square
    root): the landmark sensor's, and the laser's range noise when ``sigma_hit`` is
    derived."""
    on_weight_underflow: Literal["skip", "raise"] = "skip"
    """What to do when a measurement leaves every particle with zero weight: ``"skip"``
    drops that measurement (keeps the predicted weights) and reports it in the
    diagnostics; ``"raise"`` raises :class:`~slamkit.errors.ConvergenceError`."""
    record_innovations: bool = True
    """Landmark readings: keep every used reading's NIS against the particle mean and
    covariance before the update (see :func:`.landmark_innovations`) in the output's
    :class:`~slamkit.estimation.contract.InnovationLog`, as the EKF does."""
    snapshot_every: int = 0
    """Keep a copy of the particle set every this many measurement updates (0: never),
    plus the initial set."""
    snapshot_times: tuple[float, ...] = ()
    """Keep a copy of the particle set at the first measurement update at or after each of
    these times [s]."""

    def __post_init__(self) -> None:
        if self.n_particles_global is not None and not self.n_particles_global >= 1:
            raise ConfigError(
                f"n_particles_global: expected an integer >= 1 or None, got "
                f"{self.n_particles_global}"
            )
        if not self.global_particles_per_m2 > 0:
            raise ConfigError(
                f"global_particles_per_m2: expected a number > 0, got "
                f"{self.global_particles_per_m2}"
            )
        for name in ("n_particles", "kld_min_particles"):
            if not getattr(self, name) >= 1:
                raise ConfigError(f"{name}: expected an integer >= 1, got {getattr(self, name)}")
        if self.kld_max_particles < self.kld_min_particles:
            raise ConfigError("kld_max_particles: expected >= kld_min_particles")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ConfigError(
                f"resample_threshold: expected a fraction in [0, 1], got {self.resample_threshold}"
            )
        if not 0.0 < self.alpha_slow < self.alpha_fast <= 1.0:
            raise ConfigError(
                f"alpha_slow, alpha_fast: expected 0 < alpha_slow < alpha_fast <= 1, got "
                f"{self.alpha_slow}, {self.alpha_fast}"
            )
        for name in (
            "prior_cov_scale",
            "motion_cov_scale",
            "injection_margin",
            "injection_sigmas",
        ):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        for name in ("kld_epsilon", "kld_bin_xy", "kld_bin_theta_deg", "measurement_cov_scale"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a number > 0, got {getattr(self, name)}")
        if not 0.0 < self.kld_quantile < 1.0:
            raise ConfigError(f"kld_quantile: expected a probability, got {self.kld_quantile}")
        if self.sigma_hit is not None and not self.sigma_hit > 0:
            raise ConfigError(f"sigma_hit: expected a number > 0 or None, got {self.sigma_hit}")
        if not (self.z_hit >= 0 and self.z_rand >= 0 and self.z_hit + self.z_rand > 0):
            raise ConfigError("z_hit, z_rand: expected numbers >= 0, not both 0")
        if self.beam_stride < 1 or self.snapshot_every < 0:
            raise ConfigError("beam_stride >= 1 and snapshot_every >= 0 expected")
        if self.on_weight_underflow not in ("skip", "raise"):
            raise ConfigError(
                f"on_weight_underflow: expected 'skip' or 'raise', got {self.on_weight_underflow!r}"
            )
