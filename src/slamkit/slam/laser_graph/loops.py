"""Loop closures: candidates from a search region grown with the path travelled, matched by
the correlative matcher against a candidate's submap, verified, refined.

**Search region.** The front end's drift grows with the path it has integrated, so the
estimate of the new keyframe relative to an old keyframe ``j`` is uncertain by about

    r(j) = min(r₀ + k_r · s(j), r_max),     α(j) = min(α₀ + k_α · s(j), α_max)

where ``s(j)`` is the path length travelled since ``j`` [m] (a linear bound, chosen over
marginal covariances because it costs nothing and holds for the scan-matching drift of
indoor logs, which grows about linearly with distance). Keyframes with ``s(j) ≥
min_travel`` whose estimated position lies within ``r(j)`` of the new keyframe's are
candidates, nearest first.

**Verification.** The new keyframe's scan is matched against the candidate's submap (its
scan and its neighbours', in its frame) by Olson's correlative search over the window
``±r(j)``, ``±α(j)`` around the current estimate; the match must reach ``min_score``. The
optimum, when it lies farther than :data:`NEAR_WINDOW` from the estimate, must also score
clearly better (by ``1 / AMBIGUITY_RATIO``) than the best pose within :data:`NEAR_WINDOW`:
an aliased match along a corridor scores about as well as the true one. The optimum is
refined by point-to-normal ICP against the same submap, which must pair
:data:`MIN_INLIERS` of the scan and may move the optimum only a few cells (a refinement that
walks away means the correlative peak was not a real alignment). The back end then checks
consistency (:mod:`slamkit.slam.laser_graph.backend`: a closure whose residual stays large
after optimisation is removed).

**Pairwise consistency.** A verified closure enters the graph only once another closure
nearby (both ends within :data:`PAIR_KEYFRAMES` keyframes of its own) agrees with it: the cycle
``T_j_k`` vs ``T_j_j' ⊕ T_j'_k' ⊕ T_k'_k`` (the short chains from the current estimate)
must close within :data:`PAIR_XY` / :data:`PAIR_DEG`. Aliased matches in a corridor or between
look-alike rooms land at poses that do not agree from one keyframe to the next.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import MatchError
from slamkit.geometry.angles import wrap_angle_float
from slamkit.geometry.pose2 import between, compose, transform_points
from slamkit.scanmatch.correlative import CorrelativeConfig, CorrelativeReference, correlative_match
from slamkit.scanmatch.normal_icp import NormalCloud, NormalIcpConfig, normal_icp
from slamkit.scanmatch.point_map import PointMap, ScanNormals
from slamkit.scanmatch.result import MatchResult
from slamkit.slam.laser_graph.config import LoopSettings
from slamkit.slam.laser_graph.freespace import FreeSpace, neighbourhood

__all__ = [
    "LoopMatch",
    "SubmapCache",
    "consistent_partners",
    "loop_candidates",
    "loop_reference",
    "pair_consistent",
    "search_window",
    "submap",
    "verify_closure",
]


NEAR_WINDOW = 0.3
"""Ambiguity: a correlative optimum farther than this from the estimate [m] ..."""
AMBIGUITY_RATIO = 0.95
"""... is refused (``"ambiguous"``) when the best pose within ``NEAR_WINDOW`` of the
estimate, away from that window's edge, scores at least this fraction of it."""


@dataclass(frozen=True)
class LoopMatch:
    """A verified closure ``T_j_k`` with its covariance ``(3, 3)``, the correlative score and
    the refinement's inlier fraction."""

    pose: FloatArray
    cov: FloatArray
    score: float
    inliers: float


