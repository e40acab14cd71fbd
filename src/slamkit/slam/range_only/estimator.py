"""The range-only SLAM estimator: collects the run into a :class:`RangeOnlyProblem` (nodes at
the reading times, odometry between them, ranges), then solves it in one batch at the end
(:func:`~slamkit.slam.range_only.problem.solve_range_only`). Online, its estimate is dead
reckoning, or, with ``resolve_every_s > 0``, the latest of periodic warm-started solves of
the run so far with the odometry since; its result is the optimised path (a
:class:`SmoothedTrajectory`) and the beacons with the data set's ids. It never reads the
data set's known landmarks: the beacons are withheld by construction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, Event, LandmarkReadings
from slamkit.errors import ConfigError, ConvergenceError, InputError
from slamkit.estimation.belief import GaussianBelief, predict_unchecked
from slamkit.estimation.contract import (
    EstimatorOutput,
    LandmarkEstimate,
    LandmarkIds,
    PoseEstimate,
    RunWarning,
    SmoothedTrajectory,
)
from slamkit.estimation.shell import EstimatorShell
from slamkit.geometry.pose2 import compose
from slamkit.maps import LandmarkMap
from slamkit.optim.robust import KernelName, RobustKernel
from slamkit.slam.range_only.problem import RangeOnlyProblem, RangeOnlySolution, solve_range_only

__all__ = ["RangeOnlySlam", "RangeOnlySlamConfig"]


@dataclass(frozen=True)
class RangeOnlySlamConfig:
    """Settings of :class:`RangeOnlySlam` (measurements behind the defaults:
    ``docs/estimators/range_only.md``)."""

    motion_cov_scale: float = 1.0
    """Multiplies the data set's nominal control-noise covariance."""
    range_cov_scale: float = 1.0
    """Multiplies the data set's nominal range variance."""
    robust_kernel: KernelName = "cauchy"
    """Robust kernel on every edge of the batch solve and in the beacons' fixes (Cauchy:
    chosen on Plaza 1 and a simulated world with injected outlier ranges, see the docs)."""
    robust_width: float = 1.0
    """Its width (:mod:`slamkit.optim.robust`; Cauchy's ``c`` in standard deviations)."""
    init_max_sigma: float = 1.0
    """A beacon's first fix is taken once its standard deviation is at most this [m]."""
    max_iterations: int = 100
    """Levenberg-Marquardt iterations of the batch solve, at most."""
    resolve_every_s: float = 0.0
    """``0``: one batch solve at the end, dead reckoning online. ``T > 0``: also solve the
    run so far every ``T`` seconds of data, each solve warm-started from the previous one,
    and estimate online from the latest solution (the final solve too is warm-started)."""

    def __post_init__(self) -> None:
        for name in ("motion_cov_scale", "range_cov_scale", "robust_width", "init_max_sigma"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"{name}: expected a number > 0, got {value}")
        _ = RobustKernel(self.robust_kernel, self.robust_width)
        if not (np.isfinite(self.resolve_every_s) and self.resolve_every_s >= 0):
            raise ConfigError(
                f"resolve_every_s: expected a number >= 0, got {self.resolve_every_s}"
            )
        if not self.max_iterations >= 1:
            raise ConfigError(
                f"max_iterations: expected an integer >= 1, got {self.max_iterations}"
            )


