"""Robust kernels for iteratively reweighted least squares (IRLS).

A kernel ``ρ`` acts on an edge's squared Mahalanobis error ``s = eᵀ Ω e`` (g2o's and Ceres'
convention): the robust objective is ``Σ ρ(s)`` and, at each linearisation, an edge's whitened
residual and Jacobian are scaled by ``√ρ'(s)`` (the IRLS weight), so Gauss-Newton on the
scaled system is the usual IRLS step. ``ρ(s) = s`` for small ``s`` in every kernel, so an
inlier keeps its quadratic cost and ``ρ'(0) = 1``.

| kernel | ``ρ(s)`` | ``ρ'(s)`` |
|---|---|---|
| Huber (δ) | ``s`` if ``s ≤ δ²`` else ``2δ√s - δ²`` | ``min(1, δ/√s)`` |
| Cauchy (c) | ``c² log(1 + s/c²)`` | ``1 / (1 + s/c²)`` |
| Geman-McClure (c) | ``c² s / (c² + s)`` | ``c⁴ / (c² + s)²`` |
| DCS (φ) | ``s`` if ``s ≤ φ`` else ``3φ - 4φ² / (φ + s)`` | ``min(1, 2φ/(φ + s))²`` |

Dynamic covariance scaling (Agarwal et al., ICRA 2013) scales a residual by
``min(1, 2φ / (φ + s))``; its ``ρ`` above is the integral of that weight, so the reported
cost and the IRLS weights belong to one M-estimator.

**Widths.** ``s`` of an inlier relative-pose edge is χ² with 3 degrees of freedom (mean 3,
95 % below 7.8), so a kernel must keep ``s`` of that size nearly quadratic. The defaults
(:data:`DEFAULT_WIDTHS`: Geman-McClure ``c = 3``, DCS ``φ = 3``, Cauchy ``c = 1``) were chosen
on the vertigo ring and ringCity graphs with false loop closures, started from odometry
(measurements in ``docs/estimators/optim.md``). A redescending kernel that is too
narrow for the *start* does nothing: from odometry, every loop closure (true or false) has
``s`` in the hundreds or more, so Geman-McClure ``c = 1`` or DCS ``φ = 1`` gives them all
weight ≈ 0 and the odometry start is a stationary point of the robust cost (the first step
changes it negligibly, and the solver rightly stops there).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from slamkit.errors import ConfigError
from slamkit.optim.data import FloatArray

__all__ = ["DEFAULT_WIDTHS", "KernelName", "RobustKernel", "robust_rho_and_weight"]

KernelName = Literal["none", "huber", "cauchy", "geman_mcclure", "dcs"]


DEFAULT_WIDTHS: dict[str, float] = {
    "none": 1.0,
    "huber": 3.0,
    "cauchy": 1.0,
    "geman_mcclure": 3.0,
    "dcs": 3.0,
}
"""Default width of each kernel (see the module docstring for how they were chosen)."""


@dataclass(frozen=True)
class RobustKernel:
    """A robust kernel and its width.

    ``width`` is ``δ`` for Huber (in units of the whitened error, so ``δ²`` is a χ² value),
    ``c`` for Cauchy and Geman-McClure and ``φ`` for DCS (a χ² value).
    """

    name: KernelName = "none"
    width: float = 1.0

    def __post_init__(self) -> None:
        if self.name not in ("none", "huber", "cauchy", "geman_mcclure", "dcs"):
            raise ConfigError(f"robust kernel: unknown name {self.name!r}")
        if not (np.isfinite(self.width) and self.width > 0):
            raise ConfigError(f"robust kernel width: expected a number > 0, got {self.width}")


def robust_rho_and_weight(kernel: RobustKernel, s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``ρ(s)`` and the IRLS weight ``ρ'(s)`` of squared errors ``s`` (see the module table)."""
    name, k = kernel.name, kernel.width
    if name == "none":
        return s, np.ones_like(s)
    if name == "huber":
        d2 = k * k
        root = np.sqrt(np.maximum(s, d2))
        inlier = s <= d2
        return np.where(inlier, s, 2.0 * k * root - d2), np.where(inlier, 1.0, k / root)
    if name == "cauchy":
        c2 = k * k
        return c2 * np.log1p(s / c2), 1.0 / (1.0 + s / c2)
    if name == "geman_mcclure":
        c2 = k * k
        den = c2 + s
        return c2 * s / den, (c2 / den) ** 2
    # DCS: scale = min(1, 2φ/(φ+s)); weight = scale².
    phi = k
    inlier = s <= phi
    scale = np.where(inlier, 1.0, 2.0 * phi / (phi + s))
    return np.where(inlier, s, 3.0 * phi - 4.0 * phi * phi / (phi + s)), scale * scale