# Constants that were settings until 2026-12-07 (docs/estimators/laser_graph.md, "Settings").
# The search region at zero travel: radius [m] and rotation half-window [deg] (grown with the
# path by LoopSettings.radius_per_metre and .angle_per_metre_deg).
SEARCH_RADIUS = 0.5
SEARCH_ANGLE_DEG = 10.0
# Candidates tried per new keyframe, nearest first, at least SUBMAP_KEYFRAMES apart; a
# candidate's submap is its own scan and those of SUBMAP_KEYFRAMES // 2 keyframes either side.
MAX_CANDIDATES = 2
SUBMAP_KEYFRAMES = 11
# The correlative lookup grid: cell [m] and smear [m].
GRID_RESOLUTION = 0.05
GRID_SIGMA = 0.05
# Verification: the refining point-to-normal ICP must pair this fraction of the scan and may
# move the correlative optimum at most this far [m] and turn it at most this much [deg].
MIN_INLIERS = 0.6
MAX_REFINEMENT_XY = 0.25
MAX_REFINEMENT_DEG = 3.0
# Pairwise consistency: a verified closure waits for a partner whose ends both lie within
# PAIR_KEYFRAMES keyframes of its own and which closes the cycle with it within PAIR_XY [m]
# and PAIR_DEG [deg].
PAIR_KEYFRAMES = 10
PAIR_XY = 0.1
PAIR_DEG = 1.5


def search_window(travel: float, settings: LoopSettings) -> tuple[float, float]:
    """The search radius [m] and rotation half-window [rad] after ``travel`` metres."""
    r = min(SEARCH_RADIUS + settings.radius_per_metre * travel, settings.max_radius)
    a = min(SEARCH_ANGLE_DEG + settings.angle_per_metre_deg * travel, settings.max_angle_deg)
    return r, math.radians(a)


def loop_candidates(
    positions: FloatArray,
    travelled: FloatArray,
    k: int,
    settings: LoopSettings,
) -> list[int]:
    """The candidates for keyframe ``k``: keyframes ``j < k`` with ``travelled[k] -
    travelled[j] ≥ min_travel`` within the search radius of ``positions[k]`` (``(K, 2)``
    estimated positions, ``(K,)`` path lengths), nearest first, at most
    :data:`MAX_CANDIDATES`, at least :data:`SUBMAP_KEYFRAMES` apart in index. The radius
    grows with the path travelled since ``j``, the distance a front end drifts over."""
    travel = travelled[k] - travelled[:k]
    eligible = np.flatnonzero(travel >= settings.min_travel)
    if eligible.size == 0:
        return []
    d = np.hypot(*(positions[eligible] - positions[k]).T)
    s = travel[eligible]
    radius = np.minimum(SEARCH_RADIUS + settings.radius_per_metre * s, settings.max_radius)
    inside = d <= radius
    order = eligible[inside][np.argsort(d[inside], kind="stable")]
    chosen: list[int] = []
    for j in order:
        if all(abs(int(j) - c) >= SUBMAP_KEYFRAMES for c in chosen):
            chosen.append(int(j))
            if len(chosen) == MAX_CANDIDATES:
                break
    return chosen


def submap(
    poses: FloatArray,
    points: list[FloatArray],
    j: int,
    half: int,
    scan_normals: Callable[[int], ScanNormals] | None = None,
) -> tuple[FloatArray, NormalCloud]:
    """Keyframe ``j``'s submap in its own frame: the points of keyframes ``j - half, ...,
    j + half`` (those that exist, ``points[i]`` in keyframe ``i``'s frame, ``poses (K, 3)``),
    concatenated in keyframe and beam order, and the same points with normals as a
    :class:`NormalCloud` (one per 2.5 cm voxel). ``scan_normals(i)``: keyframe ``i``'s
    :func:`~slamkit.scanmatch.point_map.scan_normals` (a cache; None: computed here)."""
    lo, hi = max(j - half, 0), min(j + half + 1, len(points))
    T_j = np.array([between(poses[j], poses[i]) for i in range(lo, hi)]).reshape(-1, 3)
    scans = points[lo:hi]
    parts = [transform_points(T_j[a], scans[a]) for a in range(hi - lo)]
    cloud = PointMap(0.025)
    known = None if scan_normals is None else [scan_normals(i) for i in range(lo, hi)]
    cloud.insert_many(T_j, scans, known)
    pts, normals = cloud.arrays()
    return np.concatenate(parts), NormalCloud.build(pts, normals)


