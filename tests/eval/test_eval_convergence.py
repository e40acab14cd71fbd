"""Time to converge, error after convergence and lost-tracking time (slamkit.eval.convergence)
on hand-made error tracks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from slamkit.errors import InputError
from slamkit.eval.convergence import convergence, convergence_against_truth


def test_hand_values_of_a_track_that_converges_loses_and_regains() -> None:
    # 1 s samples: wrong for 3 s, a 1-sample dip below the threshold at t = 1 that does not
    # hold, converged from t = 3, lost at t = 7 and 8, fine again after.
    t = np.arange(12.0)
    err = np.array([5.0, 0.1, 4.0, 0.2, 0.1, 0.3, 0.1, 2.0, 3.0, 0.2, 0.1, 0.1])
    head = np.full(12, 0.05)
    r = convergence(t, err, threshold=0.5, hold=3.0, heading_errors=head)
    assert r.converged and r.step == 3 and r.time == 3.0
    assert r.duration == 11.0
    pe = r.position_error
    assert pe is not None and pe.count == 9
    after = err[3:]
    assert pe.median == pytest.approx(np.median(after))
    assert pe.mean == pytest.approx(after.mean())
    assert pe.rmse == pytest.approx(np.sqrt(np.mean(after**2)))
    assert pe.max == 3.0
    assert r.heading_error is not None and r.heading_error.max == pytest.approx(0.05)
    # Lost at t = 7 and 8 (each sample holds 1 s) of the 8 s after t = 3; one episode.
    assert r.lost_fraction == pytest.approx(2.0 / 8.0)
    assert r.lost_episodes == 1
    # A longer hold skips past the loss: from t = 9 the error stays below for 2 s.
    r = convergence(t, err, threshold=0.5, hold=2.0)
    assert r.step == 3  # t = 3..5 all below: 2 s held
    r = convergence(t, err, threshold=0.5, hold=4.0)
    assert r.step is None and not r.converged  # 3..6 spans 3 s; 9..11 only 2 s
    assert r.position_error is None and r.lost_fraction is None
    # hold = 0: the first sample below the threshold.
    assert convergence(t, err, 0.5, 0.0).step == 1
    # A separate lost threshold: 2.5 m counts only t = 8 as lost.
    r = convergence(t, err, 0.5, 3.0, lost_threshold=2.5)
    assert r.lost_fraction == pytest.approx(1.0 / 8.0) and r.lost_episodes == 1


def test_irregular_samples_weigh_by_the_time_they_hold() -> None:
    # Converged at once; the sample at t = 1 is lost and holds 9 s of the 10 s.
    t = np.array([0.0, 1.0, 10.0, 10.5])
    err = np.array([0.1, 1.0, 0.1, 0.1])
    # t = 0: the window [0, 0.9] holds only t = 0 itself, so it converges there.
    r = convergence(t, err, threshold=0.5, hold=0.9)
    assert r.step == 0
    assert r.lost_fraction == pytest.approx(9.0 / 10.5)
    assert r.lost_episodes == 1


def test_the_record_must_reach_the_end_of_the_hold() -> None:
    t = np.arange(5.0)
    err = np.array([1.0, 1.0, 1.0, 0.1, 0.1])
    assert convergence(t, err, 0.5, 1.0).step == 3
    assert not convergence(t, err, 0.5, 1.5).converged  # only 1 s of record left
    assert convergence(np.zeros(1), np.zeros(1), 0.5, 0.0).step == 0


def test_against_truth_pairs_times_and_reports_json() -> None:
    truth_t = np.arange(0.0, 20.0, 0.5)
    truth = np.column_stack([truth_t, np.zeros_like(truth_t), np.full_like(truth_t, 3.1)])
    est_t = truth_t[::2] + 0.001
    est = truth[::2].copy()
    est[:5, 0] += 3.0  # wrong for the first 5 estimates (t = 0 .. 4 s)
    est[:, 2] = -3.1  # heading error wraps: |−3.1 − 3.1| = 2π − 6.2
    r = convergence_against_truth(est_t, est, truth_t, truth, threshold=0.25, hold=5.0)
    assert r.converged and r.step == 5 and r.time == pytest.approx(5.0)
    assert r.position_error is not None and r.position_error.max == pytest.approx(0.0, abs=1e-12)
    assert r.heading_error is not None
    assert r.heading_error.median == pytest.approx(2 * np.pi - 6.2)
    assert r.lost_fraction == 0.0 and r.lost_episodes == 0
    d = json.loads(json.dumps(r.as_dict()))
    assert d["time_s"] == pytest.approx(5.0) and d["position_error_after"]["count"] == 15
    with pytest.raises(InputError, match="max_dt"):
        convergence_against_truth(est_t + 1.0, est, truth_t[:1], truth[:1], 0.25, 1.0)


def test_bad_input() -> None:
    t = np.arange(3.0)
    with pytest.raises(InputError, match="non-decreasing"):
        convergence(t[::-1], np.zeros(3), 0.5, 1.0)
    with pytest.raises(InputError, match="threshold"):
        convergence(t, np.zeros(3), 0.0, 1.0)
    with pytest.raises(InputError, match="hold"):
        convergence(t, np.zeros(3), 0.5, -1.0)
    with pytest.raises(InputError, match=">= 0"):
        convergence(t, -np.ones(3), 0.5, 1.0)
    with pytest.raises(InputError, match="at least one"):
        convergence(np.zeros(0), np.zeros(0), 0.5, 1.0)
    with pytest.raises(InputError):
        convergence(t, np.array([0.0, np.nan, 0.0]), 0.5, 1.0)
    with pytest.raises(InputError, match="lost_threshold"):
        convergence(t, np.zeros(3), 0.5, 1.0, lost_threshold=0.0)
