"""Score a :class:`Result` against its data set's ground truth (where there is some)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Literal, TypeVar

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Dataset
from slamkit.errors import CovarianceError, InputError, SlamkitError
from slamkit.estimation.contract import InnovationLog, LandmarkIds
from slamkit.eval import (
    AssociationScores,
    TrajectoryError,
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
    relation_errors,
    relative_pose_error,
)
from slamkit.eval.innovations import NisSummary
from slamkit.eval.monitor import ConsistencyWarning, nees_warning, nis_warning
from slamkit.eval.records import NeesSummary, RunScores, RunTime, Skipped
from slamkit.eval.signals import self_signals
from slamkit.pipeline.runner import Result

__all__ = ["CONVERGENCE", "CONVERGENCE_LOST", "Evaluation", "evaluate"]

CONVERGENCE = (0.5, 30.0)
"""``(threshold [m], hold [s])``: a run without a prior has converged once its position error
stays below 0.5 m for 30 s (:func:`slamkit.eval.convergence`)."""
CONVERGENCE_LOST = 1.0
"""Position error [m] above which a converged run counts as having lost the robot."""


@dataclass(frozen=True)
class Evaluation:
    """The typed scores of a run plus the matched arrays that plots need."""

    scores: RunScores
    matched_times: FloatArray | None = None
    errors: FloatArray | None = None
    """Per matched step ``(dx, dy, dtheta)`` estimate minus truth, no alignment."""
    aligned_errors: FloatArray | None = None
    """The same after the SE(2) alignment of the headline ATE (None: no ATE)."""
    sigmas: FloatArray | None = None
    """Per matched step standard deviations ``(3,)`` from the estimator's covariance."""
    nees: FloatArray | None = None

    @property
    def metrics(self) -> dict[str, Any]:
        """The scores in their ``metrics.json`` form (:meth:`RunScores.as_dict`)."""
        return self.scores.as_dict()


R = TypeVar("R")


def _scored(compute: Callable[[], R]) -> R | Skipped:
    """A metric, or why it could not be computed on this run (a path shorter than the RPE
    distance, a robot that never moved, maps without common landmarks)."""
    try:
        return compute()
    except SlamkitError as exc:
        return Skipped(str(exc))


def evaluate(result: Result, dataset: Dataset, *, max_dt: float | None = None) -> Evaluation:
    """ATE (SE(2)-aligned and unaligned), RPE over one step and over 10 m, NEES against the
    true trajectory, the time to converge of a run without a prior (:data:`CONVERGENCE`),
    the error against a position-only reference track (GPS, outliers
    rejected, SE(2)-aligned at its times), NIS statistics of the innovation log (windows of
    50 updates), landmark-map error (landmarks matched by id when the estimator's output
    says its ids are the data set's, by position otherwise), data-association scores
    against the true association of the readings, the relation metric against the data set's
    reference relations (:func:`~slamkit.eval.relation_errors`, default interpolation rule),
    and run times; what the estimator knows of itself (:func:`~slamkit.eval.signals.self_signals`);
    the consistency monitor's warnings (:mod:`slamkit.eval.monitor`: NEES
    and NIS over sliding windows against their χ² bands). Steps are matched by time
    stamp within ``max_dt`` (default: half the median step of the result)."""
    n = len(result)
    scores = RunScores(
        estimator=result.estimator,
        dataset=result.dataset,
        seed=result.seed,
        steps=n,
        runtime=RunTime(
            total_seconds=result.total_seconds,
            mean_step_seconds=float(result.step_seconds.mean()) if n else 0.0,
            max_step_seconds=float(result.step_seconds.max()) if n else 0.0,
        ),
        diagnostics=result.output.diagnostics,
    )
    truth = dataset.truth
    arrays: dict[str, Any] = {}
    if truth.times is not None and truth.poses is not None and n > 1:
        scores, arrays = _trajectory_scores(scores, result, dataset, max_dt)
    if truth.positions is not None and truth.position_times is not None and n > 1:
        gps_t, gps_xy = truth.position_times, truth.positions
        scores = replace(
            scores, gps=_scored(lambda: gps_error(result.times, result.poses, gps_t, gps_xy))
        )
    log = result.output.innovations
    if log is not None and len(log) > 0:
        scores = replace(
            scores, nis=_scored(lambda: nis_summary(log.times, log.nis, log.dof, window=50))
        )
    same_ids = _same_ids(result)
    if result.output.landmarks is not None and truth.landmarks is not None:
        est_map, true_map = result.output.landmarks.landmarks, truth.landmarks
        by: Literal["id", "position"] = "id" if same_ids else "position"
        scores = replace(
            scores,
            landmarks_matched_by=by,
            landmarks=_scored(lambda: landmark_map_error(est_map, true_map, match=by)),
        )
    chosen = result.output.reading_landmarks
    if chosen is not None and truth.reading_ids is not None:
        same = _same_ids(result)
        found = result.output.landmarks
        kept = None if found is None else found.landmarks.ids
        scores = replace(
            scores, association=_scored(lambda: _association(chosen, dataset, same, kept))
        )
    relations = truth.relations
    if relations is not None:
        scores = replace(
            scores,
            relations=_scored(lambda: relation_errors(result.times, result.poses, relations)),
        )
    nis = scores.nis if isinstance(scores.nis, NisSummary) else None
    signals = self_signals(result.output.diagnostics, nis)
    scores = replace(
        scores,
        signals=None if signals.empty else signals,
        warnings=(*_monitor(arrays, log), *result.output.warnings),
    )
    return Evaluation(scores, **arrays)


