"""What every scan matcher returns, and the one frame convention they share.

Convention: a matcher registers a *current* scan (points ``q`` in its own sensor frame) to a
*reference* (a scan's points ``p`` in the reference frame, or a map in the world frame) and
returns ``pose = T_ref_cur = (x, y, θ)``, the pose of the current frame in the reference
frame, so that ``p ≈ R(θ) q + (x, y)`` for corresponding points. The initial guess has the
same meaning. For scan-to-scan matching with odometry, the initial guess is the odometry
increment ``between(pose_ref, pose_cur)``.

``cov (3, 3)`` is the covariance of ``pose`` in the same ``(x, y, θ)`` coordinates.

A matcher that cannot register raises :class:`~slamkit.errors.MatchError` with a reason code
instead of returning a confident wrong pose.
"""

from __future__ import annotations

from dataclasses import dataclass

from slamkit._validation import FloatArray, as_array
from slamkit.errors import MatchError

__all__ = ["MatchError", "MatchResult", "require_points"]


@dataclass(frozen=True, eq=False)
class MatchResult:
    """One registration.

    * ``pose (3,)``: ``T_ref_cur`` (see the module docstring);
    * ``cov (3, 3)``: its covariance;
    * ``score``: the matcher's own goodness, in ``[0, 1]`` and larger is better (ICP: the
      inlier fraction; correlative: the normalised response at the optimum; scan-to-map: the
      mean per-beam likelihood relative to a perfect hit);
    * ``inlier_fraction``: the fraction of the current scan's points used at the end;
    * ``iterations``: iterations (ICP) or resolution levels searched (correlative);
    * ``method``: the matcher's name.
    """

    pose: FloatArray
    cov: FloatArray
    score: float
    inlier_fraction: float
    iterations: int
    method: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "pose", as_array(self.pose, "match pose", (3,)))
        object.__setattr__(self, "cov", as_array(self.cov, "match covariance", (3, 3)))


def require_points(points: FloatArray, minimum: int, which: str) -> FloatArray:
    """``points`` as a ``(M, 2)`` float array with at least ``minimum`` rows, else a
    :class:`MatchError` (``"too_few_points"``) naming ``which`` scan."""
    pts = as_array(points, f"{which} points", (None, 2))
    if pts.shape[0] < minimum:
        raise MatchError(
            f"{which} scan has {pts.shape[0]} valid points; at least {minimum} are needed",
            "too_few_points",
        )
    return pts
