"""The normal equations at one estimate: :class:`Linearization` (cost, χ², and ``H``, ``g``
formed on first use) and :func:`normal_equations`, which sums the per-edge block products
into the fixed pattern.

A least-squares loop linearises at every point it tries but reads ``H`` and ``g`` only at the
points it moves on from: a Levenberg-Marquardt trial that raises the cost, and the last point
of a solve, need the cost alone. :meth:`~slamkit.optim.graph.GraphProblem.linearize` can
therefore keep each block's whitened residual and Jacobians (:class:`WeightedBlock`) and
leave the products ``AᵀA``, ``AᵀB``, ``BᵀB``, ``Aᵀr``, ``Bᵀr`` and their sums to the first
read of ``H`` or ``g``. Deferring changes when they are formed, not how: the same arrays go
through the same operations, so the numbers are identical.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from slamkit.optim.data import FloatArray
from slamkit.optim.sparse import NormalPattern

__all__ = ["Linearization", "WeightedBlock", "normal_equations"]


@dataclass(frozen=True)
class WeightedBlock:
    """One edge set's IRLS-weighted whitened residual ``r`` and Jacobians ``A`` (first
    variable) and ``B`` (second, ``None`` for unary edges): edge-last ``(m, E)``,
    ``(m, d, E)`` in 2D, batch-first ``(E, m)``, ``(E, m, d)`` when ``batch_first`` (3D)."""

    r: FloatArray
    A: FloatArray
    B: FloatArray | None
    batch_first: bool


def normal_equations(
    pattern: NormalPattern, blocks: Sequence[WeightedBlock]
) -> tuple[FloatArray, FloatArray]:
    """``H`` (lower-triangle values in ``pattern``) and ``g = Jᵀ r`` from every block's
    products, emitted in the order of ``pattern.slots`` (per block ``AᵀA``, ``AᵀB``, ``BᵀB``;
    gradients ``Aᵀr``, ``Bᵀr``)."""
    hw: list[FloatArray] = []
    gw: list[FloatArray] = []
    for blk in blocks:
        A, B, r = blk.A, blk.B, blk.r
        if blk.batch_first:
            _emit_batch_first(A, B, r, hw, gw)
            continue
        hw.append(np.einsum("kpe,kqe->pqe", A, A).ravel())
        if B is not None:
            hw.append(np.einsum("kpe,kqe->pqe", A, B).ravel())
            hw.append(np.einsum("kpe,kqe->pqe", B, B).ravel())
        gw.append(np.einsum("kpe,ke->pe", A, r).ravel())
        if B is not None:
            gw.append(np.einsum("kpe,ke->pe", B, r).ravel())
    return pattern.values(np.concatenate(hw)), pattern.gradient(np.concatenate(gw))


def _emit_batch_first(
    A: FloatArray,
    B: FloatArray | None,
    r: FloatArray,
    hw: list[FloatArray],
    gw: list[FloatArray],
) -> None:
    """Append the block products ``AᵀA``, ``AᵀB``, ``BᵀB`` and gradients ``Aᵀr``, ``Bᵀr`` of
    batch-first ``A (E, m, da)``, ``B (E, m, db)``, ``r (E, m)`` in the pattern's edge-last
    order (``(d_a, d_b, E)`` raveled). Transposing ``A`` into contiguous memory first keeps
    every product on matmul's fast path."""
    At = np.ascontiguousarray(np.swapaxes(A, 1, 2))
    hw.append(np.ascontiguousarray((At @ A).transpose(1, 2, 0)).ravel())
    rc = r[:, :, None]
    if B is None:
        gw.append(np.ascontiguousarray((At @ rc)[:, :, 0].T).ravel())
        return
    Bt = np.ascontiguousarray(np.swapaxes(B, 1, 2))
    hw.append(np.ascontiguousarray((At @ B).transpose(1, 2, 0)).ravel())
    hw.append(np.ascontiguousarray((Bt @ B).transpose(1, 2, 0)).ravel())
    gw.append(np.ascontiguousarray((At @ rc)[:, :, 0].T).ravel())
    gw.append(np.ascontiguousarray((Bt @ rc)[:, :, 0].T).ravel())


class Linearization:
    """Whitened, robustly weighted system at one estimate.

    ``cost = Σ ρ(‖U e‖²)``; ``H`` (lower-triangle values in the problem's pattern) and
    ``g = Jᵀ r`` of the IRLS-weighted residual ``r`` (so the Gauss-Newton step solves
    ``H δ = -g``); ``chi2`` is the unweighted ``Σ ‖U e‖²``. ``H`` and ``g`` are ``None``
    for a cost-only evaluation. Built with ``pending`` (a function returning ``(H, g)``),
    they are formed on first read (module docstring); ``seconds`` then grows by the time
    that takes, which is also passed to ``on_formed`` when set (a solver's clock).
    """

    def __init__(
        self,
        cost: float,
        chi2: float,
        H: FloatArray | None,
        g: FloatArray | None,
        seconds: float,
        *,
        pending: Callable[[], tuple[FloatArray, FloatArray]] | None = None,
    ) -> None:
        self.cost = cost
        self.chi2 = chi2
        self.seconds = seconds
        self._H = H
        self._g = g
        self._pending = pending
        self.on_formed: Callable[[float], None] | None = None

    @property
    def H(self) -> FloatArray | None:
        self._form()
        return self._H

    @property
    def g(self) -> FloatArray | None:
        self._form()
        return self._g

    def _form(self) -> None:
        if self._pending is not None:
            t0 = time.perf_counter()
            self._H, self._g = self._pending()
            self._pending = None
            spent = time.perf_counter() - t0
            self.seconds += spent
            if self.on_formed is not None:
                self.on_formed(spent)

    def __repr__(self) -> str:
        formed = "pending" if self._pending is not None else f"H={self._H is not None}"
        return f"Linearization(cost={self.cost!r}, chi2={self.chi2!r}, {formed})"
