"""Score a :class:`Result` against its data set's ground truth (where there is some)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset
from slamkit.errors import CovarianceError, InputError, SlamkitError
from slamkit.eval import (
    absolute_trajectory_error,
    associate,
    association_scores,
    chi2_bounds,
    convergence,
    gps_error,
    landmark_map_error,
    nees,
    nis_summary,
    pose_errors,
    relative_pose_error,
)
from slamkit.pipeline.registry import ESTIMATORS
from slamkit.pipeline.runner import Result

__all__ = ["CONVERGENCE", "CONVERGENCE_LOST", "Evaluation", "evaluate"]

CONVERGENCE = (0.5, 30.0)
"""``(threshold [m], hold [s])``: a run without a prior has converged once its position error
stays below 0.5 m for 30 s (:func:`slamkit.eval.convergence`)."""
CONVERGENCE_LOST = 1.0
"""Position error [m] above which a converged run counts as having lost the robot."""


@dataclass(frozen=True)
class Evaluation:
    """Metrics (JSON-able) plus the matched arrays that plots need."""

    metrics: dict[str, Any]
    matched_times: FloatArray | None = None
    errors: FloatArray | None = None
    """Per matched step ``(dx, dy, dtheta)`` estimate minus truth, no alignment."""
    sigmas: FloatArray | None = None
    """Per matched step standard deviations ``(3,)`` from the estimator's covariance."""
    nees: FloatArray | None = None


class _HasDict(Protocol):
    def as_dict(self) -> dict[str, Any]: ...


def _metric(metrics: dict[str, Any], name: str, compute: Callable[[], _HasDict]) -> None:
    """Store one metric, or why it could not be computed on this run (a path shorter than
    the RPE distance, a robot that never moved, maps without common landmarks)."""
    try:
        metrics[name] = compute().as_dict()
    except SlamkitError as exc:
        metrics[name] = {"skipped": str(exc)}


def evaluate(result: Result, dataset: Dataset, *, max_dt: float | None = None) -> Evaluation:
    """ATE (SE(2)-aligned and unaligned), RPE over one step and over 10 m, NEES against the
    true trajectory, the time to converge of a run without a prior (:data:`CONVERGENCE`),
    the error against a position-only reference track (GPS, outliers
    rejected, SE(2)-aligned at its times), NIS statistics of the innovation log (windows of
    50 updates), landmark-map error (landmarks matched by id, or by position when the
    estimator numbered its own), data-association scores against the true association of
    the readings, and run times. Steps are matched by time stamp within ``max_dt``
    (default: half the median step of the result)."""
    metrics: dict[str, Any] = {
        "estimator": result.estimator,
        "dataset": result.dataset,
        "seed": result.seed,
        "steps": len(result),
        "runtime": {
            "total_seconds": result.total_seconds,
            "mean_step_seconds": float(result.step_seconds.mean()) if len(result) else 0.0,
            "max_step_seconds": float(result.step_seconds.max()) if len(result) else 0.0,
        },
        "diagnostics": result.output.diagnostics,
    }
    truth = dataset.truth
    ev = Evaluation(metrics)
    if truth.times is not None and truth.poses is not None and len(result) > 1:
        if max_dt is None:
            max_dt = 0.5 * float(np.median(np.diff(result.times))) if len(result) > 1 else 0.0
        ia, ib = associate(result.times, truth.times, max_dt)
        est, ref = result.poses[ia], truth.poses[ib]
        metrics["matched_steps"] = int(ia.size)
        if ia.size >= 2:
            _metric(metrics, "ate", lambda: absolute_trajectory_error(est, ref, align="se2"))
            _metric(
                metrics, "ate_unaligned", lambda: absolute_trajectory_error(est, ref, align="none")
            )
            _metric(metrics, "rpe_1_step", lambda: relative_pose_error(est, ref, delta=1))
            _metric(
                metrics,
                "rpe_10_m",
                lambda: relative_pose_error(est, ref, delta=10.0, unit="meters"),
            )
            err = pose_errors(est, ref)
            metrics["final_position_error"] = float(np.hypot(*err[-1, :2]))
            if dataset.initial_pose is None:  # a global start: when did it find the robot?
                position, heading = np.hypot(err[:, 0], err[:, 1]), np.abs(err[:, 2])
                threshold, hold = CONVERGENCE
                _metric(
                    metrics,
                    "convergence",
                    lambda: convergence(
                        result.times[ia],
                        position,
                        threshold,
                        hold,
                        lost_threshold=CONVERGENCE_LOST,
                        heading_errors=heading,
                    ),
                )
            sig = nees_vals = None
            if result.covariances is not None:
                covs = result.covariances[ia]
                sig = np.sqrt(np.clip(np.diagonal(covs, axis1=1, axis2=2), 0.0, None))
                with np.errstate(divide="ignore", invalid="ignore"):  # singular: not scored
                    ok = np.linalg.det(covs) > 1e-300
                nees_vals = np.full(ia.size, np.nan)
                try:
                    nees_vals[ok] = nees(err[ok], covs[ok])
                except CovarianceError:
                    ok[:] = False
                if np.any(ok):
                    lo, hi = chi2_bounds(3, 1, 0.95)
                    vals = nees_vals[ok]
                    metrics["nees"] = {
                        "mean": float(vals.mean()),
                        "dof": 3,
                        "band_95": [lo, hi],
                        "fraction_in_band": float(np.mean((vals >= lo) & (vals <= hi))),
                        "steps": int(ok.sum()),
                    }
            ev = Evaluation(metrics, result.times[ia], err, sig, nees_vals)
    if truth.positions is not None and truth.position_times is not None and len(result) > 1:
        gps_t, gps_xy = truth.position_times, truth.positions
        _metric(metrics, "gps", lambda: gps_error(result.times, result.poses, gps_t, gps_xy))
    log = result.output.innovations
    if log is not None and len(log) > 0:
        _metric(metrics, "nis", lambda: nis_summary(log.times, log.nis, log.dof, window=50))
    if result.output.landmarks is not None and truth.landmarks is not None:
        est_map, true_map = result.output.landmarks.landmarks, truth.landmarks
        by: Literal["id", "position"] = (
            "id" if np.intersect1d(est_map.ids, true_map.ids).size else "position"
        )
        metrics["landmarks_matched_by"] = by
        _metric(metrics, "landmarks", lambda: landmark_map_error(est_map, true_map, match=by))
    chosen = result.output.reading_landmarks
    if chosen is not None and truth.reading_ids is not None:
        _metric(metrics, "association", lambda: _association(chosen, dataset, result.estimator))
    return ev


def _association(chosen: np.ndarray, dataset: Dataset, estimator: str) -> _HasDict:
    true = dataset.check_reading_ids()
    if true.size != chosen.size:
        raise InputError(
            f"association: the estimator reported {chosen.size} readings, the data set has "
            f"{true.size}"
        )
    # An estimator that needs the known map (localization) numbers landmarks as the map
    # does; the others (SLAM) number their own.
    entry = ESTIMATORS.get(estimator)
    same_ids = entry is not None and "known_landmarks" in entry.requires
    return association_scores(chosen, true, same_ids=same_ids)
