"""Laser odometry: wheel odometry as the prior, scan matching as the measurement.

The estimator keeps one *keyframe* — a scan, its points prepared for matching, and the pose
``T_world_key`` it was taken from. Every new scan is registered to the keyframe starting from
the previous scan's match and the motion the wheels report since,

    T_key_cur⁰ = T_key_prev ⊕ between(o_prev, o_cur)     (o: the dead-reckoned odometry)

and the match ``T_key_cur`` gives the pose ``T_world_cur = T_world_key ⊕ T_key_cur``.
Matching against a keyframe rather than against the previous scan keeps the error from
growing while the robot stands still or creeps (each match then covers a longer baseline
but the same wall points); a new keyframe is taken once the robot has moved
``keyframe_distance`` or turned ``keyframe_angle_deg`` from the current one, or when a match
used too small a part of the scan.

Laser and robot frames: scan points are moved into the robot frame with the laser's
mounting (:attr:`~slamkit.datasets.LaserSpec.mounting` where the data set gives it, else the
``mounting`` setting), so the trajectory is the robot's.

A scan that cannot be matched (:class:`~slamkit.errors.MatchError`: too few points or
correspondences, degenerate geometry) or whose match disagrees with the odometry by more
than the gate (``max_correction_xy``, ``max_correction_deg``) keeps the odometry prior for
that scan; both are counted in the diagnostics.

Against the map the laser is weighed against the wheels, as graph SLAM's front end does
(:mod:`slamkit.scanmatch.relocate`): a match held to the prior that lays less than
:data:`~slamkit.scanmatch.relocate.TRUSTED_FIT` of the scan on the map's surfaces
(:func:`~slamkit.scanmatch.normal_icp.surface_fit`), fails or is gated is relocated over
every heading and ±1.5 m without the prior, and :func:`~slamkit.scanmatch.relocate.judge`
keeps the better-fitting pose. Where the laser's pose lies outside the gate and the wheels'
is refuted, the wheels glitched (an encoder or gyro spike, a message out of order): the
laser's pose is kept and the glitch counted and listed (``odometry_overrides``) with a
run warning (:mod:`slamkit.estimation.health`). Nothing else needs re-basing: the prior of
the next scan is this scan's pose moved by the wheels' motion since, with this match's
covariance, so the glitch's step is not carried on. Where the judge keeps the wheels'
poorly fitting match, the match held to the prior is run once more from the relocation's
pose and kept if it fits the map (``restarted``: a local optimum escaped without giving up
the prior). Scans that fit nowhere are ``lost`` (their pose the wheels'). The map is the
occupancy grid of the keyframes at their estimated poses
(:class:`~slamkit.mapping.occupancy.OccupancyMapper`), built as they are taken.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numpy as np

from slamkit._validation import FloatArray
from slamkit.config import (
    Section,
    finite_above,
    finite_at_least,
    fraction,
    setting,
)
from slamkit.datasets.stream import Dataset, LaserScan
from slamkit.errors import ConvergenceError, InputError, MatchError
from slamkit.estimation.contract import EstimatorOutput, PoseEstimate
from slamkit.estimation.health import UnmatchedStretch, override_rows, tracking_warnings
from slamkit.estimation.shell import EstimatorShell
from slamkit.geometry.angles import wrap_angle_float
from slamkit.geometry.pose2 import between, compose, transform_points
from slamkit.mapping.inverse_model import InverseSensorModel
from slamkit.mapping.occupancy.config import OccupancyMappingConfig
from slamkit.mapping.occupancy.mapper import OccupancyMapper
from slamkit.models.laser import scan_points
from slamkit.scanmatch.correlative import CorrelativeReference
from slamkit.scanmatch.icp import MIN_REFERENCE_POINTS, PreparedScan, prepare_scan
from slamkit.scanmatch.normal_icp import NormalCloud, NormalIcpConfig, normal_icp, surface_fit
from slamkit.scanmatch.plicp import PlIcpConfig, plicp
from slamkit.scanmatch.point_map import PointMap
from slamkit.scanmatch.relocate import RELOCATE_SEARCH, TRUSTED_FIT, judge, relocate
from slamkit.scanmatch.result import MatchResult, require_points

__all__ = [
    "NORMAL_ICP",
    "PLICP",
    "PRIOR_FLOOR",
    "LaserOdometry",
    "LaserOdometryConfig",
    "MapSettings",
]

PRIOR_FLOOR = np.diag([1e-6, 1e-6, 1e-8])
"""Added to the prior covariance before it is inverted [m², m², rad²]: 1 mm and 0.1 mrad."""

NORMAL_ICP = NormalIcpConfig(max_iterations=60)
"""The map reference's matcher: point-to-normal ICP with its defaults but up to 60 steps
rather than 30: a match held to the prior against a large map can creep for more than 30
steps, and a scan whose match gives up keeps the wheels' pose (Freiburg 079: 195 such scans
and 0.276 m with 30 steps, 1 and 0.033 m with 60; ``docs/estimators/laser_odometry.md``)."""

PLICP = PlIcpConfig()
"""The keyframe reference's matcher: point-to-line ICP with its defaults."""


