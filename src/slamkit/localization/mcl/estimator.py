"""The ``mcl`` estimator: :class:`MonteCarloLocalization`, the thin stateful shell the runner
drives over the particle-filter steps of :mod:`.core`, :mod:`.landmarks`, :mod:`.kld` and
:mod:`.augmented`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, LandmarkReadings, LaserScan
from slamkit.errors import ConfigError, ConvergenceError, GeometryError, InputError
from slamkit.estimation.contract import (
    EstimatorOutput,
    ParticleSnapshot,
    PoseEstimate,
    SnapshotSchedule,
)
from slamkit.estimation.particles import (
    ParticleSet,
    effective_sample_size,
    particle_estimate_unchecked,
)
from slamkit.estimation.shell import EstimatorShell, InnovationRecorder
from slamkit.localization.mcl.augmented import Augmentation, advance_augmentation
from slamkit.localization.mcl.config import MclConfig
from slamkit.localization.mcl.core import (
    MeasurementUpdate,
    control_noise_root,
    mcl_predict_unchecked,
    mcl_resample,
    mcl_update_laser,
    reweight,
)
from slamkit.localization.mcl.kld import kld_resample_predict
from slamkit.localization.mcl.landmarks import (
    LandmarkInnovations,
    landmark_innovations_unchecked,
    landmark_log_likelihood_unchecked,
    whitener,
)
from slamkit.localization.mcl.sampling import (
    PoseSampler,
    free_space_sampler,
    initial_poses,
    landmark_box_sampler,
)
from slamkit.maps import LandmarkMap
from slamkit.maps.likelihood_field import LikelihoodField, usable_beams
from slamkit.models import LandmarkModel, MotionModel

__all__ = ["MonteCarloLocalization"]

log = logging.getLogger(__name__)


@dataclass
class _Counters:
    predictions: int = 0
    updates: int = 0
    resamplings: int = 0
    injected: int = 0
    injection_events: int = 0
    underflows: int = 0
    first_underflow_update: int | None = None
    first_underflow_t: float | None = None
    readings_skipped: int = 0
    innovations_skipped: int = 0
    particle_counts: list[int] = dataclass_field(default_factory=list)
    ess_shares: list[float] = dataclass_field(default_factory=list)
    """``N_eff / N`` after each measurement update."""

    def diagnostics(self, global_start: bool) -> dict[str, Any]:
        counts = np.asarray(self.particle_counts)
        return {
            "global_start": global_start,
            "predictions": self.predictions,
            "measurement_updates": self.updates,
            "resamplings": self.resamplings,
            "injected_particles": self.injected,
            "injection_events": self.injection_events,
            "weight_underflows": self.underflows,
            "first_underflow_update": self.first_underflow_update,
            "first_underflow_t": self.first_underflow_t,
            "readings_skipped": self.readings_skipped,
            "particles_initial": int(counts[0]),
            "particles_final": int(counts[-1]),
            "particles_min": int(counts.min()),
            "particles_max": int(counts.max()),
            "particles_mean": float(counts.mean()),
            "ess_share_mean": float(np.mean(self.ess_shares)) if self.ess_shares else None,
            "ess_share_min": float(np.min(self.ess_shares)) if self.ess_shares else None,
        }


def _check_inputs(dataset: Dataset, config: MclConfig) -> tuple[bool, bool]:
    """Whether the laser and the landmark sensor are used; raises when neither can be."""
    if not isinstance(config, MclConfig):
        raise ConfigError(f"config: expected an MclConfig, got {type(config).__name__}")
    if dataset.motion is None:
        raise InputError(f"mcl needs a motion model; data set {dataset.name!r} has none")
    use_laser = dataset.laser is not None and dataset.known_grid is not None
    use_landmarks = dataset.landmark_sensor is not None and dataset.known_landmarks is not None
    if not (use_laser or use_landmarks):
        raise InputError(
            f"mcl needs a laser with a known grid map or a landmark sensor with known "
            f"landmarks; data set {dataset.name!r} has laser={dataset.laser is not None}, "
            f"known_grid={dataset.known_grid is not None}, "
            f"landmark_sensor={dataset.landmark_sensor is not None}, "
            f"known_landmarks={dataset.known_landmarks is not None}"
        )
    return use_laser, use_landmarks


def _laser_field(dataset: Dataset, config: MclConfig) -> LikelihoodField:
    """The likelihood field of the known grid (``sigma_hit`` derived when ``None``)."""
    assert dataset.laser is not None and dataset.known_grid is not None
    grid = dataset.known_grid
    sigma = config.laser.sigma_hit
    if sigma is None:
        s_r = dataset.laser.range_sigma
        sigma = math.sqrt(config.measurement_cov_scale) * float(
            np.sqrt(s_r**2 + grid.resolution**2 / 3.0)
        )
    return LikelihoodField.from_grid(
        grid, sigma, config.laser.z_hit, config.laser.z_rand, dataset.laser.max_range
    )


def _injection_sampler(
    dataset: Dataset, config: MclConfig, use_laser: bool
) -> tuple[PoseSampler, float]:
    """Where random particles come from, and the area they cover [m²]: the free cells of the
    known grid (laser worlds) or the landmarks' box grown by ``augmented.injection_margin``."""
    if use_laser:
        assert dataset.known_grid is not None
        return free_space_sampler(dataset.known_grid)
    assert dataset.known_landmarks is not None
    return landmark_box_sampler(
        dataset.known_landmarks.positions, config.augmented.injection_margin
    )


