"""The wheel-base error on steps backward: the turn of every step should be scaled by ``s``,
not the unsigned decomposition's ``rot1 ≈ π`` (which would turn a 2 % error into 7° heading
jumps at every step back)."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets.stream import Dataset, GroundTruth, LaserScan, LaserSpec, MotionSpec, Odometry
from slamkit.geometry import wrap_angle
from slamkit.models import OdometryModel
from slamkit.sim import OdometryErrorModel, corrupt_odometry


def _back_and_forth(n: int) -> Dataset:
    """A robot turning -0.1 rad per step while it drives 0.1 m ahead and back in turns (a
    step back then reads ``rot1 = ±π``, ``rot2 = wrap(-0.1 ∓ π)``)."""
    poses = np.zeros((n, 3))
    for k in range(1, n):
        d = 0.1 if (k // 10) % 2 == 0 else -0.1
        th = poses[k - 1, 2]
        poses[k] = poses[k - 1] + [d * np.cos(th), d * np.sin(th), -0.1]
    times = 0.25 * np.arange(n)
    events = []
    for t, p in zip(times, poses, strict=True):
        events += [Odometry(float(t), p), LaserScan(float(t), np.ones(5))]
    return Dataset(
        name="back-and-forth",
        events=tuple(events),
        motion=MotionSpec(OdometryModel(), np.eye(3) * 1e-4, source="odometry"),
        laser=LaserSpec(np.linspace(-1.0, 1.0, 5), 10.0),
        truth=GroundTruth(times=times, poses=poses),
    )


@pytest.mark.parametrize(("eps_r", "eps_b"), [(0.02, 0.0), (0.0, 0.03)])
def test_every_step_turns_by_s_times_its_turn(eps_r: float, eps_b: float) -> None:
    data = _back_and_forth(200)
    out, _ = corrupt_odometry(
        data, OdometryErrorModel.exact(eps_r, eps_b), np.random.default_rng(0)
    )
    odo = np.array([ev.pose for ev in out.events if isinstance(ev, Odometry)])
    turns = wrap_angle(np.diff(odo[:, 2]))
    np.testing.assert_allclose(turns, -0.1 * (1 + eps_r) / (1 + eps_b), atol=1e-12)
    steps = np.hypot(*np.diff(odo[:, :2], axis=0).T)
    np.testing.assert_allclose(steps, 0.1 * (1 + eps_r), atol=1e-12)
    # Each step along the heading it started with, ahead or back: no sideways part.
    d = np.diff(odo[:, :2], axis=0)
    side = -np.sin(odo[:-1, 2]) * d[:, 0] + np.cos(odo[:-1, 2]) * d[:, 1]
    np.testing.assert_allclose(side, 0.0, atol=1e-12)
