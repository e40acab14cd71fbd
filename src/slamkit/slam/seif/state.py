"""The SEIF state: the information matrix ``Ω``, the information vector ``ξ`` and the
running mean ``μ`` in preallocated buffers whose landmark capacity doubles when full, and
what is kept per landmark (ids, links).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray

__all__ = ["SeifState", "link_active", "prior_information", "with_room"]


def prior_information(cov: FloatArray, max_information: float) -> FloatArray:
    """The information ``(3, 3)`` of a pose prior with covariance ``cov``; a zero variance
    (the map frame) becomes the very large but finite information ``max_information``."""
    w, V = np.linalg.eigh(cov)
    info = V @ np.diag(1.0 / np.maximum(w, 1.0 / max_information)) @ V.T
    return np.asarray(0.5 * (info + info.T), dtype=np.float64)


def with_room(
    Om: FloatArray, xi: FloatArray, mu: FloatArray, n: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The buffers ``(Ω, ξ, μ)`` with room for one more landmark after the ``n`` entries in
    use: the same ones, or copies into buffers of twice the landmark capacity."""
    N = Om.shape[0]
    if n + 2 <= N:
        return Om, xi, mu
    cap = 2 * ((N - 3) // 2)
    M = 3 + 2 * cap
    Om_new = np.zeros((M, M))
    Om_new[:n, :n] = Om[:n, :n]
    xi_new, mu_new = np.zeros(M), np.zeros(M)
    xi_new[:n], mu_new[:n] = xi[:n], mu[:n]
    return Om_new, xi_new, mu_new


def link_active(links: list[set[int]], active: list[int]) -> None:
    """Record that the ``active`` landmarks are linked to each other (the motion update
    links every pair of them through the robot)."""
    for a in active:
        links[a].update(b for b in active if b != a)


class SeifState:
    """``Ω``, ``ξ`` and ``μ`` over ``(x_r, m_1, …, m_L)`` in buffers (the first :attr:`n`
    entries in use), the landmark ids in state order, the map row of each id, the
    landmark–landmark links (per map row, the rows it may be linked to in ``Ω``) and the
    active landmarks (linked to the robot, least recently observed first). The estimator
    owns it and mutates it."""

    def __init__(
        self, capacity: int, pose: FloatArray, cov: FloatArray, max_information: float
    ) -> None:
        N = 3 + 2 * capacity
        self.Om = np.zeros((N, N))
        self.xi = np.zeros(N)
        self.mu = np.zeros(N)
        self.Om[:3, :3] = prior_information(cov, max_information)
        self.mu[:3] = pose
        self.xi[:3] = self.Om[:3, :3] @ pose
        self.n_landmarks = 0
        self.ids: list[int] = []
        self.slot_of: dict[int, int] = {}
        self.links: list[set[int]] = []  # landmark-landmark links (map rows)
        self.active: list[int] = []  # linked to the robot, least recently observed first
        # per map row: its number of links and their state indices (relaxation)
        self.neighbour_cache: dict[int, tuple[int, NDArray[np.int64]]] = {}

    @property
    def n(self) -> int:
        """Entries of the state in use, ``3 + 2L``."""
        return 3 + 2 * self.n_landmarks

    def add(self, point: FloatArray, landmark_id: int) -> int:
        """Append a landmark with mean ``point`` and no information yet; returns its map
        row."""
        self.Om, self.xi, self.mu = with_room(self.Om, self.xi, self.mu, self.n)
        j = self.n_landmarks
        s = 3 + 2 * j
        self.mu[s : s + 2] = point
        self.n_landmarks += 1
        self.ids.append(landmark_id)
        self.slot_of[landmark_id] = j
        self.links.append(set())
        return j