def _start_poses(
    dataset: Dataset,
    config: MclConfig,
    global_start: bool,
    sampler: PoseSampler,
    area: float,
    rng: np.random.Generator,
) -> FloatArray:
    """The start particles: uniform over the map (``start.uniform``), else drawn from the
    prior ``N(initial_pose, prior_cov_scale · initial_cov)``."""
    if global_start:
        n_global, per_m2 = config.start.n_particles, config.start.particles_per_m2
        return initial_poses(sampler, area, n_global, per_m2, rng)
    assert dataset.initial_pose is not None
    cov = dataset.initial_cov if dataset.initial_cov is not None else np.zeros((3, 3))
    start: FloatArray = rng.multivariate_normal(
        dataset.initial_pose, config.start.prior_cov_scale * cov, config.n_particles
    )
    return start


def _innovations_before(
    particles: ParticleSet,
    zk: FloatArray,
    ids: NDArray[np.int64],
    lm: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
) -> LandmarkInnovations | None:
    """The readings' innovations against the particles' mean and covariance (before the
    update); ``None`` when a landmark lies on the mean pose (no bearing)."""
    mean, cov = particle_estimate_unchecked(particles.poses, particles.weights)
    try:
        return landmark_innovations_unchecked(mean, cov, zk, ids, lm, model, R)
    except GeometryError:
        return None


def _kld_predict(
    particles: ParticleSet,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    Q: FloatArray,
    rng: np.random.Generator,
    cfg: MclConfig,
    p_random: float,
    sampler: PoseSampler,
) -> tuple[ParticleSet, int]:
    """:func:`.kld_resample_predict` with the settings of ``cfg``."""
    return kld_resample_predict(
        particles,
        u,
        dt,
        model,
        Q,
        rng,
        epsilon=cfg.kld.epsilon,
        upper_quantile=cfg.kld.quantile,
        bin_size=(cfg.kld.bin_xy, np.deg2rad(cfg.kld.bin_theta_deg)),
        min_particles=cfg.kld.min_particles,
        max_particles=cfg.kld.max_particles,
        p_random=p_random,
        sampler=sampler,
    )


