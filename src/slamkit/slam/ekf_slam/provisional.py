"""The provisional feature list of EKF-SLAM: which features a scan should have seen, the
measurement-only information that confirms a feature, and the misses that remove one.

A new feature is in the state but updated by the Schmidt (consider) update only, which
leaves the robot and the map untouched, until the trace of its measurement-only covariance
``(Σₖ H_kᵀ R⁻¹ H_k)⁻¹`` falls below ``provisional_trace``
(:attr:`~slamkit.slam.ekf_slam.EkfSlamConfig.provisional_trace` says why this covariance).
A feature predicted well inside the sensor's field of view and range but not matched counts
a miss; after ``max_misses`` consecutive misses it is removed.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import LandmarkSensorSpec
from slamkit.errors import GeometryError
from slamkit.estimation.readings import ReadingStatus
from slamkit.geometry import wrap_angle
from slamkit.models import MIN_RANGE, LandmarkModel
from slamkit.slam.common import reading_jacobians
from slamkit.slam.ekf_slam.config import EkfSlamConfig
from slamkit.slam.ekf_slam.state import SlamState, diagonal_blocks

__all__ = [
    "TRACKED",
    "count_misses",
    "in_view",
    "is_confirmed",
    "miss_limit",
    "reading_information",
    "remove_missed",
    "watched",
]

TRACKED = ReadingStatus.TRACKED
"""Reading status: the reading updated a provisional feature (the feature only; see
:class:`~slamkit.slam.ekf_slam.EkfSlam`); every code is a
:class:`~slamkit.estimation.readings.ReadingStatus`."""


def in_view(
    mean: FloatArray, cov: FloatArray, sel: NDArray[np.int64], sensor: LandmarkSensorSpec
) -> NDArray[np.bool_]:
    """Which of the landmarks ``sel`` have a predicted range and bearing inside the
    sensor's limits by three standard deviations of the prediction (state uncertainty
    only, no sensor noise): those a scan should have seen.

    The limits are the sensor's, judged from where it sits (``sensor.offset`` in the robot
    frame: Victoria Park's laser is 3.78 m ahead of the rear axle, and the trees beside the
    cab are behind its half-plane) and out to its detection range (``sensor.reach``: the
    measured range within which it reads the landmarks it could see, shorter than
    ``max_range`` for a laser that seldom detects a trunk far away). The 3σ margins are
    those of the prediction from the pose's origin, the bearing's rescaled by ``r / r_s``
    (the same sideways uncertainty seen from the sensor at range ``r_s``)."""
    U = sel.size
    lm = mean[3:].reshape(-1, 2)[sel]
    dx, dy = lm[:, 0] - mean[0], lm[:, 1] - mean[1]
    r = np.hypot(dx, dy)
    ok = r >= MIN_RANGE
    rs = np.where(ok, r, 1.0)
    q = rs * rs
    b = wrap_angle(np.arctan2(dy, dx) - mean[2])
    # range-bearing Jacobians of the prediction: landmark, and pose (= −landmark | −e₂)
    Hj = np.empty((U, 2, 2))
    Hj[:, 0, 0], Hj[:, 0, 1] = dx / rs, dy / rs
    Hj[:, 1, 0], Hj[:, 1, 1] = -dy / q, dx / q
    Hr = np.zeros((U, 2, 3))
    Hr[:, :, :2] = -Hj
    Hr[:, 1, 2] = -1.0
    C = cov[:3, 3:].reshape(3, -1, 2)[:, sel, :].transpose(1, 0, 2)  # Σ_r,j (U, 3, 2)
    HC = Hr @ C @ np.swapaxes(Hj, -1, -2)
    B = diagonal_blocks(cov, (mean.size - 3) // 2)[sel]
    P = (
        Hr @ cov[:3, :3] @ np.swapaxes(Hr, -1, -2)
        + HC
        + np.swapaxes(HC, -1, -2)
        + Hj @ B @ np.swapaxes(Hj, -1, -2)
    )
    sr = 3.0 * np.sqrt(np.clip(P[:, 0, 0], 0.0, None))
    sb = 3.0 * np.sqrt(np.clip(P[:, 1, 1], 0.0, None))
    a, o = sensor.offset
    if a or o:  # range and bearing from the sensor: the point in the sensor's frame
        c, s = np.cos(mean[2]), np.sin(mean[2])
        xs, ys = c * dx + s * dy - a, c * dy - s * dx - o
        r_s = np.hypot(xs, ys)
        sb = sb * r / np.maximum(r_s, MIN_RANGE)
        r, b = r_s, np.arctan2(ys, xs)
    inside = ok & (r + sr <= sensor.reach) & (r - sr >= sensor.min_range)
    if sensor.fov < 2.0 * np.pi:
        inside &= np.abs(b) + sb <= sensor.fov / 2.0
    return np.asarray(inside)


def reading_information(
    model: LandmarkModel, mean: FloatArray, j: int, R_inv: FloatArray
) -> FloatArray | None:
    """One reading's information about feature ``j``, ``H_jᵀ R⁻¹ H_j`` (``H_j`` the
    reading's Jacobian with respect to the landmark, at the state ``mean``); ``None`` for a
    feature on the sensor."""
    s = 3 + 2 * j
    try:
        _, _, Hj = reading_jacobians(model, mean[:3], mean[s : s + 2])
    except GeometryError:
        return None
    return Hj.T @ R_inv @ Hj


def is_confirmed(info: FloatArray, threshold: float) -> bool:
    """Whether a feature with the measurement information ``info (2, 2)`` is known well
    enough to join the map: the trace of ``info⁻¹``, its measurement-only covariance, below
    ``threshold``."""
    (a, b), (c, d) = info.tolist()
    det = a * d - b * c
    return bool(det > 0.0 and (a + d) / det < threshold)  # trace of the 2 × 2 inverse


def watched(provisional: NDArray[np.bool_], config: EkfSlamConfig) -> NDArray[np.int64]:
    """Indices of the landmarks (``provisional`` flags in state order) that misses may
    remove: provisional ones if ``max_misses`` is set, confirmed ones if
    ``max_misses_confirmed`` is."""
    removable = np.zeros(provisional.size, dtype=bool)
    if config.max_misses is not None:
        removable |= provisional
    if config.max_misses_confirmed is not None:
        removable |= ~provisional
    return np.flatnonzero(removable)


def count_misses(
    misses: NDArray[np.int64],
    provisional: NDArray[np.bool_],
    seen: NDArray[np.bool_],
    L: int,
    config: EkfSlamConfig,
    limit: int | None = None,
) -> NDArray[np.int64]:
    """Count a miss (in place, in ``misses``) for every landmark expected in a scan and not
    matched — ``seen`` is ``matched | ~in_view`` over the ``n_before`` landmarks the scan
    started with — and return the indices, among the ``L`` landmarks now, of those to
    remove."""
    n_before = seen.size
    missed = np.flatnonzero(~seen)
    misses[missed] += 1
    limit_p = config.max_misses if limit is None else limit
    limit_c = config.max_misses_confirmed
    prov = provisional[:n_before]
    drop = np.zeros(L, dtype=bool)
    if limit_p is not None:
        drop[:n_before] |= prov & (misses[:n_before] >= limit_p)
    if limit_c is not None:
        drop[:n_before] |= ~prov & (misses[:n_before] >= limit_c)
    return np.flatnonzero(drop)


def miss_limit(probability: float, expected: int, seen: int) -> int:
    """The consecutive misses that remove a provisional feature when a real one, detected
    as often as the map's landmarks, would be missed that many times in a row with at most
    ``probability``: the smallest ``n ≥ 1`` with ``(1 − p_D)ⁿ ≤ probability``, where
    ``p_D = (seen + 1) / (expected + 2)`` is the detection rate of the confirmed landmarks
    (``seen`` of ``expected`` predictions in view matched; Laplace's rule, ``1/2`` before
    any)."""
    p_d = (seen + 1.0) / (expected + 2.0)
    if p_d >= 1.0:
        return 1
    return max(1, math.ceil(math.log(probability) / math.log1p(-p_d) - 1e-12))


def remove_missed(
    state: SlamState, seen: NDArray[np.bool_], config: EkfSlamConfig, limit: int | None = None
) -> tuple[int, int]:
    """:func:`count_misses` on the state (``limit``: the provisional features' miss limit
    instead of ``max_misses``), and remove (marginalise out) the landmarks that reached
    their limit; returns how many provisional and confirmed ones were removed."""
    rows = count_misses(state.misses, state.provisional, seen, state.n_landmarks, config, limit)
    if not rows.size:
        return 0, 0
    n_prov = int(np.count_nonzero(state.provisional[rows]))
    state.remove(rows)
    return n_prov, int(rows.size) - n_prov
