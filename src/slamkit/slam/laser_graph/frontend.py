"""The front end of graph-based laser SLAM: scan-to-keyframe tracking and the edges between
neighbouring keyframes.

Every scan is registered to the current keyframe (point-to-line ICP against its scan, or
point-to-normal ICP against the local map in its frame, below), starting from the last
match composed with the wheels' motion since,

    T_key_cur⁰ = T_key_prev ⊕ g(u)          (g: the data set's motion model)

so the tracker holds the scan's *offset* ``T_key_cur`` from its keyframe (and the odometry
covariance of that offset, propagated ``Σ ← G Σ Gᵀ + V Q Vᵀ`` in the keyframe's frame, which
the motion models allow since they are invariant under a change of world frame). A scan
becomes a keyframe when the offset reaches the keyframe distance or angle, or its match
overlaps too little; the edge from the previous keyframe is its offset with the match's
covariance (floored), or the odometry's covariance when the match failed. With the map
reference (``reference = "map"``, the default when there is odometry) a scan is matched
instead against the local map of the last few keyframes in the current keyframe's frame
(:func:`local_map`), by point-to-normal ICP with the wheels' offset since the keyframe as
an independent prior (:meth:`Tracker.match`), so that a direction the map leaves
unconstrained (a corridor) follows the wheels. Two ways that can go wrong are checked: the
map's points of people walking would pull the scan along with them (the estimator leaves
out of the map the points neighbouring keyframes saw through,
:mod:`slamkit.scanmatch.transient`), and wheels that stalled report no motion while the
robot drives on (:meth:`Tracker._stalled`: the scan matched without them decides).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError, InputError, MatchError
from slamkit.geometry.angles import wrap_angle_float
from slamkit.geometry.pose2 import between, compose
from slamkit.models.constant_velocity import ConstantVelocity
from slamkit.models.motion import MotionModel
from slamkit.scanmatch.correlative import (
    CorrelativeConfig,
    CorrelativeReference,
    correlative_match,
)
from slamkit.scanmatch.icp import PreparedScan
from slamkit.scanmatch.normal_icp import NormalCloud, NormalIcpConfig, normal_icp, surface_fit
from slamkit.scanmatch.plicp import PlIcpConfig, plicp
from slamkit.scanmatch.point_map import PointMap, ScanNormals
from slamkit.scanmatch.relocate import (
    FIT_MARGIN,
    RELOCATE_SEARCH,
    TRUSTED_FIT,
    judge,
    relocate,
)
from slamkit.scanmatch.result import MatchResult
from slamkit.slam.laser_graph.config import FrontEndSettings

__all__ = [
    "COAST_SEARCH",
    "COAST_WINDOW_MAX_THETA",
    "COV_FLOOR_DEG",
    "COV_FLOOR_XY",
    "LOCAL_MAP_KEYFRAMES",
    "LOCAL_MAP_VOXEL",
    "MIN_OVERLAP",
    "NORMAL_ICP",
    "PLICP",
    "STALL_SHIFT",
    "Keyframe",
    "Tracker",
    "coast_window",
    "cov_floor",
    "floored_information",
    "local_map",
]

# Constants that were settings until 2026-12-07 (docs/estimators/laser_graph.md, "Settings").
# The map reference: the local map holds the last LOCAL_MAP_KEYFRAMES keyframes, one point per
# square cell of LOCAL_MAP_VOXEL [m] (the map against the keyframe: "How it works").
LOCAL_MAP_KEYFRAMES = 20
LOCAL_MAP_VOXEL = 0.05
# A scan also becomes a keyframe when its match paired less than this fraction of its points.
MIN_OVERLAP = 0.6
# Wheels that report no motion while the scan, matched without them, moved this far [m] from
# their match have stalled (Tracker._stalled).
STALL_SHIFT = 0.05
# The standard deviations added (in quadrature) to a match's covariance in x and y [m] and in
# heading [deg] before it weights an edge or a prior: scan matchers' own covariances ignore
# the map's systematic errors.
COV_FLOOR_XY = 0.01
COV_FLOOR_DEG = 0.25
# The scan matchers: point-to-line ICP against the keyframe, point-to-normal ICP against the
# local map, the relocation's refinement and the loop closures' refinement (their defaults).
PLICP = PlIcpConfig()
NORMAL_ICP = NormalIcpConfig()


COAST_SEARCH = CorrelativeConfig(
    window_xy=0.2, window_theta=math.radians(15.0), resolution=0.03, sigma=0.05, levels=4
)
"""Without odometry, each scan is first placed by this correlative search around the
constant-velocity prediction, then refined by point-to-line ICP. Its window is the narrowest
one (±0.2 m, ±15°: about two standard deviations of the prediction at the velocity's random
walk of 0.5 m/s² and 45°/s² over a fifth of a second). A longer interval between scans
widens the heading window to two standard deviations of the prediction over that interval, up
to :data:`COAST_WINDOW_MAX_THETA` (:func:`coast_window`): turns start and stop between scans.
The translation window stays: a robot's speed changes slowly, and a wider one lets the
optimum settle on a look-alike place along a corridor, whose velocity is then held."""

COAST_WINDOW_MAX_THETA = math.radians(60.0)
"""The widest heading window of the correlative search without odometry [rad] (a wider
window costs little, the search is branch and bound, but lets more look-alikes compete)."""


def coast_window(prediction_cov: FloatArray) -> CorrelativeConfig:
    """:data:`COAST_SEARCH` with its heading half-width two standard deviations of the
    prediction ``(3, 3)``, within :data:`COAST_SEARCH`'s and
    :data:`COAST_WINDOW_MAX_THETA`."""
    d = math.sqrt(max(float(prediction_cov[2, 2]), 0.0))
    theta = min(max(2.0 * d, COAST_SEARCH.window_theta), COAST_WINDOW_MAX_THETA)
    return replace(COAST_SEARCH, window_theta=theta)


@dataclass(frozen=True)
class Keyframe:
    """A keyframe: its stamp [s], its scan's points ``(M, 2)`` in the robot frame (beam
    order), the prepared reference of those points and the path length [m] the front end
    had travelled when it was taken."""

    t: float
    points: FloatArray
    reference: PreparedScan
    travelled: float


def cov_floor() -> FloatArray:
    """The floor ``F = diag(σ_xy², σ_xy², σ_θ²)`` (:data:`COV_FLOOR_XY`,
    :data:`COV_FLOOR_DEG`) added to a match's covariance ``(3, 3)``."""
    s_xy, s_t = COV_FLOOR_XY, math.radians(COV_FLOOR_DEG)
    return np.diag([s_xy**2, s_xy**2, s_t**2])


