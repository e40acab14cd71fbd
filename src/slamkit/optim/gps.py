"""GPS in the factor graph: the absolute-position factor with an antenna lever arm, and the
robust re-weighting of the fixes (dropouts and multipath).

**The factor** (edge kind ``"gps"``). A fix ``z`` (world frame, metres) measures the antenna,
which sits at ``o`` in the robot frame (x forward, y left), so the error of pose
``X_i = (R_i, t_i)`` is::

    e = t_i + R_i o - z                                        (2,)

With the right update of :func:`slamkit.optim.factors.retract_poses`, ``t ← t + R_i δt`` and
``R_i ← R_i (I + δθ S)`` to first order (``S = R(π/2)``), so::

    ∂e/∂δt = R_i        ∂e/∂δθ = R_i S o        ∂e/∂o = R_i

The lever arm ``o`` is a variable of the graph: it is carried as a 2D point in the graph's
landmark block (additive update, as a landmark), under an id of its own (the ``j`` of every
``gps`` edge), so the existing sparse machinery needs no third kind of variable. A known lever
arm is the same factor with that point held by its data (estimate it, or give the fixes
already moved to the reference point with ``o = 0`` and a graph that has no other use of it).

**Weights.** Each edge carries the fix's information ``Σ⁻¹``; the whitened error
``U e`` (``UᵀU = Σ⁻¹``) has a χ² distribution with 2 degrees of freedom for a good fix.

**Time.** The factor acts on one pose at the fix's time stamp. The graph builder
(:mod:`slamkit.slam.landmark_graph`) puts a pose node at every fix's time (odometry is
integrated between nodes), so no interpolation between poses is needed; a graph file's
``gps`` edges are likewise taken to be stamped at their pose.

**Robustness** (:func:`reweight`). Real fixes drop out (no edge) and jump (multipath, a
wrong satellite solution). The optimiser's robust kernel acts on every edge of a graph; here
only the fixes are in doubt, so they are re-weighted on their own, by an outer
iteratively-reweighted loop: solve, compute each fix's ``s = ‖U e‖²``, scale its information
by the kernel's IRLS weight ``ρ'(s)`` (:func:`slamkit.optim.robust.robust_rho_and_weight`) or,
for the χ² gate, by 1 when ``s ≤ gate`` and 0 otherwise, and solve again from the last
solution until the weights stop changing. At its fixed point the normal equations are those
of ``Σ ρ(s)`` over the fixes plus the plain χ² of the other edges. Which kernel fits
Victoria Park was measured: ``docs/estimators/gps.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from slamkit.errors import ConfigError
from slamkit.optim.data import EdgeSet, FloatArray
from slamkit.optim.robust import RobustKernel, robust_rho_and_weight

__all__ = [
    "GpsWeighting",
    "WeightingName",
    "anchored_gps_error",
    "gps_error",
    "gps_weights",
    "reweight",
    "whitened_squares",
]

WeightingName = Literal["none", "huber", "cauchy", "geman_mcclure", "dcs", "gate"]


def gps_error(
    xi: FloatArray, lever: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``e = t_i + R_i o - z`` and its Jacobians ``∂e/∂δ_i`` ``(E, 2, 3)``, ``∂e/∂o``
    ``(E, 2, 2)`` for poses ``xi (E, 3)``, lever arms ``o (E, 2)`` and fixes ``z (E, 2)``
    (derivation in the module docstring). Batch-first views of edge-last arrays, as the
    kernels of :mod:`slamkit.optim.factors`."""
    c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    ox, oy = lever[:, 0], lever[:, 1]
    rox = c * ox - s * oy  # R_i o
    roy = s * ox + c * oy
    n = xi.shape[0]
    e = np.empty((2, n))
    e[0] = xi[:, 0] + rox - z[:, 0]
    e[1] = xi[:, 1] + roy - z[:, 1]
    Ji = np.empty((2, 3, n))
    Ji[0, 0] = c
    Ji[0, 1] = -s
    Ji[1, 0] = s
    Ji[1, 1] = c
    Ji[0, 2] = -roy  # R_i S o = S R_i o = (-(R o)_y, (R o)_x)
    Ji[1, 2] = rox
    Jo = np.empty((2, 2, n))
    Jo[0, 0] = c
    Jo[0, 1] = -s
    Jo[1, 0] = s
    Jo[1, 1] = c
    return e.T, Ji.transpose(2, 0, 1), Jo.transpose(2, 0, 1)


