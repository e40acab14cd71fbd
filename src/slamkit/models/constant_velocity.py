"""The motion prior of a laser log without odometry: the last scan-to-scan velocity, held.

Between two scans ``dt`` apart the robot is predicted to repeat the body-frame motion of the
last matched interval, scaled to ``dt``,

    Δ̂ = (v_x dt, v_y dt, ω dt),      v = Δ_last / dt_last

(``Δ_last = between(x_prev, x_cur)`` of the last two matched poses), with the velocity a
random walk: its uncertainty grows as ``σ_v dt`` per axis, so the prediction's covariance is
``diag((σ_xy dt)², (σ_xy dt)², (σ_θ dt)²)``. Accelerations of up to ``σ_xy`` per second are
thus one standard deviation — generous for an indoor robot, which keeps the scan matcher's
search region large enough to find the match after a start or a stop. A failed match keeps the
velocity's translation (in a featureless corridor, where matches fail, the robot mostly keeps
going) but not its turn rate (:meth:`ConstantVelocity.lose_turn`): turns end, and a turn rate
held past its end spins every later prediction away from the scans, so that no later match
finds them again.

The translation is held through a corridor, where the scans do not observe it, so a wrong
one held there is never corrected: a matched speed that differs from the held one by more
than ``GATE`` standard deviations of the random walk since the translation was last observed,
``|v − v̂| > GATE σ_xy T``, is a match that slid (along a corridor, or in a turn on the spot),
not a robot's acceleration; its turn is kept and its translation is not
(:meth:`ConstantVelocity.observe` returns False). The gate widens with every interval the
translation goes unobserved, so a real change of speed gets through a few scans later.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import ConfigError
from slamkit.geometry.angles import wrap_angle_float

__all__ = ["GATE", "ConstantVelocity"]

GATE = 3.0
"""Standard deviations of the velocity's random walk beyond which a matched speed is not
believed (module docstring; about the 99 % bound of a 2-D Gaussian)."""


@dataclass
class ConstantVelocity:
    """Constant-velocity prediction for scan matching without odometry (module docstring).

    ``sigma_xy`` [m/s per s] and ``sigma_deg`` [deg/s per s]: the velocity's random walk."""

    sigma_xy: float = 0.5
    sigma_deg: float = 45.0
    velocity: FloatArray = field(default_factory=lambda: np.zeros(3))
    """The body-frame velocity ``(v_x, v_y, ω)`` [m/s, m/s, rad/s] of the last interval."""
    unobserved: float = math.inf
    """Seconds since the translation was last observed (inf: never)."""

    def __post_init__(self) -> None:
        for name in ("sigma_xy", "sigma_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: expected a finite number > 0, got {v!r}")

    def predict(self, dt: float) -> tuple[FloatArray, FloatArray]:
        """The predicted increment ``Δ̂ (3,)`` over ``dt`` seconds and its covariance
        ``(3, 3)``."""
        dt = max(float(dt), 0.0)
        s_xy, s_t = self.sigma_xy * dt, math.radians(self.sigma_deg) * dt
        return self.velocity * dt, np.diag([s_xy**2, s_xy**2, s_t**2])

    def propagate(
        self, pose: FloatArray, cov: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        """``pose ⊕ Δ̂`` and its covariance ``J Σ Jᵀ + R Σ_Δ Rᵀ`` (``J = ∂(x ⊕ Δ)/∂x``,
        ``R`` the rotation of ``pose``) after ``dt`` seconds."""
        inc, inc_cov = self.predict(dt)
        x, y, th = (float(v) for v in pose)
        c, s = math.cos(th), math.sin(th)
        moved = np.array(
            [
                x + c * inc[0] - s * inc[1],
                y + s * inc[0] + c * inc[1],
                wrap_angle_float(th + inc[2]),
            ]
        )
        J = np.array([[1.0, 0.0, -s * inc[0] - c * inc[1]], [0.0, 1.0, c * inc[0] - s * inc[1]]])
        J = np.vstack([J, [0.0, 0.0, 1.0]])
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return moved, J @ cov @ J.T + R @ inc_cov @ R.T

    def lose_turn(self, dt: float) -> None:
        """A failed match over ``dt`` seconds: the translation is held, the turn rate
        dropped (module docstring)."""
        self.velocity = np.array([self.velocity[0], self.velocity[1], 0.0])
        self.unobserved += max(float(dt), 0.0)

    def observe_turn(self, turn: float, dt: float) -> None:
        """A match that fixed the heading but not the translation (a corridor, where the
        translation is the prediction's): the turn ``turn`` [rad] over ``dt`` seconds
        becomes the turn rate, the translation is held."""
        if dt > 0:
            self.velocity = np.array([self.velocity[0], self.velocity[1], turn / float(dt)])
            self.unobserved += float(dt)

    def observe(self, increment: FloatArray, dt: float) -> bool:
        """The matched motion ``increment = between(x_prev, x_cur)`` over ``dt`` seconds
        becomes the velocity, unless its speed is beyond the gate (module docstring): then
        its turn alone is taken. Returns whether the translation was taken."""
        if not dt > 0:
            return False
        v = np.asarray(increment, dtype=np.float64) / float(dt)
        span = self.unobserved + float(dt)
        jump = math.hypot(float(v[0] - self.velocity[0]), float(v[1] - self.velocity[1]))
        if jump > GATE * self.sigma_xy * span:
            self.observe_turn(float(v[2]) * float(dt), dt)
            return False
        self.velocity = v
        self.unobserved = 0.0
        return True