def floored_information(cov: FloatArray, scale: float = 1.0) -> FloatArray:
    """The information ``(scale Σ + F)⁻¹`` of a match covariance ``Σ (3, 3)`` with the floor
    ``F`` (:func:`cov_floor`, symmetrised)."""
    c = scale * np.asarray(cov, dtype=np.float64) + cov_floor()
    c = 0.5 * (c + c.T)
    info = np.linalg.solve(c, np.eye(3))
    return 0.5 * (info + info.T)


def within_gate(prior: FloatArray, pose: FloatArray, settings: FrontEndSettings) -> bool:
    """Whether a match ``pose`` stays within the correction gate of ``prior``."""
    d = between(prior, pose)
    return math.hypot(d[0], d[1]) <= settings.max_correction_xy and abs(
        wrap_angle_float(float(d[2]))
    ) <= math.radians(settings.max_correction_deg)


class Tracker:
    """The current scan's offset from its keyframe and the odometry covariance of that
    offset (see the module docstring); counts matches and failures in ``counts``.

    Without a motion model (``model=None``: a log without odometry) the prediction is the
    last scan-to-scan velocity held (:class:`~slamkit.models.constant_velocity.
    ConstantVelocity`, applied by :meth:`coast` before each scan)."""

    def __init__(
        self,
        model: MotionModel | None,
        noise_cov: FloatArray | None,
        settings: FrontEndSettings,
        plicp_config: PlIcpConfig = PLICP,
        normal_icp_config: NormalIcpConfig = NORMAL_ICP,
    ) -> None:
        self.model = model
        self.normal_icp = normal_icp_config
        self.Q = settings.motion_cov_scale * np.asarray(
            np.zeros((3, 3)) if noise_cov is None else noise_cov, dtype=np.float64
        )
        self.velocity = ConstantVelocity() if model is None else None
        self._coasted: tuple[FloatArray, float] | None = None  # offset before, dt
        self._coarse: tuple[PreparedScan | NormalCloud, CorrelativeReference] | None = None
        self._keyframe_cloud: tuple[PreparedScan, NormalCloud] | None = None
        self.track_cov: FloatArray = np.zeros((3, 3))
        """Covariance of the current offset: the last match's, propagated by the motion
        since (the prior of a degenerate scan's fused match)."""
        self.settings = settings
        self.plicp = plicp_config
        self.offset: FloatArray = np.zeros(3)
        self.odometry_offset: FloatArray = np.zeros(3)
        """The offset from the keyframe by the wheels alone (the mean of ``odometry_cov``):
        the prior of a match against the local map."""
        self.odometry_cov: FloatArray = np.zeros((3, 3))
        self.match_cov: FloatArray | None = None  # of the last match, None: it failed
        self.overlap = 1.0
        self.counts: Counter[str] = Counter()
        self.last_override: FloatArray | None = None
        """The correction ``T_wheels_laser`` of the last scan whose wheels were overridden
        by the laser (a glitch), or None when the last scan's were not."""
        self._relocation: tuple[NormalCloud, CorrelativeReference] | None = None
        self._controls = (0, False)  # since the last scan: controls, whether any moved
        self.speed = 0.0
        """The speed of the last scan interval in which the wheels moved [m/s]."""
        self._scan_offset = np.zeros(3)  # the offset at the last scan
        self.doubt = 0.0
        """Since the keyframe, the distance [m] the robot may have covered unseen: at
        :attr:`speed` through each scan interval that the wheels reported as a standstill
        and the laser could not confirm, its scan leaving a direction open (a corridor)."""

    def reset(self) -> None:
        """A new keyframe: the offset and its uncertainty start again from zero."""
        self.offset = np.zeros(3)
        self.odometry_offset = np.zeros(3)
        self.odometry_cov = np.zeros((3, 3))
        self.track_cov = np.zeros((3, 3))
        self.match_cov = None
        self.overlap = 1.0
        self._scan_offset = np.zeros(3)
        self.doubt = 0.0

    def coast(self, dt: float) -> None:
        """No odometry: move the offset by the held velocity over ``dt`` seconds."""
        if self.velocity is None:
            return
        self._coasted = (self.offset.copy(), float(dt))
        self.offset, self.odometry_cov = self.velocity.propagate(self.offset, self.odometry_cov, dt)

    def predict(self, u: FloatArray, dt: float) -> None:
        if self.model is None:
            raise InputError("a control reached a tracker without a motion model")
        n, moved_any = self._controls
        self._controls = (n + 1, moved_any or bool(np.any(np.asarray(u) != 0.0)))
        moved = np.asarray(self.model.apply(self.offset, u, dt), dtype=np.float64)
        if not np.isfinite(moved).all():
            raise ConvergenceError(f"the control {u} over {dt} s moved the pose to {moved}")
        G, V = self.model.jacobians(self.offset, u, dt)
        self.track_cov = G @ self.track_cov @ G.T + V @ self.Q @ V.T
        self.offset = moved
        # The wheels alone since the keyframe, and their covariance about that offset.
        G, V = self.model.jacobians(self.odometry_offset, u, dt)
        self.odometry_cov = G @ self.odometry_cov @ G.T + V @ self.Q @ V.T
        self.odometry_offset = np.asarray(
            self.model.apply(self.odometry_offset, u, dt), dtype=np.float64
        )

    def match(
        self, reference: PreparedScan | NormalCloud, points: FloatArray, seconds: float = 0.0
    ) -> bool:
        """Register ``points`` to the keyframe (its scan, or the local map in its frame:
        point-to-normal ICP with the wheels' offset since the keyframe as a prior) from the
        predicted offset (the last match moved by the wheels); on success the offset
        becomes the match. Returns whether it matched (failures are counted by reason,
        gated matches as ``"gated"``).

        The prior is the wheels' own offset ``odometry_offset`` with its covariance
        ``odometry_cov`` (plus the floor), not the prediction: the prediction carries the
        last match, so a prior about it would count the map's evidence twice, and a match
        that slid along a corridor would pull every later prior along with it (ACES, one
        range noise seed: 3.3 m along a corridor in 10 s, the wheels saying otherwise).
        ``seconds``: since the last scan (the speed and a doubted standstill's distance)."""
        self.last_override = None
        n, moved_any = self._controls
        still = n > 0 and not moved_any
        self._controls = (0, False)
        if isinstance(reference, NormalCloud) and self.model is not None:
            matched = self._match_map(reference, points, still, seconds)
            if matched and not still and seconds > 0.0:
                moved = self.offset[:2] - self._scan_offset[:2]
                self.speed = math.hypot(moved[0], moved[1]) / seconds
            self._scan_offset = self.offset.copy()
            return matched
        fused = False
        try:
            start = self.offset if self.velocity is None else self._search(reference, points)
            if isinstance(reference, NormalCloud):
                prior = self.odometry_cov + cov_floor()
                result = normal_icp(
                    reference, points, start, self.normal_icp,
                    prior_information=np.linalg.solve(prior, np.eye(3)),
                )  # fmt: skip
            else:
                result, start, fused = self._plicp(reference, points, start)
        except MatchError as exc:
            self.counts[f"failed:{exc.reason}"] += 1
            return self._unmatched()
        # The gate bounds ICP's correction of where it started: the prediction with the
        # wheels; without them the correlative optimum, the prediction being a guess.
        if not within_gate(start, result.pose, self.settings):
            self.counts["gated"] += 1
            return self._unmatched()
        self._accept(result)
        if self.velocity is not None and self._coasted is not None:
            before, dt = self._coasted
            moved = between(before, self.offset)
            if fused:  # its translation is mostly the prediction's: the turn alone is news
                self.velocity.observe_turn(float(moved[2]), dt)
            elif not self.velocity.observe(moved, dt):
                self.counts["speed_not_believed"] += 1
        return True

    def _plicp(
        self, reference: PreparedScan, points: FloatArray, start: FloatArray
    ) -> tuple[MatchResult, FloatArray, bool]:
        """Point-to-line ICP against the keyframe from ``start``: the match, where it started
        and whether it was fused with the prediction. Without odometry a scan that leaves a
        direction unconstrained (a corridor: ``"degenerate"``) is matched instead by
        point-to-normal ICP against the keyframe's points with the coasted prediction as its
        prior (:meth:`_degenerate_match`): the directions the scan holds (across the
        corridor, the heading) come from the scan, the others from the prediction, where
        refusing the match left every direction to the prediction."""
        try:
            return plicp(reference, points, start, self.plicp), start, False
        except MatchError as exc:
            if exc.reason != "degenerate" or self.velocity is None:
                raise
        # Along the unconstrained direction the correlative optimum is anywhere in its
        # window: ICP starts from the prediction there, with the optimum's heading.
        start = np.array([self.offset[0], self.offset[1], start[2]])
        result = self._degenerate_match(reference, points, start)
        self.counts["degenerate_fused"] += 1
        return result, start, True

    def _degenerate_match(
        self, reference: PreparedScan, points: FloatArray, start: FloatArray
    ) -> MatchResult:
        """Point-to-normal ICP of ``points`` against the keyframe's points (their normals
        as the local map's, :func:`local_map`) from ``start``, with the prior
        ``N(prediction, Σ + F)`` (the coasted offset and its covariance, floored); then the
        position along the direction the scan holds least is the prediction's.

        That direction is the weakest eigenvector ``e`` of the scan's own information
        ``H = C⁻¹ − Λ`` (``C`` the match's posterior covariance, ``Λ`` the prior's
        information) in x, y: ``p ← p + e eᵀ (p̂ − p)``. The prior alone does not hold it:
        along a uniform corridor the current scan's points fall back onto the keyframe's
        own samples at zero offset, a pull toward the keyframe that outweighs a prior of a
        few tenths of a metre (generated building 1: the estimate stood still while the
        robot drove 6 m)."""
        if self._keyframe_cloud is None or self._keyframe_cloud[0] is not reference:
            cloud = PointMap(LOCAL_MAP_VOXEL)
            cloud.insert(np.zeros(3), reference.points)
            self._keyframe_cloud = (reference, NormalCloud.build(*cloud.arrays()))
        prior_info = np.linalg.solve(self.odometry_cov + cov_floor(), np.eye(3))
        result = normal_icp(
            self._keyframe_cloud[1], points, start, self.normal_icp,
            prior_information=prior_info, prior_pose=self.offset,
        )  # fmt: skip
        scan_info = np.linalg.solve(result.cov, np.eye(3)) - prior_info
        _, vectors = np.linalg.eigh(0.5 * (scan_info[:2, :2] + scan_info[:2, :2].T))
        e = vectors[:, 0]  # (eigh sorts ascending: the weakest first)
        pose = result.pose.copy()
        pose[:2] += e * float(e @ (self.offset[:2] - pose[:2]))
        return replace(result, pose=pose)

    def _match_map(
        self, reference: NormalCloud, points: FloatArray, still: bool, seconds: float
    ) -> bool:
        """The local-map match with the wheels: point-to-normal ICP held to the wheels'
        offset, judged by its fit to the map; where it fits poorly, fails or is gated, the
        scan is relocated on the map without the wheels (:mod:`slamkit.scanmatch.relocate`)
        and the better-fitting hypothesis kept. When the laser's wins against a prediction
        outside the gate, the wheels glitched: the step is overridden (counted, and the
        correction kept in ``last_override``) and the wheels' offset starts again from the
        laser's pose, so the glitch does not pull later priors back. Where the wheels
        reported no motion at all since the last scan (``still``) but the scan, matched
        without them, moved (:meth:`_stalled`), the wheels stalled: that is a glitch
        overridden too; where that match leaves a direction open, the standstill cannot be
        confirmed and adds to :attr:`doubt` (``seconds``: since the last scan)."""
        prior = self.odometry_cov + cov_floor()
        result: MatchResult | None = None
        try:
            result = normal_icp(
                reference, points, self.offset, self.normal_icp,
                prior_information=np.linalg.solve(prior, np.eye(3)),
                prior_pose=self.odometry_offset,
            )  # fmt: skip
        except MatchError as exc:
            self.counts[f"failed:{exc.reason}"] += 1
        if result is not None and not within_gate(self.offset, result.pose, self.settings):
            self.counts["gated"] += 1
            result = None
        wheels_pose = self.offset if result is None else result.pose
        wheels_fit = surface_fit(reference, points, wheels_pose)
        if still and self._stalled(reference, points, wheels_pose, wheels_fit, seconds):
            return True
        if result is not None and wheels_fit >= TRUSTED_FIT:
            self._accept(result)
            return True
        self.counts["relocation_tried"] += 1
        if self._relocation is None or self._relocation[0] is not reference:
            self._relocation = (
                reference,
                CorrelativeReference.from_points(reference.points, RELOCATE_SEARCH),
            )
        found = relocate(reference, points, self.offset, self.normal_icp, self._relocation[1])
        overrides = found is not None and not within_gate(
            self.offset, found.match.pose, self.settings
        )
        verdict = judge(wheels_fit, found, overrides)
        if verdict == "laser":
            assert found is not None
            if overrides:
                self.counts["odometry_overridden"] += 1
                self.last_override = between(self.offset, found.match.pose)
            else:
                self.counts["relocated"] += 1
            self._accept(found.match)
            self.odometry_offset = found.match.pose.copy()
            self.odometry_cov = np.asarray(found.match.cov, dtype=np.float64).copy()
            return True
        if verdict == "lost":
            self.counts["lost"] += 1
        if result is None:
            return self._unmatched()
        self._accept(result)
        return True

    def _stalled(
        self,
        reference: NormalCloud,
        points: FloatArray,
        wheels_pose: FloatArray,
        wheels_fit: float,
        seconds: float,
    ) -> bool:
        """The wheels said the robot stood still: match the scan without them, from where
        they put it. Where that match is constrained in every direction (a scan that leaves
        one open, a corridor, is refused as degenerate and the wheels stand), lies within the
        gate, moved the pose by :data:`STALL_SHIFT` or more from the wheels' match and lays
        at least as much of the scan on the map as they do, and no less than
        :data:`~slamkit.scanmatch.relocate.TRUSTED_FIT`, the wheels stalled: the laser's pose is
        kept, as a glitch overridden (the wheels' offset starting again from it). A robot
        that does stand still matches where it stood, and the wheels' match is kept.

        A corridor can leave the laser unable to say: the scan then fits about as well where
        the robot would be had it kept its last speed over ``seconds`` (within
        :data:`~slamkit.scanmatch.relocate.FIT_MARGIN`, the margin either side must win by)
        as where the wheels put it. The wheels' pose is kept, doubted (:attr:`doubt`) by
        that distance."""
        try:
            free = normal_icp(reference, points, self.offset, self.normal_icp)
        except MatchError:
            free = None
        if free is None or math.hypot(*(free.pose[:2] - wheels_pose[:2])) < STALL_SHIFT:
            self._doubt_standstill(reference, points, wheels_pose, wheels_fit, seconds)
            return False
        fit = surface_fit(reference, points, free.pose)
        if not within_gate(self.offset, free.pose, self.settings) or fit < max(
            wheels_fit, TRUSTED_FIT
        ):
            return False
        self.counts["odometry_overridden"] += 1
        self.counts["stalled"] += 1
        self.last_override = between(wheels_pose, free.pose)
        self._accept(free)
        self.odometry_offset = free.pose.copy()
        self.odometry_cov = np.asarray(free.cov, dtype=np.float64).copy()
        return True

    def _doubt_standstill(
        self,
        reference: NormalCloud,
        points: FloatArray,
        wheels_pose: FloatArray,
        wheels_fit: float,
        seconds: float,
    ) -> None:
        """Add to :attr:`doubt` the distance ``speed · seconds`` when the scan fits where
        that would have taken the robot within ``FIT_MARGIN`` of its fit where it stood."""
        distance = self.speed * seconds
        if distance < STALL_SHIFT:
            return
        moving = compose(wheels_pose, np.array([distance, 0.0, 0.0]))
        if surface_fit(reference, points, moving) > wheels_fit - FIT_MARGIN:
            self.doubt += distance
            self.counts["standstill_doubted"] += 1

    def _accept(self, result: MatchResult) -> None:
        self.counts["matched"] += 1
        self.offset = result.pose
        self.match_cov = result.cov
        self.track_cov = np.asarray(result.cov, dtype=np.float64)
        self.overlap = result.inlier_fraction

    def _search(self, reference: PreparedScan | NormalCloud, points: FloatArray) -> FloatArray:
        """Without odometry: the correlative optimum of ``points`` against the keyframe (or
        the local map) around the coasted prediction, where ICP starts (from a prediction this
        rough, ICP alone often settles in a local minimum). The window is two standard
        deviations of the prediction over the interval since the last scan
        (:func:`coast_window`)."""
        if self._coarse is None or self._coarse[0] is not reference:
            coarse = CorrelativeReference.from_points(reference.points, COAST_SEARCH)
            self._coarse = (reference, coarse)
        config = COAST_SEARCH
        if self.velocity is not None and self._coasted is not None:
            config = coast_window(self.velocity.predict(self._coasted[1])[1])
        try:
            return correlative_match(self._coarse[1], points, self.offset, config).pose
        except MatchError:
            return self.offset

    def _unmatched(self) -> bool:
        self.match_cov, self.overlap = None, 0.0
        if self.velocity is not None:
            self.velocity.lose_turn(0.0 if self._coasted is None else self._coasted[1])
        return False

    def keyframe_due(self) -> bool:
        """Whether the current scan is to become a keyframe."""
        s = self.settings
        o = self.offset
        return (
            math.hypot(o[0], o[1]) >= s.keyframe_distance
            or abs(o[2]) >= math.radians(s.keyframe_angle_deg)
            or self.overlap < MIN_OVERLAP
        )

    def edge(self) -> tuple[FloatArray, FloatArray, bool]:
        """The edge from the keyframe to the current scan: measurement, information, and
        whether it came from the scan match (else the odometry). A standstill the laser
        could not confirm (:attr:`doubt`) widens it along the robot's heading by the
        distance it may have covered."""
        matched = self.match_cov is not None
        cov = np.array(self.match_cov if self.match_cov is not None else self.odometry_cov)
        if self.doubt > 0.0:
            heading = np.array([math.cos(self.offset[2]), math.sin(self.offset[2])])
            cov[:2, :2] += self.doubt**2 * np.outer(heading, heading)
        return self.offset.copy(), floored_information(cov), matched


def local_map(
    poses: FloatArray,
    points: list[FloatArray],
    k: int,
    count: int = LOCAL_MAP_KEYFRAMES,
    voxel: float = LOCAL_MAP_VOXEL,
    scan_normals: Callable[[int], ScanNormals] | None = None,
) -> NormalCloud:
    """The points of keyframes ``k - count + 1, ..., k`` (``points[i]`` in keyframe ``i``'s
    frame, ``poses (K, 3)``) in keyframe ``k``'s frame, newest first, one per ``voxel``.
    ``scan_normals(i)``: keyframe ``i``'s normals in its own frame (a cache; None: computed
    here)."""
    order = range(k, max(k - count, -1), -1)
    cloud = PointMap(voxel)
    cloud.insert_many(
        between(poses[k], poses[list(order)]),
        [points[i] for i in order],
        None if scan_normals is None else [scan_normals(i) for i in order],
    )
    pts, normals = cloud.arrays()
    return NormalCloud.build(pts, normals)
