"""Landmark measurement models: hand values, Jacobians and inverse-model Jacobians against
finite differences, residual wrapping, sampling statistics, batches, bad input."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from slamkit.errors import CovarianceError, GeometryError, NonFiniteError, ShapeError
from slamkit.geometry import wrap_angle
from slamkit.models import (
    BearingOnly,
    LandmarkModel,
    RangeBearing,
    RangeOnly,
    RelativePosition,
    landmark_initial_covariance,
)

MODELS: dict[str, LandmarkModel] = {
    "range-bearing": RangeBearing(),
    "range": RangeOnly(),
    "bearing": BearingOnly(),
}


def numeric_jacobian(
    f: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    angular: tuple[bool, ...],
    eps: float = 1e-6,
) -> np.ndarray:
    """Central differences of ``f`` with angular output differences wrapped."""
    x0 = np.asarray(x0, float)
    mask = np.array(angular)
    cols = []
    for i in range(x0.size):
        step = np.zeros_like(x0)
        step[i] = eps
        d = f(x0 + step) - f(x0 - step)
        cols.append(np.where(mask, wrap_angle(d), d) / (2 * eps))
    return np.stack(cols, axis=-1)


def geometry_cases() -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(2)
    cases = []
    for _ in range(6):
        pose = np.array([*rng.uniform(-10, 10, 2), rng.uniform(-np.pi, np.pi)])
        cases.append((pose, rng.uniform(-10, 10, 2)))
    # landmark straight behind: the bearing sits on the ±pi wrap
    cases.append((np.array([1.0, 1.0, 0.0]), np.array([-3.0, 1.0 + 1e-12])))
    cases.append((np.array([1.0, 1.0, 0.0]), np.array([1.0, 1.5])))  # close, straight left
    return cases


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize(("pose", "landmark"), geometry_cases())
def test_jacobians_match_finite_differences(
    name: str, pose: np.ndarray, landmark: np.ndarray
) -> None:
    model = MODELS[name]
    Hp, Hl = model.jacobians(pose, landmark)
    assert Hp.shape == (model.dim, 3) and Hl.shape == (model.dim, 2)
    Hp_num = numeric_jacobian(lambda p: model.predict(p, landmark), pose, model.angular)
    Hl_num = numeric_jacobian(lambda l: model.predict(pose, l), landmark, model.angular)
    np.testing.assert_allclose(Hp, Hp_num, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(Hl, Hl_num, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize(("pose", "landmark"), geometry_cases())
def test_inverse_jacobians_match_finite_differences(pose: np.ndarray, landmark: np.ndarray) -> None:
    rb = RangeBearing()
    z = rb.predict(pose, landmark)
    Lx, Lz = rb.inverse_jacobians(pose, z)
    assert Lx.shape == (2, 3) and Lz.shape == (2, 2)
    no_wrap = (False, False)
    np.testing.assert_allclose(
        Lx, numeric_jacobian(lambda p: rb.inverse(p, z), pose, no_wrap), rtol=1e-6, atol=1e-6
    )
    np.testing.assert_allclose(
        Lz, numeric_jacobian(lambda zz: rb.inverse(pose, zz), z, no_wrap), rtol=1e-6, atol=1e-6
    )
    # the inverse model's landmark Jacobian inverts the forward one
    _, Hl = rb.jacobians(pose, landmark)
    np.testing.assert_allclose(Hl @ Lz, np.eye(2), atol=1e-9)


def test_hand_values() -> None:
    rb = RangeBearing()
    # facing +y, landmark 3 m straight ahead
    np.testing.assert_allclose(rb.predict([1.0, 2.0, np.pi / 2], [1.0, 5.0]), [3.0, 0.0])
    # at the origin facing +x, landmark 2 m to the left
    np.testing.assert_allclose(rb.predict([0, 0, 0], [0.0, 2.0]), [2.0, np.pi / 2])
    # straight behind: bearing wrapped to -pi
    np.testing.assert_allclose(rb.predict([0, 0, 0], [-1.0, 0.0]), [1.0, -np.pi])
    # 3-4-5 triangle, robot facing the landmark's direction
    np.testing.assert_allclose(rb.predict([1, 1, np.arctan2(4, 3)], [4, 5]), [5.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(RangeOnly().predict([1, 1, 2.0], [4, 5]), [5.0])
    np.testing.assert_allclose(BearingOnly().predict([0, 0, np.pi / 4], [0.0, 2.0]), [np.pi / 4])
    Hp, Hl = rb.jacobians([0, 0, 0], [3.0, 4.0])
    # range row ±(dx, dy)/r, bearing row ±(-dy, dx)/r²
    np.testing.assert_allclose(Hp, [[-0.6, -0.8, 0], [4 / 25, -3 / 25, -1]], atol=1e-15)
    np.testing.assert_allclose(Hl, [[0.6, 0.8], [-4 / 25, 3 / 25]], atol=1e-15)


def test_inverse_round_trips() -> None:
    rb = RangeBearing()
    rng = np.random.default_rng(4)
    poses = np.column_stack([rng.uniform(-5, 5, (40, 2)), rng.uniform(-np.pi, np.pi, 40)])
    landmarks = rng.uniform(-20, 20, (40, 2))
    np.testing.assert_allclose(
        rb.inverse(poses, rb.predict(poses, landmarks)), landmarks, atol=1e-12
    )
    z = np.column_stack([rng.uniform(0.5, 30, 40), rng.uniform(-np.pi, np.pi, 40)])
    np.testing.assert_allclose(
        rb.residual(rb.predict(poses, rb.inverse(poses, z)), z), 0.0, atol=1e-12
    )
    # y = y_robot + r sin(bearing + theta)
    np.testing.assert_allclose(
        rb.inverse([1.0, 2.0, np.pi / 2], [3.0, np.pi / 2]), [-2.0, 2.0], atol=1e-15
    )


def test_landmark_initial_covariance() -> None:
    rb = RangeBearing()
    pose, z = np.array([1.0, 2.0, 0.4]), np.array([5.0, -0.3])
    Lx, Lz = rb.inverse_jacobians(pose, z)
    P = np.diag([0.04, 0.09, 0.01])
    Q = np.diag([0.25, 0.0004])
    S = landmark_initial_covariance(Lx, P, Lz, Q)
    np.testing.assert_allclose(S, Lx @ P @ Lx.T + Lz @ Q @ Lz.T, atol=1e-15)
    np.testing.assert_array_equal(S, S.T)
    assert np.all(np.linalg.eigvalsh(S) > 0)
    # known pose: only the measurement noise, rotated into the world
    c, s = np.cos(0.1), np.sin(0.1)
    R = np.array([[c, -s], [s, c]])
    expected = R @ np.diag([0.25, 25 * 0.0004]) @ R.T
    np.testing.assert_allclose(landmark_initial_covariance(Lx, np.zeros((3, 3)), Lz, Q), expected)
    # batched
    Lx2, Lz2 = rb.inverse_jacobians(np.stack([pose, pose]), np.stack([z, z]))
    S2 = landmark_initial_covariance(Lx2, P, Lz2, Q)
    assert S2.shape == (2, 2, 2)
    np.testing.assert_allclose(S2[1], S)
    with pytest.raises(CovarianceError):
        landmark_initial_covariance(Lx, -P, Lz, Q)
    with pytest.raises(ShapeError):
        landmark_initial_covariance(Lz, P, Lz, Q)


def test_residual_wraps_angular_components_only() -> None:
    rb = RangeBearing()
    np.testing.assert_allclose(rb.residual([1.0, np.pi - 0.1], [1.5, -np.pi + 0.1]), [-0.5, -0.2])
    np.testing.assert_allclose(RangeOnly().residual([10.0], [1.0]), [9.0])  # no wrapping
    np.testing.assert_allclose(BearingOnly().residual([3.0], [-3.0]), [6.0 - 2 * np.pi])
    out = rb.residual(np.zeros((4, 2)), [0.0, 0.5])
    assert out.shape == (4, 2)


@pytest.mark.parametrize("name", list(MODELS))
def test_sample_statistics(name: str) -> None:
    model = MODELS[name]
    pose, landmark = np.array([0.0, 0.0, 0.2]), np.array([-4.0, 0.3])  # bearing near ±pi
    cov = np.array([[0.04, 0.006], [0.006, 0.01]])[: model.dim, : model.dim]
    n = 20_000
    z = model.sample(np.broadcast_to(pose, (n, 3)), landmark, cov, np.random.default_rng(9))
    assert z.shape == (n, model.dim)
    mask = np.array(model.angular)
    assert np.all(np.where(mask, (z >= -np.pi) & (z < np.pi), True))
    d = model.residual(z, model.predict(pose, landmark))
    np.testing.assert_allclose(d.mean(axis=0), 0.0, atol=5 * 0.2 / np.sqrt(n))
    # covariance entries scaled by the standard deviations: sampling error ~sqrt(2/n) ≈ 1 %
    std = np.sqrt(np.diag(cov))
    S = np.cov(d, rowvar=False).reshape(cov.shape)
    np.testing.assert_allclose(S / np.outer(std, std), cov / np.outer(std, std), atol=0.05)
    again = model.sample(np.broadcast_to(pose, (n, 3)), landmark, cov, np.random.default_rng(9))
    np.testing.assert_array_equal(z, again)
    exact = model.sample(pose, landmark, np.zeros_like(cov), np.random.default_rng(9))
    np.testing.assert_array_equal(exact, model.predict(pose, landmark))


@pytest.mark.parametrize("name", list(MODELS))
def test_batches_broadcast_and_equal_loops(name: str) -> None:
    model = MODELS[name]
    rng = np.random.default_rng(5)
    particles = np.column_stack([rng.uniform(-1, 1, (4, 2)), rng.uniform(-3, 3, 4)])
    landmarks = rng.uniform(-10, 10, (6, 2))
    p0, l0 = particles.copy(), landmarks.copy()
    z = model.predict(particles[:, None, :], landmarks)
    Hp, Hl = model.jacobians(particles[:, None, :], landmarks)
    assert z.shape == (4, 6, model.dim)
    assert Hp.shape == (4, 6, model.dim, 3) and Hl.shape == (4, 6, model.dim, 2)
    for i in range(4):
        for j in range(6):
            np.testing.assert_allclose(z[i, j], model.predict(particles[i], landmarks[j]))
            Hp_ij, Hl_ij = model.jacobians(particles[i], landmarks[j])
            np.testing.assert_allclose(Hp[i, j], Hp_ij)
            np.testing.assert_allclose(Hl[i, j], Hl_ij)
    # one pose against all landmarks
    np.testing.assert_allclose(model.predict(particles[0], landmarks), z[0])
    np.testing.assert_array_equal(particles, p0)
    np.testing.assert_array_equal(landmarks, l0)


def test_zero_range_raises_geometry_error() -> None:
    pose, landmark = np.array([1.0, 2.0, 0.3]), np.array([1.0, 2.0 + 1e-12])
    for model in MODELS.values():
        with pytest.raises(GeometryError):
            model.jacobians(pose, landmark)
    with pytest.raises(GeometryError):
        RangeBearing().predict(pose, landmark)
    with pytest.raises(GeometryError):
        BearingOnly().predict(pose, landmark)
    np.testing.assert_allclose(RangeOnly().predict(pose, landmark), [1e-12], atol=1e-15)
    # one degenerate landmark in a batch is enough
    with pytest.raises(GeometryError):
        RangeBearing().jacobians(pose, [[5.0, 5.0], [1.0, 2.0]])


def test_protocol_and_metadata() -> None:
    for model in MODELS.values():
        assert isinstance(model, LandmarkModel)
        assert len(model.angular) == model.dim
    assert RangeBearing().angular == (False, True)
    assert RangeOnly().dim == 1 and BearingOnly().angular == (True,)


def test_bad_inputs_raise_typed_errors() -> None:
    rb = RangeBearing()
    rng = np.random.default_rng(0)
    with pytest.raises(NonFiniteError):
        rb.predict([0.0, np.nan, 0.0], [1.0, 1.0])
    with pytest.raises(NonFiniteError):
        rb.jacobians([0.0, 0.0, 0.0], [np.inf, 1.0])
    with pytest.raises(ShapeError):
        rb.predict([0.0, 0.0], [1.0, 1.0])
    with pytest.raises(ShapeError):
        rb.predict([0.0, 0.0, 0.0], [1.0, 1.0, 1.0])
    with pytest.raises(ShapeError):
        rb.predict(np.zeros((3, 3)), np.ones((4, 2)))
    with pytest.raises(ShapeError):
        rb.residual([1.0], [1.0, 0.0])
    with pytest.raises(CovarianceError):
        rb.sample([0, 0, 0], [1.0, 1.0], [[0.1, 0.0], [0.0, -0.1]], rng)
    with pytest.raises(ShapeError):
        RangeOnly().sample([0, 0, 0], [1.0, 1.0], np.eye(2), rng)
    with pytest.raises(NonFiniteError):
        rb.inverse([0, 0, 0], [np.nan, 0.0])


@pytest.mark.parametrize(
    "model", [RangeBearing(), RangeOnly(), BearingOnly(), RelativePosition()], ids=repr
)
def test_single_pose_kernel_agrees_with_the_batched_kernels(model):
    # The EKF's fused plain-float kernel must equal the vectorised h and H_pose exactly.
    rng = np.random.default_rng(3)
    for _ in range(50):
        pose = np.array([*rng.normal(0, 5, 2), rng.uniform(-np.pi, np.pi)])
        lm = rng.normal(0, 5, 2)
        h, H = model.predict_with_pose_jacobian(pose, lm)
        np.testing.assert_allclose(h, model.predict(pose, lm), rtol=0, atol=1e-12)
        np.testing.assert_allclose(H, model.jacobians(pose, lm)[0], rtol=0, atol=1e-12)
        assert h.shape == (model.dim,) and H.shape == (model.dim, 3)
