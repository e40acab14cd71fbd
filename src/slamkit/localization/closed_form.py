"""Closed-form steps of the pose-only EKF and UKF for the common models, on plain floats.

EKF and UKF localization carry a ``3``-vector and a ``3 × 3`` covariance and read one
range-bearing reading at a time. At that size NumPy's cost is its per-call overhead (about a
microsecond per small product, against tens of nanoseconds of arithmetic), so the general
steps of :mod:`slamkit.localization.ekf` and :mod:`slamkit.localization.ukf` — matrix
products, batched model kernels, circular means over arrays — spend most of their time
outside the arithmetic (``docs/estimators/localization.md`` has the profile). The steps here
are the same equations written out entry by entry on Python floats:

* :class:`EkfClosedForm`: the EKF prediction ``P ← G P Gᵀ + V Q Vᵀ`` for any slamkit motion
  model (``UnicycleEuler`` inlined, the others through their one-pose kernel
  ``step_single``) and the update with a :class:`~slamkit.models.RangeBearing` reading, in
  Joseph form ``P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ`` (PSD by construction: see
  :mod:`slamkit.estimation.gaussian`);
* :class:`UkfClosedForm`: the augmented unscented prediction of
  :class:`~slamkit.models.UnicycleEuler` (11 sigma points of ``[x, ε]``) and the unscented
  update with a range-bearing reading (7 sigma points), with the circular means taken about
  the central point and every angular residual wrapped, as in :mod:`slamkit.localization.ukf`.

Which steps a filter runs is decided once, when the estimator is built, from the types of
its models (``choose_ekf_steps`` and ``choose_ukf_steps`` in the filter modules); both kinds
satisfy :class:`FilterSteps`. The results equal the general steps' to rounding (the tests
compare whole runs to 1e-12). The general steps stay the reference and take over, for one
step, where the closed form would need a different algorithm: a covariance that is only
semi-definite (a known start), whose square root comes from an eigendecomposition.

The covariances are read from their upper triangles (the filters keep them exactly
symmetric) and checked by the one definiteness test,
:func:`~slamkit.estimation.gaussian.check_covariance`, whenever Sylvester's criterion on the
floats does not already prove them positive definite.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from slamkit._validation import FloatArray
from slamkit.errors import ConvergenceError, GeometryError
from slamkit.estimation.gaussian import check_covariance
from slamkit.geometry.angles import wrap_angle_float
from slamkit.models import MIN_RANGE, RangeBearing, UnicycleEuler
from slamkit.models.motion import MotionModelBase

__all__ = ["EkfClosedForm", "FilterSteps", "UkfClosedForm", "closed_form_supports"]

_PI = math.pi

Sym3 = tuple[float, float, float, float, float, float]
"""A symmetric ``3 × 3`` matrix by its upper triangle ``(p00, p01, p02, p11, p12, p22)``."""


class FilterSteps(Protocol):
    """The two steps of a pose-only Gaussian filter on validated arrays (``mean (3,)``,
    ``cov (3, 3)``); the results are new arrays, the arguments are not modified."""

    def predict(
        self, mean: FloatArray, cov: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        """``(mean, cov)`` after the control ``u`` over ``dt`` seconds."""
        ...

    def update(
        self, mean: FloatArray, cov: FloatArray, z: FloatArray, landmark: FloatArray
    ) -> tuple[FloatArray, FloatArray, float]:
        """``(mean, cov, nis)`` after the reading ``z`` of the landmark at ``landmark``."""
        ...


def closed_form_supports(motion: object, measurement: object) -> tuple[bool, bool, bool]:
    """Whether the closed forms cover these models: ``(the EKF's steps, the UKF's update,
    the UKF's prediction)``. The measurement must be a :class:`~slamkit.models.RangeBearing`;
    the EKF takes any slamkit motion model, the UKF's prediction ``UnicycleEuler``. Exact
    types, not subclasses: a subclass may change the model's equations.
    """
    rb = type(measurement) is RangeBearing
    return rb and isinstance(motion, MotionModelBase), rb, rb and type(motion) is UnicycleEuler


# --------------------------------------------------------------------------------------------
# small helpers on floats
# --------------------------------------------------------------------------------------------


def _sym(cov: FloatArray) -> Sym3:
    (a, b, c), (_, d, e), (_, _, f) = cov.tolist()
    return a, b, c, d, e, f


def _array(p: Sym3) -> FloatArray:
    a, b, c, d, e, f = p
    return np.array([[a, b, c], [b, d, e], [c, e, f]])


def _checked(p: Sym3, where: str) -> FloatArray:
    """``p`` as an array, after :func:`check_covariance` unless Sylvester's criterion (leading
    minors > 0, false for NaN) proves it positive definite on the floats already."""
    a, b, c, d, e, f = p
    out = _array(p)
    det = a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c)
    if not (a > 0.0 and a * d - b * b > 0.0 and det > 0.0):
        check_covariance(out, where)  # singular PSD passes; lost definiteness raises
    return out


def _row_times_sym(
    a0: float, a1: float, a2: float,
    p00: float, p01: float, p02: float, p11: float, p12: float, p22: float,
) -> tuple[float, float, float]:  # fmt: skip
    """The row ``(a0, a1, a2)`` times the symmetric ``P``."""
    return (
        a0 * p00 + a1 * p01 + a2 * p02,
        a0 * p01 + a1 * p11 + a2 * p12,
        a0 * p02 + a1 * p12 + a2 * p22,
    )


def _cholesky(p: Sym3) -> tuple[float, float, float, float, float, float] | None:
    """The lower Cholesky factor ``(l00, l10, l20, l11, l21, l22)`` of a positive definite
    ``p``; ``None`` when a pivot is not > 0 (semi-definite or worse: the caller's general
    step decides)."""
    a, b, c, d, e, f = p
    if not a > 0.0:
        return None
    l00 = math.sqrt(a)
    l10, l20 = b / l00, c / l00
    t = d - l10 * l10
    if not t > 0.0:
        return None
    l11 = math.sqrt(t)
    l21 = (e - l20 * l10) / l11
    t = f - l20 * l20 - l21 * l21
    if not t > 0.0:
        return None
    return l00, l10, l20, l11, l21, math.sqrt(t)


def _wrap(a: float) -> float:
    return a if -_PI <= a < _PI else wrap_angle_float(a)


def _range_bearing(x: float, y: float, th: float, lx: float, ly: float) -> tuple[float, ...]:
    """``(dx, dy, r, bearing)`` of the landmark ``(lx, ly)`` from the pose; GeometryError
    (the message of the models' kernels) when it sits on the sensor."""
    dx, dy = lx - x, ly - y
    r = math.hypot(dx, dy)
    if r < MIN_RANGE:
        raise GeometryError(
            f"a landmark closer than {MIN_RANGE:g} m to the sensor: the bearing and the "
            "Jacobians are undefined there"
        )
    return dx, dy, r, _wrap(math.atan2(dy, dx) - th)


def _inverse_2x2(s00: float, s01: float, s10: float, s11: float, where: str) -> tuple[float, ...]:
    """``S⁻¹`` of a 2x2 innovation covariance by its adjugate, after Sylvester's test (as
    :func:`slamkit.estimation.gaussian.small_spd_inverse`, with its message)."""
    det = s00 * s11 - s01 * s10
    if not (s00 > 0.0 and det > 0.0):
        raise ConvergenceError(f"{where}: the innovation covariance S is not positive definite")
    return s11 / det, -s01 / det, -s10 / det, s00 / det


# --------------------------------------------------------------------------------------------
# EKF
# --------------------------------------------------------------------------------------------


class EkfClosedForm:
    """The EKF's steps for a slamkit motion model and a range-bearing sensor (module
    docstring): the equations of :func:`~slamkit.localization.ekf.ekf_predict_unchecked` and
    :func:`~slamkit.localization.ekf.ekf_update` on floats. ``Q (k, k)`` is the control noise,
    ``R (2, 2)`` the reading noise."""

    def __init__(self, motion: MotionModelBase, Q: FloatArray, R: FloatArray) -> None:
        self._motion = motion
        self._euler = type(motion) is UnicycleEuler
        self._Q = Q.tolist()
        (r00, r01), (r10, r11) = R.tolist()
        self._R = (r00, r01, r10, r11)

    def predict(
        self, mean: FloatArray, cov: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        x, y, th = mean.tolist()
        p00, p01, p02, p11, p12, p22 = _sym(cov)
        if self._euler:
            # g = (x + v cos θ dt, y + v sin θ dt, θ + ω dt); G = I + a e₀e₂ᵀ + b e₁e₂ᵀ with
            # a = −v sin θ dt, b = v cos θ dt; V = [[cos θ dt, 0], [sin θ dt, 0], [0, dt]].
            v, w = u.tolist()
            c, s = math.cos(th), math.sin(th)
            new_mean = [x + v * c * dt, y + v * s * dt, wrap_angle_float(th + w * dt)]
            a, b = -v * s * dt, v * c * dt
            # G P Gᵀ written out for that G
            g00 = p00 + a * p02 + a * (p02 + a * p22)
            g01 = p01 + a * p12 + b * (p02 + a * p22)
            g02 = p02 + a * p22
            g11 = p11 + b * p12 + b * (p12 + b * p22)
            g12 = p12 + b * p22
            g22 = p22
            # V Q Vᵀ with V's columns (c dt, s dt, 0) and (0, 0, dt)
            (q00, q01), (_, q11) = self._Q  # symmetric: the lower entry is not read
            cd, sd = c * dt, s * dt
            vq0 = q01 * dt  # (V Q V^T)[i, 2] = V[i, 0] q01 dt for i = 0, 1
            n00 = g00 + cd * q00 * cd
            n01 = g01 + cd * q00 * sd
            n02 = g02 + cd * vq0
            n11 = g11 + sd * q00 * sd
            n12 = g12 + sd * vq0
            n22 = g22 + dt * q11 * dt
            out = (n00, n01, n02, n11, n12, n22)
        else:
            moved, G_arr, V_arr = self._motion.step_single(mean, u, dt)
            new_mean = moved.tolist()
            G, V = G_arr.tolist(), V_arr.tolist()
            P = ((p00, p01, p02), (p01, p11, p12), (p02, p12, p22))
            GP = [[G[i][0] * P[0][j] + G[i][1] * P[1][j] + G[i][2] * P[2][j] for j in range(3)]
                  for i in range(3)]  # fmt: skip
            Q = self._Q
            k = len(Q)
            VQ = [[sum(V[i][m] * Q[m][j] for m in range(k)) for j in range(k)] for i in range(3)]
            upper = [
                GP[i][0] * G[j][0] + GP[i][1] * G[j][1] + GP[i][2] * G[j][2]
                + sum(VQ[i][m] * V[j][m] for m in range(k))
                for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
            ]  # fmt: skip
            out = (upper[0], upper[1], upper[2], upper[3], upper[4], upper[5])
        return np.array(new_mean), _checked(out, "ekf_predict")

    def update(
        self, mean: FloatArray, cov: FloatArray, z: FloatArray, landmark: FloatArray
    ) -> tuple[FloatArray, FloatArray, float]:
        x, y, th = mean.tolist()
        p00, p01, p02, p11, p12, p22 = _sym(cov)
        lx, ly = landmark.tolist()
        z0, z1 = z.tolist()
        dx, dy, r, bearing = _range_bearing(x, y, th, lx, ly)
        q = r * r
        # H = [[h00, h01, 0], [h10, h11, −1]]
        h00, h01, h10, h11 = -dx / r, -dy / r, dy / q, -dx / q
        nu0, nu1 = z0 - r, _wrap(z1 - bearing)  # ν = z ⊖ h(μ): the bearing wrapped
        # P Hᵀ (3 × 2)
        a0, a1, a2 = p00 * h00 + p01 * h01, p01 * h00 + p11 * h01, p02 * h00 + p12 * h01
        b0 = p00 * h10 + p01 * h11 - p02
        b1 = p01 * h10 + p11 * h11 - p12
        b2 = p02 * h10 + p12 * h11 - p22
        # S = H P Hᵀ + R
        r00, r01, r10, r11 = self._R
        s00 = h00 * a0 + h01 * a1 + r00
        s01 = h00 * b0 + h01 * b1 + r01
        s10 = h10 * a0 + h11 * a1 - a2 + r10
        s11 = h10 * b0 + h11 * b1 - b2 + r11
        i00, i01, i10, i11 = _inverse_2x2(s00, s01, s10, s11, "ekf_update")
        # K = P Hᵀ S⁻¹ (rows k_i = (k_i0, k_i1))
        k00, k01 = a0 * i00 + b0 * i10, a0 * i01 + b0 * i11
        k10, k11 = a1 * i00 + b1 * i10, a1 * i01 + b1 * i11
        k20, k21 = a2 * i00 + b2 * i10, a2 * i01 + b2 * i11
        nis = nu0 * (i00 * nu0 + i01 * nu1) + nu1 * (i10 * nu0 + i11 * nu1)  # νᵀ S⁻¹ ν
        new_mean = [x + k00 * nu0 + k01 * nu1, y + k10 * nu0 + k11 * nu1]
        new_mean.append(_wrap(th + k20 * nu0 + k21 * nu1))
        # Joseph form P ← A P Aᵀ + K R Kᵀ with A = I − K H (PSD by construction).
        a00, a01, a02 = 1.0 - k00 * h00 - k01 * h10, -k00 * h01 - k01 * h11, k01
        a10, a11, a12 = -k10 * h00 - k11 * h10, 1.0 - k10 * h01 - k11 * h11, k11
        a20, a21, a22 = -k20 * h00 - k21 * h10, -k20 * h01 - k21 * h11, 1.0 + k21
        # rows of A P
        c00, c01, c02 = _row_times_sym(a00, a01, a02, p00, p01, p02, p11, p12, p22)
        c10, c11, c12 = _row_times_sym(a10, a11, a12, p00, p01, p02, p11, p12, p22)
        c20, c21, c22 = _row_times_sym(a20, a21, a22, p00, p01, p02, p11, p12, p22)
        # rows of K R
        e0, f0 = k00 * r00 + k01 * r10, k00 * r01 + k01 * r11
        e1, f1 = k10 * r00 + k11 * r10, k10 * r01 + k11 * r11
        e2, f2 = k20 * r00 + k21 * r10, k20 * r01 + k21 * r11
        out = (
            c00 * a00 + c01 * a01 + c02 * a02 + e0 * k00 + f0 * k01,
            c00 * a10 + c01 * a11 + c02 * a12 + e0 * k10 + f0 * k11,
            c00 * a20 + c01 * a21 + c02 * a22 + e0 * k20 + f0 * k21,
            c10 * a10 + c11 * a11 + c12 * a12 + e1 * k10 + f1 * k11,
            c10 * a20 + c11 * a21 + c12 * a22 + e1 * k20 + f1 * k21,
            c20 * a20 + c21 * a21 + c22 * a22 + e2 * k20 + f2 * k21,
        )
        return np.array(new_mean), _checked(out, "ekf_update"), nis


# --------------------------------------------------------------------------------------------
# UKF
# --------------------------------------------------------------------------------------------


def _circular_mean_about(angles: list[float], w0: float, wi: float) -> float:
    """The weighted circular mean of ``angles`` (weights ``w0`` for the first, ``wi`` for the
    others) about the first one, wrapped: :func:`slamkit.localization.ukf.circular_mean_about`
    on floats."""
    ref = angles[0]
    s = c = 0.0
    for a in angles[1:]:
        s += math.sin(a - ref)
        c += math.cos(a - ref)
    # the first offset is 0: sin 0 = 0, cos 0 = 1
    m = math.atan2(wi * s, w0 + wi * c)
    return _wrap(ref + _wrap(m))


class UkfClosedForm:
    """The UKF's steps for a range-bearing sensor (and, with ``euler``, the
    :class:`~slamkit.models.UnicycleEuler` motion; the general prediction otherwise): the
    equations of :mod:`slamkit.localization.ukf` on floats (module docstring).

    ``general`` is the UKF's general steps, which take over for one step when a covariance
    has no Cholesky factor (semi-definite: its root then comes from ``eigh``). ``weights3``
    and ``weights5`` are ``(Wm₀, Wc₀, Wᵢ, √c)`` of the sigma points of the update (``n = 3``)
    and of the augmented prediction (``n = 5``); ``sqrt_Q`` a root of the control noise
    (``L Lᵀ = Q``), ``R (2, 2)`` the reading noise.
    """

    def __init__(
        self,
        general: FilterSteps,
        euler: bool,
        weights3: tuple[float, float, float, float],
        weights5: tuple[float, float, float, float],
        sqrt_Q: FloatArray,
        R: FloatArray,
    ) -> None:
        self._general = general
        self._euler = euler
        self._w3, self._w5 = weights3, weights5
        # (the prediction's closed form is the unicycle's: two controls)
        self._sqrt_Q = tuple(sqrt_Q.ravel().tolist()) if euler else (0.0, 0.0, 0.0, 0.0)
        (r00, r01), (_, r11) = R.tolist()  # symmetric: the lower entry is not read
        self._R = (r00, r01, r11)

    def predict(
        self, mean: FloatArray, cov: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        L = _cholesky(_sym(cov)) if self._euler else None
        if L is None:
            return self._general.predict(mean, cov, u, dt)
        l00, l10, l20, l11, l21, l22 = L
        wm0, wc0, wi, s = self._w5
        x, y, th = mean.tolist()
        v, w = u.tolist()
        q00, q01, q10, q11 = self._sqrt_Q
        # The 11 augmented sigma points [x, ε] (see unscented_motion_unchecked): the centre;
        # the state ± √c Lx columns with the nominal control; the nominal state with the
        # control ± √c Lq columns.
        ox = (s * l00, 0.0, 0.0)
        oy = (s * l10, s * l11, 0.0)
        ot = (s * l20, s * l21, s * l22)
        states = [(x, y, th)]
        states += [(x + ox[j], y + oy[j], th + ot[j]) for j in range(3)]
        states += [(x - ox[j], y - oy[j], th - ot[j]) for j in range(3)]
        ev = (s * q00, s * q01)
        ew = (s * q10, s * q11)
        c, sn = math.cos(th), math.sin(th)
        moved = []  # g(x, u + ε, dt) = (x + v cos θ dt, y + v sin θ dt, θ + ω dt)
        for px, py, pt in states:
            ct, st = (c, sn) if pt == th else (math.cos(pt), math.sin(pt))
            moved.append((px + v * ct * dt, py + v * st * dt, _wrap(pt + w * dt)))
        for sign in (1.0, -1.0):
            for j in range(2):
                vj, wj = v + sign * ev[j], w + sign * ew[j]
                moved.append((x + vj * c * dt, y + vj * sn * dt, _wrap(th + wj * dt)))
        # order of the general step's rows: 0, +Lx (1-3), +Lq (4-5), −Lx (6-8), −Lq (9-10)
        Y = moved[:4] + moved[7:9] + moved[4:7] + moved[9:]
        mx = wm0 * Y[0][0] + wi * math.fsum(p[0] for p in Y[1:])
        my = wm0 * Y[0][1] + wi * math.fsum(p[1] for p in Y[1:])
        headings = [p[2] for p in Y]
        if not math.isfinite(mx + my + math.fsum(headings)):
            raise ConvergenceError(
                "ukf_predict: the motion moved a sigma point to a non-finite pose"
            )
        mt = _circular_mean_about(headings, wm0, wi)
        # covariance Σ Wcᵢ Dᵢ Dᵢᵀ of the residuals, the heading's wrapped
        d0x, d0y, d0t = Y[0][0] - mx, Y[0][1] - my, _wrap(Y[0][2] - mt)
        c00 = c01 = c02 = c11 = c12 = c22 = 0.0
        for px, py, pt in Y[1:]:
            dx, dy, dth = px - mx, py - my, _wrap(pt - mt)
            c00 += dx * dx
            c01 += dx * dy
            c02 += dx * dth
            c11 += dy * dy
            c12 += dy * dth
            c22 += dth * dth
        out = (
            wc0 * d0x * d0x + wi * c00,
            wc0 * d0x * d0y + wi * c01,
            wc0 * d0x * d0t + wi * c02,
            wc0 * d0y * d0y + wi * c11,
            wc0 * d0y * d0t + wi * c12,
            wc0 * d0t * d0t + wi * c22,
        )
        return np.array([mx, my, mt]), _checked(out, "ukf_predict")

    def update(
        self, mean: FloatArray, cov: FloatArray, z: FloatArray, landmark: FloatArray
    ) -> tuple[FloatArray, FloatArray, float]:
        p00, p01, p02, p11, p12, p22 = p = _sym(cov)
        L = _cholesky(p)
        if L is None:
            return self._general.update(mean, cov, z, landmark)
        l00, l10, l20, l11, l21, l22 = L
        wm0, wc0, wi, s = self._w3
        x, y, th = mean.tolist()
        lx, ly = landmark.tolist()
        z0, z1 = z.tolist()
        # sigma offsets χᵢ − μ: 0, then + and − the columns of √c L (lower triangular)
        a0, a1, a2, b1, b2, c2 = s * l00, s * l10, s * l20, s * l11, s * l21, s * l22
        offsets = (
            (0.0, 0.0, 0.0), (a0, a1, a2), (0.0, b1, b2), (0.0, 0.0, c2),
            (-a0, -a1, -a2), (-0.0, -b1, -b2), (-0.0, -0.0, -c2),
        )  # fmt: skip
        ranges, bearings = [], []
        for ox, oy, ot in offsets:  # h(χᵢ)
            dx, dy = lx - (x + ox), ly - (y + oy)
            ranges.append(math.hypot(dx, dy))
            bearings.append(_wrap(math.atan2(dy, dx) - (th + ot)))
        if min(ranges) < MIN_RANGE:
            near = sum(r < MIN_RANGE for r in ranges)
            raise GeometryError(
                f"{near} landmark(s) closer than {MIN_RANGE:g} m to the sensor: the bearing "
                "and the Jacobians are undefined there"
            )
        zr = wm0 * ranges[0] + wi * math.fsum(ranges[1:])
        zb = _circular_mean_about(bearings, wm0, wi)
        dr = [r - zr for r in ranges]
        db = [_wrap(b - zb) for b in bearings]  # residuals wrapped before the products
        # S = Σ Wcᵢ ΔZᵢ ΔZᵢᵀ + R
        srr = srb = sbb = 0.0
        for u, v in zip(dr[1:], db[1:], strict=True):
            srr += u * u
            srb += u * v
            sbb += v * v
        r00, r01, r11 = self._R
        s00 = wc0 * dr[0] * dr[0] + wi * srr + r00
        s01 = wc0 * dr[0] * db[0] + wi * srb + r01
        s11 = wc0 * db[0] * db[0] + wi * sbb + r11
        # P_xz = Σ Wcᵢ (χᵢ − μ) ΔZᵢᵀ: the offsets ±column j pair up, each with weight Wᵢ
        gr0, gr1, gr2 = dr[1] - dr[4], dr[2] - dr[5], dr[3] - dr[6]
        gb0, gb1, gb2 = db[1] - db[4], db[2] - db[5], db[3] - db[6]
        x0, x1 = wi * (a0 * gr0), wi * (a0 * gb0)
        y0, y1 = wi * (a1 * gr0 + b1 * gr1), wi * (a1 * gb0 + b1 * gb1)
        t0, t1 = wi * (a2 * gr0 + b2 * gr1 + c2 * gr2), wi * (a2 * gb0 + b2 * gb1 + c2 * gb2)
        nu0, nu1 = z0 - zr, _wrap(z1 - zb)
        i00, i01, _, i11 = _inverse_2x2(s00, s01, s01, s11, "ukf_update")
        # K = P_xz S⁻¹ (S and S⁻¹ symmetric)
        k00, k01 = x0 * i00 + x1 * i01, x0 * i01 + x1 * i11
        k10, k11 = y0 * i00 + y1 * i01, y0 * i01 + y1 * i11
        k20, k21 = t0 * i00 + t1 * i01, t0 * i01 + t1 * i11
        nis = nu0 * (i00 * nu0 + i01 * nu1) + nu1 * (i01 * nu0 + i11 * nu1)  # νᵀ S⁻¹ ν
        new_mean = np.array(
            [x + k00 * nu0 + k01 * nu1, y + k10 * nu0 + k11 * nu1,
             _wrap(th + k20 * nu0 + k21 * nu1)]
        )  # fmt: skip
        # P ← P − K S Kᵀ
        e0, f0 = k00 * s00 + k01 * s01, k00 * s01 + k01 * s11  # rows of K S
        e1, f1 = k10 * s00 + k11 * s01, k10 * s01 + k11 * s11
        e2, f2 = k20 * s00 + k21 * s01, k20 * s01 + k21 * s11
        out = (
            p00 - (e0 * k00 + f0 * k01),
            p01 - (e0 * k10 + f0 * k11),
            p02 - (e0 * k20 + f0 * k21),
            p11 - (e1 * k10 + f1 * k11),
            p12 - (e1 * k20 + f1 * k21),
            p22 - (e2 * k20 + f2 * k21),
        )
        return new_mean, _checked(out, "ukf_update"), nis
