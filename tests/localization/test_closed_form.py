"""The closed-form EKF/UKF steps against the general ones: the same numbers to 1e-12 over
simulated runs, the same fallbacks and the same errors, and the choice made from the models."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from slamkit.errors import ConvergenceError, GeometryError
from slamkit.geometry import wrap_angle
from slamkit.localization.closed_form import EkfClosedForm, UkfClosedForm, closed_form_supports
from slamkit.localization.ekf import GeneralEkfSteps, choose_ekf_steps
from slamkit.localization.ukf import (
    GeneralUkfSteps,
    SigmaPointParams,
    choose_ukf_steps,
    psd_sqrt,
)
from slamkit.models import (
    BearingOnly,
    DifferentialDrive,
    OdometryModel,
    RangeBearing,
    RangeOnly,
    UnicycleArc,
    UnicycleEuler,
)

TOL = 1e-12
"""Closed form against general steps, absolute, on means (metres, radians) and covariances
(m², rad²) of a whole run: the two differ by the order of their roundings only."""

LANDMARKS = np.array([[6.0, 4.0], [-3.0, 7.0], [2.0, -6.0], [9.0, -1.0]])
R_RB = np.array([[0.1**2, 1e-4], [1e-4, np.deg2rad(2.0) ** 2]])

CONTROLS = {
    UnicycleEuler: (lambda k: np.array([1.0, 0.25 + 0.2 * math.sin(0.02 * k)]), 0.1),
    UnicycleArc: (lambda k: np.array([1.0, 0.3 * math.cos(0.03 * k)]), 0.1),
    DifferentialDrive: (lambda k: np.array([0.9, 1.1 + 0.1 * math.sin(0.05 * k)]), 0.1),
    OdometryModel: (lambda k: np.array([0.02 * math.sin(0.1 * k), 0.1, -0.01]), 0.0),
}


def _model(kind: type) -> object:
    return kind(0.5) if kind is DifferentialDrive else kind()


def _Q(k: int) -> np.ndarray:
    return np.diag([0.1**2, np.deg2rad(5.0) ** 2, 0.02**2][:k]) + 1e-5 * (k == 2)


def _simulated(model: object, steps: int, seed: int) -> list[tuple[np.ndarray, float, list]]:
    """Controls and the readings of every landmark at every step of a noisy drive."""
    rng = np.random.default_rng(seed)
    control, dt = CONTROLS[type(model)]
    k = model.control_dim  # type: ignore[attr-defined]
    sensor = RangeBearing()
    x = np.array([0.5, -0.3, 3.0])  # starts near the heading wrap at ±π
    out = []
    for step in range(1, steps + 1):
        u = control(step)
        x = model.apply(x, u + rng.multivariate_normal(np.zeros(k), _Q(k)), dt)  # type: ignore[attr-defined]
        z = sensor.predict(x, LANDMARKS) + rng.multivariate_normal(np.zeros(2), R_RB, 4)
        z[:, 1] = wrap_angle(z[:, 1])
        out.append((u, dt, list(z)))
    return out


def _run_both(fast, general, steps, mean, cov):
    """Both step objects along the same run, each on its own state; the largest differences
    of the means (heading difference wrapped) and covariances, and the NIS."""
    m1, P1, m2, P2 = mean, cov, mean.copy(), cov.copy()
    worst_mean = worst_cov = worst_nis = 0.0
    for u, dt, readings in steps:
        m1, P1 = fast.predict(m1, P1, u, dt)
        m2, P2 = general.predict(m2, P2, u, dt)
        for j, z in enumerate(readings):
            m1, P1, n1 = fast.update(m1, P1, z, LANDMARKS[j])
            m2, P2, n2 = general.update(m2, P2, z, LANDMARKS[j])
            worst_nis = max(worst_nis, abs(n1 - n2) / max(1.0, abs(n2)))
        d = np.abs(m1 - m2)
        d[2] = abs(float(wrap_angle(m1[2] - m2[2])))
        worst_mean = max(worst_mean, float(d.max()))
        worst_cov = max(worst_cov, float(np.abs(P1 - P2).max()))
        assert np.array_equal(P1, P1.T)
    return worst_mean, worst_cov, worst_nis


START_COV = np.diag([0.1**2, 0.1**2, np.deg2rad(5.0) ** 2])


@pytest.mark.parametrize("kind", [UnicycleEuler, UnicycleArc, DifferentialDrive, OdometryModel])
def test_ekf_closed_form_equals_general_steps_over_a_run(kind):
    model = _model(kind)
    Q = _Q(model.control_dim)
    fast = choose_ekf_steps(model, RangeBearing(), Q, R_RB)
    assert isinstance(fast, EkfClosedForm)
    general = GeneralEkfSteps(model, RangeBearing(), Q, R_RB)
    start = np.array([0.5, -0.3, 3.0])
    worst = _run_both(fast, general, _simulated(model, 300, 1), start, START_COV)
    assert max(worst) < TOL, worst


@pytest.mark.parametrize(
    ("kind", "params"),
    [
        (UnicycleEuler, SigmaPointParams()),
        (UnicycleEuler, SigmaPointParams(alpha=0.5, beta=2.0, kappa=1.0)),
        (UnicycleArc, SigmaPointParams()),  # the general prediction, the closed-form update
        (UnicycleArc, SigmaPointParams(alpha=0.5, beta=2.0, kappa=1.0)),
        (DifferentialDrive, SigmaPointParams()),
        (OdometryModel, SigmaPointParams()),
    ],
    ids=lambda v: v.__name__ if isinstance(v, type) else f"alpha{v.alpha}",
)
def test_ukf_closed_form_equals_general_steps_over_a_run(kind, params):
    model = _model(kind)
    Q = _Q(model.control_dim)
    sqrt_Q = psd_sqrt(Q, "Q")
    fast = choose_ukf_steps(model, RangeBearing(), Q, sqrt_Q, R_RB, params)
    assert isinstance(fast, UkfClosedForm)
    general = GeneralUkfSteps(model, RangeBearing(), Q, sqrt_Q, R_RB, params)
    start = np.array([0.5, -0.3, 3.0])
    worst = _run_both(fast, general, _simulated(model, 300, 2), start, START_COV)
    assert max(worst) < TOL, worst


def test_a_known_start_takes_the_general_steps_first_step():
    # Zero covariance: no Cholesky factor, so the UKF's closed form hands the step to the
    # general one (root from eigh); the EKF's closed form needs no root. Same numbers.
    model, Q = UnicycleEuler(), _Q(2)
    sqrt_Q = psd_sqrt(Q, "Q")
    params = SigmaPointParams()
    pairs = [
        (
            choose_ekf_steps(model, RangeBearing(), Q, R_RB),
            GeneralEkfSteps(model, RangeBearing(), Q, R_RB),
        ),
        (
            choose_ukf_steps(model, RangeBearing(), Q, sqrt_Q, R_RB, params),
            GeneralUkfSteps(model, RangeBearing(), Q, sqrt_Q, R_RB, params),
        ),
    ]
    for fast, general in pairs:
        worst = _run_both(fast, general, _simulated(model, 20, 3), np.zeros(3), np.zeros((3, 3)))
        assert max(worst) < TOL, (type(fast).__name__, worst)
        m, P, _ = fast.update(np.zeros(3), np.zeros((3, 3)), np.array([5.0, 0.5]), LANDMARKS[0])
        _, P2, _ = general.update(np.zeros(3), np.zeros((3, 3)), np.array([5.0, 0.5]), LANDMARKS[0])
        np.testing.assert_array_equal(m, np.zeros(3))  # a known pose does not move
        np.testing.assert_allclose(P, P2, rtol=0, atol=TOL)


@dataclass(frozen=True)
class ScaledRangeBearing(RangeBearing):
    """A subclass may change the equations: the closed form must not take it."""


def test_the_choice_follows_the_models():
    Q2, Q3 = _Q(2), _Q(3)
    params = SigmaPointParams()
    assert closed_form_supports(UnicycleEuler(), RangeBearing()) == (True, True, True)
    assert closed_form_supports(UnicycleArc(), RangeBearing()) == (True, True, False)
    for meas in (RangeOnly(), BearingOnly(), ScaledRangeBearing()):
        assert closed_form_supports(UnicycleEuler(), meas) == (False, False, False)
        R = np.eye(meas.dim) * 0.01
        assert isinstance(choose_ekf_steps(UnicycleEuler(), meas, Q2, R), GeneralEkfSteps)
        steps = choose_ukf_steps(UnicycleEuler(), meas, Q2, psd_sqrt(Q2, "Q"), R, params)
        assert isinstance(steps, GeneralUkfSteps)
    # odometry (three controls): the EKF's closed form; the UKF's update only
    assert isinstance(choose_ekf_steps(OdometryModel(), RangeBearing(), Q3, R_RB), EkfClosedForm)
    ukf = choose_ukf_steps(OdometryModel(), RangeBearing(), Q3, psd_sqrt(Q3, "Q"), R_RB, params)
    assert isinstance(ukf, UkfClosedForm)


def _both_kinds():
    model, Q = UnicycleEuler(), _Q(2)
    sqrt_Q, params = psd_sqrt(Q, "Q"), SigmaPointParams()
    return [
        (
            choose_ekf_steps(model, RangeBearing(), Q, R_RB),
            GeneralEkfSteps(model, RangeBearing(), Q, R_RB),
        ),
        (
            choose_ukf_steps(model, RangeBearing(), Q, sqrt_Q, R_RB, params),
            GeneralUkfSteps(model, RangeBearing(), Q, sqrt_Q, R_RB, params),
        ),
    ]


@pytest.mark.parametrize("which", [0, 1], ids=["ekf", "ukf"])
def test_errors_are_the_general_steps_errors(which):
    fast, general = _both_kinds()[which]
    mean, cov = np.array([1.0, 2.0, 0.3]), np.diag([0.01, 0.01, 0.001])
    z = np.array([1.0, 0.0])
    # a landmark on the sensor: no bearing
    for steps in (fast, general):
        with pytest.raises(GeometryError, match="closer than 1e-09 m"):
            steps.update(mean, 1e-24 * cov, z, mean[:2].copy())
    # a covariance that has lost definiteness: the one check's message, from both
    bad = np.diag([0.01, 0.01, -0.5])
    messages = []
    for steps in (fast, general):
        with pytest.raises(ConvergenceError) as err:
            steps.predict(mean, bad, np.array([1.0, 0.1]), 0.1)
        messages.append(str(err.value))
    assert messages[0] == messages[1]
    assert "lost positive definiteness" in messages[0]
    # a non-finite covariance (NumPy's warnings on the way are not the point)
    for steps in (fast, general):
        with np.errstate(all="ignore"), pytest.raises(ConvergenceError, match="non-finite"):
            steps.predict(mean, np.full((3, 3), np.inf), np.array([1.0, 0.1]), 0.1)
