"""Trajectories: controls that follow waypoints, and the true motion under control noise."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance, as_positive
from slamkit.errors import InputError
from slamkit.geometry import wrap_angle
from slamkit.models import MotionModel, UnicycleEuler

__all__ = ["simulate_motion", "waypoint_controls"]


def waypoint_controls(
    start_pose: ArrayLike,
    waypoints: ArrayLike,
    *,
    speed: float,
    dt: float,
    max_turn_rate: float = 1.0,
    gain: float = 2.0,
    tolerance: float = 0.3,
    laps: int = 1,
    max_steps: int = 1_000_000,
) -> FloatArray:
    """Unicycle controls ``(N, 2)`` of ``(v, omega)`` that drive from ``start_pose`` through
    ``waypoints (W, 2)`` in order, ``laps`` times, then stop.

    A proportional heading controller: ``omega = clip(gain * bearing error, ±max_turn_rate)``;
    the speed drops with the cosine of the heading error so sharp turns happen nearly on the
    spot. The controls are computed on the noise-free Euler unicycle, so they are
    deterministic; :func:`simulate_motion` then adds the control noise.
    """
    pose = as_array(start_pose, "start_pose", (3,)).copy()
    wps = as_array(waypoints, "waypoints", (None, 2))
    if wps.shape[0] == 0:
        raise InputError("waypoints: expected at least one waypoint")
    v_max = as_positive(speed, "speed")
    step = as_positive(dt, "dt")
    model = UnicycleEuler()
    route = np.tile(wps, (max(1, int(laps)), 1))
    controls: list[tuple[float, float]] = []
    target = 0
    while target < len(route):
        if len(controls) >= max_steps:
            raise InputError(f"waypoints not reached within max_steps={max_steps}")
        d = route[target] - pose[:2]
        if np.hypot(*d) < tolerance:
            target += 1
            continue
        err = float(wrap_angle(np.arctan2(d[1], d[0]) - pose[2]))
        omega = float(np.clip(gain * err, -max_turn_rate, max_turn_rate))
        v = v_max * max(np.cos(err), 0.05)
        controls.append((v, omega))
        pose = model.apply(pose, np.array([v, omega]), step)
    return np.asarray(controls, dtype=float).reshape(-1, 2)


def simulate_motion(
    model: MotionModel,
    start_pose: ArrayLike,
    controls: ArrayLike,
    dt: float,
    control_cov: ArrayLike,
    rng: np.random.Generator,
) -> FloatArray:
    """True poses ``(N + 1, 3)``: the robot executes each commanded control with additive
    noise ``N(0, control_cov)`` drawn from ``rng`` (the estimator is told the commanded one)."""
    x = as_array(start_pose, "start_pose", (3,))
    u = as_array(controls, "controls", (None, model.control_dim))
    cov = as_covariance(control_cov, "control_cov", model.control_dim, semidefinite=True)
    step = as_positive(dt, "dt")
    poses = np.empty((u.shape[0] + 1, 3))
    poses[0] = x
    for k in range(u.shape[0]):
        poses[k + 1] = model.sample(poses[k], u[k], step, cov, rng)
    return poses
