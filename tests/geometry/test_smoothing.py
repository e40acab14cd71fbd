"""Kernel smoothing of point and pose sequences with clamped ends."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import GeometryError, InputError, NonFiniteError, ShapeError
from slamkit.geometry.angles import angle_diff
from slamkit.geometry.smoothing import smooth_points, smooth_poses

K3 = [0.25, 0.5, 0.25]


def test_constant_sequence_is_unchanged() -> None:
    pts = np.tile([3.0, -7.5, 0.25], (9, 1))
    out = smooth_points(pts, [0.1, 0.2, 0.4, 0.2, 0.1], iterations=4)
    np.testing.assert_allclose(out, pts, rtol=0, atol=1e-14)


def test_hand_worked_five_points() -> None:
    x = np.array([0.0, 1.0, 4.0, 9.0, 16.0])
    pts = np.column_stack([x, x[::-1]])
    # Clamped: pad to [0, 0, 1, 4, 9, 16, 16]; out[i] = .25 x[i-1] + .5 x[i] + .25 x[i+1].
    one = [0.25, 1.5, 4.5, 9.5, 14.25]
    two = [0.5625, 1.9375, 5.0, 9.4375, 13.0625]
    np.testing.assert_allclose(smooth_points(pts, K3)[:, 0], one, rtol=0, atol=1e-15)
    np.testing.assert_allclose(smooth_points(pts, K3)[:, 1], one[::-1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(smooth_points(pts, K3, 2)[:, 0], two, rtol=0, atol=1e-14)


def test_kernel_orientation_and_long_kernel() -> None:
    x = np.array([[1.0], [2.0], [3.0], [4.0]])
    # kernel[0] weights the earlier neighbour: [1, 0, 0] is a one-step delay with clamping.
    np.testing.assert_allclose(smooth_points(x, [1.0, 0.0, 0.0])[:, 0], [1.0, 1.0, 2.0, 3.0])
    # A kernel longer than the sequence replicates the ends as often as needed.
    two = np.array([[0.0], [7.0]])
    out = smooth_points(two, np.full(7, 1 / 7))[:, 0]
    np.testing.assert_allclose(out, [3.0, 4.0], atol=1e-14)  # (4·0+3·7)/7, (3·0+4·7)/7


def test_linear_ramp_is_unchanged_in_the_interior() -> None:
    n, iterations = 30, 3
    t = np.arange(n, dtype=float)
    pts = np.column_stack([2.0 * t - 5.0, -0.5 * t])
    out = smooth_points(pts, [0.1, 0.2, 0.4, 0.2, 0.1], iterations)
    reach = 2 * iterations  # half-width 2, applied 3 times
    np.testing.assert_allclose(out[reach : n - reach], pts[reach : n - reach], atol=1e-12)
    assert out[0, 0] > pts[0, 0]  # the clamped ends are pulled inwards


def test_input_not_modified_and_zero_iterations_copy() -> None:
    pts = np.arange(10.0).reshape(5, 2)
    before = pts.copy()
    out = smooth_points(pts, K3, iterations=0)
    np.testing.assert_array_equal(out, before)
    assert out is not pts
    smooth_points(pts, K3, iterations=3)
    np.testing.assert_array_equal(pts, before)


def test_headings_across_pi_smooth_to_pi_not_zero() -> None:
    a = np.deg2rad(179.0)
    theta = np.array([a, -a, a, -a, a])
    poses = np.column_stack([np.arange(5.0), np.zeros(5), theta])
    out = smooth_poses(poses, K3)
    # Interior: .25 a + .5 (−a) + .25 a → sin cancels, heading exactly π (wrapped to −π).
    np.testing.assert_allclose(angle_diff(out[1:4, 2], np.pi), 0.0, atol=1e-12)
    assert np.all(out[:, 2] >= -np.pi) and np.all(out[:, 2] < np.pi)
    # End 0: .75 a + .25 (−a) → atan2(.5 sin a, cos a), still within 1° of 180°.
    expected_end = np.arctan2(0.5 * np.sin(a), np.cos(a))
    assert out[0, 2] == pytest.approx(expected_end, abs=1e-14)
    assert abs(angle_diff(out[0, 2], np.pi)) < np.deg2rad(1.0)
    # Positions are smoothed exactly like points.
    np.testing.assert_allclose(out[:, :2], smooth_points(poses[:, :2], K3))


def test_cancelling_headings_raise() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, np.pi], [2.0, 0.0, 0.0]])
    with pytest.raises(GeometryError, match="cancel"):
        smooth_poses(poses, [0.5, 0.0, 0.5])


@pytest.mark.parametrize(
    ("kernel", "error", "match"),
    [
        ([0.5, 0.5], ShapeError, "odd"),
        ([], ShapeError, "odd"),
        ([0.2, 0.5, 0.2], InputError, "summing to 1"),
        ([0.25, 0.5 + 1e-8, 0.25], InputError, "summing to 1"),
        ([0.25, np.nan, 0.75], NonFiniteError, "kernel"),
        ([[0.25, 0.5, 0.25]], ShapeError, "kernel"),
    ],
)
def test_bad_kernels(kernel: object, error: type[Exception], match: str) -> None:
    pts = np.zeros((4, 2))
    with pytest.raises(error, match=match):
        smooth_points(pts, kernel)  # type: ignore[arg-type]
    with pytest.raises(error, match=match):
        smooth_poses(np.zeros((4, 3)), kernel)  # type: ignore[arg-type]


def test_kernel_sum_tolerance_accepts_rounding() -> None:
    out = smooth_points(np.ones((3, 1)), [1 / 3, 1 / 3, 1 / 3 + 1e-12])
    np.testing.assert_allclose(out, 1.0, atol=1e-11)


def test_bad_points_and_iterations() -> None:
    with pytest.raises(NonFiniteError):
        smooth_points([[0.0, np.nan], [1.0, 1.0]], K3)
    with pytest.raises(ShapeError):
        smooth_poses(np.zeros((4, 2)), K3)
    with pytest.raises(InputError, match="at least one"):
        smooth_points(np.zeros((0, 2)), K3)
    with pytest.raises(InputError, match="iterations"):
        smooth_points(np.zeros((3, 2)), K3, iterations=-1)
    with pytest.raises(InputError, match="iterations"):
        smooth_points(np.zeros((3, 2)), K3, iterations=1.5)  # type: ignore[arg-type]
