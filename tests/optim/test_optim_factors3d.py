"""SE(3) factors: analytic Jacobians against finite differences on the manifold, the g2o
error against a direct quaternion computation, SE-Sync's 3D objective by hand."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.geometry.se3 import SE3
from slamkit.geometry.so3 import matrix_to_quat, quat_exp, quat_to_matrix
from slamkit.optim import factors3d as f3

H = 1e-6


def _random_internal(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    poses = np.concatenate([rng.normal(size=(n, 3)) * 2.0, q], axis=1)
    return f3.poses_to_internal(poses)


def _fd(fn, x: np.ndarray) -> np.ndarray:
    cols = []
    for k in range(6):
        d = np.zeros((x.shape[0], 6))
        d[:, k] = H
        cols.append((fn(f3.retract_poses3(x, d)) - fn(f3.retract_poses3(x, -d))) / (2 * H))
    return np.stack(cols, axis=-1)


def test_internal_external_round_trip() -> None:
    rng = np.random.default_rng(0)
    x = _random_internal(rng, 10)
    ext = f3.poses_to_external(x)
    assert np.all(ext[:, 3] >= 0)
    np.testing.assert_allclose(f3.poses_to_internal(ext), x, atol=1e-12)


def test_retract_is_right_multiplication_by_the_exponential() -> None:
    rng = np.random.default_rng(1)
    x = _random_internal(rng, 5)
    d = rng.normal(size=(5, 6)) * 0.3
    out = f3.retract_poses3(x, d)
    R = x[:, 3:].reshape(-1, 3, 3)
    inc = SE3.exp(d).as_matrix()
    T = np.zeros((5, 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, x[:, :3], 1.0
    expected = T @ inc
    np.testing.assert_allclose(out[:, 3:].reshape(-1, 3, 3), expected[:, :3, :3], atol=1e-12)
    np.testing.assert_allclose(out[:, :3], expected[:, :3, 3], atol=1e-12)
    # The rotation part is R Exp(δω); a step without rotation is g2o's t + R δv.
    dR = quat_to_matrix(quat_exp(d[:, 3:]))
    np.testing.assert_allclose(out[:, 3:].reshape(-1, 3, 3), R @ dR, atol=1e-12)
    move = d * np.array([1.0, 1, 1, 0, 0, 0])
    np.testing.assert_allclose(
        f3.retract_poses3(x, move)[:, :3], x[:, :3] + np.einsum("nij,nj->ni", R, move[:, :3])
    )


@pytest.mark.parametrize("seed", [2, 3])
def test_se3_between_jacobians_and_value(seed: int) -> None:
    rng = np.random.default_rng(seed)
    xi, xj = _random_internal(rng, 15), _random_internal(rng, 15)
    # Measurements near the true relative pose keep Q away from a half turn (w ≈ 0 flips).
    rel = np.empty_like(xi)
    Ri, Rj = xi[:, 3:].reshape(-1, 3, 3), xj[:, 3:].reshape(-1, 3, 3)
    rel[:, :3] = np.einsum("nji,nj->ni", Ri, xj[:, :3] - xi[:, :3])
    rel[:, 3:] = (np.swapaxes(Ri, 1, 2) @ Rj).reshape(-1, 9)
    z = f3.retract_poses3(rel, rng.normal(size=(15, 6)) * 0.2)
    e, Ji, Jj = f3.se3_between_error(xi, xj, z)
    Rz = z[:, 3:].reshape(-1, 3, 3)
    Q = np.swapaxes(Rz, 1, 2) @ np.swapaxes(Ri, 1, 2) @ Rj
    q = matrix_to_quat(Q)
    q *= np.sign(q[:, :1])
    np.testing.assert_allclose(e[:, 3:], q[:, 1:], atol=1e-12)
    np.testing.assert_allclose(Ji, _fd(lambda x: f3.se3_between_error(x, xj, z)[0], xi), atol=1e-6)
    np.testing.assert_allclose(Jj, _fd(lambda x: f3.se3_between_error(xi, x, z)[0], xj), atol=1e-6)


def test_se3_prior_jacobian() -> None:
    rng = np.random.default_rng(4)
    x = _random_internal(rng, 10)
    z = f3.retract_poses3(x, rng.normal(size=(10, 6)) * 0.2)
    _, J = f3.se3_prior_error(x, z)
    np.testing.assert_allclose(J, _fd(lambda p: f3.se3_prior_error(p, z)[0], x), atol=1e-6)


def test_se3_chordal_jacobians_and_objective() -> None:
    rng = np.random.default_rng(5)
    xi, xj, z = _random_internal(rng, 10), _random_internal(rng, 10), _random_internal(rng, 10)
    r, Ji, Jj = f3.se3_chordal_residual(xi, xj, z)
    np.testing.assert_allclose(
        Ji, _fd(lambda x: f3.se3_chordal_residual(x, xj, z)[0], xi), atol=1e-6
    )
    np.testing.assert_allclose(
        Jj, _fd(lambda x: f3.se3_chordal_residual(xi, x, z)[0], xj), atol=1e-6
    )
    info = np.diag([10.0, 20.0, 40.0, 100.0, 200.0, 400.0])[None].repeat(10, axis=0)
    w = f3.sesync_row_weights_3d(info)
    kappa = 3.0 / (2.0 * (1 / 100 + 1 / 200 + 1 / 400))
    tau = 3.0 / (1 / 10 + 1 / 20 + 1 / 40)
    Ri, Rj, Rz = (a[0, 3:].reshape(3, 3) for a in (xi, xj, z))
    F = kappa * np.sum((Rj - Ri @ Rz) ** 2) + tau * np.sum(
        (xj[0, :3] - xi[0, :3] - Ri @ z[0, :3]) ** 2
    )
    assert np.sum((w[0] * r[0]) ** 2) == pytest.approx(F, rel=1e-12)
