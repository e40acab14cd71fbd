"""Scores of SLAM output without shared ids: landmark matching by position, and the data
association against the true one."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.errors import InputError, ShapeError
from slamkit.eval import association_scores, landmark_map_error, match_landmarks
from slamkit.geometry.alignment import Similarity
from slamkit.maps import LandmarkMap
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate


def test_association_scores_hand_case() -> None:
    # true landmarks 1, 2, 3; estimate 10 holds landmark 1, 20 holds most of 2, 21 is a
    # duplicate of 2, 30 holds 3 and one reading of 1 (wrong), one reading unused, one unknown.
    true = np.array([1, 1, 1, 2, 2, 2, 2, 3, 3, 1, 3, -1])
    est = np.array([10, 10, 10, 20, 20, 20, 21, 30, 30, 30, -1, 40])
    s = association_scores(est, true)
    assert s.readings == 11 and s.used == 10
    assert s.accuracy == pytest.approx(8 / 11)  # wrong: the 21, the 30 of landmark 1, unused
    assert s.precision == pytest.approx(8 / 10)
    assert s.duplicates == 1 and s.merged == 0
    assert s.true_landmarks == 3 and s.estimated_landmarks == 4


def test_association_scores_with_the_truths_ids() -> None:
    # Localization in a known map: a landmark consistently taken for another is wrong, even
    # though it is "the estimate holding most of its readings".
    true = np.array([1, 1, 2, 2, 3])
    est = np.array([1, 1, 3, 3, -1])
    assert association_scores(est, true).accuracy == pytest.approx(4 / 5)
    s = association_scores(est, true, same_ids=True)
    assert s.accuracy == pytest.approx(2 / 5) and s.precision == pytest.approx(2 / 4)


def test_evaluate_scores_ml_association_of_ekf_localization() -> None:
    """EKF localization on the five-feature world without ids (maximum-likelihood
    association, χ² gate): every reading is paired with its true landmark (measured 893 of
    893, seed 0); unassociated readings would be reported, not forced."""
    ds = load_dataset("five-features", seed=0, options={"identities": False})
    m = evaluate(run("ekf-localization", ds, config={"association": "ml"}), ds).metrics
    a = m["association"]
    assert a["readings"] > 800 and a["accuracy"] > 0.995 and a["precision"] == 1.0
    assert (
        a["used"] + m["diagnostics"]["unassociated"] + m["diagnostics"]["rejected_by_gate"]
        == a["readings"]
    )


def test_association_scores_merge_and_bad_input() -> None:
    s = association_scores(np.array([5, 5, 5, 5]), np.array([1, 1, 2, 2]))
    assert s.merged == 1 and s.duplicates == 0 and s.accuracy == 1.0  # 5 is both's estimate
    with pytest.raises(ShapeError):
        association_scores(np.array([1, 2]), np.array([1]))
    with pytest.raises(InputError, match="no reading"):
        association_scores(np.array([1, 2]), np.array([-1, -1]))


def test_match_landmarks_finds_an_unknown_frame() -> None:
    """A map in a frame rotated by 2 rad and shifted by (5, -3) m, 25 of 30 landmarks, 5 cm
    noise, shuffled: every landmark paired with its true one, the frame recovered."""
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.0, 20.0, (30, 2))
    frame = Similarity.from_pose([5.0, -3.0, 2.0])
    keep = rng.permutation(30)[:25]
    est = frame.inverse().apply_to_points(truth[keep]) + rng.normal(0.0, 0.05, (25, 2))
    m = match_landmarks(est, truth)
    assert m.estimate_index.size == 25
    np.testing.assert_array_equal(keep[m.estimate_index], m.truth_index)
    np.testing.assert_allclose(m.alignment.as_pose(), [5.0, -3.0, 2.0], atol=0.05)
    # in the same frame, without alignment: the identity pairs them directly
    same = match_landmarks(truth[keep] + 0.01, truth, align=False)
    np.testing.assert_array_equal(keep[same.estimate_index], same.truth_index)


def test_landmark_map_error_by_position_reports_spurious_and_missing() -> None:
    truth = LandmarkMap.from_positions(np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0], [4, 4]]))
    est = LandmarkMap(np.array([[0.1, 0.0], [4.0, 0.1], [0.0, 3.9], [9.0, 9.0]]),
                      np.array([100, 101, 102, 103]))  # fmt: skip
    err = landmark_map_error(est, truth, match="position", align=False)
    assert err.n_matched == 3 and err.n_missing == 1 and err.n_spurious == 1
    np.testing.assert_array_equal(err.spurious_ids, [103])
    assert err.rmse == pytest.approx(0.1)
    with pytest.raises(InputError, match="share no landmark id"):
        landmark_map_error(est, truth, match="id")


def test_evaluate_scores_an_unlabelled_slam_run() -> None:
    """EKF-SLAM on the cluttered world without ids: evaluate() pairs its own-numbered map
    with the truth by position and scores the association against the simulator's true
    ids. Measured (seed 0): 139 of 150 landmarks mapped (the others never in range), RMSE
    0.047 m; accuracy 0.998, precision 1.0, no duplicate."""
    ds = load_dataset("landmark-clutter", seed=0)
    assert ds.truth.reading_ids is not None
    result = run("ekf-slam", ds, config={"use_ids": False}, seed=0)
    m = evaluate(result, ds).metrics
    assert m["landmarks_matched_by"] == "position"
    assert m["landmarks"]["n_matched"] >= 130 and m["landmarks"]["rmse"] < 0.08
    a = m["association"]
    assert a["readings"] > 2500 and a["accuracy"] > 0.99 and a["duplicates"] == 0


def test_evaluate_reports_convergence_of_a_global_start_only() -> None:
    """A run without a prior (MCL from a uniform start in the rooms world) gets the time to
    converge (error below 0.5 m held for 30 s) and the error after it; a run with a prior
    does not. Measured (seed 0): converged after 1.2 s, median error after 0.042 m."""
    ds = load_dataset("rooms-laser-global", seed=0)
    assert ds.initial_pose is None
    m = evaluate(run("mcl", ds, seed=0), ds).metrics
    c = m["convergence"]
    assert c["converged"] and c["time_s"] < 10.0 and c["lost_episodes"] == 0
    assert c["position_error_after"]["median"] < 0.08
    tracked = load_dataset("five-features", seed=0)
    assert "convergence" not in evaluate(run("ekf-localization", tracked), tracked).metrics
