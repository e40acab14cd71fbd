"""A scan as the free space it saw (:class:`slamkit.scanmatch.transient.ScanView`): points in
front of what a beam hit are seen through; points on the surfaces, behind them, outside the
field of view or along beams without a return are not."""

from __future__ import annotations

import math

import numpy as np

from slamkit.geometry.pose2 import inverse_transform_points, transform_points
from slamkit.scanmatch.transient import SEE_THROUGH_MARGIN, ScanView

ANGLES = np.radians(np.arange(-90.0, 90.5, 1.0))  # 181 beams, 1° apart


def _wall_scan(distance: float) -> np.ndarray:
    """Ranges to a wall ``x = distance`` in front of the laser."""
    return distance / np.cos(ANGLES)


def test_a_point_in_front_of_the_wall_is_seen_through_and_the_wall_is_not() -> None:
    view = ScanView(_wall_scan(5.0), ANGLES, max_range=30.0)
    points = np.array(
        [
            [2.0, 0.0],  # a person in the open space before the wall
            [5.0, 0.5],  # on the wall
            [6.0, 0.0],  # behind the wall: occluded, nothing known
            [5.0 - SEE_THROUGH_MARGIN, 0.0],  # within the margin of the wall
            [-1.0, 0.0],  # behind the laser: outside the field of view
        ]
    )
    assert view.seen_through(points).tolist() == [True, False, False, False, False]


def test_a_beam_without_a_return_clears_nothing() -> None:
    ranges = _wall_scan(5.0)
    ranges[88:93] = 30.0  # around the bearing 0: max range, no return
    view = ScanView(ranges, ANGLES, max_range=30.0)
    assert view.seen_through(np.array([[2.0, 0.0], [2.0, 1.0]])).tolist() == [False, True]


def test_a_corner_edge_is_kept_where_one_beam_slips_past() -> None:
    # A wall at 3 m ending at y = 0: beams to the left of it reach a far wall at 10 m.
    y_hit = np.tan(ANGLES) * 3.0
    ranges = np.where(y_hit <= 0.0, 3.0 / np.cos(ANGLES), 10.0 / np.cos(ANGLES))
    view = ScanView(ranges, ANGLES, max_range=30.0)
    edge = np.array([[3.0, 0.02]])  # the wall's end, a beam's width past the last beam on it
    assert not view.seen_through(edge)[0]
    assert view.seen_through(np.array([[3.0, 0.6]]))[0]  # well past the edge: open


def test_points_from_another_frame_and_a_mounted_laser() -> None:
    mounting = np.array([0.3, 0.1, math.radians(10.0)])
    ranges = _wall_scan(5.0)
    view = ScanView(ranges, ANGLES, max_range=30.0, mounting=mounting)
    # A person 2 m in front of the laser and a point on the wall, in the laser's frame, then
    # in the robot frame, then in another frame (behind and turned).
    in_laser = np.array([[2.0, 0.0], [5.0, -1.0]])
    in_robot = transform_points(mounting, in_laser)
    other = np.array([-1.0, 0.2, math.radians(-30.0)])  # the other frame in this robot's
    in_other = inverse_transform_points(other, in_robot)
    assert view.seen_through(in_robot).tolist() == [True, False]
    assert view.seen_through_from(other, in_other).tolist() == [True, False]