@dataclass(frozen=True)
class MapSettings(Section):
    """The occupancy grid built from the keyframes."""

    SECTION: ClassVar[str] = "map"

    enabled: bool = True
    resolution: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Side of a grid cell [m]."""
    max_range: float | None = 30.0
    """Readings beyond this [m] are not mapped (long rays through doors and windows fill a
    grid with free space that a short-range view does not contradict); None: the laser's."""


@dataclass(frozen=True)
class LaserOdometryConfig(Section):
    """Settings of :class:`LaserOdometry`. Metres, degrees where named."""

    reference: Literal["keyframe", "map"] = "map"
    """What a scan is registered to: the last keyframe (point-to-line ICP, Censi 2008,
    :data:`PLICP`), or the map of the keyframes' points within ``map_radius`` of the robot
    (point-to-normal ICP, :mod:`slamkit.scanmatch.normal_icp`, :data:`NORMAL_ICP`, over a
    :class:`~slamkit.scanmatch.point_map.PointMap`, with the odometry's prediction as a
    prior)."""
    map_radius: float = setting(20.0, finite_above(0.0), "a finite number > 0")
    """Map reference: the map points within this distance of the robot take part [m]."""
    voxel: float = setting(0.05, finite_above(0.0), "a finite number > 0")
    """Map reference: one point per square cell of this side [m] (the first one in)."""
    keyframe_distance: float = setting(0.5, finite_at_least(0.0), "a finite number >= 0")
    """Take a new keyframe once the robot is this far from the current one [m]."""
    keyframe_angle_deg: float = setting(15.0, finite_at_least(0.0), "a finite number >= 0")
    """... or has turned this much [deg]."""
    min_overlap: float = setting(0.6, fraction(), "a fraction in [0, 1]")
    """... or a match paired less than this fraction of the scan's points with the keyframe."""
    max_correction_xy: float = setting(0.5, finite_above(0.0), "a finite number > 0")
    """Gate: a match that moves the pose farther than this from the odometry prior [m] is
    refused (the prior is kept); against the map, a relocation beyond it overrides the
    wheels only where their pose is refuted (:func:`~slamkit.scanmatch.relocate.judge`)."""
    max_correction_deg: float = setting(20.0, finite_above(0.0), "a finite number > 0")
    """Gate: ... or turns it more than this [deg]."""
    min_range: float = setting(0.05, finite_at_least(0.0), "a finite number >= 0")
    """Readings at or below this [m] are dropped (a laser's minimum range, dust, the robot)."""
    max_range: float | None = None
    """Readings at or beyond this [m] are dropped; None: the laser's max range."""
    motion_cov_scale: float = setting(1.0, finite_above(0.0), "a finite number > 0")
    """Map reference: multiplies the data set's control-noise covariance in the odometry
    prior (its covariance propagated since the last match, so that where the map leaves a
    direction unconstrained, a corridor, the prediction holds it)."""
    mounting: tuple[float, float, float] | None = None
    """The laser's pose in the robot frame (x [m], y [m], yaw [rad]); None: the data set's
    (:attr:`~slamkit.datasets.LaserSpec.mounting`, else the robot's origin)."""
    map: MapSettings = field(default_factory=MapSettings)