def anchored_gps_error(
    base: FloatArray, local: FloatArray, lever: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A fix seen through a submap (the hierarchical graph's top level): the pose of the fix
    is ``B ∘ Y`` with ``B`` the submap's base frame (a variable) and ``Y`` the pose of the
    fix's time in the submap's frame (a constant, from the local solve), so with
    ``p = t_Y + R_Y o`` (the antenna in the base frame)::

        e = t_B + R_B p - z                                     (2,)

    which is :func:`gps_error` of pose ``B`` with lever arm ``p``. Moving ``B`` by the right
    update, ``t_B ← t_B + R_B δt``, ``R_B ← R_B (I + δθ S)``, gives
    ``∂e/∂δ_B = [R_B, R_B S p]``; ``∂e/∂o = R_B R_Y``. Returns ``e (E, 2)``,
    ``∂e/∂δ_B (E, 2, 3)`` and ``∂e/∂o (E, 2, 2)`` for ``base``, ``local`` ``(E, 3)``,
    ``lever`` ``(E, 2)`` and ``z`` ``(E, 2)``."""
    c, s = np.cos(local[:, 2]), np.sin(local[:, 2])
    p = np.stack(
        [
            local[:, 0] + c * lever[:, 0] - s * lever[:, 1],
            local[:, 1] + s * lever[:, 0] + c * lever[:, 1],
        ],
        axis=1,
    )
    e, Jb, Rb = gps_error(base, p, z)
    Ry = np.empty((base.shape[0], 2, 2))
    Ry[:, 0, 0] = c
    Ry[:, 0, 1] = -s
    Ry[:, 1, 0] = s
    Ry[:, 1, 1] = c
    return e, Jb, Rb @ Ry


def whitened_squares(
    poses: FloatArray, lever: FloatArray, fixes: FloatArray, information: FloatArray
) -> FloatArray:
    """``s_k = e_kᵀ Ω_k e_k`` of every fix for poses ``(E, 3)`` (the pose of each fix), one
    lever arm ``(2,)``, fixes ``(E, 2)`` and informations ``(E, 2, 2)``."""
    e, _, _ = gps_error(poses, np.broadcast_to(lever, fixes.shape), fixes)
    return np.einsum("ei,eij,ej->e", e, information, e)


@dataclass(frozen=True)
class GpsWeighting:
    """How the fixes are re-weighted against outliers (see the module docstring)."""

    name: WeightingName = "gate"
    """``"none"``, a robust kernel of :mod:`slamkit.optim.robust` (``"huber"``, ``"cauchy"``,
    ``"geman_mcclure"``, ``"dcs"``), or ``"gate"`` (a fix with ``s`` above ``width`` gets
    weight 0). The default was measured on Victoria Park: ``docs/estimators/gps.md``."""
    width: float = 9.21
    """The kernel's width (δ, c or φ as in :class:`~slamkit.optim.robust.RobustKernel`) or the
    gate's χ² bound (9.21: the 99 % quantile of χ² with 2 degrees of freedom)."""
    max_rounds: int = 10
    """Outer rounds (solves) at most."""
    tolerance: float = 1e-3
    """Stop when no weight changes by more than this between rounds."""

    def __post_init__(self) -> None:
        if self.name not in ("none", "huber", "cauchy", "geman_mcclure", "dcs", "gate"):
            raise ConfigError(f"gps weighting: unknown name {self.name!r}")
        if not (np.isfinite(self.width) and self.width > 0):
            raise ConfigError(f"gps weighting width: expected a number > 0, got {self.width}")
        if self.max_rounds < 1:
            raise ConfigError(f"gps weighting max_rounds: expected >= 1, got {self.max_rounds}")
        if not (np.isfinite(self.tolerance) and self.tolerance > 0):
            raise ConfigError(f"gps weighting tolerance: expected > 0, got {self.tolerance}")


def gps_weights(weighting: GpsWeighting, s: FloatArray) -> FloatArray:
    """The weight of each fix for its squared whitened error ``s``."""
    if weighting.name == "gate":
        return (s <= weighting.width).astype(np.float64)
    _, w = robust_rho_and_weight(RobustKernel(weighting.name, weighting.width), s)
    return np.asarray(w, dtype=np.float64)


def reweight(edges: EdgeSet, base_information: FloatArray, weights: FloatArray) -> EdgeSet:
    """``edges`` with information ``w_k Ω_k``; a weight of 0 keeps a tiny ``1e-12 Ω_k`` so the
    edge stays positive definite (its pull is nil) and the graph keeps its shape."""
    w = np.maximum(weights, 1e-12)
    return EdgeSet(
        edges.kind,
        edges.i,
        edges.j,
        edges.measurement,
        base_information * w[:, None, None],
        edges.lines,
    )
