"""2D scan matching: register a laser scan to another scan or to a map.

Every matcher works on whole arrays (no Python loop per point), returns a
:class:`MatchResult` (pose, covariance, score, inlier fraction, iterations) in the frame
convention of :mod:`slamkit.scanmatch.result`, and raises :class:`~slamkit.errors.MatchError`
when it cannot match.
"""

from slamkit.models.laser import scan_points
from slamkit.scanmatch.correlative import CorrelativeConfig, CorrelativeReference, correlative_match
from slamkit.scanmatch.icp import IcpConfig, PreparedScan, icp, prepare_scan
from slamkit.scanmatch.plicp import PlIcpConfig, plicp
from slamkit.scanmatch.result import MatchError, MatchResult, require_points
from slamkit.scanmatch.to_map import MapMatchConfig, match_to_map

__all__ = [
    "CorrelativeConfig",
    "CorrelativeReference",
    "IcpConfig",
    "MapMatchConfig",
    "MatchError",
    "MatchResult",
    "PlIcpConfig",
    "PreparedScan",
    "correlative_match",
    "icp",
    "match_to_map",
    "plicp",
    "prepare_scan",
    "require_points",
    "scan_points",
]
