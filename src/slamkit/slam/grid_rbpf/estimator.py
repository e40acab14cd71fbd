"""Grid-based Rao-Blackwellized particle filter SLAM (Grisetti, Stachniss & Burgard, IEEE
T-RO 2007, "Improved techniques for grid mapping with Rao-Blackwellized particle filters").

Every particle carries a pose, the path that led to it and an occupancy grid built from
that path (:class:`~slamkit.slam.grid_rbpf.maps.TiledMap`: tiles shared between particles,
copied on write). The filter updates only after the odometry reports ``update_distance``
of travel or ``update_angle_deg`` of turning since the last update, summed step by step (a
robot that backs up and drives on has travelled the whole way, whatever its net motion; the
scans between are not used; the odometry accumulates into one motion ``Δ`` in the frame of
the last update, whose noise grows with that travel).
At an update the guard (:mod:`.guard`) first weighs the laser against the wheels on the best
particle's map: where the map refutes the wheels' step (an odometry glitch) and the scan
fits it elsewhere, ``Δ`` becomes the laser's step for every particle, and the glitch is
counted, listed and warned about (:mod:`slamkit.estimation.health`). Then, for every
particle:

1. predict ``x̂ = x' ⊕ Δ``;
2. build the likelihood field of the particle's own map over the box of the scan's end
   points seen from ``x̂`` (+ 1 m) and register the scan to it from ``x̂``
   (:func:`~slamkit.scanmatch.to_map.match_to_map`);
3. draw the new pose from the improved proposal around the match
   (:mod:`.proposal`: ``"gaussian"``, the paper's, or ``"mode"``, GMapping's released one)
   and multiply the weight by the proposal's ``η``; a match that fails, or lands farther from
   ``x̂`` than the gate, falls back to the motion model (counted);
4. integrate the scan into the particle's map from the drawn pose.

Every few metres the watch (:mod:`.loops`) searches the scan on the best particle's old
scans around its pose: a clear fit far from it is a loop the filter did not close (its map
holds the place twice), counted and warned about.

Weights are kept as logarithms and normalised with log-sum-exp; when ``N_eff = 1/Σ w²``
drops below :data:`RESAMPLE_SHARE` ``· N`` the set is resampled (low variance), which only
shares map tiles and copies poses. Paths are a parent-pointer tree: each update stores the
drawn poses and, per particle, the slot of its ancestor at the previous update, so
resampling copies nothing and the best particle's path is read back at the end.

The runner records the best particle's current pose after every time stamp (the online
estimate); the answer of an RBPF is the best particle's whole path, returned as
:attr:`EstimatorOutput.trajectory` (every time stamp: the pose of the path at the last
update before it, moved by the odometry since), with that particle's map as the grid.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import replace
from typing import Any

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset, Event, LaserScan
from slamkit.errors import ConvergenceError, InputError, MatchError
from slamkit.estimation.contract import (
    EstimatorOutput,
    ParticleSnapshot,
    PoseEstimate,
    SmoothedTrajectory,
    SpreadSnapshots,
)
from slamkit.estimation.health import UnmatchedStretch, override_rows, tracking_warnings
from slamkit.estimation.particles import (
    low_variance_resample_unchecked,
    normalize_log_weights,
)
from slamkit.estimation.shell import EstimatorShell
from slamkit.geometry.angles import wrap_angle_float
from slamkit.geometry.pose2 import between, compose, transform_points
from slamkit.mapping.grid import lattice_cells
from slamkit.mapping.inverse_model import InverseSensorModel
from slamkit.mapping.logodds import expit
from slamkit.maps import OccupancyGrid
from slamkit.maps.likelihood_field import LikelihoodField
from slamkit.models.laser import scan_points
from slamkit.scanmatch.correlative import CorrelativeConfig, CorrelativeReference
from slamkit.scanmatch.relocate import TRUSTED_FIT, WINDOW_XY, judge
from slamkit.scanmatch.result import MatchResult
from slamkit.scanmatch.to_map import MapMatchConfig, match_to_map
from slamkit.slam.grid_rbpf.config import GridRbpfConfig
from slamkit.slam.grid_rbpf.guard import (
    WIDE_TURN,
    map_fit,
    refuse_wide_turn,
    relocate_on_map,
)
from slamkit.slam.grid_rbpf.loops import LoopWatch, particle_spread
from slamkit.slam.grid_rbpf.maps import TiledMap, TilePool, scan_cells
from slamkit.slam.grid_rbpf.proposal import (
    Scan,
    gaussian_proposal,
    mode_proposal,
    motion_covariance,
    motion_log_density,
    motion_proposal,
)

__all__ = ["FIELD_MARGIN", "MATCH", "RECOVERY_SEARCH", "RESAMPLE_SHARE", "TILE_CELLS", "GridRbpf"]

FIELD_MARGIN = 1.0
"""The likelihood field covers the box of the predicted end points plus this [m] on each
side (more than the match gate, so a matched scan stays on the field)."""

MATCH = MapMatchConfig(
    max_iterations=10, step_tolerance_xy=1e-3, step_tolerance_theta=math.radians(0.02)
)
"""A particle's scan match (its ``sigma_hit`` is the setting's): at most 10 Gauss-Newton
steps, stopping once a step moves less than 1 mm (a fiftieth of a 5 cm cell) and turns less
than 0.02°, both far below the proposal's own spread."""