class SubmapCache:
    """Candidates' submaps (:func:`submap`) and their correlative references
    (:func:`loop_reference`), kept from one keyframe to the next while the poses of their
    keyframes stay exactly as they were (no solve in between): consecutive keyframes often
    share a candidate. ``scan_normals(i)``: keyframe ``i``'s normals (see :func:`submap`)."""

    def __init__(
        self, settings: LoopSettings, scan_normals: Callable[[int], ScanNormals] | None = None
    ) -> None:
        self.settings = settings
        self.scan_normals = scan_normals
        self._last: dict[int, _Submap] = {}
        self._used: dict[int, _Submap] = {}
        self._free: dict[int, tuple[tuple[int, int, bytes], FreeSpace]] = {}

    def get(
        self, poses: FloatArray, points: list[FloatArray], j: int
    ) -> tuple[FloatArray, NormalCloud, CorrelativeReference | None]:
        """Candidate ``j``'s submap points, cloud and reference (None: no points, which
        :func:`verify_closure` reports) at ``poses (K, 3)``."""
        key = _span_key(poses, len(points), j)
        found = self._used.get(j) or self._last.get(j)
        if found is None or found[0] != key:
            ref_points, cloud = submap(poses, points, j, SUBMAP_KEYFRAMES // 2, self.scan_normals)
            try:
                reference: CorrelativeReference | None = loop_reference(ref_points, self.settings)
            except MatchError:
                reference = None
            found = (key, ref_points, cloud, reference)
        self._used[j] = found
        return found[1], found[2], found[3]

    def free_space(
        self, poses: FloatArray, points: list[FloatArray], j: int, mounting: FloatArray
    ) -> FreeSpace:
        """Candidate ``j``'s submap as :class:`~slamkit.slam.laser_graph.freespace.FreeSpace`
        in its frame (the laser at ``mounting`` on the robot), kept like the submaps."""
        key = _span_key(poses, len(points), j)
        found = self._free.get(j)
        if found is None or found[0] != key:
            half = SUBMAP_KEYFRAMES // 2
            found = (key, neighbourhood(poses, points, mounting, j, j - half, j + half + 1))
            self._free[j] = found
        return found[1]

    def advance(self) -> None:
        """The next keyframe: keep only the submaps asked for since the last call."""
        self._free = {j: f for j, f in self._free.items() if j in self._used}
        self._last, self._used = self._used, {}


def _span_key(poses: FloatArray, n: int, j: int) -> tuple[int, int, bytes]:
    """Submap ``j``'s span and the poses of its keyframes: equal keys, equal submaps."""
    half = SUBMAP_KEYFRAMES // 2
    lo, hi = max(j - half, 0), min(j + half + 1, n)
    return lo, hi, np.ascontiguousarray(poses[lo:hi]).tobytes()


_Submap = tuple[tuple[int, int, bytes], FloatArray, NormalCloud, CorrelativeReference | None]
"""A cached submap: (its span and the poses it was built at, points, cloud, reference)."""


def _search_config(settings: LoopSettings, window: tuple[float, float]) -> CorrelativeConfig:
    radius, angle = window
    return CorrelativeConfig(
        window_xy=radius,
        window_theta=angle,
        resolution=GRID_RESOLUTION,
        sigma=GRID_SIGMA,
        levels=5,
        min_score=settings.min_score,
    )


def loop_reference(reference_points: FloatArray, settings: LoopSettings) -> CorrelativeReference:
    """The correlative reference of a submap's points ``(M, 2)`` for :func:`verify_closure`
    (it does not depend on the search window, so one serves every search against the
    submap). Raises :class:`MatchError` when there are no points."""
    return CorrelativeReference.from_points(reference_points, _search_config(settings, (0, 0)))


def verify_closure(
    reference_points: FloatArray,
    reference_cloud: NormalCloud,
    points: FloatArray,
    initial: FloatArray,
    window: tuple[float, float],
    settings: LoopSettings,
    icp_config: NormalIcpConfig,
    *,
    reference: CorrelativeReference | None = None,
) -> LoopMatch | str:
    """Match ``points (N, 2)`` (the new keyframe, its frame) to a candidate's submap from
    ``initial = T_j_k`` over ``window = (radius [m], angle [rad])``; the verified
    :class:`LoopMatch`, or the reason it was refused (``"low_score"``, ``"degenerate"``,
    ``"too_few_points"``, ``"ambiguous"``, ``"refine:<reason>"``, ``"inliers"``,
    ``"refinement"``). ``reference``: the submap's :func:`loop_reference`, when the caller
    has it already."""
    cfg = _search_config(settings, window)
    try:
        if reference is None:
            reference = loop_reference(reference_points, settings)
        coarse = correlative_match(reference, points, initial, cfg)
    except MatchError as exc:
        return exc.reason
    shift = between(initial, coarse.pose)
    if math.hypot(shift[0], shift[1]) > NEAR_WINDOW:
        # A far optimum must beat the best pose near the estimate clearly: along a corridor
        # or between look-alike rooms the two score alike (an aliased match).
        near = dataclasses.replace(cfg, window_xy=NEAR_WINDOW, min_score=0.0)
        try:
            close: MatchResult | None = correlative_match(reference, points, initial, near)
        except MatchError:
            close = None
        # A near optimum on the window's edge is the far peak's flank, not a peak of its own.
        inner = NEAR_WINDOW - 2.0 * GRID_RESOLUTION
        if (
            close is not None
            and np.abs(close.pose[:2] - initial[:2]).max() < inner
            and close.score >= AMBIGUITY_RATIO * coarse.score
        ):
            return "ambiguous"
    try:
        fine: MatchResult = normal_icp(reference_cloud, points, coarse.pose, icp_config)
    except MatchError as exc:
        return f"refine:{exc.reason}"
    if fine.inlier_fraction < MIN_INLIERS:
        return "inliers"
    step = between(coarse.pose, fine.pose)
    if math.hypot(step[0], step[1]) > MAX_REFINEMENT_XY or abs(
        wrap_angle_float(float(step[2]))
    ) > math.radians(MAX_REFINEMENT_DEG):
        return "refinement"
    return LoopMatch(fine.pose, fine.cov, coarse.score, fine.inlier_fraction)


def pair_consistent(
    poses: FloatArray, a: tuple[int, int, FloatArray], b: tuple[int, int, FloatArray]
) -> bool:
    """Whether closures ``a = (j, k, T_j_k)`` and ``b = (j', k', T_j'_k')`` agree: the cycle
    ``between(T_j_k, T_j_j' ⊕ T_j'_k' ⊕ T_k'_k)`` (chains at ``poses (K, 3)``) within
    :data:`PAIR_XY` [m] and :data:`PAIR_DEG`."""
    return consistent_partners(poses, a, [b])[0]


def consistent_partners(
    poses: FloatArray,
    a: tuple[int, int, FloatArray],
    others: list[tuple[int, int, FloatArray]],
) -> list[bool]:
    """:func:`pair_consistent` of ``a`` with each of ``others``, the cycles composed for all
    of them at once (the same numbers as one at a time)."""
    if not others:
        return []
    j, k, z = a
    j2 = np.array([o[0] for o in others])
    k2 = np.array([o[1] for o in others])
    z2 = np.array([o[2] for o in others], dtype=np.float64).reshape(-1, 3)
    via = compose(compose(between(poses[j], poses[j2]), z2), between(poses[k2], poses[k]))
    e = between(z, via)
    limit = math.radians(PAIR_DEG)
    return [
        math.hypot(float(x), float(y)) <= PAIR_XY and abs(wrap_angle_float(float(t))) <= limit
        for x, y, t in e.tolist()
    ]
