"""Simulated sensors: point-landmark readings and laser scans, with injected randomness."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.datasets.stream import LandmarkSensorSpec, LaserSpec
from slamkit.geometry import wrap_angle
from slamkit.maps import LandmarkMap, OccupancyGrid, SegmentMap
from slamkit.models import LaserScanner, RangeBearing

__all__ = ["observe_landmarks", "observe_landmarks_labelled", "simulate_scan"]


def observe_landmarks(
    pose: ArrayLike,
    landmarks: LandmarkMap,
    sensor: LandmarkSensorSpec,
    rng: np.random.Generator,
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Readings ``z (K, m)`` and ids ``(K,)`` of the landmarks within ``[min_range,
    max_range]`` and the field of view of ``pose``; noise ``N(0, sensor.noise_cov)``; ids
    are ``-1`` (and the order shuffled) when the sensor gives no identities."""
    z, ids, _ = observe_landmarks_labelled(pose, landmarks, sensor, rng)
    return z, ids


def observe_landmarks_labelled(
    pose: ArrayLike,
    landmarks: LandmarkMap,
    sensor: LandmarkSensorSpec,
    rng: np.random.Generator,
) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
    """:func:`observe_landmarks` plus the true id of every reading (in the order of the
    readings), which a sensor without identities does not report: the ground truth of the
    data association. Draws the same random numbers."""
    x = as_array(pose, "pose", (3,))
    # Visibility is decided on the noise-free range and bearing.
    rb = RangeBearing().predict(x, landmarks.positions)
    visible = (
        (rb[:, 0] <= sensor.max_range)
        & (rb[:, 0] >= sensor.min_range)
        & (np.abs(rb[:, 1]) <= sensor.fov / 2.0)
    )
    z_true = sensor.model().predict(x, landmarks.positions[visible])
    noise = rng.standard_normal(z_true.shape) @ np.linalg.cholesky(sensor.noise_cov).T
    z = z_true + noise
    model = sensor.model()
    for j, angular in enumerate(model.angular):
        if angular:
            z[:, j] = wrap_angle(z[:, j])
    if sensor.kind in ("range-bearing", "range"):
        z[:, 0] = np.abs(z[:, 0])  # a range reading is never negative
    true_ids = landmarks.ids[visible].copy()
    if sensor.identities:
        return z, true_ids.copy(), true_ids
    order = rng.permutation(true_ids.size)
    return z[order], np.full(true_ids.size, -1, dtype=np.int64), true_ids[order]


def simulate_scan(
    pose: ArrayLike,
    world: SegmentMap | OccupancyGrid,
    laser: LaserSpec,
    rng: np.random.Generator,
) -> FloatArray:
    """One noisy scan ``(B,)`` from ``pose``; ``laser.max_range`` marks no return."""
    scanner = LaserScanner(laser.beam_angles, laser.max_range, laser.range_sigma)
    return scanner.simulate(as_array(pose, "pose", (3,)), world, rng)
