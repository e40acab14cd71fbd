"""evaluate() returns typed scores; JSON only in their as_dict() form."""

from __future__ import annotations

import json

import numpy as np

import slamkit.datasets as ds
from slamkit.estimation import LandmarkIds
from slamkit.eval import (
    AssociationScores,
    LandmarkError,
    TrajectoryError,
    absolute_trajectory_error,
    associate,
)
from slamkit.eval.records import RunScores, Skipped
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate


def test_scores_are_typed_and_their_json_form_matches() -> None:
    data = ds.load_dataset("five-features", seed=0)
    result = run("dead-reckoning", data)
    ev = evaluate(result, data)
    assert isinstance(ev.scores, RunScores)
    assert isinstance(ev.scores.ate, TrajectoryError)
    assert data.truth.times is not None and data.truth.poses is not None
    ia, ib = associate(result.times, data.truth.times, 0.5 * np.median(np.diff(result.times)))
    want = absolute_trajectory_error(result.poses[ia], data.truth.poses[ib], align="se2")
    assert ev.scores.ate.rmse == want.rmse > 0.0 and ev.scores.matched_steps == ia.size
    m = ev.metrics
    assert m["ate"]["rmse"] == ev.scores.ate.rmse
    assert m == json.loads(json.dumps(m))  # plain values only
    assert "gps" not in m and ev.scores.gps is None  # no GPS to score against


def test_a_metric_that_does_not_apply_is_skipped_with_its_reason() -> None:
    data = ds.load_dataset("five-features", seed=0)
    short = ds.Dataset(
        name="short",
        events=data.events[:6],
        motion=data.motion,
        landmark_sensor=data.landmark_sensor,
        initial_pose=data.initial_pose,
        initial_cov=data.initial_cov,
        truth=data.truth,
    )
    ev = evaluate(run("dead-reckoning", short), short)
    assert isinstance(ev.scores.rpe_10_m, Skipped) and ev.scores.rpe_10_m.reason
    assert ev.metrics["rpe_10_m"] == {"skipped": ev.scores.rpe_10_m.reason}


def test_localization_says_its_ids_are_the_maps() -> None:
    data = ds.load_dataset("five-features", seed=1)
    result = run("ekf-localization", data, config={"association": "ml"})
    assert result.output.landmark_numbering is LandmarkIds.DATASET
    ev = evaluate(result, data)
    assert isinstance(ev.scores.association, AssociationScores)
    # scored with exact ids: a reading is correct only with its true landmark
    true = data.check_reading_ids()
    chosen = result.output.reading_landmarks
    assert chosen is not None
    used = chosen >= 0
    exact = float(np.mean(chosen[used & (true >= 0)] == true[used & (true >= 0)]))
    assert abs(ev.scores.association.accuracy - exact) < 0.05


def test_a_map_numbered_by_the_filter_is_paired_by_position() -> None:
    """FastSLAM 2.0 on the cluttered world without ids numbers its own landmarks; its output
    says so, and evaluation pairs its map with the true one by position. (Matched by id, as
    before the output said so, the same map scored a landmark RMSE of 17.4 m.)"""
    data = ds.load_dataset("landmark-clutter", seed=0)
    result = run("fastslam2", data, seed=0)
    assert result.output.landmark_numbering is LandmarkIds.OWN
    scores = evaluate(result, data).scores
    assert scores.landmarks_matched_by == "position"
    lm = scores.landmarks
    assert isinstance(lm, LandmarkError)
    assert lm.rmse < 2.0 and lm.n_matched > 120  # measured: 0.063 m, 139 landmarks
    assert isinstance(scores.association, AssociationScores)
    assert scores.association.accuracy > 0.99