class MonteCarloLocalization(EstimatorShell):
    """Particle-filter localization in a known map (registered as ``mcl``).

    Needs a motion model and either a landmark sensor with ``known_landmarks`` or a laser
    with ``known_grid`` (both are used when both are there). With a prior pose the particles
    start from ``N(initial_pose, prior_cov_scale · initial_cov)``; without one (or with
    ``start.uniform``) uniformly over the map's free space (laser) or the landmarks' bounding
    box grown by ``augmented.injection_margin``. See :class:`MclConfig` for the rest.
    """

    name = "mcl"

    def __init__(self, dataset: Dataset, config: MclConfig, rng: np.random.Generator) -> None:
        use_laser, use_landmarks = _check_inputs(dataset, config)
        assert dataset.motion is not None
        super().__init__()
        self._cfg = config
        self._rng = rng
        self._motion = dataset.motion
        self._Q = config.motion_cov_scale * dataset.motion.noise_cov
        self._Q_root = control_noise_root(self._Q)

        self._field: LikelihoodField | None = None
        self._laser_offset: FloatArray | None = None
        self._beam_angles: FloatArray | None = None
        if use_laser:
            assert dataset.laser is not None
            self._field = _laser_field(dataset, config)
            self._beam_angles = dataset.laser.beam_angles
            mounting = config.laser.offset
            if mounting is None:
                mounting = dataset.laser.mounting
            self._laser_offset = np.asarray(mounting, dtype=np.float64) if any(mounting) else None
        self._landmarks: LandmarkMap | None = None
        if use_landmarks:
            assert dataset.landmark_sensor is not None and dataset.known_landmarks is not None
            self._landmarks = dataset.known_landmarks
            self._lm_model = dataset.landmark_sensor.model()
            self._lm_cov = config.measurement_cov_scale * dataset.landmark_sensor.noise_cov
            self._lm_whitener = whitener(self._lm_cov)
        self._sampler, area = _injection_sampler(dataset, config, use_laser)
        self._global_start = dataset.initial_pose is None or config.start.uniform
        start = _start_poses(dataset, config, self._global_start, self._sampler, area, rng)
        self._particles = ParticleSet.uniform_weights(start)
        # A uniform belief over the map stays (nearly) uniform under the motion model, so a
        # global start's particles are not moved until the first measurement has weighted
        # them: that saves moving start.n_particles particles at every step before it.
        self._uniform = self._global_start
        self._estimate: PoseEstimate | None = None
        self._estimate_of: ParticleSet | None = None
        self._n_target = len(self._particles)
        self._aug: Augmentation | None = None
        self._resample_pending = False
        self._inject_pending = 0
        self._p_inject = 0.0
        self._c = _Counters(particle_counts=[len(self._particles)])
        self._snapshots: list[ParticleSnapshot] = []
        self._innovations = InnovationRecorder(use_landmarks and config.record_innovations)
        self._schedule = SnapshotSchedule(config.snapshots.every, config.snapshots.times)
        if config.snapshots.every > 0:
            self._snapshot(dataset.start_time)

    # -- the Estimator protocol ---------------------------------------------------------

    def on_control(self, u: FloatArray, dt: float) -> None:
        self._predict(u, dt)

    def on_scan(self, event: LaserScan) -> None:
        if self._field is None or self._beam_angles is None:
            return
        field_, angles = self._field, self._beam_angles
        cfg = self._cfg
        offset = self._laser_offset
        exponent = 1.0
        if cfg.laser.independent_beams is not None:
            used = usable_beams(field_, event.ranges, angles, cfg.laser.beam_stride)
            exponent = min(1.0, cfg.laser.independent_beams / max(used, 1))
        self._update(
            event.t,
            lambda ps: mcl_update_laser(
                ps, event.ranges, field_, angles, offset, cfg.laser.beam_stride, exponent
            ),
            exponent,
        )

    def on_landmarks(self, event: LandmarkReadings) -> None:
        if self._landmarks is not None:
            self._landmark_readings(event, self._landmarks)

    def estimate(self) -> PoseEstimate:
        ps = self._particles
        if self._estimate_of is not ps:  # the set changed since the last call
            mean, cov = particle_estimate_unchecked(ps.poses, ps.weights)
            self._estimate, self._estimate_of = PoseEstimate(mean, cov), ps
        assert self._estimate is not None
        return PoseEstimate(
            self._estimate.pose.copy(),
            None if self._estimate.cov is None else self._estimate.cov.copy(),
        )

    def finish(self) -> EstimatorOutput:
        c = self._c
        diagnostics = c.diagnostics(self._global_start)
        innovations = self._innovations.log()
        if innovations is not None:
            nis = innovations.nis
            diagnostics["innovations_skipped"] = c.innovations_skipped
            diagnostics["mean_nis_per_dof"] = (
                float(nis.mean()) / self._lm_model.dim if nis.size else None
            )
        return EstimatorOutput(
            diagnostics=diagnostics,
            innovations=innovations,
            particle_snapshots=tuple(self._snapshots),
        )

    def particle_poses(self) -> FloatArray:
        """The particle poses ``(P, 3)`` now (animation frames)."""
        return self._particles.poses.copy()

    # -- read-only views (tests, plots) ---------------------------------------------------

    @property
    def global_start(self) -> bool:
        """Whether the particles started uniform over the map (no prior, or ``start.uniform``)."""
        return self._global_start

    @property
    def particles(self) -> ParticleSet:
        return self._particles

    @property
    def augmentation(self) -> Augmentation | None:
        return self._aug

    @property
    def particle_counts(self) -> tuple[int, ...]:
        """The number of particles after every prediction (the first entry: at the start)."""
        return tuple(self._c.particle_counts)

    # -- steps ------------------------------------------------------------------------------

    def _predict(self, u: ArrayLike, dt: float) -> None:
        cfg, rng = self._cfg, self._rng
        if self._uniform:  # see __init__: a uniform set is left where it is
            self._c.predictions += 1
            self._c.particle_counts.append(len(self._particles))
            return
        if cfg.kld.enabled and self._resample_pending:
            ps, p, sampler = self._particles, self._p_inject, self._sampler
            self._particles, n_random = _kld_predict(
                ps, u, dt, self._motion.model, self._Q, rng, cfg, p, sampler
            )
            self._c.resamplings += 1
            self._count_injection(n_random)
        else:
            if self._resample_pending and not cfg.kld.enabled:
                k = min(self._inject_pending, self._n_target)
                self._particles = mcl_resample(
                    self._particles, rng, self._n_target, n_random=k, sampler=self._sampler
                )
                self._c.resamplings += 1
                self._count_injection(k)
            ps = self._particles
            moved = mcl_predict_unchecked(
                ps.poses, np.asarray(u, dtype=np.float64), dt, self._motion.model, self._Q_root, rng
            )
            self._particles = ParticleSet(moved, ps.log_weights.copy())
        self._resample_pending = False
        self._inject_pending = 0
        self._p_inject = 0.0
        self._c.predictions += 1
        self._c.particle_counts.append(len(self._particles))

    def _landmark_readings(self, event: LandmarkReadings, lms: LandmarkMap) -> None:
        ids = np.asarray(event.ids)
        known = np.isin(ids, lms.ids)
        self._c.readings_skipped += int(np.count_nonzero(~known))
        if not known.any():
            return
        used = ids[known].astype(np.int64)
        zk, lm = event.z[known], lms.position_of(used)
        model = self._lm_model
        innov = None
        if self._cfg.record_innovations:
            innov = _innovations_before(self._particles, zk, used, lm, model, self._lm_cov)
            if innov is None:
                self._c.innovations_skipped += 1
        L_inv, log_norm = self._lm_whitener

        def correct(ps: ParticleSet) -> MeasurementUpdate:
            ll = landmark_log_likelihood_unchecked(ps.poses, zk, lm, model, L_inv, log_norm)
            out = reweight(ps, ll)
            return MeasurementUpdate(out.particles, ll, out.log_evidence, int(used.size))

        if self._update(event.t, correct) and innov is not None:
            for nis, lm_id in zip(innov.nis.tolist(), innov.landmark_ids.tolist(), strict=True):
                self._innovations.add(event.t, nis, model.dim, lm_id)

    def _count_injection(self, n: int) -> None:
        if n > 0:
            self._c.injected += n
            self._c.injection_events += 1

    def _update(
        self,
        t: float,
        step: Callable[[ParticleSet], MeasurementUpdate],
        exponent: float = 1.0,
    ) -> bool:
        """Apply a correction; False if it was skipped (every weight underflowed).

        ``exponent``: the likelihood was tempered by this power, so its ``n`` readings count
        as ``n · exponent`` in the per-reading evidence that augmented MCL averages (for a
        concentrated set, ``log Σ w p^e ≈ e log p``: the same per-reading value as untempered).
        """
        cfg = self._cfg
        self._c.updates += 1
        try:
            result = step(self._particles)
        except ConvergenceError as exc:
            self._c.underflows += 1
            if self._c.first_underflow_update is None:
                self._c.first_underflow_update = self._c.updates
                self._c.first_underflow_t = float(t)
            if cfg.on_weight_underflow == "raise":
                raise ConvergenceError(f"mcl at t = {t}: {exc}", step=self.clock.step) from exc
            log.warning("mcl at t = %s: measurement skipped (%s)", t, exc)
            return False
        self._particles = result.particles
        self._uniform = False
        n = len(self._particles)
        if result.n_readings > 0 and cfg.augmented.enabled:
            log_w_avg = result.log_evidence / (result.n_readings * exponent)
            self._aug, self._p_inject = advance_augmentation(
                self._aug,
                log_w_avg,
                cfg.augmented.alpha_slow,
                cfg.augmented.alpha_fast,
                cfg.augmented.injection_sigmas,
            )
            # KLD-sampling injects with this probability per drawn particle; a fixed-size set
            # replaces a binomial number of particles at its next resampling.
            if not cfg.kld.enabled and self._p_inject > 0:
                self._inject_pending = int(self._rng.binomial(n, self._p_inject))
        ess = effective_sample_size(self._particles.weights)
        self._c.ess_shares.append(ess / n)
        if ess < cfg.resample_threshold * n or self._inject_pending > 0 or self._p_inject > 0:
            self._resample_pending = True
        self._maybe_snapshot(t)
        return True

    def _maybe_snapshot(self, t: float) -> None:
        if self._schedule.due(t, self._c.updates):
            self._snapshot(t)

    def _snapshot(self, t: float) -> None:
        ps = self._particles
        self._snapshots.append(ParticleSnapshot(float(t), ps.poses.copy(), ps.weights))
