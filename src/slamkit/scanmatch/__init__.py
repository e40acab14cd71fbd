"""2D scan matching: register a laser scan to another scan or to a map.

Every matcher works on whole arrays (no Python loop per point), returns a
:class:`MatchResult` (pose, covariance, score, inlier fraction, iterations) in the frame
convention of :mod:`slamkit.scanmatch.result`, and raises :class:`~slamkit.errors.MatchError`
when it cannot match.
"""

from slamkit.scanmatch.icp import IcpConfig, PreparedScan, icp, prepare_scan
from slamkit.scanmatch.plicp import PlIcpConfig, plicp
from slamkit.scanmatch.result import MatchError, MatchResult, require_points, scan_points

__all__ = [
    "IcpConfig",
    "MatchError",
    "MatchResult",
    "PlIcpConfig",
    "PreparedScan",
    "icp",
    "plicp",
    "prepare_scan",
    "require_points",
    "scan_points",
]
