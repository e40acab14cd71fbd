"""Maximum-likelihood data association with a χ² gate."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import Control, LandmarkReadings, load_dataset
from slamkit.errors import CovarianceError, InputError, NonFiniteError
from slamkit.geometry import wrap_angle
from slamkit.localization import GaussianBelief
from slamkit.localization.association import Association, associate_ml
from slamkit.localization.ekf import ekf_predict, ekf_update
from slamkit.maps import LandmarkMap
from slamkit.models import BearingOnly, RangeBearing, RangeOnly
from slamkit.prob import chi2_gate, mahalanobis_squared

R_RB = np.diag([0.1**2, np.deg2rad(2.0) ** 2])


def _brute_force_d2(belief, z, landmarks, model, R):
    """The reference: a Python double loop over readings and landmarks."""
    out = np.empty((len(z), len(landmarks)))
    for k, zk in enumerate(z):
        for j, l in enumerate(landmarks.positions):
            Hp, _ = model.jacobians(belief.pose, l)
            S = Hp @ belief.pose_cov @ Hp.T + R
            nu = model.residual(zk, model.predict(belief.pose, l))
            out[k, j] = float(mahalanobis_squared(nu, S))
    return out


@pytest.mark.parametrize(
    "model,R",
    [(RangeBearing(), R_RB), (RangeOnly(), [[0.01]]), (BearingOnly(), [[0.002]])],
    ids=["range-bearing", "range", "bearing"],
)
def test_vectorised_distances_match_a_double_loop(model, R):
    rng = np.random.default_rng(0)
    landmarks = LandmarkMap(rng.uniform(-10, 10, (7, 2)), np.arange(10, 17))
    belief = GaussianBelief([0.5, -0.3, 2.9], np.diag([0.04, 0.09, 0.02]))
    z = np.array([model.sample(belief.pose, l, R, rng) for l in landmarks.positions[[3, 1, 6]]])
    ref = _brute_force_d2(belief, z, landmarks, model, R)
    a = associate_ml(belief, z, landmarks, model, R, gate_probability=0.99)
    np.testing.assert_allclose(a.d2, ref.min(axis=1), rtol=1e-10)
    gate = chi2_gate(model.dim, 0.99)
    expected = np.where(ref.min(axis=1) <= gate, landmarks.ids[ref.argmin(axis=1)], -1)
    np.testing.assert_array_equal(a.landmark_ids, expected)
    assert a.landmark_ids.dtype == np.int64


def test_hand_case_nearest_inside_gate_and_far_reading_unassociated():
    landmarks = LandmarkMap(np.array([[5.0, 0.0], [0.0, 5.0], [5.0, 0.3]]), np.array([7, 8, 9]))
    belief = GaussianBelief([0.0, 0.0, 0.0], np.diag([0.01, 0.01, 1e-4]))
    m = RangeBearing()
    z = np.array(
        [
            m.predict(belief.pose, [5.0, 0.0]) + np.array([0.02, 0.002]),  # 7 (9: 0.3 m off)
            m.predict(belief.pose, [0.0, 5.0]),  # landmark 8 exactly
            [20.0, 2.0],  # nowhere near any landmark
            [5.0, wrap_angle(np.pi + 0.01)],  # right range, opposite direction
        ]
    )
    a = associate_ml(belief, z, landmarks, m, R_RB)
    assert isinstance(a, Association)
    np.testing.assert_array_equal(a.landmark_ids, [7, 8, -1, -1])
    np.testing.assert_array_equal(a.associated, [True, True, False, False])
    assert a.d2[1] == pytest.approx(0.0, abs=1e-20)
    assert a.d2[2] > chi2_gate(2, 0.99) and np.isfinite(a.d2[2])
    # Never forced: with a tiny gate even the good reading of landmark 7 is rejected.
    tight = associate_ml(belief, z[:1], landmarks, m, R_RB, gate_probability=1e-6)
    np.testing.assert_array_equal(tight.landmark_ids, [-1])


def test_empty_inputs():
    belief = GaussianBelief([0.0, 0.0, 0.0], np.eye(3) * 0.01)
    m = RangeBearing()
    landmarks = LandmarkMap(np.array([[5.0, 0.0]]), np.array([3]))
    a = associate_ml(belief, np.empty((0, 2)), landmarks, m, R_RB)
    assert a.landmark_ids.shape == (0,) and a.d2.shape == (0,)
    empty_map = LandmarkMap(np.empty((0, 2)), np.empty(0, dtype=np.int64))
    b = associate_ml(belief, [[5.0, 0.0]], empty_map, m, R_RB)
    np.testing.assert_array_equal(b.landmark_ids, [-1])
    assert b.d2[0] == np.inf
    # A landmark on the sensor has no bearing: it is skipped, not an error.
    on_top = LandmarkMap(np.array([[0.0, 0.0], [5.0, 0.0]]), np.array([1, 2]))
    c = associate_ml(belief, [[5.0, 0.0]], on_top, m, R_RB)
    np.testing.assert_array_equal(c.landmark_ids, [2])


def test_bad_input_raises_typed_errors():
    belief = GaussianBelief([0.0, 0.0, 0.0], np.eye(3) * 0.01)
    landmarks = LandmarkMap(np.array([[5.0, 0.0]]), np.array([3]))
    m = RangeBearing()
    with pytest.raises(NonFiniteError):
        associate_ml(belief, [[np.nan, 0.0]], landmarks, m, R_RB)
    with pytest.raises(CovarianceError):
        associate_ml(belief, [[5.0, 0.0]], landmarks, m, np.diag([0.01, -0.01]))
    with pytest.raises(InputError):
        associate_ml(belief, [[5.0, 0.0]], landmarks, m, R_RB, gate_probability=1.5)
    with pytest.raises(InputError):
        associate_ml(belief, [[5.0]], landmarks, m, R_RB)
    with pytest.raises(InputError):
        associate_ml(belief, [[5.0, 0.0]], np.array([[5.0, 0.0]]), m, R_RB)


def test_reproduces_the_true_ids_in_five_features():
    # The simulator's identities=False variant draws extra random numbers (it shuffles each
    # scan), so its readings differ from the identities=True build after the first scan and
    # cannot be matched to it by value. The truth therefore comes from the identities=True
    # build with the ids stripped here and each scan shuffled by the test's own generator.
    # An EKF driven only by the ML associations tracks the robot.
    # Measured (seeds 0..4): gate 0.999 → 99.93 % correct, 0 wrong; gate 0.99 → 99.2 %
    # correct (the gate rejects 1 % of the correct associations by design), 0 wrong.
    total = correct = wrong = 0
    for seed in range(3):
        ds = load_dataset("five-features", seed=seed)
        rng = np.random.default_rng(100 + seed)
        model, R = ds.landmark_sensor.model(), ds.landmark_sensor.noise_cov
        landmarks = ds.known_landmarks
        b = GaussianBelief(ds.initial_pose, ds.initial_cov)
        for ev in ds.events:
            if isinstance(ev, Control):
                b = ekf_predict(b, ev.u, ev.dt, ds.motion.model, ds.motion.noise_cov)
                continue
            assert isinstance(ev, LandmarkReadings)
            order = rng.permutation(ev.ids.size)
            z, truth = ev.z[order], ev.ids[order]
            a = associate_ml(b, z, landmarks, model, R, gate_probability=0.999)
            total += truth.size
            correct += int(np.sum(a.landmark_ids == truth))
            wrong += int(np.sum((a.landmark_ids != truth) & a.associated))
            for j in np.flatnonzero(a.associated):
                l = landmarks.position_of([a.landmark_ids[j]])[0]
                b, _ = ekf_update(b, z[j], l, model, R)
    assert total > 2500
    assert correct / total >= 0.99, correct / total
    assert wrong == 0
