"""The ``(x, y, θ)`` pose-array operators of :mod:`slamkit.geometry.pose2`: agreement with the
:class:`~slamkit.geometry.se2.SE2` group value, broadcasting, heading wrapping and hand values."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamkit.geometry import pose2
from slamkit.geometry.angles import angle_diff
from slamkit.geometry.se2 import SE2

PROPERTY = settings(max_examples=25, deadline=None)
SEEDS = st.integers(min_value=0, max_value=2**32 - 1)
BATCH_SHAPES = st.sampled_from([(), (1,), (50,), (2, 3)])


def random_poses(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Positions ~ N(0, 10²) metres, headings uniform on [-π, π)."""
    xy = 10.0 * rng.standard_normal((*shape, 2))
    theta = rng.uniform(-np.pi, np.pi, (*shape, 1))
    return np.concatenate([xy, theta], axis=-1)


def assert_poses_close(actual: np.ndarray, expected: np.ndarray, atol: float = 1e-12) -> None:
    """Positions within ``atol``; headings within ``atol`` on the circle (±π are neighbours)."""
    assert actual.shape == expected.shape
    np.testing.assert_allclose(actual[..., :2], expected[..., :2], rtol=0, atol=atol)
    np.testing.assert_allclose(angle_diff(actual[..., 2], expected[..., 2]), 0.0, atol=atol)


def assert_headings_wrapped(poses: np.ndarray) -> None:
    assert np.all(poses[..., 2] >= -np.pi) and np.all(poses[..., 2] < np.pi)


# --------------------------------------------------------------------- agreement with SE2


@PROPERTY
@given(seed=SEEDS, shape=BATCH_SHAPES)
def test_compose_inverse_between_agree_with_se2(seed: int, shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(seed)
    a, b = random_poses(rng, shape), random_poses(rng, shape)
    A, B = SE2.from_xy_theta(a), SE2.from_xy_theta(b)
    for result, expected in [
        (pose2.compose(a, b), (A @ B).xy_theta()),
        (pose2.inverse(a), A.inverse().xy_theta()),
        (pose2.between(a, b), (A.inverse() @ B).xy_theta()),
    ]:
        assert_poses_close(result, expected)
        assert_headings_wrapped(result)


@PROPERTY
@given(seed=SEEDS, shape=BATCH_SHAPES)
def test_transform_points_agree_with_se2(seed: int, shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(seed)
    T = random_poses(rng, shape)
    p = 10.0 * rng.standard_normal((*shape, 2))
    X = SE2.from_xy_theta(T)
    np.testing.assert_allclose(pose2.transform_points(T, p), X @ p, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        pose2.inverse_transform_points(T, p), X.inverse() @ p, rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        pose2.inverse_transform_points(T, pose2.transform_points(T, p)), p, rtol=0, atol=1e-12
    )


@PROPERTY
@given(seed=SEEDS, shape=BATCH_SHAPES)
def test_between_undoes_compose(seed: int, shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(seed)
    a, b = random_poses(rng, shape), random_poses(rng, shape)
    assert_poses_close(pose2.between(a, pose2.compose(a, b)), b)
    assert_poses_close(pose2.compose(a, pose2.between(a, b)), b)
    assert_poses_close(pose2.compose(a, pose2.inverse(a)), np.zeros((*shape, 3)))


# --------------------------------------------------------------------- broadcasting


def test_single_pose_broadcasts_against_a_batch() -> None:
    rng = np.random.default_rng(1)
    one = random_poses(rng, ())
    many = random_poses(rng, (40,))
    points = rng.standard_normal((40, 2))
    for fn in (pose2.compose, pose2.between):
        left, right = fn(one, many), fn(many, one)
        assert left.shape == right.shape == (40, 3)
        for i in range(40):
            assert_poses_close(left[i], fn(one, many[i]))
            assert_poses_close(right[i], fn(many[i], one))
    for fn in (pose2.transform_points, pose2.inverse_transform_points):
        moved = fn(one, points)
        assert moved.shape == (40, 2)
        for i in range(40):
            np.testing.assert_allclose(moved[i], fn(one, points[i]), rtol=0, atol=1e-12)
    # A (3,) pose and (N, 3) poses agree with the SE2 class's own broadcasting.
    assert_poses_close(
        pose2.compose(one, many), (SE2.from_xy_theta(one) @ SE2.from_xy_theta(many)).xy_theta()
    )


def test_inputs_are_not_modified() -> None:
    rng = np.random.default_rng(2)
    a, b = random_poses(rng, (10,)), random_poses(rng, (10,))
    a0, b0 = a.copy(), b.copy()
    pose2.compose(a, b)
    pose2.inverse(a)
    pose2.between(a, b)
    pose2.transform_points(a, b[:, :2])
    np.testing.assert_array_equal(a, a0)
    np.testing.assert_array_equal(b, b0)


# --------------------------------------------------------------------- headings and hand values


def test_compose_by_hand() -> None:
    np.testing.assert_allclose(
        pose2.compose([1.0, 2.0, np.pi / 2], [1.0, 0.0, 0.0]), [1.0, 3.0, np.pi / 2], atol=1e-15
    )
    np.testing.assert_allclose(
        pose2.between([1.0, 2.0, np.pi / 2], [1.0, 3.0, np.pi / 2]), [1.0, 0.0, 0.0], atol=1e-15
    )
    np.testing.assert_allclose(
        pose2.transform_points([1.0, 2.0, np.pi / 2], [[1.0, 0.0], [0.0, 1.0]]),
        [[1.0, 3.0], [0.0, 2.0]],
        atol=1e-15,
    )


def test_headings_are_wrapped() -> None:
    np.testing.assert_allclose(pose2.compose([0, 0, 3.0], [0, 0, 3.0])[2], 6.0 - 2 * np.pi)
    assert pose2.inverse([0.0, 0.0, -np.pi])[2] == -np.pi
    assert pose2.compose([0, 0, np.pi / 2], [0, 0, np.pi / 2])[2] == -np.pi
    np.testing.assert_allclose(pose2.between([0, 0, 3.0], [0, 0, -3.0])[2], 2 * np.pi - 6.0)
    rng = np.random.default_rng(3)
    big = random_poses(rng, (100,))
    big[:, 2] *= 7.0  # headings far outside [-π, π)
    for result in (pose2.compose(big, big), pose2.inverse(big), pose2.between(big, big[::-1])):
        assert_headings_wrapped(result)


@pytest.mark.parametrize("theta", [np.pi, -np.pi, 3 * np.pi, np.nextafter(np.pi, 0.0)])
def test_headings_at_the_seam_agree_with_se2(theta: float) -> None:
    pose = np.array([1.0, -2.0, theta])
    assert_poses_close(SE2.from_xy_theta(pose).xy_theta(), pose2.compose(np.zeros(3), pose))
    assert_headings_wrapped(SE2.from_xy_theta(pose).xy_theta())
