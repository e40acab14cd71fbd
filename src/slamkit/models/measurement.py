"""Point-landmark measurement models ``z = h(pose, landmark)`` with analytic Jacobians.

Conventions:

* ``pose`` is ``(..., 3)`` = ``(x, y, theta)``, ``landmark`` is ``(..., 2)`` (world metres);
  their batch axes broadcast, so one pose against ``M`` landmarks, or ``P`` particles
  ``(P, 1, 3)`` against ``M`` landmarks ``(M, 2)``, is one call.
* A range-bearing measurement is ordered **(range, bearing)** everywhere:
  ``range = |l - p|`` (m) and ``bearing = wrap(atan2(dy, dx) - theta)`` (rad, in
  ``[-pi, pi)``, counter-clockwise from the robot's heading), with ``(dx, dy) = l - p``.
  :class:`RangeOnly` and :class:`BearingOnly` keep one of the two components.
* A relative-position measurement (:class:`RelativePosition`) is the landmark's ``(x, y)`` in
  the robot frame (m), ``R(theta)ᵀ (l - p)``.
* ``angular`` flags the components that are angles; :meth:`residual` wraps those.
* A landmark closer than ``1e-9`` m to the sensor makes the bearing and every Jacobian
  undefined: such calls raise :class:`slamkit.errors.GeometryError` instead of returning NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import GeometryError, InputError, ShapeError
from slamkit.geometry.angles import wrap_angle, wrap_angle_float
from slamkit.prob.gaussian import gaussian_draws

__all__ = [
    "MIN_RANGE",
    "BearingOnly",
    "InvertibleLandmarkModel",
    "LandmarkModel",
    "LandmarkModelBase",
    "RangeBearing",
    "RangeOnly",
    "RelativePosition",
    "landmark_initial_covariance",
]

MIN_RANGE = 1e-9
"""Ranges (m) below which bearings and Jacobians are undefined (GeometryError)."""


@runtime_checkable
class LandmarkModel(Protocol):
    """What filters and the simulator need from a point-landmark measurement model."""

    @property
    def dim(self) -> int: ...

    @property
    def angular(self) -> tuple[bool, ...]: ...

    def predict(self, pose: ArrayLike, landmark: ArrayLike) -> FloatArray:
        """Expected measurement ``h(pose, landmark)`` ``(..., m)``."""
        ...

    def jacobians(self, pose: ArrayLike, landmark: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(H_pose (..., m, 3), H_landmark (..., m, 2))`` of ``h`` at the arguments."""
        ...

    def residual(self, z: ArrayLike, z_hat: ArrayLike) -> FloatArray:
        """``z - z_hat`` ``(..., m)`` with angular components wrapped to ``[-pi, pi)``."""
        ...

    def sample(
        self, pose: ArrayLike, landmark: ArrayLike, cov: ArrayLike, rng: np.random.Generator
    ) -> FloatArray:
        """``h(pose, landmark) + n``, ``n ~ N(0, cov)`` per batch element, angles wrapped."""
        ...


def _prepare(pose: ArrayLike, landmark: ArrayLike) -> tuple[FloatArray, FloatArray]:
    p = as_array(pose, "pose", (..., 3))
    l = as_array(landmark, "landmark", (..., 2))
    try:
        batch = np.broadcast_shapes(p.shape[:-1], l.shape[:-1])
    except ValueError as exc:
        raise ShapeError(
            f"pose {p.shape} and landmark {l.shape}: batch axes do not broadcast"
        ) from exc
    return np.broadcast_to(p, (*batch, 3)), np.broadcast_to(l, (*batch, 2))


