"""2D scan matching: register a laser scan to another scan or to a map.

Every matcher works on whole arrays (no Python loop per point), returns a
:class:`MatchResult` (pose, covariance, score, inlier fraction, iterations) in the frame
convention of :mod:`slamkit.scanmatch.result`, and raises :class:`~slamkit.errors.MatchError`
when it cannot match.
"""

from slamkit.scanmatch.correlative import CorrelativeConfig, CorrelativeReference, correlative_match
from slamkit.scanmatch.result import MatchError, MatchResult, require_points, scan_points
from slamkit.scanmatch.to_map import MapMatchConfig, match_to_map

__all__ = [
    "CorrelativeConfig",
    "CorrelativeReference",
    "MapMatchConfig",
    "MatchError",
    "MatchResult",
    "correlative_match",
    "match_to_map",
    "require_points",
    "scan_points",
]
