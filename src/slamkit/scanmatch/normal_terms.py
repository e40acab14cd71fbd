"""The per-iteration terms of point-to-normal ICP (:func:`~slamkit.scanmatch.normal_icp.
normal_icp`): the pairs, their normal distances, Jacobian rows and Huber weights, in one
compiled pass instead of ~20 NumPy calls on ~180-element arrays.

What is computed (``q_i`` a current point, ``m_i`` it moved by the pose, ``j_i`` its
nearest map point or ``M`` for none, ``p``/``n`` map points and normals, ``c, s`` the cosine
and sine of the pose's angle):

* the pairs ``k`` with ``j_k < M``, and the *stamp* ``j_i`` or ``−1`` for every point
  (what the caller compares across iterations to detect a cycle);
* ``e_k = n_x (m_x − p_x) + n_y (m_y − p_y)``;
* the Jacobian rows ``[n_x, n_y, n_x (−s q_x − c q_y) + n_y (c q_x − s q_y)]``
  (:func:`~slamkit.scanmatch.covariance.line_jacobian`);
* ``σ̂ = max(1.4826 · median |e|, floor)`` and the Huber weights ``w_k = min(1, k σ̂ /
  max(|e_k|, 1e-300))``, with the rows weighted, ``J_k w_k``.

Bit for bit the NumPy expressions' results (:func:`pair_terms_numpy`, the path without
numba and the kernel's oracle; :mod:`slamkit.backend` chooses): each is a sequence of IEEE
operations, rounded one by one, in the same order and grouping as NumPy evaluates them
(numba compiles without fast-math, so nothing is fused or reassociated; ``einsum`` over two
terms is the same multiply, multiply, add), and a median is an order statistic (the mean
of two for an even count), whatever the selection algorithm. The products that go through
BLAS (``Jᵀ W J``) stay with the caller, in NumPy, on arrays of the same layout.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.backend import SEAM, jit, writable
from slamkit.scanmatch.compiled import median_in_place
from slamkit.scanmatch.covariance import line_jacobian, median

__all__ = [
    "PairTerms",
    "TermBuffers",
    "normal_terms_kernel",
    "pair_terms",
    "pair_terms_numpy",
]


class PairTerms(NamedTuple):
    """One ICP iteration's terms (see the module docstring); with fewer than the minimum of
    pairs only ``n_pairs`` is meaningful and the arrays are empty."""

    n_pairs: int
    stamp: bytes
    """``j_i`` or ``−1`` for every current point, as bytes (comparable across iterations)."""
    current: FloatArray  # (n, 2) the paired current points
    e: FloatArray  # (n,) normal distances
    jac: FloatArray  # (n, 3) Jacobian rows
    w: FloatArray  # (n,) Huber weights
    jw: FloatArray  # (n, 3) rows times weights
    sigma: float


TermBuffers = tuple[NDArray[np.intp], FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]
"""The outputs :func:`normal_terms_kernel` fills, ``K`` rows each (the first ``n`` used):
``(stamp (K,), cur (K, 2), e (K,), jac (K, 3), w (K,), jw (K, 3))`` (:class:`PairTerms`).
A plain tuple, not a named one: numba types a named tuple argument about 1 µs slower per
call, and the kernel runs once per ICP iteration."""


def pair_terms(
    moved: FloatArray,
    q: FloatArray,
    j: NDArray[np.intp],
    points: FloatArray,
    normals: FloatArray,
    theta: float,
    huber_k: float,
    noise_floor: float,
    min_pairs: int,
) -> PairTerms:
    """The terms for current points ``q (K, 2)`` moved to ``moved (K, 2)`` by a pose of angle
    ``theta``, paired by ``j (K,)`` (``M = len(points)``: unpaired) with map ``points (M,
    2)`` and ``normals (M, 2)``; only the stamp when fewer than ``min_pairs`` pair up.
    Compiled (:func:`normal_terms_kernel`) under numba, else :func:`pair_terms_numpy` (the
    same numbers to the bit)."""
    return _pair_terms(moved, q, j, points, normals, theta, huber_k, noise_floor, min_pairs)


def _pair_terms_compiled(
    moved: FloatArray,
    q: FloatArray,
    j: NDArray[np.intp],
    points: FloatArray,
    normals: FloatArray,
    theta: float,
    huber_k: float,
    noise_floor: float,
    min_pairs: int,
) -> PairTerms:
    """:func:`pair_terms` through :func:`normal_terms_kernel`."""
    c, s = np.cos(theta), np.sin(theta)  # as line_jacobian takes them
    k = q.shape[0]
    out: TermBuffers = (
        np.empty(k, dtype=np.intp), np.empty((k, 2)), np.empty(k), np.empty((k, 3)),
        np.empty(k), np.empty((k, 3)),
    )  # fmt: skip
    n, sigma = normal_terms_kernel(
        writable(moved), writable(q), writable(j), writable(points), writable(normals),
        (float(c), float(s), float(huber_k), float(noise_floor)), int(min_pairs), out,
    )  # fmt: skip
    stamp, cur, e, jac, w, jw = out
    m = n if n >= min_pairs else 0
    return PairTerms(
        n, stamp.tobytes(), cur[:m], e[:m], jac[:m], w[:m], jw[:m], sigma if m else 0.0
    )


def pair_terms_numpy(
    moved: FloatArray,
    q: FloatArray,
    j: NDArray[np.intp],
    points: FloatArray,
    normals: FloatArray,
    theta: float,
    huber_k: float,
    noise_floor: float,
    min_pairs: int,
) -> PairTerms:
    """:func:`pair_terms` in NumPy: the path without numba and the oracle of
    :func:`normal_terms_kernel` (bit for bit)."""
    ok = j < points.shape[0]
    n = int(np.count_nonzero(ok))
    stamp = np.where(ok, j, -1).tobytes()
    if n < min_pairs:
        empty = np.zeros((0, 3))
        return PairTerms(n, stamp, np.zeros((0, 2)), np.zeros(0), empty, np.zeros(0), empty, 0.0)
    jk, qk = j[ok], q[ok]
    nk = normals[jk]
    e = np.einsum("ij,ij->i", nk, moved[ok] - points[jk])
    jac = line_jacobian(qk, nk, theta)
    sigma = max(1.4826 * median(np.abs(e)), noise_floor)
    w = np.minimum(1.0, huber_k * sigma / np.maximum(np.abs(e), 1e-300))
    return PairTerms(n, stamp, qk, e, jac, w, jac * w[:, None], sigma)


@jit
def normal_terms_kernel(
    moved: FloatArray,
    q: FloatArray,
    j: NDArray[np.intp],
    points: FloatArray,
    normals: FloatArray,
    numbers: tuple[float, float, float, float],
    min_pairs: int,
    out: TermBuffers,
) -> tuple[int, float]:
    """The kernel of :func:`pair_terms` (``numbers = (cos θ, sin θ, huber_k,
    noise_floor)``): fills the first ``n`` rows of ``out`` (``n`` the pairs) and returns
    ``(n, σ̂)`` (σ̂ = 0 and only the stamp filled when ``n < min_pairs``). The weights'
    buffer holds ``|e|`` for the median until the weights replace it."""
    c, s, huber_k, noise_floor = numbers
    stamp, cur, e, jac, w, jw = out
    m = points.shape[0]
    n = 0
    for i in range(j.shape[0]):
        if j[i] < m:
            stamp[i] = j[i]
            n += 1
        else:
            stamp[i] = -1
    if n < min_pairs:
        return n, 0.0
    u = 0
    for i in range(j.shape[0]):
        a = j[i]
        if a >= m:
            continue
        qx, qy = q[i, 0], q[i, 1]
        nx, ny = normals[a, 0], normals[a, 1]
        d0 = moved[i, 0] - points[a, 0]
        d1 = moved[i, 1] - points[a, 1]
        ek = nx * d0
        ek = ek + ny * d1
        cur[u, 0], cur[u, 1] = qx, qy
        e[u] = ek
        jac[u, 0], jac[u, 1] = nx, ny
        jac[u, 2] = nx * (-s * qx - c * qy) + ny * (c * qx - s * qy)
        w[u] = abs(ek)
        u += 1
    sigma = max(1.4826 * median_in_place(w[:n]), noise_floor)
    hs = huber_k * sigma
    for u in range(n):
        wk = min(1.0, hs / max(abs(e[u]), 1e-300))
        w[u] = wk
        jw[u, 0] = jac[u, 0] * wk
        jw[u, 1] = jac[u, 1] * wk
        jw[u, 2] = jac[u, 2] * wk
    return n, sigma


_pair_terms = SEAM.pair(compiled=_pair_terms_compiled, oracle=pair_terms_numpy)
"""The terms, compiled under numba, else in NumPy (:mod:`slamkit.backend`)."""