RECOVERY_SEARCH = CorrelativeConfig(
    window_xy=0.5, window_theta=math.radians(30.0), max_flatness=None
)
"""The recovery's correlative search (``GridRbpfConfig.recovery_score``): ± 0.5 m and
± 30° around the prediction, wide enough for Freiburg 079's wheels, which err by up to 26°
between two updates (``docs/estimators/grid_rbpf.md``)."""

RESAMPLE_SHARE = 0.5
"""Resample (low variance) when ``N_eff`` falls below this share of the particles: the rule
of Grisetti et al. (2007), ``N_eff < N/2``."""

TILE_CELLS = 64
"""Cells per side of a shared map tile (a power of two; :class:`.maps.TilePool`): 64 × 64
float32 cells are 16 kB, small enough that copy-on-write copies little."""


class GridRbpf(EstimatorShell):
    """Grid RBPF SLAM (registered as ``grid-rbpf``); see the module docstring. Needs a laser
    and odometry (or controls)."""

    name = "grid RBPF"

    def __init__(self, dataset: Dataset, config: GridRbpfConfig, rng: np.random.Generator):
        if dataset.laser is None:
            raise InputError(f"grid RBPF needs laser scans; {dataset.name!r} has none")
        if dataset.motion is None:
            raise InputError(f"grid RBPF needs odometry or controls; {dataset.name!r} has none")
        super().__init__()
        cfg = self._cfg = config
        self._rng = rng
        laser = dataset.laser
        self._model = dataset.motion.model
        self._angles = laser.beam_angles
        self._laser_max = float(laser.max_range)
        mounting = laser.mounting if cfg.mounting is None else cfg.mounting
        self._mounting = np.asarray(mounting, dtype=np.float64)
        self._ism = InverseSensorModel(max_range=cfg.max_range).resolve(
            cfg.resolution, self._angles, self._laser_max
        )
        self._match_cfg = replace(MATCH, sigma_hit=cfg.sigma_hit)
        self._wide_cfg = RECOVERY_SEARCH
        start = dataset.initial_pose if dataset.initial_pose is not None else np.zeros(3)
        n = cfg.particles
        self._odom: FloatArray = np.array(start, dtype=np.float64)  # dead-reckoned
        self._odom_at_update = self._odom.copy()
        # Path length [m] and turning [rad] of the odometry since the last update, summed.
        self._travel = 0.0
        self._turn = 0.0
        self._poses: FloatArray = np.tile(self._odom, (n, 1))
        self._logw: FloatArray = np.full(n, -math.log(n))
        self._pool = TilePool(cfg.resolution, TILE_CELLS, self._ism.l0)
        self._maps: list[TiledMap] = [self._pool.new_map() for _ in range(n)]
        # The path tree: poses (P, 3) of every update, each particle's ancestor slot.
        self._hist_poses: list[FloatArray] = [self._poses.copy()]
        self._hist_parent: list[np.ndarray] = [np.arange(n)]
        self._parent = np.arange(n)
        self._started = False
        # One record per time stamp: the update it follows and the odometry since.
        self._track_t: list[float] = []
        self._track_u: list[int] = []
        self._track_delta: list[FloatArray] = []
        self._counts: Counter[str] = Counter()
        self._neff: list[float] = []
        self._seconds: dict[str, float] = dict.fromkeys(
            ("field", "match", "proposal", "integrate", "guard", "loops"), 0.0
        )
        self._snapshots = SpreadSnapshots(cfg.snapshots)
        # The guard's record (:mod:`.guard`): overridden glitches (stamp, T_wheels_laser)
        # and the longest unmatched stretch.
        self._overrides: list[tuple[float, FloatArray]] = []
        self._stretch = UnmatchedStretch()
        self._last_t = dataset.start_time
        # The lost-loop watch (:mod:`.loops`): every update's end points, the total travel.
        self._distance = 0.0
        self._loops = LoopWatch()
        self._loops.add(np.zeros((0, 2)), 0.0)  # the start, before any scan

    # -- the Estimator protocol ---------------------------------------------------------

    def handle(self, event: Event) -> None:
        super().handle(event)
        delta = between(self._odom_at_update, self._odom)
        u = len(self._hist_poses) - 1
        if self._track_t and self._track_t[-1] == event.t:
            self._track_u[-1], self._track_delta[-1] = u, delta
        else:
            self._track_t.append(float(event.t))
            self._track_u.append(u)
            self._track_delta.append(delta)
        self._last_t = event.t

    def on_control(self, u: FloatArray, dt: float) -> None:
        moved = np.asarray(self._model.apply(self._odom, u, dt), dtype=np.float64)
        if not np.isfinite(moved).all():
            raise ConvergenceError(f"the control {u} over {dt} s moved the odometry to {moved}")
        step = between(self._odom, moved)
        self._travel += math.hypot(float(step[0]), float(step[1]))
        self._turn += abs(wrap_angle_float(float(step[2])))
        self._odom = moved

    def on_scan(self, event: LaserScan) -> None:
        self._counts["scans"] += 1
        cfg = self._cfg
        delta = between(self._odom_at_update, self._odom)
        if not self._started:
            self._first_scan(event, delta)
            return
        moved = self._travel >= cfg.update_distance or self._turn >= math.radians(
            cfg.update_angle_deg
        )
        if not moved:
            return
        self._update(event, delta)

    def estimate(self) -> PoseEstimate:
        best = int(np.argmax(self._logw))
        return PoseEstimate(compose(self._poses[best], between(self._odom_at_update, self._odom)))

    def particle_poses(self) -> FloatArray:
        """The particles' current poses ``(P, 3)`` (their last update moved by the odometry
        since)."""
        out: FloatArray = compose(self._poses, between(self._odom_at_update, self._odom))
        return out

    @property
    def updates(self) -> int:
        """Filter updates so far (the first scan, mapped from the start, included)."""
        return len(self._hist_poses) - 1

    def best_path(self) -> FloatArray:
        """The poses ``(U + 1, 3)`` of the most likely particle at the start and after every
        update, read back through the parent pointers."""
        slot = int(self._parent[int(np.argmax(self._logw))])
        path = np.empty((len(self._hist_poses), 3))
        for u in range(len(self._hist_poses) - 1, -1, -1):
            path[u] = self._hist_poses[u][slot]
            slot = int(self._hist_parent[u][slot])
        return path

    def finish(self) -> EstimatorOutput:
        best = int(np.argmax(self._logw))
        path = self.best_path()
        times = np.asarray(self._track_t, dtype=np.float64)
        if times.size:
            deltas = np.asarray(self._track_delta).reshape(-1, 3)
            poses = compose(path[np.asarray(self._track_u)], deltas)
        else:
            poses = np.zeros((0, 3))
        grid = self._maps[best].to_log_odds_grid()
        c = self._counts
        neff = np.asarray(self._neff)
        diagnostics: dict[str, Any] = {
            "particles": self._cfg.particles,
            "proposal": self._cfg.proposal,
            "scans": c["scans"],
            "updates": self.updates,
            "resamplings": c["resamplings"],
            "matched": c["matched"],
            "recovered": c["recovered"],
            "proposal_failures": {
                k[len("failed:") :]: v for k, v in c.items() if k.startswith("failed:")
            },
            "dead_particles": c["dead"],
            "relocation_tried": c["relocation_tried"],
            "relocated": c["relocated"],
            "turns_refused": c["turns_refused"],
            "odometry_overridden": len(self._overrides),
            "odometry_overrides": override_rows(self._overrides),
            "lost": c["lost"],
            **self._loops.diagnostics(),
            "neff_mean": float(neff.mean()) if neff.size else None,
            "neff_min": float(neff.min()) if neff.size else None,
            "maps": self._pool.stats(),
            "seconds": {k: round(v, 3) for k, v in self._seconds.items()},
        }
        snapshot = ParticleSnapshot(self._last_t, self.particle_poses(), self._weights())
        return EstimatorOutput(
            grid=None if grid is None else grid.to_occupancy_grid(),
            diagnostics=diagnostics,
            particle_snapshots=self._snapshots.pick(snapshot),
            trajectory=SmoothedTrajectory(times, poses),
            warnings=(
                *tracking_warnings(self.updates, c["lost"], self._overrides, self._stretch),
                *self._loops.warnings(),
            ),
        )

    # -- steps ----------------------------------------------------------------------------

    def _weights(self) -> FloatArray:
        w: FloatArray = np.exp(self._logw - self._logw.max())
        return w / w.sum()

    def _sensor(self, poses: FloatArray) -> FloatArray:
        out: FloatArray = compose(poses, self._mounting)
        return out

    def _integrate(self, k: int, pose: FloatArray, ranges: FloatArray) -> None:
        tic = time.perf_counter()
        rows, cols, regions = scan_cells(
            self._sensor(pose), ranges, self._angles, self._ism, self._cfg.resolution
        )
        self._maps[k].integrate(rows, cols, regions, self._ism)
        self._seconds["integrate"] += time.perf_counter() - tic

    def _first_scan(self, event: LaserScan, delta: FloatArray) -> None:
        """Every particle maps the first scan from the same pose: one map, shared."""
        self._started = True
        pose = compose(self._poses[0], delta)
        self._integrate(0, pose, event.ranges)
        for k in range(1, len(self._maps)):
            self._maps[k].release()
            self._maps[k] = self._maps[0].share()
        self._store(np.tile(pose, (len(self._maps), 1)), event.t)
        ranges = event.ranges[:: self._cfg.beam_stride]
        self._loops.add(
            self._points(ranges, self._angles[:: self._cfg.beam_stride]), self._distance
        )

    def _field(self, tiled: TiledMap, predicted: FloatArray, points: FloatArray) -> LikelihoodField:
        """The likelihood field of ``tiled`` over the end points seen from ``predicted``."""
        world = transform_points(predicted, points)
        return self._field_over(tiled, world.min(axis=0), world.max(axis=0))

    def _wide_field(
        self, tiled: TiledMap, around: FloatArray, points: FloatArray
    ) -> LikelihoodField:
        """The likelihood field of ``tiled`` over the scan seen from anywhere within the
        relocation's window around ``around`` (every heading, ± ``WINDOW_XY``)."""
        reach = float(np.sqrt(np.einsum("ij,ij->i", points, points).max())) + WINDOW_XY
        return self._field_over(tiled, around[:2] - reach, around[:2] + reach)

    def _field_over(self, tiled: TiledMap, low: FloatArray, high: FloatArray) -> LikelihoodField:
        """The likelihood field of ``tiled`` over the box ``low``-``high`` [m] (+ the
        margin)."""
        tic = time.perf_counter()
        res = self._cfg.resolution
        lo = lattice_cells(low - FIELD_MARGIN, res)
        hi = lattice_cells(high + FIELD_MARGIN, res)
        rows, cols = int(hi[0] - lo[0]) + 1, int(hi[1] - lo[1]) + 1
        window = tiled.window(int(lo[0]), int(lo[1]), rows, cols)
        grid = OccupancyGrid(
            expit(window), res, np.array([lo[1] * res, lo[0] * res], dtype=np.float64)
        )
        # Every cell that is not an obstacle counts as free: the distance to the nearest wall
        # is what the match descends, also across cells the particle has not seen yet.
        field = LikelihoodField.from_grid(
            grid, self._cfg.sigma_hit, max_range=self._cfg.max_range, free_threshold=1.0
        )
        self._seconds["field"] += time.perf_counter() - tic
        return field

    def _update(self, event: LaserScan, delta: FloatArray) -> None:
        cfg = self._cfg
        stride = cfg.beam_stride
        ranges = event.ranges[::stride].copy()
        angles = self._angles[::stride]
        reach = min(cfg.max_range, self._laser_max)
        # Too short, no return, or beyond the match range: set to the field's max range,
        # which the likelihood field skips.
        ranges[(ranges <= cfg.min_range) | (ranges >= reach)] = cfg.max_range
        scan = Scan(ranges, angles, self._mounting)
        points = self._points(event.ranges[::stride], angles)
        motion_cov = motion_covariance(delta, cfg, (self._travel, self._turn))
        finite_motion = bool(np.isfinite(motion_cov).all() and np.isfinite(delta).all())
        if finite_motion and points.shape[0]:
            delta = self._guard(event.t, points, delta)
        n = len(self._maps)
        drawn = np.empty((n, 3))
        for k in range(n):
            predicted = compose(self._poses[k], delta)
            if not (finite_motion and np.isfinite(predicted).all()):
                self._counts["dead"] += 1
                drawn[k] = predicted
                self._logw[k] = -math.inf
                continue
            field = self._field(self._maps[k], predicted, points) if points.shape[0] else None
            tic = time.perf_counter()
            result = None
            if field is not None:
                try:
                    result = match_to_map(field, points, predicted, self._match_cfg)
                except MatchError as exc:
                    self._counts[f"failed:{exc.reason}"] += 1
            if result is not None and not self._within_gate(predicted, result.pose):
                self._counts["failed:gated"] += 1
                result = None
            poor = result is None or result.score < cfg.recovery_score
            if field is not None and cfg.recovery_score > 0 and poor:
                result = self._recover(field, scan, points, predicted, motion_cov, result)
            self._seconds["match"] += time.perf_counter() - tic
            tic = time.perf_counter()
            if result is None or field is None:
                if field is None:
                    self._counts["failed:no_points"] += 1
                pose, factor = motion_proposal(
                    field, scan, self._poses[k], delta, motion_cov, cfg, self._rng
                )
            else:
                self._counts["matched"] += 1
                if cfg.proposal == "gaussian":
                    info = np.asarray(np.linalg.inv(result.cov), dtype=np.float64)
                    pose, factor = gaussian_proposal(
                        field, scan, predicted, result.pose, info, motion_cov, cfg, self._rng
                    )
                else:
                    pose, factor = mode_proposal(
                        field, scan, predicted, result.pose, motion_cov, cfg, self._rng
                    )
            self._seconds["proposal"] += time.perf_counter() - tic
            drawn[k] = pose
            if not (np.isfinite(pose).all() and math.isfinite(factor)):
                self._counts["dead"] += 1
                self._logw[k] = -math.inf
                continue
            self._logw[k] += factor
        # Normalise (ConvergenceError when every particle died), then map from the draws.
        logw, _ = normalize_log_weights(self._logw)
        for k in range(n):
            if np.isfinite(logw[k]):
                self._integrate(k, drawn[k], event.ranges)
        self._logw = logw
        self._store(drawn, event.t)
        self._watch(event.t, points)

    def _points(self, ranges: FloatArray, angles: FloatArray) -> FloatArray:
        """The end points ``(K, 2)`` in the robot frame of the readings used for matching."""
        reach = min(self._cfg.max_range, self._laser_max)
        points = scan_points(ranges, angles, reach, min_range=self._cfg.min_range)
        if self._mounting.any():
            points = transform_points(self._mounting, points)
        return points

    def _watch(self, t: float, points: FloatArray) -> None:
        """Record the update's scan for the lost-loop watch, and check when it is due."""
        self._loops.add(points, self._distance)
        if self._loops.due():
            tic = time.perf_counter()
            spread = particle_spread(self._poses, self._weights())
            self._loops.check(float(t), self.best_path(), spread)
            self._seconds["loops"] += time.perf_counter() - tic

    def _within_gate(self, predicted: FloatArray, pose: FloatArray) -> bool:
        """Whether ``pose`` lies within the match gate around ``predicted``."""
        corr = between(predicted, pose)
        return math.hypot(corr[0], corr[1]) <= self._cfg.max_correction_xy and abs(
            wrap_angle_float(float(corr[2]))
        ) <= math.radians(self._cfg.max_correction_deg)

    def _guard(self, t: float, points: FloatArray, delta: FloatArray) -> FloatArray:
        """The step every particle takes at this update: the wheels' ``delta``, or the
        laser's where the best particle's map refutes the wheels (:mod:`.guard`). Counts
        the verdict, an overridden glitch with its stamp and correction, and whether the
        scan matched (the unmatched stretch's)."""
        best = int(np.argmax(self._logw))
        start = self._poses[best]
        predicted = compose(start, delta)
        tiled = self._maps[best]
        tic = time.perf_counter()
        wheels, matched = predicted, False
        near = self._field(tiled, predicted, points)
        try:
            found = match_to_map(near, points, predicted, self._match_cfg)
            if self._within_gate(predicted, found.pose):
                wheels, matched = found.pose, True
        except MatchError:
            pass
        step = delta
        if not matched or map_fit(near, points, wheels) < TRUSTED_FIT:
            self._counts["relocation_tried"] += 1
            field = self._wide_field(tiled, predicted, points)
            wheels_fit = map_fit(field, points, wheels)
            laser = relocate_on_map(field, points, predicted, self._match_cfg)
            overrides = laser is not None and not self._within_gate(predicted, laser.match.pose)
            if laser is not None and overrides:
                turn = abs(wrap_angle_float(float(between(predicted, laser.match.pose)[2])))
                side = None
                if turn > WIDE_TURN:
                    side = refuse_wide_turn(field, points, predicted, self._match_cfg, laser)
                if side is not None:
                    self._counts["turns_refused"] += 1
                    laser = side
                    overrides = not self._within_gate(predicted, laser.match.pose)
            verdict = judge(wheels_fit, laser, overrides)
            if verdict == "laser":
                assert laser is not None
                if overrides:
                    self._overrides.append((float(t), between(predicted, laser.match.pose)))
                else:
                    self._counts["relocated"] += 1
                step, matched = between(start, laser.match.pose), True
            elif verdict == "lost":
                self._counts["lost"] += 1
        self._stretch.add(float(t), matched, self._travel)
        self._seconds["guard"] += time.perf_counter() - tic
        return step

    def _recover(
        self,
        field: LikelihoodField,
        scan: Scan,
        points: FloatArray,
        predicted: FloatArray,
        motion_cov: FloatArray,
        local: MatchResult | None,
    ) -> MatchResult | None:
        """The wide match of a poor one (``GridRbpfConfig.recovery_score``): a correlative
        search around ``predicted`` refined by Gauss-Newton; kept if it lies within the
        window and its ``log p(z | x, m) / T + log p(x | x', u)`` beats the local match's,
        with ``T = likelihood_temperature``: the evidence of the scan as the weights count
        it (its beams are far from independent), so that a jump has to pay for itself."""
        try:
            wide = match_to_map(
                field,
                points,
                predicted,
                self._match_cfg,
                coarse=CorrelativeReference.from_likelihood_field(field, self._wide_cfg),
            )
        except MatchError:
            return local
        corr = between(predicted, wide.pose)
        w = self._wide_cfg
        if math.hypot(corr[0], corr[1]) > math.sqrt(2.0) * w.window_xy or abs(corr[2]) > (
            w.window_theta
        ):
            return local
        if local is not None:
            poses = np.stack([local.pose, wide.pose])
            t = self._cfg.likelihood_temperature
            log_f = scan.log_likelihood(field, poses, t) + motion_log_density(
                poses, predicted, motion_cov
            )
            if not log_f[1] > log_f[0]:
                return local
        self._counts["recovered"] += 1
        return wide

    def _store(self, drawn: FloatArray, t: float) -> None:
        """Record the drawn poses in the path tree, resample when ``N_eff`` is low."""
        self._hist_poses.append(drawn.copy())
        self._hist_parent.append(self._parent)
        n = drawn.shape[0]
        self._poses = drawn
        self._parent = np.arange(n)
        self._odom_at_update = self._odom.copy()
        self._distance += self._travel
        self._travel = self._turn = 0.0
        w = self._weights()
        neff = float(1.0 / np.sum(w * w))
        self._neff.append(neff)
        if neff < RESAMPLE_SHARE * n:
            idx = low_variance_resample_unchecked(w, self._rng, n)
            maps = [self._maps[int(i)].share() for i in idx]
            for m in self._maps:
                m.release()
            self._maps = maps
            self._poses = drawn[idx]
            self._parent = idx
            self._logw = np.full(n, -math.log(n))
            self._counts["resamplings"] += 1
        self._snapshots.offer(
            self.updates,
            lambda: ParticleSnapshot(float(t), self._poses.copy(), self._weights()),
        )
