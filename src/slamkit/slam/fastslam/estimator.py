"""The FastSLAM 1.0 and 2.0 estimators: the event shell over the kernels."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray, as_covariance
from slamkit.datasets.stream import Dataset, Event, GpsFix, LandmarkReadings
from slamkit.errors import ConfigError, ConvergenceError
from slamkit.estimation.contract import (
    EstimatorOutput,
    LandmarkEstimate,
    LandmarkIds,
    ParticleSnapshot,
    PoseEstimate,
    SnapshotSchedule,
    SpreadSnapshots,
)
from slamkit.estimation.gps import GpsFrontEnd, gps_warnings
from slamkit.estimation.particles import (
    low_variance_resample_unchecked,
)
from slamkit.estimation.shell import EstimatorShell
from slamkit.mapping.ekf_mapping import (
    INITIALISED,
)
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.models.motion import motion_kernels
from slamkit.slam.fastslam.association import (
    kept_readings,
    normalised_with_weights,
    prune_landmarks,
    scan_at_poses,
)
from slamkit.slam.fastslam.config import (
    FastSlamConfig,
    check_dataset,
    steering_limit,
    update_settings,
)
from slamkit.slam.fastslam.gps import (
    fix_distance,
    fix_update,
    frame_draws,
    move_gaussians,
    move_poses,
)
from slamkit.slam.fastslam.history import (
    AssociationHistory,
    mixture_estimate,
    particle_diagnostics,
)
from slamkit.slam.fastslam.particles import FastSlamParticles, IntArray
from slamkit.slam.fastslam.proposal import fold_motion, sym_sqrt, update2
from slamkit.slam.fastslam.settings import UpdateSettings
from slamkit.slam.fastslam.store import Work


class _FastSlam(EstimatorShell):
    """The stateful shell shared by both versions (see :class:`FastSlam1`)."""

    version = 1
    name = "fastslam1"

    def __init__(self, dataset: Dataset, config: FastSlamConfig, rng: np.random.Generator) -> None:
        if not isinstance(config, FastSlamConfig):
            raise ConfigError(f"config: expected a FastSlamConfig, got {type(config).__name__}")
        motion, sensor, model = check_dataset(dataset, self.name)
        self._cfg = config
        self._rng = rng
        self._motion = motion.model
        self._Q = as_covariance(
            config.motion_cov_scale * motion.noise_cov,
            "scaled motion noise_cov",
            self._motion.control_dim,
            semidefinite=True,
        )
        self._Q_root = sym_sqrt(self._Q)  # symmetric: ε = n @ root = root @ n
        self._model: InvertibleLandmarkModel = model
        self._R = as_covariance(
            config.measurement_cov_scale * sensor.noise_cov, "scaled landmark noise_cov", 2
        )
        self._settings = update_settings(dataset, sensor, config, self._R)
        n = config.n_particles
        if dataset.initial_pose is None:
            start = np.zeros((n, 3))
        else:
            cov = dataset.initial_cov if dataset.initial_cov is not None else np.zeros((3, 3))
            start = rng.multivariate_normal(
                dataset.initial_pose, config.prior_cov_scale * cov, n, method="eigh"
            )
        ps = FastSlamParticles.start(
            start, config.initial_capacity, self._settings.first_unlabelled_id
        )
        # The state, mutated in place by the kernels: poses, log-weights, weights and the
        # planar maps (the particle set is built from them on demand, see `particles`).
        self._poses = ps.poses
        self._log_weights = ps.log_weights
        self._weights = ps.weights
        self._w = Work.of(ps)
        self._w.common = True
        self._w.maybe_prunable = False  # no landmark yet
        self._kernels = motion_kernels(self._motion)
        self._steering_limit = steering_limit(self._motion)
        self._pending: tuple[FloatArray, float] | None = None  # 2.0: a motion not yet sampled
        # 2.0: the earlier controls since the last scan, as each particle's Gaussian (mean
        # poses, covariances) before the pending control (None: the poses are exact).
        self._moved: tuple[FloatArray, FloatArray] | None = None
        self._after: tuple[FloatArray, FloatArray] | None = None  # ... and after it (cache)
        self._resample_pending = False
        self._updates = 0
        # The map is numbered as the data set's landmarks when the readings' ids are used.
        self._ids_used = config.use_ids and sensor.identities
        super().__init__()
        self._t = dataset.start_time
        self._resamplings = 0
        self._readings_skipped = 0
        self._removed = 0
        self._ess: list[float] = []
        self._snapshots: list[ParticleSnapshot] = []
        self._history = AssociationHistory()  # to trace any final particle's association
        self._schedule = SnapshotSchedule(config.snapshot_every, config.snapshot_times)
        spread = config.snapshot_every == 0 and not config.snapshot_times
        self._spread = SpreadSnapshots(config.n_snapshots if spread else 0)
        if config.snapshot_every > 0:
            self._snapshot(dataset.start_time)
        self._spread.offer(0, lambda: self._copy(dataset.start_time))
        self._gps = None if dataset.gps is None else GpsFrontEnd(
            dataset.gps.noise_cov, config.gps_lever_arm, config.gps_gate_probability,
            dataset.start_time, self.estimate().pose,
        )  # fmt: skip

    # -- the Estimator protocol -------------------------------------------------------------

    def handle(self, event: Event) -> None:
        self._t = float(event.t)
        super().handle(event)

    def on_control(self, u: FloatArray, dt: float) -> None:
        self._motion_step(np.asarray(u, dtype=float), float(dt))

    def on_landmarks(self, event: LandmarkReadings) -> None:
        if event.ids.size:
            self._update(event)

    def on_gps(self, event: GpsFix) -> None:
        if self._gps is not None:  # the Dataset refuses fixes without a GpsSpec
            self._fix(float(event.t), np.asarray(event.position, dtype=float))

    def after_event(self, step: int) -> None:
        if self._gps is not None:
            self._gps.record(self._t, self.estimate().pose)

    def estimate(self) -> PoseEstimate:
        # 2.0 between a control and its scan: each particle's motion since the scan as a
        # Gaussian (the estimate is their mixture).
        poses, covs = (self._poses, None) if self._pending is None else self._pending_gaussian()
        best = int(np.argmax(self._log_weights)) if self._cfg.estimate == "best" else None
        return PoseEstimate(*mixture_estimate(poses, self._weights, covs, best))

    def finish(self) -> EstimatorOutput:
        ps = self.particles
        best = ps.best
        diagnostics = particle_diagnostics(ps, np.asarray(self._ess, dtype=float))
        diagnostics.update(
            version=self.version,
            measurement_updates=self._updates,
            resamplings=self._resamplings,
            readings_skipped=self._readings_skipped,
            landmarks_removed=self._removed,
            p0=self._settings.p0,
        )
        if self._schedule.pending and (not self._snapshots or self._snapshots[-1].t < self._t):
            self._snapshot(self._t)  # times left after the last update: the final set
        if self._spread.n > 0:
            self._snapshots = list(self._spread.pick(self._copy(self._t)))
        _, chosen, status = self.reading_log()
        diagnostics["readings"] = int(chosen.size)
        diagnostics["readings_new_landmark"] = int(np.count_nonzero(status == INITIALISED))
        if self._gps is not None:
            diagnostics.update(self._gps.counts)
        return EstimatorOutput(
            trajectory=None if self._gps is None else self._gps.trajectory(),
            warnings=() if self._gps is None else gps_warnings(self._gps.counts),
            landmarks=ps.landmarks_of(best),
            diagnostics=diagnostics,
            particle_snapshots=tuple(self._snapshots),
            reading_landmarks=chosen,
            landmark_numbering=LandmarkIds.DATASET if self._ids_used else LandmarkIds.OWN,
        )

    def landmark_estimate(self) -> LandmarkEstimate:
        """The map of the particle with the largest weight now (animation frames)."""
        ps = self.particles
        return ps.landmarks_of(ps.best)

    def particle_poses(self) -> FloatArray:
        """The particle poses ``(P, 3)`` now (animation frames); for 2.0 between a control
        and its scan, the means of each particle's motion since the scan."""
        if self._pending is not None:
            return self._pending_gaussian()[0].copy()
        return self._poses.copy()

    # -- read-only views (tests, plots) ---------------------------------------------------

    @property
    def particles(self) -> FastSlamParticles:
        """The current particle set (a copy: later steps do not change it)."""
        return self._w.particles(self._poses.copy(), self._log_weights.copy())

    @property
    def generator(self) -> np.random.Generator:
        """The random generator the estimator was given and draws from (its state advances
        as the filter runs; a deep copy of the estimator copies it too)."""
        return self._rng

    @property
    def settings(self) -> UpdateSettings:
        return self._settings

    @property
    def resample_pending(self) -> bool:
        """Whether the ESS fell below the threshold: the set is resampled before it moves."""
        return self._resample_pending

    @property
    def ess_history(self) -> tuple[float, ...]:
        """The effective sample size after every measurement update."""
        return tuple(self._ess)

    def reading_log(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading handled so far, as the particle that now has the largest weight saw
        it (its own association and those of its ancestors): ``(times, landmark ids,
        status)`` — the id of the landmark the reading updated or started (``-1`` if none);
        status codes as :meth:`EkfSlam.reading_log <slamkit.slam.EkfSlam.reading_log>`'s:
        :data:`~slamkit.mapping.ekf_mapping.UPDATED`, ``INITIALISED``, ``DISCARDED`` (the
        landmark was at the sensor) and ``TOO_CLOSE`` (skipped, see
        :attr:`FastSlamConfig.min_range`)."""
        return self._history.trace(int(np.argmax(self._log_weights)))

    # -- steps ----------------------------------------------------------------------------

    def _maybe_snapshot(self, t: float) -> None:
        if self._schedule.due(t, self._updates):
            self._snapshot(t)
        self._spread.offer(self._updates, lambda: self._copy(t))

    def _copy(self, t: float) -> ParticleSnapshot:
        return ParticleSnapshot(float(t), self._poses.copy(), self._weights.copy())

    def _snapshot(self, t: float) -> None:
        self._snapshots.append(self._copy(t))

    def _resample_if_due(self) -> None:
        if self._resample_pending:
            # The weights are normalised and finite by construction: the unchecked kernel.
            idx = low_variance_resample_unchecked(self._weights, self._rng, self._weights.size)
            n = idx.size
            self._history.log_resampling(idx)
            self._poses = self._poses[idx]
            if self._moved is not None:
                self._moved = (self._moved[0][idx], self._moved[1][idx])
            if self._after is not None:
                self._after = (self._after[0][idx], self._after[1][idx])
            self._w = self._w.select(idx)
            self._log_weights, self._weights = np.empty(n), np.empty(n)
            self._log_weights.fill(-math.log(n))
            self._weights.fill(1.0 / n)
            self._resamplings += 1
            self._resample_pending = False

    def _predict(self, u: FloatArray, dt: float) -> None:
        self._resample_if_due()
        poses = self._poses
        # g(x, u + ε), ε = Q^½ n, n ~ N(0, I): MotionModel.sample with Q's root computed once.
        eps = self._rng.standard_normal((poses.shape[0], self._Q_root.shape[0])) @ self._Q_root
        eps += u
        if self._steering_limit is not None:  # Ackermann: keep sampled steering in its domain
            np.clip(eps[:, 1], -self._steering_limit, self._steering_limit, out=eps[:, 1])
        self._kernels.move_particles(poses, eps, dt)  # validated once: the in-place kernel

    def _motion_step(self, u: FloatArray, dt: float) -> None:
        self._predict(u, dt)

    def _pending_gaussian(self) -> tuple[FloatArray, FloatArray]:
        """2.0: each particle's pose after the pending control as a Gaussian (means
        ``(P, 3)``, covariances ``(P, 3, 3)``), the motion since the last scan linearised
        (:func:`fold_motion`); computed once per control."""
        assert self._pending is not None
        if self._after is None:
            u, dt = self._pending
            x0, cov0 = self._moved if self._moved is not None else (self._poses, None)
            self._after = fold_motion(self._motion, x0, cov0, u, dt, self._Q)
        return self._after

    def _fix(self, t: float, z: FloatArray) -> None:
        """A GPS fix (:mod:`~slamkit.slam.fastslam.gps`): collected for the move into the GPS
        frame, then weighed (and, for 2.0's Gaussians, folded into the proposal)."""
        gps = self._gps
        assert gps is not None
        means, covs = self._pose_gaussians()
        if not gps.aligned:
            fit = gps.collect(t, z, self.estimate().pose)
            if fit is not None:
                angles, shifts = frame_draws(fit, self._poses.shape[0], self._rng)
                self._poses = move_poses(self._poses, angles, shifts)
                self._w.move(angles, shifts)
                if covs is not None:
                    self._hold(*move_gaussians(means, covs, angles, shifts))
            return
        used = fix_distance(means, covs, self._weights, z, gps.lever, gps.noise_cov) <= gps.gate
        gps.judged(used)
        if not used:  # a refused fix changes nothing, draws nothing
            return
        if self._resample_pending:  # as before a scan
            self._resample_if_due()
            means, covs = self._pose_gaussians()
        loglik, means, covs = fix_update(means, covs, z, gps.lever, gps.noise_cov)
        if covs is not None:
            self._hold(means, covs)
        self._log_weights, self._weights = normalised_with_weights(self._log_weights + loglik)
        ess = 1.0 / float((self._weights * self._weights).sum())
        if ess < self._cfg.resample_threshold * self._weights.size:
            self._resample_pending = True

    def _pose_gaussians(self) -> tuple[FloatArray, FloatArray | None]:
        """Each particle's pose now: 2.0 with motion since the scan, a Gaussian (means,
        covariances); else exact (poses, None)."""
        return self._pending_gaussian() if self._pending is not None else (self._poses, None)

    def _hold(self, means: FloatArray, covs: FloatArray) -> None:
        """2.0: the particles' pose Gaussians after a fix, held as the motion since the scan
        with a control of zero length pending (``g(x, 0, 0) = x``, no noise), so the next
        control and the next scan's proposal start from them."""
        self._moved = self._after = (means, covs)
        self._pending = (np.zeros(self._Q.shape[0]), 0.0)

    def _scan(self, z: FloatArray, rid: IntArray) -> FloatArray:
        """The scan on the state (in place); returns the new log-weights (not normalised)."""
        w = self._w
        w.begin_scan()
        ll = scan_at_poses(w, self._poses, z, rid, self._R, self._model, self._settings)
        prune_landmarks(w, self._poses, self._settings)
        return self._log_weights + ll

    def _update(self, event: LandmarkReadings) -> None:
        z, rid, use = kept_readings(event, self._model, self._settings)
        if use is not None:
            self._readings_skipped += use.size - int(np.count_nonzero(use))
            if not use.any():
                self._history.log_scan(event.t, np.zeros(0, np.int64), np.zeros(0, np.int8), use)
                return
        self._updates += 1
        self._resample_if_due()
        try:
            self._log_weights, w = normalised_with_weights(self._scan(z, rid))
        except ConvergenceError as exc:  # the shell adds the name, the time and the step
            raise ConvergenceError(f"measurement update {self._updates}: {exc}") from exc
        self._removed += self._w.removed
        self._history.log_scan(event.t, self._w.assoc, self._w.assoc_status, use)
        self._weights = w
        self._maybe_snapshot(event.t)
        ess = 1.0 / float((w * w).sum())  # effective_sample_size of normalised weights
        self._ess.append(ess)
        if ess < self._cfg.resample_threshold * w.size:
            self._resample_pending = True


class FastSlam1(_FastSlam):
    """FastSLAM 1.0 (registered as ``fastslam1``): poses sampled from the motion model,
    weighted by the readings' likelihood; per-particle landmark EKFs, maximum-likelihood
    association with a new-landmark threshold, existence counters, low-variance resampling
    when the effective sample size drops. See the module docstring and
    :class:`FastSlamConfig`.

    Needs a motion model and a range-bearing or relative-position landmark sensor. The
    estimate is the particles' weighted mean (or best particle) with their covariance;
    :meth:`finish` returns the map of the particle with the largest weight.
    """


class FastSlam2(_FastSlam):
    """FastSLAM 2.0 (registered as ``fastslam2``): as :class:`FastSlam1`, but the controls
    since the last scan and the scan are processed together, and each particle's pose is
    drawn from the Gaussian proposal that includes the readings (over the control noise and
    the linearised error of the earlier controls, see the module docstring), weighted by the
    marginal likelihood with the motion noise integrated out.

    Nothing is sampled until the scan: each particle's pose since its last scan is a
    Gaussian (EKF predictions), and :meth:`estimate` meanwhile reports their mixture (the
    weighted mean of the means; the spread of the means plus the mean covariance).
    """

    version = 2
    name = "fastslam2"

    def _motion_step(self, u: FloatArray, dt: float) -> None:
        if self._pending is None:
            self._resample_if_due()  # before the motion, as 1.0
        else:  # an earlier control since the scan: into each particle's pose Gaussian
            self._moved = self._pending_gaussian()
        self._pending, self._after = (u, dt), None

    def _scan(self, z: FloatArray, rid: IntArray) -> FloatArray:
        if self._pending is None:
            return super()._scan(z, rid)
        u, dt = self._pending
        x0, cov0 = self._moved if self._moved is not None else (self._poses, None)
        self._pending = self._moved = self._after = None
        self._poses, lw, _ = update2(
            self._w, x0, self._log_weights, self._motion, u, dt, self._Q, z, rid,
            self._R, self._model, self._settings, self._rng, cov0,
        )  # fmt: skip
        return lw  # normalised already: normalising again changes nothing