def _offsets(
    p: FloatArray, l: FloatArray, *, need_direction: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``dx, dy, r`` from pose to landmark; GeometryError when a direction is needed at r≈0."""
    dx, dy = l[..., 0] - p[..., 0], l[..., 1] - p[..., 1]
    r = np.hypot(dx, dy)
    if need_direction and np.any(r < MIN_RANGE):
        n = int(np.count_nonzero(r < MIN_RANGE))
        raise GeometryError(
            f"{n} landmark(s) closer than {MIN_RANGE:g} m to the sensor: the bearing and the "
            "Jacobians are undefined there"
        )
    return dx, dy, r


def _offsets_single(p: FloatArray, l: FloatArray) -> tuple[float, float, float]:
    """:func:`_offsets` for one pose and one landmark, as plain floats (direction needed)."""
    dx, dy = float(l[0]) - float(p[0]), float(l[1]) - float(p[1])
    r = math.hypot(dx, dy)
    if r < MIN_RANGE:
        raise GeometryError(
            f"a landmark closer than {MIN_RANGE:g} m to the sensor: the bearing and the "
            "Jacobians are undefined there"
        )
    return dx, dy, r


class LandmarkModelBase:
    """The base of every slamkit landmark model: the estimators' fast-path contract.

    A subclass sets ``dim`` and ``angular`` and implements two kernels on validated,
    broadcast float64 arrays — ``predict_unchecked`` (``h``) and ``jacobians_unchecked``
    (``H_pose, H_landmark``) — and inherits the validating :class:`LandmarkModel` methods
    (``predict``, ``jacobians``, ``residual``, ``sample``) and the fused single-reading
    kernel :meth:`predict_with_pose_jacobian` that EKF updates call. Estimators evaluate a
    model that only satisfies the :class:`LandmarkModel` protocol through its public methods
    (:mod:`slamkit.estimation.gaussian`), with the same numbers.
    """

    dim: ClassVar[int]
    angular: ClassVar[tuple[bool, ...]]

    def predict_unchecked(self, p: FloatArray, l: FloatArray) -> FloatArray:
        """``h(p, l)`` ``(..., m)`` for a validated pose ``(..., 3)`` and landmark
        ``(..., 2)`` of the same batch shape (or broadcasting); angles wrapped."""
        raise NotImplementedError(f"{type(self).__name__} does not implement predict_unchecked")

    def jacobians_unchecked(self, p: FloatArray, l: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(H_pose (..., m, 3), H_landmark (..., m, 2))`` for validated arguments."""
        raise NotImplementedError(f"{type(self).__name__} does not implement jacobians_unchecked")

    def predict_with_pose_jacobian(
        self, p: FloatArray, l: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """``(h (m,), H_pose (m, 3))`` for ONE validated pose ``(3,)`` and landmark ``(2,)``:
        what an EKF update needs. Subclasses override it with plain-float arithmetic (NumPy's
        per-call overhead on 0-d arrays is ~20x the arithmetic); a test checks every override
        against the batched kernels ``predict_unchecked`` and ``jacobians_unchecked``."""
        return self.predict_unchecked(p, l), self.jacobians_unchecked(p, l)[0]

    def predict(self, pose: ArrayLike, landmark: ArrayLike) -> FloatArray:
        """Expected measurement ``(..., m)`` of ``landmark (..., 2)`` from ``pose (..., 3)``."""
        p, l = _prepare(pose, landmark)
        return self.predict_unchecked(p, l)

    def jacobians(self, pose: ArrayLike, landmark: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(H_pose (..., m, 3), H_landmark (..., m, 2))``; GeometryError at zero range."""
        p, l = _prepare(pose, landmark)
        return self.jacobians_unchecked(p, l)

    def residual(self, z: ArrayLike, z_hat: ArrayLike) -> FloatArray:
        """``z - z_hat`` ``(..., m)``, angular components wrapped to ``[-pi, pi)``."""
        za = as_array(z, "z", (..., self.dim))
        zh = as_array(z_hat, "z_hat", (..., self.dim))
        try:
            d = za - zh
        except ValueError as exc:
            raise ShapeError(f"z {za.shape} and z_hat {zh.shape}: do not broadcast") from exc
        mask = np.array(self.angular)
        return np.where(mask, wrap_angle(d), d)

    def sample(
        self, pose: ArrayLike, landmark: ArrayLike, cov: ArrayLike, rng: np.random.Generator
    ) -> FloatArray:
        """``h(pose, landmark) + n`` with ``n ~ N(0, cov)`` drawn per batch element.

        ``cov`` is ``(m, m)`` (or a broadcasting batch), symmetric positive semi-definite.
        Angular components are wrapped; ranges are **not** clipped at zero (the model is
        Gaussian; a simulator may clip).
        """
        p, l = _prepare(pose, landmark)
        q = as_covariance(cov, "measurement cov", self.dim, semidefinite=True)
        z = self.predict_unchecked(p, l)
        z = z + gaussian_draws(q, z.shape[:-1], rng)
        return np.where(np.array(self.angular), wrap_angle(z), z)


@dataclass(frozen=True)
class RangeBearing(LandmarkModelBase):
    """``z = (range, bearing)`` of a point landmark, plus its inverse for initialisation.

    With ``(dx, dy) = l - p``, ``q = dx² + dy²`` and ``r = sqrt(q)``:
    ``H_pose = [[-dx/r, -dy/r, 0], [dy/q, -dx/q, -1]]`` and
    ``H_landmark = [[dx/r, dy/r], [-dy/q, dx/q]]``.
    """

    dim: ClassVar[int] = 2
    angular: ClassVar[tuple[bool, ...]] = (False, True)

    def predict_unchecked(self, p: FloatArray, l: FloatArray) -> FloatArray:
        dx, dy, r = _offsets(p, l, need_direction=True)
        return np.stack([r, wrap_angle(np.arctan2(dy, dx) - p[..., 2])], axis=-1)

    def jacobians_unchecked(self, p: FloatArray, l: FloatArray) -> tuple[FloatArray, FloatArray]:
        dx, dy, r = _offsets(p, l, need_direction=True)
        q = r * r
        batch = r.shape
        Hl = np.empty((*batch, 2, 2))
        Hl[..., 0, 0] = dx / r  # d range / d l
        Hl[..., 0, 1] = dy / r
        Hl[..., 1, 0] = -dy / q  # d atan2(dy, dx) / d l
        Hl[..., 1, 1] = dx / q
        Hp = np.zeros((*batch, 2, 3))
        Hp[..., :, :2] = -Hl  # l - p: the position enters with the opposite sign
        Hp[..., 1, 2] = -1.0
        return Hp, Hl

    def predict_with_pose_jacobian(
        self, p: FloatArray, l: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        dx, dy, r = _offsets_single(p, l)
        q = r * r
        bearing = wrap_angle_float(math.atan2(dy, dx) - float(p[2]))
        H = np.array([[-dx / r, -dy / r, 0.0], [dy / q, -dx / q, -1.0]])
        return np.array([r, bearing]), H

    def inverse(self, pose: ArrayLike, z: ArrayLike) -> FloatArray:
        """The landmark ``(..., 2)`` seen at ``z = (range, bearing)`` from ``pose``:
        ``l = p + r (cos(theta + bearing), sin(theta + bearing))``."""
        p, za = self._prepare_inverse(pose, z)
        ang = p[..., 2] + za[..., 1]
        r = za[..., 0]
        return np.stack([p[..., 0] + r * np.cos(ang), p[..., 1] + r * np.sin(ang)], axis=-1)

    def inverse_jacobians(self, pose: ArrayLike, z: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(L_x (..., 2, 3), L_z (..., 2, 2))``: derivatives of :meth:`inverse` with respect
        to the pose and to ``(range, bearing)``."""
        p, za = self._prepare_inverse(pose, z)
        ang = p[..., 2] + za[..., 1]
        r = za[..., 0]
        c, s = np.cos(ang), np.sin(ang)
        batch = r.shape
        Lx = np.zeros((*batch, 2, 3))
        Lx[..., 0, 0] = Lx[..., 1, 1] = 1.0
        Lx[..., 0, 2] = -r * s
        Lx[..., 1, 2] = r * c
        Lz = np.empty((*batch, 2, 2))
        Lz[..., 0, 0] = c
        Lz[..., 1, 0] = s
        Lz[..., 0, 1] = -r * s
        Lz[..., 1, 1] = r * c
        return Lx, Lz

    @staticmethod
    def _prepare_inverse(pose: ArrayLike, z: ArrayLike) -> tuple[FloatArray, FloatArray]:
        p = as_array(pose, "pose", (..., 3))
        za = as_array(z, "z", (..., 2))
        try:
            batch = np.broadcast_shapes(p.shape[:-1], za.shape[:-1])
        except ValueError as exc:
            raise ShapeError(
                f"pose {p.shape} and z {za.shape}: batch axes do not broadcast"
            ) from exc
        return np.broadcast_to(p, (*batch, 3)), np.broadcast_to(za, (*batch, 2))


@dataclass(frozen=True)
class RangeOnly(LandmarkModelBase):
    """``z = (range,)``: distance to a point landmark (e.g. a radio beacon), metres.

    Predicting is defined at zero range; the Jacobians are not (GeometryError).
    """

    dim: ClassVar[int] = 1
    angular: ClassVar[tuple[bool, ...]] = (False,)

    def predict_unchecked(self, p: FloatArray, l: FloatArray) -> FloatArray:
        _, _, r = _offsets(p, l, need_direction=False)
        return r[..., None]

    def predict_with_pose_jacobian(
        self, p: FloatArray, l: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        dx, dy, r = _offsets_single(p, l)
        return np.array([r]), np.array([[-dx / r, -dy / r, 0.0]])

    def jacobians_unchecked(self, p: FloatArray, l: FloatArray) -> tuple[FloatArray, FloatArray]:
        dx, dy, r = _offsets(p, l, need_direction=True)
        Hl = np.stack([dx / r, dy / r], axis=-1)[..., None, :]
        Hp = np.concatenate([-Hl, np.zeros((*r.shape, 1, 1))], axis=-1)
        return Hp, Hl


@dataclass(frozen=True)
class BearingOnly(LandmarkModelBase):
    """``z = (bearing,)``: direction of a point landmark relative to the heading, radians."""

    dim: ClassVar[int] = 1
    angular: ClassVar[tuple[bool, ...]] = (True,)

    def predict_unchecked(self, p: FloatArray, l: FloatArray) -> FloatArray:
        dx, dy, _ = _offsets(p, l, need_direction=True)
        return wrap_angle(np.arctan2(dy, dx) - p[..., 2])[..., None]

    def predict_with_pose_jacobian(
        self, p: FloatArray, l: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        dx, dy, r = _offsets_single(p, l)
        q = r * r
        bearing = wrap_angle_float(math.atan2(dy, dx) - float(p[2]))
        return np.array([bearing]), np.array([[dy / q, -dx / q, -1.0]])

    def jacobians_unchecked(self, p: FloatArray, l: FloatArray) -> tuple[FloatArray, FloatArray]:
        dx, dy, r = _offsets(p, l, need_direction=True)
        q = r * r
        Hl = np.stack([-dy / q, dx / q], axis=-1)[..., None, :]
        Hp = np.concatenate([-Hl, np.full((*r.shape, 1, 1), -1.0)], axis=-1)
        return Hp, Hl


def landmark_initial_covariance(
    L_x: ArrayLike, pose_cov: ArrayLike, L_z: ArrayLike, meas_cov: ArrayLike
) -> FloatArray:
    """Covariance ``(..., 2, 2)`` of a landmark initialised by an inverse measurement model.

    ``P_l = L_x P L_xᵀ + L_z Q L_zᵀ`` (first-order propagation of the pose uncertainty ``P``
    ``(..., 3, 3)`` and the measurement noise ``Q`` ``(..., 2, 2)``, assumed independent),
    symmetrised. ``L_x (..., 2, 3)`` and ``L_z (..., 2, 2)`` come from
    :meth:`RangeBearing.inverse_jacobians`.
    """
    Lx = as_array(L_x, "L_x", (..., 2, 3))
    Lz = as_array(L_z, "L_z", (..., 2, 2))
    P = as_covariance(pose_cov, "pose_cov", 3, semidefinite=True)
    Q = as_covariance(meas_cov, "meas_cov", 2, semidefinite=True)
    try:
        out = Lx @ P @ np.swapaxes(Lx, -1, -2) + Lz @ Q @ np.swapaxes(Lz, -1, -2)
    except ValueError as exc:
        raise InputError("landmark_initial_covariance: batch axes do not broadcast") from exc
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def _prepare_pose_and_z(pose: ArrayLike, z: ArrayLike, m: int) -> tuple[FloatArray, FloatArray]:
    p = as_array(pose, "pose", (..., 3))
    za = as_array(z, "z", (..., m))
    try:
        batch = np.broadcast_shapes(p.shape[:-1], za.shape[:-1])
    except ValueError as exc:
        raise ShapeError(f"pose {p.shape} and z {za.shape}: batch axes do not broadcast") from exc
    return np.broadcast_to(p, (*batch, 3)), np.broadcast_to(za, (*batch, m))


@dataclass(frozen=True)
class RelativePosition(LandmarkModelBase):
    """``z = (x, y)`` of a point landmark in the ROBOT frame (metres): ``z = R(θ)ᵀ (l − t)``.

    This is what pose-graph files with landmarks store (iSAM's ``LANDMARK`` lines, GTSAM's
    Pose2–Point2 factors) and what a stereo camera or a laser feature detector reports after
    converting its own readings to Cartesian coordinates. No component is an angle and the
    model is defined everywhere, including at zero range.

    With ``(dx, dy) = l − t``, ``c = cos θ``, ``s = sin θ`` and ``z = (zx, zy)``:
    ``zx = c dx + s dy``, ``zy = −s dx + c dy``, so
    ``H_landmark = R(θ)ᵀ = [[c, s], [−s, c]]`` and
    ``H_pose = [[−c, −s, zy], [s, −c, −zx]]`` (``∂/∂θ`` of ``R(θ)ᵀ d`` is ``(zy, −zx)``).
    The inverse ``l = t + R(θ) z`` is ``pose ⊕ z``; its Jacobians are
    ``L_x = [[1, 0, −s zx − c zy], [0, 1, c zx − s zy]]`` and ``L_z = R(θ)``.
    """

    dim: ClassVar[int] = 2
    angular: ClassVar[tuple[bool, ...]] = (False, False)

    def predict_unchecked(self, p: FloatArray, l: FloatArray) -> FloatArray:
        c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
        dx, dy = l[..., 0] - p[..., 0], l[..., 1] - p[..., 1]
        return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)

    def jacobians_unchecked(self, p: FloatArray, l: FloatArray) -> tuple[FloatArray, FloatArray]:
        c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
        dx, dy = l[..., 0] - p[..., 0], l[..., 1] - p[..., 1]
        zx, zy = c * dx + s * dy, -s * dx + c * dy
        batch = c.shape
        Hl = np.empty((*batch, 2, 2))
        Hl[..., 0, 0] = c  # R(θ)ᵀ
        Hl[..., 0, 1] = s
        Hl[..., 1, 0] = -s
        Hl[..., 1, 1] = c
        Hp = np.empty((*batch, 2, 3))
        Hp[..., :, :2] = -Hl  # l − t: the position enters with the opposite sign
        Hp[..., 0, 2] = zy
        Hp[..., 1, 2] = -zx
        return Hp, Hl

    def inverse(self, pose: ArrayLike, z: ArrayLike) -> FloatArray:
        """The landmark ``(..., 2)`` in the world seen at ``z`` (robot frame) from ``pose``:
        ``l = t + R(θ) z`` (the point ``pose ⊕ z``)."""
        p, za = _prepare_pose_and_z(pose, z, 2)
        c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
        zx, zy = za[..., 0], za[..., 1]
        return np.stack([p[..., 0] + c * zx - s * zy, p[..., 1] + s * zx + c * zy], axis=-1)

    def inverse_jacobians(self, pose: ArrayLike, z: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(L_x (..., 2, 3), L_z (..., 2, 2))``: derivatives of :meth:`inverse` with respect
        to the pose and to ``z``."""
        p, za = _prepare_pose_and_z(pose, z, 2)
        c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
        zx, zy = za[..., 0], za[..., 1]
        batch = c.shape
        Lz = np.empty((*batch, 2, 2))
        Lz[..., 0, 0] = c  # R(θ)
        Lz[..., 0, 1] = -s
        Lz[..., 1, 0] = s
        Lz[..., 1, 1] = c
        Lx = np.zeros((*batch, 2, 3))
        Lx[..., 0, 0] = Lx[..., 1, 1] = 1.0
        Lx[..., 0, 2] = -s * zx - c * zy  # ∂(R(θ) z)/∂θ
        Lx[..., 1, 2] = c * zx - s * zy
        return Lx, Lz


@runtime_checkable
class InvertibleLandmarkModel(Protocol):
    """A landmark model whose single reading determines the landmark: it has the inverse
    ``g(pose, z)`` and its Jacobians (range-bearing and relative-position models do; range-
    only and bearing-only models do not)."""

    @property
    def dim(self) -> int: ...

    @property
    def angular(self) -> tuple[bool, ...]: ...

    def predict(self, pose: ArrayLike, landmark: ArrayLike) -> FloatArray: ...

    def jacobians(self, pose: ArrayLike, landmark: ArrayLike) -> tuple[FloatArray, FloatArray]: ...

    def residual(self, z: ArrayLike, z_hat: ArrayLike) -> FloatArray: ...

    def inverse(self, pose: ArrayLike, z: ArrayLike) -> FloatArray: ...

    def inverse_jacobians(self, pose: ArrayLike, z: ArrayLike) -> tuple[FloatArray, FloatArray]: ...
