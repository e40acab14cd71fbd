"""Linear Kalman filter: hand values, the class against the functions, the Joseph form."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamkit.errors import ConvergenceError, CovarianceError, NonFiniteError, ShapeError
from slamkit.estimation.kalman import Gaussian, KalmanFilter, kf_predict, kf_update
from slamkit.localization import GaussianBelief

# A 1-D constant-velocity target: state (position, velocity), position observed.
A_CV = np.array([[1.0, 1.0], [0.0, 1.0]])
Q_CV = np.diag([0.0, 0.1])  # noise on the velocity only: positive semi-definite
H_POS = np.array([[1.0, 0.0]])


def _random_spd(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    M = rng.normal(size=(n, n))
    return scale * (M @ M.T + 0.5 * np.eye(n))


def test_constant_velocity_hand_values():
    g = Gaussian([0.0, 1.0], np.eye(2))
    g = kf_predict(g, A_CV, None, None, Q_CV)
    # A P Aᵀ + Q = [[2, 1], [1, 1.1]], mean (1, 1).
    np.testing.assert_allclose(g.mean, [1.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(g.cov, [[2.0, 1.0], [1.0, 1.1]], atol=1e-15)
    g2, info = kf_update(g, [1.5], H_POS, [[1.0]])
    # S = 3, K = (2/3, 1/3), ν = 0.5.
    np.testing.assert_allclose(info.S, [[3.0]], atol=1e-15)
    np.testing.assert_allclose(info.innovation, [0.5], atol=1e-15)
    assert info.nis == pytest.approx(0.25 / 3.0, abs=1e-15)
    np.testing.assert_allclose(g2.mean, [1.0 + 1.0 / 3.0, 1.0 + 1.0 / 6.0], atol=1e-15)
    np.testing.assert_allclose(
        g2.cov, [[2.0 / 3.0, 1.0 / 3.0], [1.0 / 3.0, 1.1 - 1.0 / 3.0]], atol=1e-14
    )
    # Inputs are frozen values and are not modified.
    np.testing.assert_allclose(g.mean, [1.0, 1.0], atol=0)


def test_control_input_and_types_are_kept():
    b = GaussianBelief([1.0, 2.0, 3.1], np.eye(3) * 0.01)
    B = np.eye(3) * 0.5
    out = kf_predict(b, np.eye(3), B, [0.0, 0.0, 0.2], np.eye(3) * 1e-4)
    assert isinstance(out, GaussianBelief)
    # 3.1 + 0.1 wraps to 3.2 − 2π: a pose belief keeps its heading wrapped.
    assert out.mean[2] == pytest.approx(3.2 - 2 * np.pi, abs=1e-12)
    g = kf_predict(Gaussian([1.0], [[1.0]]), [[2.0]], [[1.0]], [3.0], [[0.5]])
    assert isinstance(g, Gaussian)
    np.testing.assert_allclose(g.mean, [5.0])
    np.testing.assert_allclose(g.cov, [[4.5]])


def test_class_agrees_with_functions_to_1e12():
    rng = np.random.default_rng(7)
    n, m, k = 4, 2, 2
    A = np.eye(n) + 0.1 * rng.normal(size=(n, n))
    B = rng.normal(size=(n, k))
    Q = _random_spd(rng, n, 0.01)
    H = rng.normal(size=(m, n))
    R = _random_spd(rng, m, 0.1)
    g = Gaussian(rng.normal(size=n), _random_spd(rng, n))
    kf = KalmanFilter(g, A, Q, H, R, B=B)
    for _ in range(50):
        u = rng.normal(size=k)
        z = rng.normal(size=m)
        g = kf_predict(g, A, B, u, Q)
        kf.predict(u)
        g, info = kf_update(g, z, H, R)
        info_c = kf.update(z)
        np.testing.assert_allclose(kf.mean, g.mean, rtol=0, atol=1e-12)
        np.testing.assert_allclose(kf.cov, g.cov, rtol=0, atol=1e-12)
        assert info_c.nis == pytest.approx(info.nis, abs=1e-12)
    assert isinstance(kf.belief, Gaussian)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 5),
    m=st.integers(1, 3),
    seed=st.integers(0, 2**31 - 1),
)
def test_update_matches_textbook_form_and_is_symmetric_psd(n, m, seed):
    rng = np.random.default_rng(seed)
    P = _random_spd(rng, n)
    R = _random_spd(rng, m, 0.5)
    H = rng.normal(size=(m, n))
    x = rng.normal(size=n)
    z = rng.normal(size=m)
    g, info = kf_update(Gaussian(x, P), z, H, R)
    # Textbook (information-free) form with an explicit inverse, as a reference only.
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    np.testing.assert_allclose(g.mean, x + K @ (z - H @ x), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(g.cov, P - K @ S @ K.T, rtol=1e-8, atol=1e-9)
    np.testing.assert_array_equal(g.cov, g.cov.T)
    assert np.linalg.eigvalsh(g.cov).min() > -1e-12
    nu = z - H @ x
    assert info.nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-9)


def test_joseph_form_stays_psd_where_the_short_form_does_not():
    # Very precise readings of one of two strongly correlated states (variance 1e6,
    # correlation 0.9999, reading noise 1e-10): the short form (I − K H) P cancels to a
    # matrix with a negative eigenvalue after three updates; the Joseph form stays symmetric
    # positive definite.
    s2, rho = 1e6, 0.9999
    P0 = np.array([[s2, rho * s2], [rho * s2, s2]])
    H = np.array([[1.0, 0.1]])
    R = np.array([[1e-10]])
    g = Gaussian([0.0, 0.0], P0)
    P_short = P0.copy()
    for _ in range(3):
        g, _ = kf_update(g, [0.0], H, R)
        K = P_short @ H.T / (H @ P_short @ H.T + R)
        P_short = (np.eye(2) - K @ H) @ P_short
    np.testing.assert_array_equal(g.cov, g.cov.T)
    assert np.linalg.eigvalsh(g.cov).min() > 0.0
    assert np.linalg.eigvalsh(0.5 * (P_short + P_short.T)).min() < 0.0  # the test has teeth


def test_bad_input_raises_typed_errors():
    g = Gaussian([0.0, 1.0], np.eye(2))
    with pytest.raises(NonFiniteError):
        kf_update(g, [np.nan], H_POS, [[1.0]])
    with pytest.raises(CovarianceError):
        kf_update(g, [1.0], H_POS, [[-1.0]])
    with pytest.raises(CovarianceError):
        kf_update(Gaussian([0.0, 0.0], np.eye(2)), [0.0, 0.0], np.eye(2), [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ShapeError):
        kf_update(g, [1.0, 2.0], H_POS, [[1.0]])
    with pytest.raises(ShapeError):
        kf_predict(g, A_CV, np.eye(2), None, Q_CV)
    with pytest.raises(CovarianceError):
        kf_predict(g, A_CV, None, None, -np.eye(2))
    with pytest.raises(CovarianceError):
        KalmanFilter(g, A_CV, Q_CV, H_POS, [[0.0]])
    kf = KalmanFilter(g, A_CV, Q_CV, H_POS, [[1.0]])
    with pytest.raises(ShapeError):
        kf.predict([1.0])
    with pytest.raises(NonFiniteError):
        kf.update([np.inf])


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_overflowing_covariance_raises_convergence_error_not_nan():
    g = Gaussian([0.0, 0.0], np.diag([1e300, 1e300]))
    with pytest.raises(ConvergenceError):
        kf_predict(g, [[1e10, 0.0], [0.0, 1.0]], None, None, np.zeros((2, 2)))
