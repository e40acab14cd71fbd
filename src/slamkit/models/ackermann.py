"""The Ackermann (car-like) motion model: a rear-axle reference point, a steering angle and
a wheel-encoder speed, with the sensor and encoder offsets of a real vehicle (conventions as
in :mod:`slamkit.models.motion`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from slamkit._validation import FloatArray, as_array, as_positive
from slamkit.errors import GeometryError
from slamkit.geometry.angles import wrap_angle
from slamkit.models.motion import MotionModelBase, wrap_in_place

__all__ = ["Ackermann"]


@dataclass(frozen=True)
class Ackermann(MotionModelBase):
    """Car-like vehicle with controls ``(speed, steering)`` (m/s, rad), one Euler step.

    Geometry (all in metres, in the vehicle frame whose origin is the centre of the rear axle,
    x forward, y to the left):

    * ``wheelbase`` ``L``: distance from the rear axle to the front axle (> 0).
    * ``sensor_offset = (a, b)``: the tracked point (e.g. the laser) sits ``a`` ahead of and
      ``b`` to the **left** of the rear-axle centre (``b > 0`` = left, ``b < 0`` = right).
      The state ``x`` is the pose of this point with the vehicle's heading; with the default
      ``(0, 0)`` it is the rear-axle centre.
    * ``encoder_offset`` ``H``: the measured ``speed`` is that of a rear wheel ``H`` to the
      **left** of the centre line (``H < 0`` for a right wheel; 0 = the axle centre).

    ``steering`` ``alpha`` is the (bicycle-model) front steering angle, positive = turning
    left. Kinematics, with ``phi`` the heading and ``v_c`` the speed of the rear-axle centre:

    * yaw rate ``omega = v_c tan(alpha) / L``;
    * the encoder wheel moves at ``v_c - omega H = v_c (1 - tan(alpha) H / L)``, hence
      ``v_c = speed / (1 - tan(alpha) H / L)``;
    * the point ``(a, b)`` moves with ``v_c (cos phi, sin phi) + omega × r`` where
      ``r = R(phi) (a, b)``:
      ``x_dot = v_c cos phi - omega (a sin phi + b cos phi)``,
      ``y_dot = v_c sin phi + omega (a cos phi - b sin phi)``, ``phi_dot = omega``;
    * Euler step: ``x' = x + x_dot dt`` etc., rates evaluated at the start of the step.

    For Victoria Park (Guivant & Nebot's truck; ``speed`` from the left rear wheel) use
    ``Ackermann(2.83, (a, 0.5), 0.76)`` with ``a`` the laser's forward offset from the rear
    axle given in the dataset notes. Steering with ``|alpha| >= pi/2`` or that puts the
    encoder wheel on the instantaneous centre of rotation raises :class:`GeometryError`.
    """

    wheelbase: float
    sensor_offset: tuple[float, float] = (0.0, 0.0)
    encoder_offset: float = 0.0

    control_dim: ClassVar[int] = 2
    control_names: ClassVar[tuple[str, ...]] = ("speed", "steering")

    def __post_init__(self) -> None:
        object.__setattr__(self, "wheelbase", as_positive(self.wheelbase, "wheelbase"))
        off = as_array(self.sensor_offset, "sensor_offset", (2,))
        object.__setattr__(self, "sensor_offset", (float(off[0]), float(off[1])))
        enc = as_array(self.encoder_offset, "encoder_offset", ())
        object.__setattr__(self, "encoder_offset", float(enc))

    def _rates(
        self, u: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """``v_c, omega`` and the factors ``tan(alpha), sec²(alpha), D = 1 - tan H / L``."""
        speed, alpha = u[..., 0], u[..., 1]
        cos_a = np.cos(alpha)
        if np.any(np.abs(alpha) >= np.pi / 2):
            raise GeometryError("steering: expected |alpha| < pi/2 (the yaw rate is unbounded)")
        tan_a = np.tan(alpha)
        L, H = self.wheelbase, self.encoder_offset
        D = 1.0 - tan_a * H / L
        if np.any(D < 1e-9):
            raise GeometryError(
                "steering: the encoder wheel lies at or beyond the instantaneous centre of "
                "rotation (1 - tan(alpha) H / L <= 0); its speed does not determine the motion"
            )
        v_c = speed / D
        return v_c, v_c * tan_a / L, tan_a, 1.0 / (cos_a * cos_a), D

    def apply_unchecked(self, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        v_c, w, _, _, _ = self._rates(u)
        a, b = self.sensor_offset
        phi = x[..., 2]
        c, s = np.cos(phi), np.sin(phi)
        return np.stack(
            [
                x[..., 0] + dt * (v_c * c - w * (a * s + b * c)),
                x[..., 1] + dt * (v_c * s + w * (a * c - b * s)),
                wrap_angle(phi + w * dt),
            ],
            axis=-1,
        )

    def move_particles(self, x: FloatArray, u: FloatArray, dt: float) -> None:
        # _g in place (the same expressions, evaluated before any column is overwritten)
        v_c, w, _, _, _ = self._rates(u)
        a, b = self.sensor_offset
        phi = x[:, 2]
        c, s = np.cos(phi), np.sin(phi)
        dx = dt * (v_c * c - w * (a * s + b * c))
        dy = dt * (v_c * s + w * (a * c - b * s))
        x[:, 0] += dx
        x[:, 1] += dy
        phi += w * dt
        wrap_in_place(phi)

    @property
    def max_steering(self) -> float:
        """The largest steering magnitude [rad] the model is defined for in both directions:
        ``|alpha| < pi/2``, and the encoder wheel off the centre of rotation
        (``tan |alpha| < L / |H|``), i.e. ``min(pi/2, atan(L / |H|))`` (a supremum: the
        model raises :class:`GeometryError` at it)."""
        h = abs(self.encoder_offset)
        return math.pi / 2 if h == 0 else min(math.pi / 2, math.atan(self.wheelbase / h))

    def jacobians_unchecked(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        v_c, w, tan_a, sec2, D = self._rates(u)
        speed = u[..., 0]
        a, b = self.sensor_offset
        L, H = self.wheelbase, self.encoder_offset
        phi = x[..., 2]
        c, s = np.cos(phi), np.sin(phi)
        batch = phi.shape
        G = np.zeros((*batch, 3, 3))
        G[..., 0, 0] = G[..., 1, 1] = G[..., 2, 2] = 1.0
        G[..., 0, 2] = dt * (-v_c * s - w * (a * c - b * s))
        G[..., 1, 2] = dt * (v_c * c - w * (a * s + b * c))
        # d(x', y', phi') / d(v_c, omega)
        A = np.zeros((*batch, 3, 2))
        A[..., 0, 0] = dt * c
        A[..., 1, 0] = dt * s
        A[..., 0, 1] = -dt * (a * s + b * c)
        A[..., 1, 1] = dt * (a * c - b * s)
        A[..., 2, 1] = dt
        # d(v_c, omega) / d(speed, alpha), from v_c = speed / D, D = 1 - tan(alpha) H / L:
        #   dv_c/dspeed = 1/D,            dv_c/dalpha = speed H sec² / (L D²)
        #   domega/dspeed = tan / (L D),  domega/dalpha = speed sec² / (L D²)
        B = np.zeros((*batch, 2, 2))
        B[..., 0, 0] = 1.0 / D
        B[..., 0, 1] = speed * H * sec2 / (L * D * D)
        B[..., 1, 0] = tan_a / (L * D)
        B[..., 1, 1] = speed * sec2 / (L * D * D)
        return G, A @ B