def _monitor(arrays: dict[str, Any], log: InnovationLog | None) -> tuple[ConsistencyWarning, ...]:
    """The consistency monitor over the run's NEES (steps with a regular covariance) and
    NIS (every update of the innovation log)."""
    found: list[ConsistencyWarning | None] = []
    values, times = arrays.get("nees"), arrays.get("matched_times")
    if values is not None and times is not None:
        ok = np.isfinite(values)
        found.append(nees_warning(times[ok], values[ok], 3))
    if log is not None and len(log) > 0:
        found.append(nis_warning(log.times, log.nis, log.dof))
    return tuple(w for w in found if w is not None)


def _same_ids(result: Result) -> bool:
    """Whether the estimator's landmark ids are the data set's: its output says so (an
    output that does not say is taken as numbering its own, which position matching and a
    relabelling association score handle either way)."""
    return result.output.landmark_numbering is LandmarkIds.DATASET


def _trajectory_scores(
    scores: RunScores, result: Result, dataset: Dataset, max_dt: float | None
) -> tuple[RunScores, dict[str, Any]]:
    """The scores against the true trajectory and the matched arrays for the plots."""
    truth = dataset.truth
    assert truth.times is not None and truth.poses is not None
    if max_dt is None:
        max_dt = 0.5 * float(np.median(np.diff(result.times)))
    ia, ib = associate(result.times, truth.times, max_dt)
    scores = replace(scores, matched_steps=int(ia.size))
    if ia.size < 2:
        return scores, {}
    est, ref = result.poses[ia], truth.poses[ib]
    err = pose_errors(est, ref)
    scores = replace(
        scores,
        ate=_scored(lambda: absolute_trajectory_error(est, ref, align="se2")),
        ate_unaligned=_scored(lambda: absolute_trajectory_error(est, ref, align="none")),
        rpe_1_step=_scored(lambda: relative_pose_error(est, ref, delta=1)),
        rpe_10_m=_scored(lambda: relative_pose_error(est, ref, delta=10.0, unit="meters")),
        final_position_error=float(np.hypot(*err[-1, :2])),
    )
    if dataset.initial_pose is None:  # a global start: when did it find the robot?
        position, heading = np.hypot(err[:, 0], err[:, 1]), np.abs(err[:, 2])
        threshold, hold = CONVERGENCE
        times = result.times[ia]
        scores = replace(
            scores,
            convergence=_scored(
                lambda: convergence(
                    times,
                    position,
                    threshold,
                    hold,
                    lost_threshold=CONVERGENCE_LOST,
                    heading_errors=heading,
                )
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
            scores = replace(
                scores,
                nees=NeesSummary(
                    mean=float(vals.mean()),
                    dof=3,
                    band_95=(lo, hi),
                    fraction_in_band=float(np.mean((vals >= lo) & (vals <= hi))),
                    steps=int(ok.sum()),
                ),
            )
    ate = scores.ate
    aligned = pose_errors(ate.aligned_estimate, ref) if isinstance(ate, TrajectoryError) else None
    arrays = {
        "matched_times": result.times[ia],
        "errors": err,
        "aligned_errors": aligned,
        "sigmas": sig,
        "nees": nees_vals,
    }
    return scores, arrays


def _association(
    chosen: np.ndarray, dataset: Dataset, same_ids: bool, kept: np.ndarray | None
) -> AssociationScores:
    true = dataset.check_reading_ids()
    if true.size != chosen.size:
        raise InputError(
            f"association: the estimator reported {chosen.size} readings, the data set has "
            f"{true.size}"
        )
    return association_scores(chosen, true, same_ids=same_ids, kept=kept)
