"""Angle wrapping, circular means and pose means: hand values and properties."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from slamkit.errors import InputError, NonFiniteError
from slamkit.geometry import angle_diff, circular_mean, pose_mean, wrap_angle


def test_wrap_hand_values_and_half_open_interval():
    np.testing.assert_allclose(
        wrap_angle([0.0, np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 2 * np.pi, 7.0]),
        [0.0, -np.pi, -np.pi, -np.pi, -np.pi, 0.0, 7.0 - 2 * np.pi],
        atol=1e-15,
    )
    # The rounding edge just below +pi stays inside [-pi, pi).
    w = wrap_angle(np.nextafter(np.pi, 0.0))
    assert -np.pi <= w < np.pi
    assert wrap_angle(1e-12) == 1e-12 and wrap_angle(-0.5) == -0.5


@given(st.floats(min_value=-1e6, max_value=1e6, allow_nan=False))
def test_wrap_stays_in_range_and_preserves_the_direction(a):
    w = float(wrap_angle(a))
    assert -np.pi <= w < np.pi
    assert abs(np.sin(w) - np.sin(a)) < 1e-9 and abs(np.cos(w) - np.cos(a)) < 1e-9


def test_circular_mean_of_350_and_10_degrees_is_0():
    assert circular_mean(np.deg2rad([350.0, 10.0])) == pytest.approx(0.0, abs=1e-15)
    assert circular_mean(np.deg2rad([170.0, -170.0])) == pytest.approx(-np.pi, abs=1e-12)
    # Weights pull the mean towards the heavier angle: atan2(3 sin 90°, 1) for 0° and 90°.
    m = circular_mean(np.deg2rad([0.0, 90.0]), weights=[1.0, 3.0])
    assert m == pytest.approx(np.arctan2(3.0, 1.0))
    assert angle_diff(np.deg2rad(10.0), np.deg2rad(350.0)) == pytest.approx(np.deg2rad(20.0))


def test_pose_mean_averages_positions_and_headings_through_unit_vectors():
    poses = np.array([[0.0, 0.0, np.deg2rad(350.0)], [2.0, 4.0, np.deg2rad(10.0)]])
    np.testing.assert_allclose(pose_mean(poses), [1.0, 2.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(pose_mean(poses, weights=[3.0, 1.0])[:2], [0.5, 1.0])
    with pytest.raises(InputError):
        pose_mean(np.zeros((0, 3)))
    with pytest.raises(NonFiniteError):
        pose_mean([[0.0, np.nan, 0.0]])
    with pytest.raises(InputError, match="non-negative"):
        pose_mean(poses, weights=[1.0, -1.0])
