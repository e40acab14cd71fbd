"""Leave-out scoring against GPS: the error of an estimate at fixes it was not given.

When the GPS is fused into an estimate, scoring that estimate on the same fixes measures how
well it follows its own input. :func:`holdout_gps_error` scores it on fixes held out of the
estimator instead (``held_out``, e.g. every tenth), and scores estimators that saw no GPS
the same way, so they compare:

* the fixes that :func:`slamkit.eval.gps.gps_outliers` rejects on the *whole* track (GPS
  alone) are left out of both the alignment and the statistics;
* the estimate's antenna position ``t + R(θ) o`` (``o`` the lever arm, ``(0, 0)`` for the
  reference point itself) is interpolated at each fix (as :func:`slamkit.geometry.pose2.
  interpolate_poses`: linearly between the two samples around it), and fixes farther than
  ``max_interp_gap`` from a sample on either side are not used;
* **aligned**: the SE(2) transform that maps the estimate onto the fixes *not* held out
  (least squares) is applied before the held-out fixes are scored (an estimate without GPS
  lives in its own frame); **direct**: no alignment (an estimate in the GPS frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError
from slamkit.eval.gps import GpsScoreConfig, gps_outliers
from slamkit.geometry.alignment import Similarity, align_points_2d
from slamkit.geometry.angles import wrap_angle

__all__ = ["HoldoutError", "holdout_gps_error"]


@dataclass(frozen=True, eq=False)
class HoldoutError:
    """Errors at the held-out fixes (metres)."""

    alignment: Similarity
    """Fitted on the fixes not held out; maps the estimate into the GPS frame."""
    aligned_errors: FloatArray
    """Distance from each scored fix after the alignment ``(K,)``."""
    direct_errors: FloatArray
    """Distance without alignment ``(K,)``."""
    scored: NDArray[np.bool_]
    """Mask over the fixes: held out, not an outlier, covered by the estimate."""
    fitted: int
    """Fixes the alignment was fitted on."""

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.aligned_errors**2)))

    @property
    def median(self) -> float:
        return float(np.median(self.aligned_errors))

    @property
    def direct_rmse(self) -> float:
        return float(np.sqrt(np.mean(self.direct_errors**2)))

    @property
    def direct_median(self) -> float:
        return float(np.median(self.direct_errors))

    def as_dict(self) -> dict[str, float | int]:
        return {
            "rmse": self.rmse,
            "median": self.median,
            "direct_rmse": self.direct_rmse,
            "direct_median": self.direct_median,
            "scored": int(self.scored.sum()),
            "fitted": self.fitted,
            "alignment_angle": self.alignment.angle,
        }


def _antenna_at(
    times: FloatArray, poses: FloatArray, t: FloatArray, lever: FloatArray, gap: float
) -> tuple[FloatArray, NDArray[np.bool_]]:
    hi = np.clip(np.searchsorted(times, t, side="left"), 0, times.size - 1)
    lo = np.clip(np.where(times[hi] == t, hi, hi - 1), 0, times.size - 1)
    covered = (t >= times[0]) & (t <= times[-1]) & (t - times[lo] <= gap) & (times[hi] - t <= gap)
    span = times[hi] - times[lo]
    w = np.where(span > 0, (t - times[lo]) / np.where(span > 0, span, 1.0), 0.0)
    xy = poses[lo, :2] + w[:, None] * (poses[hi, :2] - poses[lo, :2])
    th = poses[lo, 2] + w * wrap_angle(poses[hi, 2] - poses[lo, 2])
    c, s = np.cos(th), np.sin(th)
    ant = xy + np.stack([c * lever[0] - s * lever[1], s * lever[0] + c * lever[1]], axis=1)
    return ant, covered


def holdout_gps_error(
    estimate_times: ArrayLike,
    estimate: ArrayLike,
    gps_times: ArrayLike,
    gps_positions: ArrayLike,
    held_out: ArrayLike,
    lever_arm: ArrayLike = (0.0, 0.0),
    config: GpsScoreConfig | None = None,
) -> HoldoutError:
    """Score poses ``estimate (N, 3)`` at ``estimate_times (N,)`` on the fixes where
    ``held_out (M,)`` is true (module docstring). Raises :class:`~slamkit.errors.InputError`
    when fewer than two fixes remain to fit the alignment or none to score."""
    cfg = config or GpsScoreConfig()
    est_t = as_array(estimate_times, "estimate times", (None,))
    est = as_array(estimate, "estimate", (est_t.size, 3))
    t = as_array(gps_times, "gps times", (None,))
    xy = as_array(gps_positions, "gps positions", (t.size, 2))
    held = np.asarray(held_out, dtype=bool)
    if held.shape != t.shape:
        raise InputError(f"held_out: expected shape {t.shape}, got {held.shape}")
    lever = as_array(lever_arm, "lever arm", (2,))
    if est_t.size < 2 or np.any(np.diff(est_t) < 0):
        raise InputError("estimate times: expected at least 2 non-decreasing times")
    good = ~gps_outliers(t, xy, cfg).rejected
    ant, covered = _antenna_at(est_t, est, t, lever, cfg.max_interp_gap)
    fit = good & covered & ~held
    scored = good & covered & held
    if fit.sum() < 2 or not scored.any():
        raise InputError(
            f"holdout_gps_error: {int(fit.sum())} fixes to align on and {int(scored.sum())} "
            "to score; need at least 2 and 1"
        )
    sim = align_points_2d(ant[fit], xy[fit])
    aligned = np.linalg.norm(sim.apply_to_points(ant[scored]) - xy[scored], axis=1)
    direct = np.linalg.norm(ant[scored] - xy[scored], axis=1)
    return HoldoutError(sim, aligned, direct, scored, int(fit.sum()))