@dataclass
class _Keyframe:
    pose: FloatArray  # T_world_key
    reference: PreparedScan | None  # the keyframe reference's; the map reference has none


class LaserOdometry(EstimatorShell):
    """Scan-to-keyframe laser odometry (registered as ``laser-odometry``); see the module
    docstring. Needs a laser and a motion model (wheel odometry or controls)."""

    name = "laser odometry"

    def __init__(self, dataset: Dataset, config: LaserOdometryConfig, rng: np.random.Generator):
        if dataset.laser is None:
            raise InputError(f"laser odometry needs laser scans; {dataset.name!r} has none")
        if dataset.motion is None:
            raise InputError(f"laser odometry needs odometry; {dataset.name!r} has none")
        super().__init__()
        self._cfg = config
        laser = dataset.laser
        self._model = dataset.motion.model
        self._angles = laser.beam_angles
        self._max_range = laser.max_range if config.max_range is None else config.max_range
        mounting = config.mounting
        if mounting is None:
            mounting = laser.mounting
        self._mounting = np.asarray(mounting, dtype=np.float64)
        start = dataset.initial_pose if dataset.initial_pose is not None else np.zeros(3)
        self._pose: FloatArray = np.array(start, dtype=np.float64)
        self._cov: FloatArray = np.zeros((3, 3))  # of the pose relative to the map
        self._Q = config.motion_cov_scale * dataset.motion.noise_cov
        self._key: _Keyframe | None = None
        self._points = PointMap(config.voxel) if config.reference == "map" else None
        self._local: NormalCloud | None = None  # the map around the last keyframe
        self._counts: Counter[str] = Counter()
        self._iterations = 0
        self._overrides: list[tuple[float, FloatArray]] = []  # (stamp, T_wheels_laser)
        self._override: FloatArray | None = None  # the current scan's, if it was overridden
        self._stretch = UnmatchedStretch()  # the longest run of unmatched scans
        self._last_pose: FloatArray | None = None  # the pose after the last scan
        self._relocation: tuple[NormalCloud, CorrelativeReference] | None = None
        self._mapper: OccupancyMapper | None = None
        if config.map.enabled:
            map_cfg = OccupancyMappingConfig(
                resolution=config.map.resolution,
                bounds="grow",
                model=InverseSensorModel(max_range=config.map.max_range),
            )
            self._mapper = OccupancyMapper(laser, map_cfg, None)

    # -- the Estimator protocol ---------------------------------------------------------

    def on_control(self, u: FloatArray, dt: float) -> None:
        # Between scans the wheels move the estimate, x ← g(x, u), and its uncertainty
        # relative to the map, Σ ← G Σ Gᵀ + V Q Vᵀ (the prior of the next match).
        moved = np.asarray(self._model.apply(self._pose, u, dt), dtype=np.float64)
        if not np.isfinite(moved).all():
            raise ConvergenceError(f"the control {u} over {dt} s moved the pose to {moved}")
        if self._points is not None:  # only the map reference's prior reads Σ
            G, V = self._model.jacobians(self._pose, u, dt)
            self._cov = G @ self._cov @ G.T + V @ self._Q @ V.T
        self._pose = moved

    def on_scan(self, event: LaserScan) -> None:
        self._counts["scans"] += 1
        cfg = self._cfg
        points = scan_points(event.ranges, self._angles, self._max_range, min_range=cfg.min_range)
        if any(self._mounting):
            points = transform_points(self._mounting, points)
        # How far the wheels moved the robot since the last scan (the unmatched stretch's).
        moved = 0.0
        if self._last_pose is not None:
            d = between(self._last_pose, self._pose)
            moved = math.hypot(d[0], d[1])
        key = self._key
        if key is None:
            self._stretch.add(event.t, self._new_keyframe(points, event.ranges), moved)
            self._last_pose = self._pose.copy()
            return
        # The reference's frame: the keyframe's pose, or the world for the local map. The
        # prior: the last match and the wheels' motion since, in that frame.
        frame = key.pose if self._local is None else np.zeros(3)
        reference = key.reference if self._local is None else self._local
        assert reference is not None  # a keyframe without a scan comes with the local map
        prior = between(frame, self._pose)
        self._override = None
        result = self._match(reference, points, prior)
        self._stretch.add(event.t, result is not None, moved)
        if self._override is not None:
            self._overrides.append((float(event.t), self._override))
        overlap = 0.0
        if result is not None:
            self._pose = compose(frame, result.pose)
            overlap = result.inlier_fraction
            if self._local is not None:
                self._cov = result.cov
        travelled = between(key.pose, self._pose)
        if (
            math.hypot(travelled[0], travelled[1]) >= cfg.keyframe_distance
            or abs(travelled[2]) >= math.radians(cfg.keyframe_angle_deg)
            or overlap < cfg.min_overlap
        ):
            self._new_keyframe(points, event.ranges)
        self._last_pose = self._pose.copy()

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(self._pose.copy())

    def finish(self) -> EstimatorOutput:
        c = self._counts
        matched = c["matched"]
        diagnostics = {
            "scans": c["scans"],
            "keyframes": c["keyframes"],
            "matched": matched,
            "unmatched": {k[len("failed:") :]: v for k, v in c.items() if k.startswith("failed:")},
            "gated": c["gated"],
            "relocation_tried": c["relocation_tried"],
            "relocated": c["relocated"],
            "restarted": c["restarted"],
            "odometry_overridden": len(self._overrides),
            "odometry_overrides": override_rows(self._overrides),
            "lost": c["lost"],
            "mean_iterations": self._iterations / matched if matched else None,
            "reference": self._cfg.reference,
            "matcher": "normal-icp" if self._local is not None else "plicp",
        }
        grid = None
        if self._mapper is not None and self._mapper.grid is not None:
            grid = self._mapper.occupancy_grid()
            diagnostics["mapping"] = self._mapper.stats.as_dict()
        warnings = tracking_warnings(c["scans"], c["lost"], self._overrides, self._stretch)
        return EstimatorOutput(grid=grid, diagnostics=diagnostics, warnings=tuple(warnings))

    # -- steps ----------------------------------------------------------------------------

    def _match(
        self, reference: PreparedScan | NormalCloud, points: FloatArray, prior: FloatArray
    ) -> MatchResult | None:
        """The match of ``points`` to the reference from ``prior`` (against the map, weighed
        against a relocation where it fits poorly: :meth:`_weigh`), or None (counted) when
        the matcher fails or the gate refuses it and no relocation replaces it."""
        result: MatchResult | None = None
        try:
            if isinstance(reference, NormalCloud):
                # (Σ + a floor)⁻¹: a pose that has not moved is still known only so well.
                info = np.linalg.inv(self._cov + PRIOR_FLOOR)
                result = normal_icp(reference, points, prior, NORMAL_ICP, prior_information=info)
            else:
                result = plicp(reference, points, prior, PLICP)
        except MatchError as exc:
            self._counts[f"failed:{exc.reason}"] += 1
        if result is not None and not self._within_gate(prior, result.pose):
            self._counts["gated"] += 1
            result = None
        if isinstance(reference, NormalCloud):
            result = self._weigh(reference, points, prior, result)
        if result is not None:
            self._counts["matched"] += 1
            self._iterations += result.iterations
        return result

    def _within_gate(self, prior: FloatArray, pose: FloatArray) -> bool:
        cfg = self._cfg
        correction = between(prior, pose)
        return math.hypot(correction[0], correction[1]) <= cfg.max_correction_xy and abs(
            wrap_angle_float(correction[2])
        ) <= math.radians(cfg.max_correction_deg)

    def _weigh(
        self,
        reference: NormalCloud,
        points: FloatArray,
        prior: FloatArray,
        found: MatchResult | None,
    ) -> MatchResult | None:
        """``found`` (the match held to the prior, or None when it failed or was gated)
        where it lays at least :data:`~slamkit.scanmatch.relocate.TRUSTED_FIT` of the scan
        on the map; else the scan relocated on the map without the prior
        (:func:`~slamkit.scanmatch.relocate.relocate`) where
        :func:`~slamkit.scanmatch.relocate.judge` prefers it to the wheels' pose (``found``,
        or the prior itself). A relocation beyond the gate overrides the wheels: its
        correction ``T_prior_laser`` is kept for the caller's list of glitches.

        Wheel odometry can be wrong by far more than its stated noise: Intel's messages,
        stamped on arrival and sometimes out of order, predict a spinning robot's heading
        15-40° off for a scan, and a generated odometry glitch turns it 30-90° for good. A
        match held to such a prior settles on the few walls that agree with it (10-20 % of
        the scan on the map's surfaces, where half of Intel's matches lay over 94 %), and
        the gate then keeps the wheels, which are what is wrong."""
        wheels_fit = surface_fit(reference, points, prior if found is None else found.pose)
        if found is not None and wheels_fit >= TRUSTED_FIT:
            return found
        self._counts["relocation_tried"] += 1
        laser = None
        if reference.points.shape[0]:  # a local map may hold nothing within its radius
            if self._relocation is None or self._relocation[0] is not reference:
                search = CorrelativeReference.from_points(reference.points, RELOCATE_SEARCH)
                self._relocation = (reference, search)
            laser = relocate(reference, points, prior, NORMAL_ICP, self._relocation[1])
        overrides = laser is not None and not self._within_gate(prior, laser.match.pose)
        verdict = judge(wheels_fit, laser, overrides)
        if verdict == "laser":
            assert laser is not None
            if overrides:
                self._override = between(prior, laser.match.pose)
            else:
                self._counts["relocated"] += 1
            return laser.match
        if found is not None and laser is not None:
            again = self._restart(reference, points, prior, laser.match.pose)
            if again is not None:
                self._counts["restarted"] += 1
                return again
        if verdict == "lost":
            self._counts["lost"] += 1
        return found

    def _restart(
        self, reference: NormalCloud, points: FloatArray, prior: FloatArray, start: FloatArray
    ) -> MatchResult | None:
        """The match held to the prior once more, started at ``start`` (the relocation's
        pose the judge refused) instead of at the prior: kept where it stays within the
        gate and lays at least :data:`~slamkit.scanmatch.relocate.TRUSTED_FIT` of the scan
        on the map, else None.

        The judge asks a free relocation to beat the wheels by a margin because, free, it
        can slide along a corridor; held to the same prior as the first match it cannot, so
        a trusted fit is evidence enough that the first match stopped in a local optimum
        near a prediction a few degrees off (``docs/estimators/laser_odometry.md``, "The
        restart": Intel 0.097 → 0.029 m, one scan restarted)."""
        info = np.linalg.inv(self._cov + PRIOR_FLOOR)
        try:
            again = normal_icp(
                reference, points, start, NORMAL_ICP, prior_information=info, prior_pose=prior
            )
        except MatchError:
            return None
        fits = surface_fit(reference, points, again.pose) >= TRUSTED_FIT
        return again if fits and self._within_gate(prior, again.pose) else None

    def _new_keyframe(self, points: FloatArray, ranges: FloatArray) -> bool:
        """Make the scan ``points`` (robot frame) at the current pose the keyframe, its
        points part of the map; False (counted) when it has too few points to be one."""
        reference = None
        try:  # the map reference matches against the point map, not the keyframe's scan
            if self._points is None:
                reference = prepare_scan(points)
            else:
                require_points(points, MIN_REFERENCE_POINTS, "reference")
        except MatchError as exc:  # too few points to be a reference: keep the old one
            self._counts[f"failed:{exc.reason}"] += 1
            return False
        self._key = _Keyframe(self._pose.copy(), reference)
        self._counts["keyframes"] += 1
        if self._points is not None:
            self._points.insert(self._pose, points)
            self._local = self._points.near(self._pose[:2], self._cfg.map_radius)
        if self._mapper is not None:
            self._mapper.integrate(compose(self._pose, self._mounting), ranges)
        return True
