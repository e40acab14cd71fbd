"""Odometry steps with a signed translation: the same motion, small rotations."""

from __future__ import annotations

import numpy as np

from slamkit.geometry import wrap_angle
from slamkit.models import OdometryModel, odometry_control, signed_odometry_steps


def test_signed_steps_move_the_pose_the_same_way() -> None:
    rng = np.random.default_rng(0)
    start = rng.uniform(-3, 3, (500, 3))
    # Forward, backward and in-place steps with turns up to ±0.5 rad.
    heading = rng.uniform(-np.pi, np.pi, 500)
    dist = rng.uniform(-0.3, 0.3, 500)
    end = start + np.column_stack(
        [dist * np.cos(start[:, 2] + heading * 0.1), dist * np.sin(start[:, 2] + heading * 0.1),
         rng.uniform(-0.5, 0.5, 500)]
    )  # fmt: skip
    u = odometry_control(start, end)
    s = signed_odometry_steps(u)
    model = OdometryModel()
    a, b = model.apply(start, u), model.apply(start, s)
    np.testing.assert_allclose(a[:, :2], b[:, :2], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(a[:, 2] - b[:, 2]), 0.0, atol=1e-12)
    assert np.all(np.abs(s[:, 0]) <= 0.5 * np.pi) and np.all(np.abs(s[:, 2]) <= np.pi)
    back = dist < -1e-6
    assert np.all(s[back, 1] < 0) and np.all(s[~back & (dist > 1e-6), 1] > 0)


def test_a_backward_step_by_hand() -> None:
    # 0.1 m straight back while turning 0.2 rad: unsigned rot1 = π, rot2 = 0.2 - π.
    u = odometry_control(np.zeros(3), np.array([-0.1, 0.0, 0.2]))
    np.testing.assert_allclose([abs(u[0]), u[1], wrap_angle(u[0] + u[2])], [np.pi, 0.1, 0.2])
    np.testing.assert_allclose(signed_odometry_steps(u), [0.0, -0.1, 0.2], atol=1e-12)
