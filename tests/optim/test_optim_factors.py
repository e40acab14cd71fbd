"""Every 2D factor's analytic Jacobian against central finite differences on the manifold,
hand values of the errors, and the robust kernels' weights against ``dρ/ds``."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.geometry import pose2
from slamkit.geometry.se2 import SE2
from slamkit.optim import factors
from slamkit.optim.graph import sesync_row_weights
from slamkit.optim.robust import RobustKernel, robust_rho_and_weight

H = 1e-6


def _random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    p = rng.normal(size=(n, 3)) * [3.0, 3.0, 1.0]
    p[:, 2] = np.arctan2(np.sin(p[:, 2]), np.cos(p[:, 2]))
    return p


def _diff(a: np.ndarray, b: np.ndarray, angle_rows: tuple[int, ...]) -> np.ndarray:
    d = a - b
    for r in angle_rows:
        d[:, r] = np.arctan2(np.sin(d[:, r]), np.cos(d[:, r]))
    return d


def _fd_pose(fn, x: np.ndarray, angle_rows: tuple[int, ...]) -> np.ndarray:
    """Numerical ∂e/∂δ for the right update X ⊕ δ, shape (E, m, 3)."""
    cols = []
    for k in range(3):
        d = np.zeros_like(x)
        d[:, k] = H
        plus = fn(factors.retract_poses(x, d))
        minus = fn(factors.retract_poses(x, -d))
        cols.append(_diff(plus, minus, angle_rows) / (2 * H))
    return np.stack(cols, axis=-1)


def _fd_point(fn, p: np.ndarray, angle_rows: tuple[int, ...]) -> np.ndarray:
    cols = []
    for k in range(2):
        d = np.zeros_like(p)
        d[:, k] = H
        cols.append(_diff(fn(p + d), fn(p - d), angle_rows) / (2 * H))
    return np.stack(cols, axis=-1)


def test_se2_between_error_hand_value() -> None:
    xi = np.array([[1.0, 2.0, 0.3]])
    xj = np.array([[2.0, 1.0, -0.4]])
    z = np.array([[0.5, -0.2, 0.1]])
    e, _, _ = factors.se2_between_error(xi, xj, z)
    expected = pose2.between(z[0], pose2.between(xi[0], xj[0]))  # Z⁻¹ · Xi⁻¹ · Xj
    np.testing.assert_allclose(e[0], expected, atol=1e-12)


def test_se2_between_error_wraps_angle() -> None:
    xi = np.array([[0.0, 0.0, 3.0]])
    xj = np.array([[0.0, 0.0, -3.0]])
    z = np.array([[0.0, 0.0, 0.0]])
    e, _, _ = factors.se2_between_error(xi, xj, z)
    assert e[0, 2] == pytest.approx(2 * np.pi - 6.0, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_se2_between_jacobians(seed: int) -> None:
    rng = np.random.default_rng(seed)
    xi, xj, z = _random_poses(rng, 20), _random_poses(rng, 20), _random_poses(rng, 20)
    _, Ji, Jj = factors.se2_between_error(xi, xj, z)
    num_i = _fd_pose(lambda x: factors.se2_between_error(x, xj, z)[0], xi, (2,))
    num_j = _fd_pose(lambda x: factors.se2_between_error(xi, x, z)[0], xj, (2,))
    np.testing.assert_allclose(Ji, num_i, atol=1e-6)
    np.testing.assert_allclose(Jj, num_j, atol=1e-6)


def test_se2_prior_jacobian_and_value() -> None:
    rng = np.random.default_rng(3)
    x, z = _random_poses(rng, 20), _random_poses(rng, 20)
    e, J = factors.se2_prior_error(x, z)
    np.testing.assert_allclose(e, pose2.between(z, x), atol=1e-12)  # Z⁻¹ · X
    num = _fd_pose(lambda p: factors.se2_prior_error(p, z)[0], x, (2,))
    np.testing.assert_allclose(J, num, atol=1e-6)


@pytest.mark.parametrize(
    ("fn", "m", "angle_rows"),
    [
        (factors.se2_xy_error, 2, ()),
        (factors.range_error, 1, ()),
        (factors.bearing_error, 1, (0,)),
        (factors.range_bearing_error, 2, (1,)),
    ],
)
def test_landmark_jacobians(fn, m: int, angle_rows: tuple[int, ...]) -> None:
    rng = np.random.default_rng(4)
    x = _random_poses(rng, 25)
    lm = rng.normal(size=(25, 2)) * 5.0
    z = rng.normal(size=(25, m))
    e, Ji, Jl = fn(x, lm, z)
    assert e.shape == (25, m) and Ji.shape == (25, m, 3) and Jl.shape == (25, m, 2)
    np.testing.assert_allclose(Ji, _fd_pose(lambda p: fn(p, lm, z)[0], x, angle_rows), atol=1e-6)
    np.testing.assert_allclose(Jl, _fd_point(lambda q: fn(x, q, z)[0], lm, angle_rows), atol=1e-6)


def test_landmark_errors_hand_values() -> None:
    x = np.array([[1.0, 1.0, np.pi / 2]])
    lm = np.array([[1.0, 3.0]])  # 2 m straight ahead of the robot
    zero1, zero2 = np.zeros((1, 1)), np.zeros((1, 2))
    np.testing.assert_allclose(factors.se2_xy_error(x, lm, zero2)[0], [[2.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(factors.range_error(x, lm, zero1)[0], [[2.0]], atol=1e-12)
    np.testing.assert_allclose(factors.bearing_error(x, lm, zero1)[0], [[0.0]], atol=1e-12)
    rb = factors.range_bearing_error(x, np.array([[0.0, 1.0]]), np.array([[1.0, 0.0]]))[0]
    np.testing.assert_allclose(rb, [[0.0, np.pi / 2]], atol=1e-12)  # landmark to the left


def test_chordal_residual_jacobians_and_objective() -> None:
    rng = np.random.default_rng(5)
    xi, xj, z = _random_poses(rng, 20), _random_poses(rng, 20), _random_poses(rng, 20)
    r, Ji, Jj = factors.se2_chordal_residual(xi, xj, z)
    np.testing.assert_allclose(
        Ji, _fd_pose(lambda p: factors.se2_chordal_residual(p, xj, z)[0], xi, ()), atol=1e-6
    )
    np.testing.assert_allclose(
        Jj, _fd_pose(lambda p: factors.se2_chordal_residual(xi, p, z)[0], xj, ()), atol=1e-6
    )

    # ‖r‖² with the weights equals SE-Sync's κ‖R_j - R_i R̃‖²_F + τ‖t_j - t_i - R_i t̃‖².
    def rot(t: np.ndarray) -> np.ndarray:
        return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])

    info = np.array([[[40.0, 3.0, 0.0], [3.0, 20.0, 0.0], [0.0, 0.0, 500.0]]] * 20)
    w = sesync_row_weights(info)
    kappa, tau = 500.0, 2.0 / np.trace(np.linalg.inv(info[0, :2, :2]))
    for k in range(3):
        Ri, Rj, Rz = rot(xi[k, 2]), rot(xj[k, 2]), rot(z[k, 2])
        F = kappa * np.sum((Rj - Ri @ Rz) ** 2) + tau * np.sum(
            (xj[k, :2] - xi[k, :2] - Ri @ z[k, :2]) ** 2
        )
        assert np.sum((w[k] * r[k]) ** 2) == pytest.approx(F, rel=1e-12)


def test_retract_poses_is_right_multiplication_by_the_exponential() -> None:
    rng = np.random.default_rng(6)
    x, d = _random_poses(rng, 10), _random_poses(rng, 10) * 0.1
    np.testing.assert_allclose(
        factors.retract_poses(x, d), pose2.compose(x, SE2.exp(d).xy_theta()), atol=1e-12
    )
    # A pure turn leaves the position; a pure translation is g2o's oplus.
    turn = d * np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(factors.retract_poses(x, turn)[:, :2], x[:, :2], atol=1e-12)
    move = d * np.array([1.0, 1.0, 0.0])
    np.testing.assert_allclose(factors.retract_poses(x, move), pose2.compose(x, move), atol=1e-12)
    # A constant twist along a circle: one step of angle 2π·k/n in n steps closes the loop.
    step = np.array([[2 * np.pi / 8, 0.0, 2 * np.pi / 8]])
    p = np.zeros((1, 3))
    for _ in range(8):
        p = factors.retract_poses(p, step)
    np.testing.assert_allclose(p, 0.0, atol=1e-12)


@pytest.mark.parametrize("name", ["huber", "cauchy", "geman_mcclure", "dcs"])
def test_robust_weight_is_derivative_of_rho(name: str) -> None:
    kernel = RobustKernel(name, 1.7)  # type: ignore[arg-type]
    s = np.linspace(0.01, 30.0, 400)
    rho, w = robust_rho_and_weight(kernel, s)
    rho_p, _ = robust_rho_and_weight(kernel, s + 1e-6)
    rho_m, _ = robust_rho_and_weight(kernel, s - 1e-6)
    np.testing.assert_allclose(w, (rho_p - rho_m) / 2e-6, rtol=1e-5, atol=1e-7)
    small = s < 0.05
    np.testing.assert_allclose(rho[small], s[small], rtol=0.05)  # quadratic near zero
    assert np.all(np.diff(rho) > 0) and np.all(w <= 1.0 + 1e-12)
