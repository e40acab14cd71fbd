"""Filter consistency: NEES / NIS and their χ² acceptance bands.

A filter is *consistent* when its errors are as large as its covariance claims. For an
``n``-dimensional Gaussian error ``e ~ N(0, P)`` the normalised estimation error squared

    ε = eᵀ P⁻¹ e

is χ²-distributed with ``n`` degrees of freedom (mean ``n``). The same statistic on the
innovation ``ν`` and its covariance ``S`` is the NIS. Averaged over ``R`` independent Monte
Carlo runs, ``R · ε̄ ~ χ²(n R)``, which gives the two-sided band of :func:`chi2_bounds`
(Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
§5.4). Too high: the filter is over-confident; too low: it is too cautious.

For SE(2) states build the error with :func:`slamkit.eval.trajectory.pose_errors`, which wraps
the heading difference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import InputError, ShapeError

__all__ = ["ConsistencyReport", "chi2_bounds", "consistency_report", "nees", "nis"]


def _normalised_squared(
    values: ArrayLike, covariances: ArrayLike, vname: str, cname: str
) -> FloatArray:
    e = as_array(values, vname, (..., None))
    n = e.shape[-1]
    P = as_covariance(covariances, cname, n)
    try:
        batch = np.broadcast_shapes(e.shape[:-1], P.shape[:-2])
    except ValueError as exc:
        raise ShapeError(
            f"{cname}: batch shape {P.shape[:-2]} does not broadcast against {vname} batch "
            f"shape {e.shape[:-1]}"
        ) from exc
    # eᵀ P⁻¹ e = ‖L⁻¹ e‖² with P = L Lᵀ: one triangular system per item, no inverse formed.
    # (as_covariance already proved every P positive definite with the same factorisation.)
    L = np.linalg.cholesky(P)
    L_b = np.broadcast_to(L, (*batch, n, n))
    e_b = np.broadcast_to(e, (*batch, n))
    y = np.linalg.solve(L_b, e_b[..., None])[..., 0]
    return np.einsum("...i,...i->...", y, y)


def nees(errors: ArrayLike, covariances: ArrayLike) -> FloatArray:
    """Normalised estimation error squared ``eᵀ P⁻¹ e`` for ``errors (..., n)`` and
    ``covariances (..., n, n)`` (batch axes broadcast, e.g. one ``(n, n)`` for all).

    Computed through the Cholesky factor of ``P``; raises
    :class:`~slamkit.errors.CovarianceError` if a covariance is not symmetric positive
    definite. Returns shape ``(...)``.
    """
    return _normalised_squared(errors, covariances, "errors", "covariances")


def nis(innovations: ArrayLike, covariances: ArrayLike) -> FloatArray:
    """Normalised innovation squared ``νᵀ S⁻¹ ν``: :func:`nees` applied to innovations
    ``(..., m)`` and their covariances ``S (..., m, m)``."""
    return _normalised_squared(innovations, covariances, "innovations", "covariances")


def _check_count(value: int, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise InputError(f"{name}: expected an integer >= 1, got {value!r}")
    return int(value)


def _check_probability(probability: float) -> float:
    p = float(probability)
    if not (0.0 < p < 1.0):
        raise InputError(f"probability: expected a number in (0, 1), got {probability!r}")
    return p


def chi2_bounds(dof: int, n_runs: int = 1, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided ``probability`` band for the AVERAGE of ``n_runs`` independent χ²(``dof``)
    values: ``(χ²_{dof·R}((1−p)/2) / R, χ²_{dof·R}((1+p)/2) / R)`` with ``R = n_runs``.

    Example: ``chi2_bounds(3, 50)`` ≈ ``(2.36, 3.72)``, the 95 % band of the 50-run average
    NEES of a 3-D state.
    """
    k = _check_count(dof, "dof")
    r = _check_count(n_runs, "n_runs")
    p = _check_probability(probability)
    lo = float(stats.chi2.ppf((1.0 - p) / 2.0, k * r)) / r
    hi = float(stats.chi2.ppf((1.0 + p) / 2.0, k * r)) / r
    return lo, hi


@dataclass(frozen=True, eq=False)
class ConsistencyReport:
    """Summary of a NEES or NIS sequence over ``n_runs`` Monte Carlo runs and ``n_steps``
    time steps."""

    dof: int
    n_runs: int
    n_steps: int
    probability: float
    per_step: FloatArray
    """Run-averaged statistic at each step, ``(T,)``."""
    lower: float
    """Lower end of the band for one run-averaged value (:func:`chi2_bounds` with R runs)."""
    upper: float
    fraction_inside: float
    """Fraction of steps whose run-averaged value lies in ``[lower, upper]``; about
    ``probability`` for a consistent filter (if steps were independent)."""
    mean: float
    """Average over all ``R · T`` values; ≈ ``dof`` for a consistent filter."""
    mean_lower: float
    """Band for :attr:`mean`, treating the ``R · T`` values as independent χ²(dof)."""
    mean_upper: float

    @property
    def mean_inside(self) -> bool:
        """Whether the time- and run-averaged value lies in its band."""
        return self.mean_lower <= self.mean <= self.mean_upper

    def as_dict(self) -> dict[str, float | int | bool]:
        """The summary as plain Python values (JSON-ready); ``per_step`` is left out."""
        return {
            "dof": self.dof,
            "n_runs": self.n_runs,
            "n_steps": self.n_steps,
            "probability": self.probability,
            "lower": self.lower,
            "upper": self.upper,
            "fraction_inside": self.fraction_inside,
            "mean": self.mean,
            "mean_lower": self.mean_lower,
            "mean_upper": self.mean_upper,
            "mean_inside": self.mean_inside,
        }


def consistency_report(values: ArrayLike, dof: int, probability: float = 0.95) -> ConsistencyReport:
    """Check NEES/NIS ``values`` of shape ``(T,)`` (one run) or ``(R, T)`` (R runs).

    At each step the values are averaged over runs and compared with
    ``chi2_bounds(dof, R, probability)``. The overall mean is compared with
    ``chi2_bounds(dof, R·T, probability)``; that band assumes independent values, which
    holds across Monte Carlo runs but only approximately along time (filter errors are
    correlated from step to step), so read it as a screening test.
    """
    v = as_array(values, "values")
    if v.ndim == 1:
        v = v[None, :]
    if v.ndim != 2 or v.size == 0:
        raise ShapeError(f"values: expected shape (T,) or (R, T) with T, R >= 1, got {v.shape}")
    if np.any(v < 0):
        raise InputError("values: NEES/NIS values are squared norms and cannot be negative")
    k = _check_count(dof, "dof")
    p = _check_probability(probability)
    r, t = v.shape
    per_step = v.mean(axis=0)
    lo, hi = chi2_bounds(k, r, p)
    mlo, mhi = chi2_bounds(k, r * t, p)
    inside = (per_step >= lo) & (per_step <= hi)
    return ConsistencyReport(
        dof=k,
        n_runs=r,
        n_steps=t,
        probability=p,
        per_step=per_step,
        lower=lo,
        upper=hi,
        fraction_inside=float(np.mean(inside)),
        mean=float(v.mean()),
        mean_lower=mlo,
        mean_upper=mhi,
    )
