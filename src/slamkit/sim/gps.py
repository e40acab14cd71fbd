"""A simulated GPS on a data set with a true path: fixes of an antenna at a known lever arm,
in a GPS frame of its own, with noise, multipath outliers and a held-out share — the test
bed of every filter's GPS fusion (``docs/estimators/gps.md``)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.datasets.assemble import assemble_events
from slamkit.datasets.gps_split import holdout_mask
from slamkit.datasets.stream import Dataset, GpsFix, GpsSpec
from slamkit.errors import InputError
from slamkit.geometry.pose2 import transform_points
from slamkit.sim.scenarios import build_landmark_loop

__all__ = [
    "LOOP_GPS_SIGMA",
    "LOOP_LEVER_ARM",
    "LOOP_OUTLIERS",
    "SimulatedGps",
    "landmark_loop_with_gps",
    "with_simulated_gps",
]


@dataclass(frozen=True, eq=False)
class SimulatedGps:
    """A data set with simulated fixes, and what the fixes are."""

    dataset: Dataset
    """The data set with the fixes not held out in its stream (``GpsFix``, noise in its
    ``GpsSpec``) and every fix, outliers included, as ``truth.positions`` (the GPS track
    scoring reads)."""
    outliers: NDArray[np.bool_]
    """Which fixes ``(M,)`` were moved far off (multipath)."""
    held_out: NDArray[np.bool_]
    """Which fixes ``(M,)`` were kept out of the stream."""
    true_antenna: FloatArray
    """The antenna's true position at every fix ``(M, 2)``, in the GPS frame."""

    frame_angle: float
    """The GPS frame's turn from the world's [rad]."""
    frame_shift: FloatArray
    """... and its shift [m] (``p_gps = R(frame_angle) p + frame_shift``)."""

    def to_gps(self, xy: ArrayLike) -> FloatArray:
        """World points ``(N, 2)`` in the GPS frame."""
        frame = np.array([*self.frame_shift, self.frame_angle])
        return transform_points(frame, as_array(xy, "points", (None, 2)))


def with_simulated_gps(
    dataset: Dataset,
    rng: np.random.Generator,
    *,
    lever_arm: tuple[float, float],
    sigma: float,
    every: int = 5,
    n_outliers: int = 0,
    outlier_range: tuple[float, float] = (15.0, 30.0),
    frame_angle: float = 0.0,
    frame_shift: tuple[float, float] = (0.0, 0.0),
    holdout_every: int = 0,
) -> SimulatedGps:
    """Fixes at every ``every``-th true pose (from the second), of the antenna at
    ``lever_arm`` [m], moved into a GPS frame turned by ``frame_angle`` [rad] and shifted by
    ``frame_shift`` [m], with ``N(0, sigma²)`` noise per axis; ``n_outliers`` fixes after the
    first quarter moved ``outlier_range`` metres in a random direction; every
    ``holdout_every``-th fix kept out of the stream (:func:`~slamkit.datasets.gps_split.
    holdout_mask`). Draws, in order: the noise, the outliers' indices, directions and
    distances."""
    times, poses = dataset.truth.times, dataset.truth.poses
    if times is None or poses is None:
        raise InputError(f"with_simulated_gps: {dataset.name} has no true path")
    take = np.arange(1, times.shape[0], every)
    if n_outliers > take.size - take.size // 4:
        raise InputError(f"with_simulated_gps: {n_outliers} outliers among {take.size} fixes")
    sim = SimulatedGps(dataset, np.zeros(0, bool), np.zeros(0, bool), np.zeros((0, 2)),
                       frame_angle, np.asarray(frame_shift, dtype=float))  # fmt: skip
    true_xy = sim.to_gps(transform_points(poses[take], np.asarray(lever_arm)))  # t + R(θ) o
    xy = true_xy + rng.normal(0.0, sigma, (take.size, 2))
    out = rng.choice(np.arange(take.size // 4, take.size), n_outliers, replace=False)
    ang = rng.uniform(0.0, 2.0 * np.pi, n_outliers)
    dist = rng.uniform(*outlier_range, n_outliers)
    xy[out] += dist[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    outliers = np.zeros(take.size, dtype=bool)
    outliers[out] = True
    held = holdout_mask(take.size, holdout_every)
    t = times[take]
    fixes = [GpsFix(float(ti), p.copy()) for ti, p in zip(t[~held], xy[~held], strict=True)]
    truth = replace(dataset.truth, position_times=t.copy(), positions=xy.copy())
    ds = replace(dataset, events=assemble_events(dataset.events, fixes), truth=truth,
                 gps=GpsSpec(np.eye(2) * sigma**2))  # fmt: skip
    return replace(sim, dataset=ds, outliers=outliers, held_out=held, true_antenna=true_xy)


LOOP_LEVER_ARM = (1.5, -0.4)
"""The antenna of :func:`landmark_loop_with_gps` in the robot frame [m]."""
LOOP_GPS_SIGMA = 0.5
"""... its fixes' standard deviation per axis [m]."""
LOOP_OUTLIERS = 8
"""... and how many of its fixes are moved 15-30 m (multipath)."""


def landmark_loop_with_gps(seed: int, holdout_every: int = 0) -> SimulatedGps:
    """The filters' GPS test drive: two laps of the landmark loop with a 4 m range and a
    noisy turn rate (8° per step; EKF-SLAM alone drifts 2-4 m), a fix every fifth step of
    the antenna at :data:`LOOP_LEVER_ARM`, in a GPS frame turned 0.7 rad and shifted by
    (120, −45) m, σ :data:`LOOP_GPS_SIGMA`, :data:`LOOP_OUTLIERS` outliers; the data set
    and the fixes' noise drawn from ``seed``."""
    opts = {"max_range": 4.0, "laps": 2, "sigma_omega_deg": 8.0, "sigma_bearing_deg": 3.0}
    ds = build_landmark_loop(opts, seed=seed)
    return with_simulated_gps(ds, np.random.default_rng(seed), lever_arm=LOOP_LEVER_ARM,
                              sigma=LOOP_GPS_SIGMA, n_outliers=LOOP_OUTLIERS, frame_angle=0.7,
                              frame_shift=(120.0, -45.0), holdout_every=holdout_every)  # fmt: skip