class RangeOnlySlam(EstimatorShell):
    """Batch range-only SLAM with unknown beacons (see the module docstring)."""

    name = "range-only SLAM"

    def __init__(
        self, dataset: Dataset, config: RangeOnlySlamConfig, rng: np.random.Generator
    ) -> None:
        if dataset.motion is None:
            raise InputError(f"range-only SLAM needs a motion model; {dataset.name} has none")
        sensor = dataset.landmark_sensor
        if sensor is None or sensor.kind != "range":
            kind = None if sensor is None else sensor.kind
            raise InputError(
                f"range-only SLAM needs range readings; {dataset.name} has {kind or 'none'}"
            )
        self._cfg = config
        self._model = dataset.motion.model
        self._Q = config.motion_cov_scale * dataset.motion.noise_cov
        self._sigma = float(np.sqrt(config.range_cov_scale * sensor.noise_cov[0, 0]))
        start = dataset.initial_pose if dataset.initial_pose is not None else np.zeros(3)
        self._prior_cov = dataset.initial_cov
        if self._prior_cov is not None and not np.all(np.linalg.eigvalsh(self._prior_cov) > 0):
            self._prior_cov = None  # a known start: node 0 is held fixed
        self._pose = np.asarray(start, dtype=np.float64).copy()
        self._rel = GaussianBelief.from_pose(np.zeros(3))
        self._moved = False
        self._node_t = [float(dataset.start_time)]
        self._node_pose = [self._pose.copy()]
        self._odo: list[FloatArray] = []
        self._odo_cov: list[FloatArray] = []
        self._r_node: list[int] = []
        self._r_id: list[int] = []
        self._r_z: list[float] = []
        self._unlabelled = 0
        self._stamps = [float(dataset.start_time)]
        self._anchors = [0]
        self._offsets: list[FloatArray] = [np.zeros(3)]
        # the latest solution (resolve_every_s > 0): its node poses and beacons, and the
        # online pose of the current node (chained from it with the odometry)
        self._solved: RangeOnlySolution | None = None
        self._solved_at = float(dataset.start_time)
        self._node_online = self._pose.copy()
        self._solves = 0
        super().__init__()

    # -- events -------------------------------------------------------------------------
    def handle(self, event: Event) -> None:
        super().handle(event)
        anchor, offset = len(self._node_t) - 1, self._rel.pose.copy()
        if event.t == self._stamps[-1]:  # the latest event of a stamp holds
            self._anchors[-1], self._offsets[-1] = anchor, offset
        else:
            self._stamps.append(float(event.t))
            self._anchors.append(anchor)
            self._offsets.append(offset)

    def on_control(self, u: FloatArray, dt: float) -> None:
        self._pose = self._model.apply(self._pose, u, dt)
        self._rel = predict_unchecked(self._rel, u, dt, self._model, self._Q)
        self._moved = True

    def on_landmarks(self, event: LandmarkReadings) -> None:
        if self._moved:  # a new node at this stamp; else the last node holds these too
            self._odo.append(self._rel.pose.copy())
            self._odo_cov.append(self._rel.cov.copy())
            self._node_t.append(float(event.t))
            self._node_pose.append(self._pose.copy())
            self._node_online = compose(self._node_online, self._rel.pose)
            self._rel = GaussianBelief.from_pose(np.zeros(3))
            self._moved = False
        node = len(self._node_t) - 1
        for z, b in zip(event.z[:, 0], event.ids, strict=True):
            if b < 0:
                self._unlabelled += 1
                continue
            self._r_node.append(node)
            self._r_id.append(int(b))
            self._r_z.append(float(z))
        every = self._cfg.resolve_every_s
        if every > 0 and event.t - self._solved_at >= every:
            self._solved = self.solve()
            self._solved_at = float(event.t)
            self._solves += 1
            self._node_online = self._solved.node_poses[-1].copy()

    def after_event(self, step: int) -> None:
        if not np.isfinite(self._pose).all():  # the shell stamps it with the step
            raise ConvergenceError("the dead-reckoned pose became non-finite")

    def estimate(self) -> PoseEstimate:
        if self._cfg.resolve_every_s > 0:
            return PoseEstimate(compose(self._node_online, self._rel.pose))
        return PoseEstimate(self._pose.copy())

    # -- the batch solve ----------------------------------------------------------------
    @property
    def problem(self) -> RangeOnlyProblem:
        """The run so far as a :class:`RangeOnlyProblem`."""
        return RangeOnlyProblem(
            node_times=np.asarray(self._node_t),
            node_poses=np.asarray(self._node_pose).reshape(-1, 3),
            odometry=np.asarray(self._odo).reshape(-1, 3),
            odometry_cov=np.asarray(self._odo_cov).reshape(-1, 3, 3),
            prior_cov=None if self._prior_cov is None else np.asarray(self._prior_cov),
            reading_node=np.asarray(self._r_node, dtype=np.int64),
            beacon_id=np.asarray(self._r_id, dtype=np.int64),
            ranges=np.asarray(self._r_z, dtype=np.float64),
            sigma_range=self._sigma,
        )

    def solve(self) -> RangeOnlySolution:
        """The batch solution of :attr:`problem`: from the dead-reckoned path, or warm-started
        from the latest solution (nodes since then chained on with the odometry)."""
        problem = self.problem
        kernel = RobustKernel(self._cfg.robust_kernel, self._cfg.robust_width)
        poses, beacons = None, None
        last = self._solved
        if last is not None:
            m = last.node_poses.shape[0]
            poses = problem.node_poses.copy()
            poses[:m] = last.node_poses
            for k in range(m, poses.shape[0]):  # X_k = X_{k-1} ⊕ U_{k-1,k}
                poses[k] = compose(poses[k - 1], problem.odometry[k - 1])
            beacons = {int(b): p for b, p in zip(last.beacon_ids, last.beacons, strict=True)}
        return solve_range_only(
            problem,
            kernel,
            self._cfg.init_max_sigma,
            self._cfg.max_iterations,
            initial_poses=poses,
            initial_beacons=beacons,
        )

    def finish(self) -> EstimatorOutput:
        sol = self.solve()
        anchors = np.asarray(self._anchors)
        offsets = np.asarray(self._offsets).reshape(-1, 3)
        path = SmoothedTrajectory(
            np.asarray(self._stamps), compose(sol.node_poses[anchors], offsets)
        )
        landmarks = None
        if sol.beacon_ids.size:
            landmarks = LandmarkEstimate(
                LandmarkMap(sol.beacons.copy(), sol.beacon_ids.copy()), sol.beacon_covariances
            )
        return EstimatorOutput(
            landmarks=landmarks,
            landmark_numbering=LandmarkIds.DATASET,
            trajectory=path,
            diagnostics=_diagnostics(sol, self._unlabelled, self._solves),
            warnings=_warnings(sol),
        )


