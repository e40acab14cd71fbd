"""Trajectories: controls that follow waypoints, and the true motion under control noise."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance, as_positive
from slamkit.errors import InputError
from slamkit.geometry import wrap_angle
from slamkit.models import MotionModel, UnicycleEuler

__all__ = ["Drive", "follow_waypoints", "simulate_motion", "waypoint_controls"]


@dataclass(frozen=True)
class Drive:
    """A simulated drive: ``controls (N, 2)`` as commanded (what an estimator is told) and
    ``poses (N + 1, 3)`` as really driven."""

    controls: FloatArray
    poses: FloatArray


def follow_waypoints(
    start_pose: ArrayLike,
    waypoints: ArrayLike,
    *,
    speed: float,
    dt: float,
    control_cov: ArrayLike | None = None,
    rng: np.random.Generator | None = None,
    max_turn_rate: float = 1.0,
    gain: float = 2.0,
    tolerance: float = 0.3,
    laps: int = 1,
    kidnap: tuple[int, int] | None = None,
    max_steps: int = 1_000_000,
) -> Drive:
    """Drive a unicycle from ``start_pose`` through ``waypoints (W, 2)`` in order, ``laps``
    times, in CLOSED LOOP: every step the controller looks at the true pose, commands
    ``(v, omega)``, and the robot executes that command plus noise ``N(0, control_cov)``.

    The controller: ``omega = clip(gain · bearing error, ±max_turn_rate)`` and a speed that
    drops with the cosine of the heading error, so sharp turns happen nearly on the spot.
    A waypoint counts as reached within ``max(tolerance, speed · dt)``: a robot that moves
    further than the tolerance in one step would otherwise step over it and orbit it.
    Steering on the true pose keeps the robot on its route however long it drives (open-loop
    replay of planned controls would drift through walls).

    ``kidnap = (k0, skip)``: at step ``k0`` the robot is carried to where the noise-free drive
    is ``skip`` steps later, and the command of that step is a standstill (the robot is not
    told) — the kidnapped-robot problem.
    """
    pose = as_array(start_pose, "start_pose", (3,))
    wps = as_array(waypoints, "waypoints", (None, 2))
    if wps.shape[0] == 0:
        raise InputError("waypoints: expected at least one waypoint")
    step = as_positive(dt, "dt")
    reach = max(float(tolerance), float(speed) * step)
    ctl = _Controller(as_positive(speed, "speed"), max_turn_rate, gain, reach)
    noise = None
    if control_cov is not None:
        if rng is None:
            raise InputError("rng: a noisy drive needs an np.random.Generator")
        noise = (as_covariance(control_cov, "control_cov", 2, semidefinite=True), rng)
    route = np.tile(wps, (max(1, int(laps)), 1))
    landing = None
    if kidnap is not None:  # where the robot would be without noise, to land it there
        plan_poses, plan_targets = _drive(pose, route, ctl, step, None, None, max_steps)[1:]
        k_land = kidnap[0] + kidnap[1]
        if k_land >= len(plan_poses):
            raise InputError(f"kidnap: step {k_land} lies beyond the route")
        landing = (kidnap[0], plan_poses[k_land], int(plan_targets[k_land]))
    controls, poses, _ = _drive(pose, route, ctl, step, noise, landing, max_steps)
    return Drive(controls, poses)


@dataclass(frozen=True)
class _Controller:
    """Proportional heading control towards the current waypoint."""

    speed: float
    max_turn_rate: float
    gain: float
    tolerance: float

    def command(self, pose: np.ndarray, goal: np.ndarray) -> tuple[float, float]:
        d = goal - pose[:2]
        err = float(wrap_angle(np.arctan2(d[1], d[0]) - pose[2]))
        omega = float(np.clip(self.gain * err, -self.max_turn_rate, self.max_turn_rate))
        return self.speed * max(np.cos(err), 0.05), omega


def _drive(
    pose: np.ndarray,
    route: np.ndarray,
    ctl: _Controller,
    dt: float,
    noise: tuple[np.ndarray, np.random.Generator] | None,
    landing: tuple[int, np.ndarray, int] | None,
    max_steps: int,
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Commanded controls, driven poses and the waypoint index steered to at every pose."""
    model = UnicycleEuler()
    controls: list[tuple[float, float]] = []
    poses, targets = [pose], [0]
    target = 0
    while target < len(route):
        if len(controls) >= max_steps:
            raise InputError(f"waypoints not reached within max_steps={max_steps}")
        if landing is not None and len(controls) == landing[0]:
            controls.append((0.0, 0.0))  # carried away; the robot is not told
            pose, target = landing[1].copy(), landing[2]
        elif np.hypot(*(route[target] - pose[:2])) < ctl.tolerance:
            target += 1
            targets[-1] = target
            continue
        else:
            u = ctl.command(pose, route[target])
            controls.append(u)
            if noise is None:
                pose = model.apply(pose, np.array(u), dt)
            else:
                pose = model.sample(pose, np.array(u), dt, noise[0], noise[1])
        poses.append(pose)
        targets.append(target)
    return np.asarray(controls, dtype=float).reshape(-1, 2), np.asarray(poses), np.asarray(targets)


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
    """The noise-free controls ``(N, 2)`` of :func:`follow_waypoints` (a plan; replaying it
    with noise drifts, so simulations use :func:`follow_waypoints` with ``control_cov``)."""
    return follow_waypoints(
        start_pose, waypoints, speed=speed, dt=dt, max_turn_rate=max_turn_rate, gain=gain,
        tolerance=tolerance, laps=laps, max_steps=max_steps,
    ).controls  # fmt: skip


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
