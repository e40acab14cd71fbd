"""Dead reckoning: the propagated covariance grows and matches Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import Control, Dataset, MotionSpec, Odometry, load_dataset
from slamkit.errors import InputError
from slamkit.geometry import pose2, wrap_angle
from slamkit.localization import GaussianBelief, predict
from slamkit.models import (
    Ackermann,
    DifferentialDrive,
    OdometryModel,
    UnicycleArc,
    UnicycleEuler,
)
from slamkit.pipeline import run

CASES = [
    (UnicycleEuler(), np.array([1.0, 0.3]), 0.1, np.diag([0.05**2, 0.02**2])),
    (UnicycleArc(), np.array([1.0, 0.3]), 0.1, np.diag([0.05**2, 0.02**2])),
    (DifferentialDrive(0.5), np.array([0.9, 1.1]), 0.1, np.diag([0.03**2, 0.03**2])),
    (OdometryModel(), np.array([0.02, 0.1, -0.01]), 0.0, np.diag([0.005**2, 0.01**2, 0.005**2])),
    (
        Ackermann(2.83, sensor_offset=(3.78, 0.5), encoder_offset=0.76),
        np.array([3.0, 0.1]),
        0.025,
        np.diag([0.1**2, np.deg2rad(1.0) ** 2]),
    ),
]


@pytest.mark.parametrize("model,u,dt,Q", CASES, ids=lambda c: type(c).__name__)
def test_covariance_grows_and_matches_monte_carlo(model, u, dt, Q):
    rng = np.random.default_rng(4)
    steps, runs = 40, 4000
    belief = GaussianBelief.from_pose([1.0, -2.0, 0.4])
    particles = np.tile(belief.mean, (runs, 1))
    traces = []
    for _ in range(steps):
        belief = predict(belief, u, dt, model, Q)
        particles = model.sample(particles, u, dt, Q, rng)
        traces.append(np.trace(belief.cov))
    # Monotone growth of the uncertainty without measurements.
    assert np.all(np.diff(traces) > 0)
    # Sample mean and covariance of the Monte Carlo particles against the propagation.
    err = particles - belief.mean
    err[:, 2] = wrap_angle(err[:, 2])
    sample_cov = np.cov(err.T)
    sd = np.sqrt(np.diag(belief.cov))
    np.testing.assert_allclose(
        err.mean(axis=0), 0.0, atol=5 * sd.max() / np.sqrt(runs) + 0.02 * sd.max()
    )
    # Linearisation is accurate for these small noises: within 10 % (sampling error ~3 %).
    corr = sample_cov / np.outer(sd, sd)
    np.testing.assert_allclose(np.sqrt(np.diag(sample_cov)) / sd, 1.0, atol=0.1)
    np.testing.assert_allclose(corr, belief.cov / np.outer(sd, sd), atol=0.08)


def test_dead_reckoning_estimator_on_five_features_is_consistent_over_seeds():
    # Mean NEES over seeds of the final pose is close to 3 (the state dimension): the
    # propagated covariance is neither optimistic nor pessimistic.
    vals = []
    for seed in range(40):
        ds = load_dataset("five-features", seed=seed)
        res = run("dead-reckoning", ds, seed=seed)
        np.testing.assert_array_equal(res.times, ds.truth.times)
        e = res.poses[-1] - ds.truth.poses[-1]
        e[2] = wrap_angle(e[2])
        vals.append(e @ np.linalg.solve(res.covariances[-1], e))
    mean = float(np.mean(vals))
    # Two-sided 95 % band of the average of 40 χ²(3) values: [2.36, 3.72].
    assert 2.36 < mean < 3.72, mean


def test_odometry_stream_dead_reckoning_reproduces_odometry_path():
    # With an odometry-pose stream, dead reckoning from the first odometry pose traces the
    # odometry path exactly (up to its starting frame).
    rng = np.random.default_rng(0)
    odo = np.cumsum(rng.normal(0, 0.1, (50, 3)), axis=0)
    odo[:, 2] = wrap_angle(odo[:, 2])
    events = tuple(Odometry(float(i), odo[i]) for i in range(50))
    ds = Dataset(
        "odo",
        events,
        motion=MotionSpec(OdometryModel(), np.diag([1e-4, 1e-4, 1e-4]), source="odometry"),
        initial_pose=odo[0],
    )
    res = run("dead-reckoning", ds)
    np.testing.assert_allclose(
        pose2.between(res.poses[0], res.poses[-1]), pose2.between(odo[0], odo[-1]), atol=1e-9
    )


def test_dead_reckoning_needs_a_motion_model():
    ds = Dataset("empty", ())
    with pytest.raises(InputError, match="motion"):
        run("dead-reckoning", ds)


def test_control_event_without_motion_spec_is_rejected():
    with pytest.raises(InputError, match="Control"):
        Dataset("bad", (Control(0.0, np.zeros(2), 0.1),))
