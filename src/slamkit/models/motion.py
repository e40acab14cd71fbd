"""Motion models ``x_t = g(x_{t-1}, u_t, dt)`` for planar robots, with analytic Jacobians.

Conventions shared by every model here:

* A pose ``x`` is an array ``(..., 3)`` holding ``(x, y, theta)`` in metres and radians; the
  returned heading is always wrapped to ``[-pi, pi)`` by :func:`slamkit.geometry.wrap_angle`.
* A control ``u`` is an array ``(..., k)`` whose meaning each model names in
  ``control_names``. Leading (batch) axes of ``x`` and ``u`` broadcast against each other, so a
  particle set ``(P, 3)`` moves under one control ``(k,)`` in a single call.
* ``dt`` is the duration of the step in seconds (a float ``>= 0``); the control is held
  constant over the step.
* ``jacobians`` returns ``G = dg/dx`` of shape ``(..., 3, 3)`` and ``V = dg/du`` of shape
  ``(..., 3, k)``, evaluated at the given ``(x, u)``.
* ``sample`` perturbs the *control*: it returns ``g(x, u + eps, dt)`` with
  ``eps ~ N(0, control_cov)`` drawn independently for every batch element, which is the
  noise model that :func:`propagate_gaussian` linearises (``G C Gᵀ + V Q Vᵀ``).

Inputs are never modified; every function returns new arrays (the one exception is the
particle-filter kernel :meth:`MotionModelBase.move_particles`, which moves the poses it is
given in place). :class:`MotionModelBase` is the fast-path contract the estimators use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance, as_positive
from slamkit.errors import InputError, ShapeError
from slamkit.geometry.angles import wrap_angle, wrap_angle_float
from slamkit.prob.gaussian import gaussian_draws

__all__ = [
    "DifferentialDrive",
    "MotionModel",
    "MotionModelBase",
    "OdometryModel",
    "UnicycleArc",
    "UnicycleEuler",
    "integrate_odometry",
    "motion_kernels",
    "odometry_control",
    "odometry_noise_cov",
    "propagate_gaussian",
    "propagate_gaussian_unchecked",
    "wrap_in_place",
]


@runtime_checkable
class MotionModel(Protocol):
    """What filters, the simulator and dead reckoning need from a motion model.

    ``control_dim`` is ``k``, the length of a control vector; ``control_names`` names its
    components in order.
    """

    @property
    def control_dim(self) -> int: ...

    @property
    def control_names(self) -> tuple[str, ...]: ...

    def apply(self, x: ArrayLike, u: ArrayLike, dt: float) -> FloatArray:
        """``g(x, u, dt)``: the poses ``(..., 3)`` after one step, heading wrapped."""
        ...

    def jacobians(self, x: ArrayLike, u: ArrayLike, dt: float) -> tuple[FloatArray, FloatArray]:
        """``(G, V)`` with ``G = dg/dx`` ``(..., 3, 3)`` and ``V = dg/du`` ``(..., 3, k)``."""
        ...

    def sample(
        self,
        x: ArrayLike,
        u: ArrayLike,
        dt: float,
        control_cov: ArrayLike,
        rng: np.random.Generator,
    ) -> FloatArray:
        """``g(x, u + eps, dt)`` with ``eps ~ N(0, control_cov)`` per batch element."""
        ...


# --------------------------------------------------------------------------------------------
# Shared plumbing
# --------------------------------------------------------------------------------------------


def _as_dt(dt: float) -> float:
    return as_positive(dt, "dt", allow_zero=True)


def _prepare(x: ArrayLike, u: ArrayLike, k: int) -> tuple[FloatArray, FloatArray]:
    """Validate a pose and a control and broadcast their batch axes against each other."""
    xa = as_array(x, "pose x", (..., 3))
    ua = as_array(u, "control u", (..., k))
    if xa.shape[:-1] == ua.shape[:-1]:
        return xa, ua  # nothing to broadcast (one pose, or one control per particle)
    try:
        batch = np.broadcast_shapes(xa.shape[:-1], ua.shape[:-1])
    except ValueError as exc:
        raise ShapeError(
            f"pose x {xa.shape} and control u {ua.shape}: batch axes do not broadcast"
        ) from exc
    return np.broadcast_to(xa, (*batch, 3)), np.broadcast_to(ua, (*batch, k))


def wrap_in_place(theta: FloatArray) -> None:
    """Headings wrapped to ``[-pi, pi)`` in place; :func:`wrap_angle` returns angles in
    range bit-identical, so it is called only when one is out of range (two reductions
    instead of its ~10 operations on every step)."""
    if theta.size and not (float(theta.min()) >= -math.pi and float(theta.max()) < math.pi):
        theta[...] = wrap_angle(theta)


def _advance_in_place(x: FloatArray, heading: FloatArray, distance: FloatArray) -> None:
    """``x += distance cos(heading)``, ``y += distance sin(heading)`` in place for particle
    poses ``x (P, 3)`` (the products in the order of the models' ``apply_unchecked``, so
    the result is bit-identical)."""
    t = np.cos(heading)
    t *= distance
    x[:, 0] += t
    np.sin(heading, out=t)
    t *= distance
    x[:, 1] += t


class MotionModelBase:
    """The base of every slamkit motion model: the estimators' fast-path contract.

    A subclass sets ``control_dim`` and ``control_names`` and implements two kernels on
    validated, broadcast float64 arrays — ``apply_unchecked`` (``g``) and
    ``jacobians_unchecked`` (``G, V``). It inherits the validating public methods of
    :class:`MotionModel` (``apply``, ``jacobians``, ``sample``) and the two fused kernels that
    estimators call in their loops: :meth:`step_single` (an EKF prediction of one pose) and
    :meth:`move_particles` (a particle filter's prediction, in place). Overriding those two
    with faster arithmetic is optional; an override must agree with the batch kernels (the
    built-in models each have a test to 1e-12).

    A model written elsewhere that only satisfies the :class:`MotionModel` protocol gets the
    same kernels through :func:`motion_kernels`, which wraps its public methods.
    """

    control_dim: ClassVar[int]
    control_names: ClassVar[tuple[str, ...]]

    def apply_unchecked(self, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        """``g(x, u, dt)`` for validated poses ``(..., 3)`` and controls ``(..., k)`` of the
        same batch shape, ``dt >= 0``; heading wrapped."""
        raise NotImplementedError(f"{type(self).__name__} does not implement apply_unchecked")

    def jacobians_unchecked(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        """``(G (..., 3, 3), V (..., 3, k))`` for validated arguments as in
        :meth:`apply_unchecked`."""
        raise NotImplementedError(f"{type(self).__name__} does not implement jacobians_unchecked")

    def step_single(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(g, G, V)`` for ONE validated pose ``(3,)`` and control ``(k,)``: an EKF
        prediction. Overrides use plain floats (NumPy's per-call overhead on 0-d arrays
        dominates there); a test checks each against the batch kernels."""
        G, V = self.jacobians_unchecked(x, u, dt)
        return self.apply_unchecked(x, u, dt), G, V

    def move_particles(self, x: FloatArray, u: FloatArray, dt: float) -> None:
        """``x ← g(x, u, dt)`` IN PLACE for validated particle poses ``x (P, 3)`` (float64,
        writeable, not aliasing ``u``) and controls ``u (P, k)``: a particle filter's
        prediction, once per control. Overrides write the result into ``x`` column by column
        with the operations of ``apply_unchecked`` (bit-identical; a test checks 1e-12) and
        skip the wrapping of headings already in range; at a few hundred particles stacking
        a new array and wrapping every heading cost as much as the motion."""
        x[...] = self.apply_unchecked(x, u, dt)

    def apply(self, x: ArrayLike, u: ArrayLike, dt: float) -> FloatArray:
        """``g(x, u, dt)``: poses ``(..., 3)`` after one step, heading in ``[-pi, pi)``."""
        xa, ua = _prepare(x, u, self.control_dim)
        return self.apply_unchecked(xa, ua, _as_dt(dt))

    def jacobians(self, x: ArrayLike, u: ArrayLike, dt: float) -> tuple[FloatArray, FloatArray]:
        """``(G, V)``: ``G = dg/dx`` ``(..., 3, 3)`` and ``V = dg/du`` ``(..., 3, k)``."""
        xa, ua = _prepare(x, u, self.control_dim)
        return self.jacobians_unchecked(xa, ua, _as_dt(dt))

    def sample(
        self,
        x: ArrayLike,
        u: ArrayLike,
        dt: float,
        control_cov: ArrayLike,
        rng: np.random.Generator,
    ) -> FloatArray:
        """``g(x, u + eps, dt)`` with ``eps ~ N(0, control_cov)`` drawn per batch element.

        ``control_cov`` is ``(k, k)`` (or a batch ``(..., k, k)`` broadcasting against the
        poses), symmetric positive semi-definite; zero entries mean a noise-free component.
        """
        k = self.control_dim
        xa, ua = _prepare(x, u, k)
        dt = _as_dt(dt)
        q = as_covariance(control_cov, "control_cov", k, semidefinite=True)
        eps = gaussian_draws(q, xa.shape[:-1], rng)
        batch = eps.shape[:-1]
        xa = np.broadcast_to(xa, (*batch, 3))
        return self.apply_unchecked(xa, ua + eps, dt)


_MOTION_MEMBERS = ("control_dim", "control_names", "apply", "jacobians", "sample")


class _ProtocolMotion(MotionModelBase):
    """The kernels of a :class:`MotionModel` that is not a :class:`MotionModelBase`, through
    its public (validating) methods."""

    def __init__(self, model: MotionModel) -> None:
        self.model = model
        self.control_dim = int(model.control_dim)  # type: ignore[misc]
        self.control_names = tuple(model.control_names)  # type: ignore[misc]

    def apply_unchecked(self, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        return np.asarray(self.model.apply(x, u, dt), dtype=np.float64)

    def jacobians_unchecked(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        G, V = self.model.jacobians(x, u, dt)
        return np.asarray(G, dtype=np.float64), np.asarray(V, dtype=np.float64)

    def sample(
        self,
        x: ArrayLike,
        u: ArrayLike,
        dt: float,
        control_cov: ArrayLike,
        rng: np.random.Generator,
    ) -> FloatArray:
        return np.asarray(self.model.sample(x, u, dt, control_cov, rng), dtype=np.float64)


def motion_kernels(model: object) -> MotionModelBase:
    """The fast-path kernels of a motion model: the model itself when it is a
    :class:`MotionModelBase` (every slamkit model), else the kernels of a
    :class:`MotionModel` through its public methods (same numbers, without the fused
    arithmetic). Raise :class:`~slamkit.errors.InputError` naming what a model lacks."""
    if isinstance(model, MotionModelBase):
        return model
    missing = [m for m in _MOTION_MEMBERS if not hasattr(model, m)]
    if missing:
        raise InputError(
            f"motion model {type(model).__name__}: expected the MotionModel protocol "
            f"(control_dim, control_names, apply, jacobians, sample); missing "
            f"{', '.join(missing)}"
        )
    return _ProtocolMotion(model)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------
# Kinematic kernels on (v, omega), shared by the unicycle and differential-drive models
# --------------------------------------------------------------------------------------------


def _euler_g(x: FloatArray, v: FloatArray, w: FloatArray, dt: float) -> FloatArray:
    # x' = x + v cos(theta) dt,  y' = y + v sin(theta) dt,  theta' = theta + omega dt
    th = x[..., 2]
    return np.stack(
        [
            x[..., 0] + v * np.cos(th) * dt,
            x[..., 1] + v * np.sin(th) * dt,
            wrap_angle(th + w * dt),
        ],
        axis=-1,
    )


def _euler_jac(
    x: FloatArray, v: FloatArray, w: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray]:
    """``G`` (..., 3, 3) and ``V_vw = d g / d(v, omega)`` (..., 3, 2) of the Euler step."""
    th = x[..., 2]
    c, s = np.cos(th), np.sin(th)
    batch = th.shape
    G = np.zeros((*batch, 3, 3))
    G[..., 0, 0] = G[..., 1, 1] = G[..., 2, 2] = 1.0
    G[..., 0, 2] = -v * s * dt  # d x' / d theta
    G[..., 1, 2] = v * c * dt  # d y' / d theta
    V = np.zeros((*batch, 3, 2))
    V[..., 0, 0] = c * dt
    V[..., 1, 0] = s * dt
    V[..., 2, 1] = dt
    return G, V


# Below this |phi| = |omega dt| the arc kernels use Taylor series: the closed forms divide by
# phi (and phi²) and lose all precision, then become 0/0 at phi = 0. The truncation error of
# the series at the switch is below 1e-17 relative.
_ARC_SERIES_BELOW = 1e-3


def _sinc_half(phi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``s(phi) = sin(phi/2) / (phi/2)`` and its derivative ``s'(phi)``, finite at 0."""
    if phi.ndim == 0:  # one pose (an EKF step): plain floats are ~20x cheaper than 0-d arrays
        s0, d0 = _sinc_half_scalar(float(phi))
        return np.float64(s0), np.float64(d0)  # type: ignore[return-value]
    small = np.abs(phi) < _ARC_SERIES_BELOW
    h = np.where(small, 1.0, phi / 2.0)  # safe divisor on the series branch
    s_closed = np.sin(h) / h
    # s'(phi) = (h cos h - sin h) / (2 h²) with h = phi / 2
    ds_closed = (h * np.cos(h) - np.sin(h)) / (2.0 * h * h)
    p2 = phi * phi
    # sin(h)/h = 1 - h²/6 + h⁴/120 - ...  with h = phi/2
    s_series = 1.0 - p2 / 24.0 + p2 * p2 / 1920.0
    ds_series = -phi / 12.0 + phi * p2 / 480.0
    return np.where(small, s_series, s_closed), np.where(small, ds_series, ds_closed)


def _sinc_half_value(phi: FloatArray) -> FloatArray:
    """``s(phi)`` of :func:`_sinc_half` alone, each branch evaluated only where some
    ``phi`` needs it (the same values: a particle filter's per-control kernel)."""
    small = np.abs(phi) < _ARC_SERIES_BELOW
    if not small.any():
        h = phi / 2.0
        return np.sin(h) / h
    s, _ = _sinc_half(phi)
    return s


def _sinc_half_scalar(phi: float) -> tuple[float, float]:
    if abs(phi) < _ARC_SERIES_BELOW:
        p2 = phi * phi
        return 1.0 - p2 / 24.0 + p2 * p2 / 1920.0, -phi / 12.0 + phi * p2 / 480.0
    h = phi / 2.0
    sh, ch = math.sin(h), math.cos(h)
    return sh / h, (h * ch - sh) / (2.0 * h * h)


def _arc_g(x: FloatArray, v: FloatArray, w: FloatArray, dt: float) -> FloatArray:
    # Exact integration of constant (v, omega) over dt, phi = omega dt:
    #   x' = x + (v/omega) (sin(theta + phi) - sin theta) = x + v dt s(phi) cos(theta + phi/2)
    #   y' = y + (v/omega) (cos theta - cos(theta + phi)) = y + v dt s(phi) sin(theta + phi/2)
    # using sin a - sin b = 2 cos((a+b)/2) sin((a-b)/2) (and the cosine analogue); the
    # right-hand forms stay finite as omega -> 0, where they become the straight line.
    th = x[..., 2]
    phi = w * dt
    s, _ = _sinc_half(phi)
    mid = th + phi / 2.0
    chord = v * dt * s
    return np.stack(
        [x[..., 0] + chord * np.cos(mid), x[..., 1] + chord * np.sin(mid), wrap_angle(th + phi)],
        axis=-1,
    )


def _arc_jac(
    x: FloatArray, v: FloatArray, w: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray]:
    """``G`` and ``V_vw = d g / d(v, omega)`` of the exact arc step (finite at omega = 0)."""
    th = x[..., 2]
    phi = w * dt
    s, ds = _sinc_half(phi)
    mid = th + phi / 2.0
    c, sn = np.cos(mid), np.sin(mid)
    batch = th.shape
    G = np.zeros((*batch, 3, 3))
    G[..., 0, 0] = G[..., 1, 1] = G[..., 2, 2] = 1.0
    G[..., 0, 2] = -v * dt * s * sn
    G[..., 1, 2] = v * dt * s * c
    V = np.zeros((*batch, 3, 2))
    V[..., 0, 0] = dt * s * c
    V[..., 1, 0] = dt * s * sn
    # d/d omega of v dt s(omega dt) cos(theta + omega dt / 2)
    #   = v dt² (s'(phi) cos(mid) - s(phi) sin(mid) / 2), and the sine analogue
    V[..., 0, 1] = v * dt * dt * (ds * c - 0.5 * s * sn)
    V[..., 1, 1] = v * dt * dt * (ds * sn + 0.5 * s * c)
    V[..., 2, 1] = dt
    return G, V


# --------------------------------------------------------------------------------------------
# Velocity models
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class UnicycleEuler(MotionModelBase):
    """Velocity model with controls ``(v, omega)`` (m/s, rad/s), one Euler step.

    ``x' = x + v cos(theta) dt``, ``y' = y + v sin(theta) dt``, ``theta' = theta + omega dt``
    where ``theta`` is the heading at the *start* of the step (``dt`` multiplies the rate; it
    is not inside the cosine). Accurate when ``omega dt`` is small; :class:`UnicycleArc` is
    exact for constant controls.
    """

    control_dim: ClassVar[int] = 2
    control_names: ClassVar[tuple[str, ...]] = ("v", "omega")

    def apply_unchecked(self, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        return _euler_g(x, u[..., 0], u[..., 1], dt)

    def move_particles(self, x: FloatArray, u: FloatArray, dt: float) -> None:
        # _euler_g in place: x += v cos(θ) dt, y += v sin(θ) dt, θ += ω dt
        th = x[:, 2]
        v = u[:, 0]
        t = np.cos(th)
        t *= v
        t *= dt
        x[:, 0] += t
        np.sin(th, out=t)
        t *= v
        t *= dt
        x[:, 1] += t
        th += np.multiply(u[:, 1], dt, out=t)
        wrap_in_place(th)

    def step_single(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        th, v, w = float(x[2]), float(u[0]), float(u[1])
        c, s = math.cos(th), math.sin(th)
        g = np.array([x[0] + v * c * dt, x[1] + v * s * dt, wrap_angle_float(th + w * dt)])
        G = np.array([[1.0, 0.0, -v * s * dt], [0.0, 1.0, v * c * dt], [0.0, 0.0, 1.0]])
        V = np.array([[c * dt, 0.0], [s * dt, 0.0], [0.0, dt]])
        return g, G, V

    def jacobians_unchecked(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        return _euler_jac(x, u[..., 0], u[..., 1], dt)


@dataclass(frozen=True)
class UnicycleArc(MotionModelBase):
    """Velocity model with controls ``(v, omega)`` (m/s, rad/s), integrated exactly.

    With constant ``(v, omega)`` the robot drives a circular arc of radius ``v / omega``:
    ``x' = x + (v/omega)(sin(theta + omega dt) - sin theta)``,
    ``y' = y + (v/omega)(cos theta - cos(theta + omega dt))``, ``theta' = theta + omega dt``.
    It is evaluated in the equivalent chord form ``v dt s(omega dt) (cos, sin)(theta +
    omega dt / 2)`` with ``s(phi) = sin(phi/2)/(phi/2)``, and a Taylor series of ``s`` for
    ``|omega dt| < 1e-3``, so pose and Jacobians are finite and accurate down to
    ``omega = 0`` (a straight line).
    """

    control_dim: ClassVar[int] = 2
    control_names: ClassVar[tuple[str, ...]] = ("v", "omega")

    def apply_unchecked(self, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        return _arc_g(x, u[..., 0], u[..., 1], dt)

    def move_particles(self, x: FloatArray, u: FloatArray, dt: float) -> None:
        # _arc_g in place: the chord v dt s(φ) along θ + φ/2, then θ += φ
        th = x[:, 2]
        phi = u[:, 1] * dt
        s = _sinc_half_value(phi)
        mid = th + phi / 2.0
        chord = u[:, 0] * dt
        chord *= s
        _advance_in_place(x, mid, chord)
        th += phi
        wrap_in_place(th)

    def step_single(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        # The same chord form as _arc_g / _arc_jac, in plain floats.
        th, v, w = float(x[2]), float(u[0]), float(u[1])
        phi = w * dt
        s, ds = _sinc_half_scalar(phi)
        mid = th + phi / 2.0
        c, sn = math.cos(mid), math.sin(mid)
        chord = v * dt * s
        g = np.array([x[0] + chord * c, x[1] + chord * sn, wrap_angle_float(th + phi)])
        G = np.array([[1.0, 0.0, -chord * sn], [0.0, 1.0, chord * c], [0.0, 0.0, 1.0]])
        vdt2 = v * dt * dt
        V = np.array(
            [
                [dt * s * c, vdt2 * (ds * c - 0.5 * s * sn)],
                [dt * s * sn, vdt2 * (ds * sn + 0.5 * s * c)],
                [0.0, dt],
            ]
        )
        return g, G, V

    def jacobians_unchecked(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        return _arc_jac(x, u[..., 0], u[..., 1], dt)


@dataclass(frozen=True)
class DifferentialDrive(MotionModelBase):
    """Two-wheel (tank) drive with controls ``(v_left, v_right)``: wheel ground speeds, m/s.

    Both wheels drive forward for positive speeds. The body velocities are
    ``v = (v_left + v_right) / 2`` and ``omega = (v_right - v_left) / wheel_distance``
    (counter-clockwise positive: a faster right wheel turns left), followed by the Euler step
    of :class:`UnicycleEuler` or, with ``exact=True``, the arc of :class:`UnicycleArc`. The
    control Jacobian is ``V = V_(v, omega) @ [[1/2, 1/2], [-1/d, 1/d]]`` (chain rule).

    ``wheel_distance`` ``d`` is the distance between the wheel contact points (m, > 0).
    """

    wheel_distance: float
    exact: bool = False

    control_dim: ClassVar[int] = 2
    control_names: ClassVar[tuple[str, ...]] = ("v_left", "v_right")

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "wheel_distance", as_positive(self.wheel_distance, "wheel_distance")
        )
        object.__setattr__(self, "exact", bool(self.exact))

    def body_velocity(self, u: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(v, omega)`` from wheel speeds ``u (..., 2)`` = ``(v_left, v_right)``."""
        ua = as_array(u, "control u", (..., 2))
        return self._vw(ua)

    def _vw(self, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        vl, vr = u[..., 0], u[..., 1]
        return 0.5 * (vl + vr), (vr - vl) / self.wheel_distance

    def apply_unchecked(self, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        v, w = self._vw(u)
        return (_arc_g if self.exact else _euler_g)(x, v, w, dt)

    def jacobians_unchecked(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        v, w = self._vw(u)
        G, V_vw = (_arc_jac if self.exact else _euler_jac)(x, v, w, dt)
        inv_d = 1.0 / self.wheel_distance
        # d(v, omega) / d(v_left, v_right)
        J = np.array([[0.5, 0.5], [-inv_d, inv_d]])
        return G, V_vw @ J


# --------------------------------------------------------------------------------------------
# Odometry model
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OdometryModel(MotionModelBase):
    """The odometry motion model of *Probabilistic Robotics* (ch. 5.4).

    The control ``u = (rot1, trans, rot2)`` describes the motion between two odometry
    readings as: turn by ``rot1`` (rad), drive ``trans`` (m) straight ahead, turn by ``rot2``
    (rad). Compute it with :func:`odometry_control`. Then
    ``x' = x + trans cos(theta + rot1)``, ``y' = y + trans sin(theta + rot1)``,
    ``theta' = theta + rot1 + rot2``. ``dt`` is accepted for the common interface and
    ignored.

    Noise: ``control_cov`` in :meth:`sample` and :func:`propagate_gaussian` is the
    covariance of ``(rot1, trans, rot2)`` (rad², m², rad²); :func:`odometry_noise_cov` builds
    the motion-dependent diagonal of the book's ``alpha1..alpha4`` parameters.
    """

    control_dim: ClassVar[int] = 3
    control_names: ClassVar[tuple[str, ...]] = ("rot1", "trans", "rot2")

    def apply(self, x: ArrayLike, u: ArrayLike, dt: float = 0.0) -> FloatArray:
        """``g(x, u)``: the pose after ``(rot1, trans, rot2)``; ``dt`` is ignored."""
        xa, ua = _prepare(x, u, 3)
        return self.apply_unchecked(xa, ua, 0.0)

    def jacobians(
        self, x: ArrayLike, u: ArrayLike, dt: float = 0.0
    ) -> tuple[FloatArray, FloatArray]:
        """``(G (..., 3, 3), V (..., 3, 3))``; ``dt`` is ignored."""
        xa, ua = _prepare(x, u, 3)
        return self.jacobians_unchecked(xa, ua, 0.0)

    def sample(
        self,
        x: ArrayLike,
        u: ArrayLike,
        dt: float,
        control_cov: ArrayLike,
        rng: np.random.Generator,
    ) -> FloatArray:
        """``g(x, u + eps)`` with ``eps ~ N(0, control_cov)``; ``dt`` is ignored."""
        return super().sample(x, u, 0.0, control_cov, rng)

    def apply_unchecked(self, x: FloatArray, u: FloatArray, dt: float) -> FloatArray:
        rot1, trans, rot2 = u[..., 0], u[..., 1], u[..., 2]
        th = x[..., 2]
        heading = th + rot1
        return np.stack(
            [
                x[..., 0] + trans * np.cos(heading),
                x[..., 1] + trans * np.sin(heading),
                wrap_angle(heading + rot2),
            ],
            axis=-1,
        )

    def move_particles(self, x: FloatArray, u: FloatArray, dt: float) -> None:
        # _g in place: turn rot1, drive trans, turn rot2
        th = x[:, 2]
        heading = th + u[:, 0]
        _advance_in_place(x, heading, u[:, 1])
        np.add(heading, u[:, 2], out=th)
        wrap_in_place(th)

    def jacobians_unchecked(
        self, x: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        rot1, trans = u[..., 0], u[..., 1]
        heading = x[..., 2] + rot1
        c, s = np.cos(heading), np.sin(heading)
        batch = heading.shape
        G = np.zeros((*batch, 3, 3))
        G[..., 0, 0] = G[..., 1, 1] = G[..., 2, 2] = 1.0
        G[..., 0, 2] = -trans * s
        G[..., 1, 2] = trans * c
        V = np.zeros((*batch, 3, 3))
        V[..., 0, 0] = -trans * s  # d x' / d rot1
        V[..., 1, 0] = trans * c
        V[..., 0, 1] = c  # d x' / d trans
        V[..., 1, 1] = s
        V[..., 2, 0] = 1.0
        V[..., 2, 2] = 1.0
        return G, V


def odometry_control(
    odom_prev: ArrayLike, odom_curr: ArrayLike, *, min_translation: float = 1e-9
) -> FloatArray:
    """``(rot1, trans, rot2)`` ``(..., 3)`` taking odometry pose ``odom_prev`` to ``odom_curr``.

    ``trans = |p_curr - p_prev|``, ``rot1 = atan2(dy, dx) - theta_prev`` and
    ``rot2 = theta_curr - theta_prev - rot1`` (angles wrapped). When ``trans`` is below
    ``min_translation`` (m) the direction of travel is undefined: then ``rot1 = 0`` and
    ``rot2`` is the whole rotation. Both arguments are ``(..., 3)`` and broadcast.
    Applying :class:`OdometryModel` to the result moves ``odom_prev`` onto ``odom_curr``
    (exactly up to rounding when ``trans >= min_translation``).
    """
    a = as_array(odom_prev, "odom_prev", (..., 3))
    b = as_array(odom_curr, "odom_curr", (..., 3))
    min_t = as_positive(min_translation, "min_translation", allow_zero=True)
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    trans = np.hypot(dx, dy)
    moved = trans >= min_t
    rot1 = np.where(moved, wrap_angle(np.arctan2(dy, dx) - a[..., 2]), 0.0)
    rot2 = wrap_angle(b[..., 2] - a[..., 2] - rot1)
    return np.stack(np.broadcast_arrays(rot1, trans, rot2), axis=-1)


def signed_odometry_steps(u: ArrayLike) -> FloatArray:
    """Steps ``(..., 3)`` of :func:`odometry_control` with a signed translation: a step
    whose first turn exceeds 90° (the robot backed up, or jittered while turning in place)
    becomes ``(rot1 ∓ π, -trans, turn - rot1')``, ``turn = wrap(rot1 + rot2)``: the same
    motion under :class:`OdometryModel`, both rotations small. Scaling the rotations of a
    step (a wheel-base error) is only right in this form: in the unsigned one a backward
    step's ``rot1 ≈ π`` would scale the heading by ``(s - 1) 2π`` instead of ``s · turn``."""
    ua = as_array(u, "odometry steps", (..., 3))
    rot1, trans = ua[..., 0], ua[..., 1]
    turn = wrap_angle(rot1 + ua[..., 2])
    back = np.abs(rot1) > 0.5 * np.pi
    r1 = np.where(back, rot1 - np.pi * np.sign(rot1), rot1)
    return np.stack([r1, np.where(back, -trans, trans), turn - r1], axis=-1)


def integrate_odometry(start: ArrayLike, u: ArrayLike) -> FloatArray:
    """Odometry poses ``(N + 1, 3)``: ``start (3,)`` followed by the poses reached by applying
    the increments ``u (N, 3) = (rot1, trans, rot2)`` one after the other with
    :class:`OdometryModel` (``x_k = x_{k-1} + trans cos(theta_{k-1} + rot1)``,
    ``theta_k = theta_{k-1} + rot1 + rot2``), written as cumulative sums so that a whole log
    is integrated at once. The inverse of :func:`odometry_control` along a path."""
    x0 = as_array(start, "start", (3,))
    steps = as_array(u, "u", (None, 3))
    rot1, trans, rot2 = steps[:, 0], steps[:, 1], steps[:, 2]
    theta = x0[2] + np.concatenate([[0.0], np.cumsum(rot1 + rot2)])  # unwrapped
    heading = theta[:-1] + rot1
    out = np.empty((steps.shape[0] + 1, 3))
    out[:, 0] = x0[0] + np.concatenate([[0.0], np.cumsum(trans * np.cos(heading))])
    out[:, 1] = x0[1] + np.concatenate([[0.0], np.cumsum(trans * np.sin(heading))])
    out[:, 2] = wrap_angle(theta)
    return out


def odometry_noise_cov(u: ArrayLike, alphas: ArrayLike) -> FloatArray:
    """Motion-dependent covariance ``(..., 3, 3)`` of ``(rot1, trans, rot2)``.

    The diagonal model of *Probabilistic Robotics* (table 5.6) with ``alphas =
    (a1, a2, a3, a4) >= 0``: ``var(rot1) = a1 rot1² + a2 trans²``,
    ``var(trans) = a3 trans² + a4 (rot1² + rot2²)``, ``var(rot2) = a1 rot2² + a2 trans²``.
    Units: ``a1`` and ``a3`` are dimensionless, ``a2`` is rad²/m² and ``a4`` m²/rad².
    Pass the result as ``control_cov`` (it broadcasts against the batch of ``u``).
    """
    ua = as_array(u, "control u", (..., 3))
    al = as_array(alphas, "alphas", (4,))
    if np.any(al < 0):
        raise InputError(f"alphas: expected four values >= 0, got {al.tolist()}")
    r1, t, r2 = ua[..., 0] ** 2, ua[..., 1] ** 2, ua[..., 2] ** 2
    cov = np.zeros((*ua.shape[:-1], 3, 3))
    cov[..., 0, 0] = al[0] * r1 + al[1] * t
    cov[..., 1, 1] = al[2] * t + al[3] * (r1 + r2)
    cov[..., 2, 2] = al[0] * r2 + al[1] * t
    return cov


# --------------------------------------------------------------------------------------------
# Gaussian propagation (the dead-reckoning / EKF prediction step)
# --------------------------------------------------------------------------------------------


def propagate_gaussian(
    model: MotionModel,
    mean: ArrayLike,
    cov: ArrayLike,
    u: ArrayLike,
    dt: float,
    control_cov: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """One linearised prediction of a Gaussian pose belief through ``model``.

    ``mean' = g(mean, u, dt)`` and ``cov' = G cov Gᵀ + V Q Vᵀ`` with ``(G, V)`` evaluated at
    ``(mean, u)`` and ``Q = control_cov`` ``(k, k)``; the result is symmetrised
    ``(P + Pᵀ)/2`` so round-off never makes it asymmetric. ``mean (..., 3)``,
    ``cov (..., 3, 3)`` (PSD; zero for a known start) and ``control_cov`` may carry batch
    axes that broadcast together.
    """
    m = as_array(mean, "mean", (..., 3))
    P = as_covariance(cov, "cov", 3, semidefinite=True)
    Q = as_covariance(control_cov, "control_cov", model.control_dim, semidefinite=True)
    return propagate_gaussian_unchecked(model, m, P, u, dt, Q)


def propagate_gaussian_unchecked(
    model: MotionModel,
    mean: FloatArray,
    cov: FloatArray,
    u: ArrayLike,
    dt: float,
    control_cov: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """:func:`propagate_gaussian` without re-validating ``mean``, ``cov`` and
    ``control_cov``: for estimators that validated their noise once and feed back their own
    (PSD by construction) covariances every step. The eigenvalue check of a covariance costs
    more than the propagation itself."""
    new_mean = model.apply(mean, u, dt)
    G, V = model.jacobians(mean, u, dt)
    Gt, Vt = np.swapaxes(G, -1, -2), np.swapaxes(V, -1, -2)
    new_cov = G @ cov @ Gt + V @ control_cov @ Vt
    new_cov = 0.5 * (new_cov + np.swapaxes(new_cov, -1, -2))
    return new_mean, new_cov