def _warnings(sol: RangeOnlySolution) -> tuple[RunWarning, ...]:
    """The run's doubts about itself: beacons never started, a solve that did not converge."""
    out = []
    if sol.readings_unfixed:
        out.append(
            RunWarning(
                "beacons_not_started",
                f"{sol.readings_unfixed} readings of beacons that were never started (too few "
                "readings, too short a path, or the mirror never resolved) were left out",
            )
        )
    if sol.optimizer is not None and not sol.optimizer.converged:
        out.append(
            RunWarning(
                "not_converged",
                f"the batch solve stopped without converging ({sol.optimizer.reason})",
            )
        )
    return tuple(out)


def _diagnostics(sol: RangeOnlySolution, unlabelled: int, solves: int) -> dict[str, object]:
    res = sol.optimizer
    out: dict[str, object] = {
        "nodes": int(sol.node_poses.shape[0]),
        "beacons_started": int(sol.beacon_ids.size),
        "readings_used": sol.readings_used,
        "readings_of_unstarted_beacons": sol.readings_unfixed,
        "readings_unlabelled": unlabelled,
        "init_seconds": sol.init_seconds,
        "solves": solves + 1,
        "beacon_starts": {
            str(b): {
                "time_s": s.time,
                "readings_used": s.readings_used,
                "ambiguous_attempts": s.ambiguous_attempts,
                "reason": s.fix.reason,
            }
            for b, s in sol.starts.items()
        },
    }
    if res is not None:
        out.update(
            iterations=res.iterations,
            converged=res.converged,
            chi2=res.chi2,
            solve_seconds=res.total_seconds,
        )
    return out
