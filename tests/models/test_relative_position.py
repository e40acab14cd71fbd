"""The relative-position landmark model z = R(θ)ᵀ (l − t): hand values, Jacobians and
inverse-model Jacobians against finite differences, agreement with the SE(2) point maps,
batches, sampling statistics, and the "position" landmark sensor kind."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from slamkit.datasets import LandmarkSensorSpec
from slamkit.errors import InputError, ShapeError
from slamkit.geometry import pose2
from slamkit.models import LandmarkModel, RelativePosition


def central_difference(
    f: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, eps: float = 1e-6
) -> np.ndarray:
    """Jacobian of ``f`` at ``x0`` by central differences (no angular outputs here)."""
    cols = []
    for i in range(x0.size):
        step = np.zeros_like(x0)
        step[i] = eps
        cols.append((f(x0 + step) - f(x0 - step)) / (2 * eps))
    return np.stack(cols, axis=-1)


def cases() -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(7)
    out = []
    for _ in range(8):
        pose = np.array([*rng.uniform(-10, 10, 2), rng.uniform(-np.pi, np.pi)])
        out.append((pose, rng.uniform(-10, 10, 2)))
    out.append((np.array([1.0, -2.0, np.pi]), np.array([1.0, -2.0])))  # landmark at the sensor
    out.append((np.array([0.0, 0.0, -np.pi / 2]), np.array([-3.0, 0.0])))  # straight behind
    return out


def test_is_a_landmark_model_with_the_declared_shape() -> None:
    model = RelativePosition()
    assert isinstance(model, LandmarkModel)
    assert model.dim == 2 and model.angular == (False, False)


@pytest.mark.parametrize(("pose", "landmark"), cases())
def test_jacobians_match_finite_differences(pose: np.ndarray, landmark: np.ndarray) -> None:
    model = RelativePosition()
    Hp, Hl = model.jacobians(pose, landmark)
    assert Hp.shape == (2, 3) and Hl.shape == (2, 2)
    np.testing.assert_allclose(
        Hp, central_difference(lambda p: model.predict(p, landmark), pose), atol=1e-7
    )
    np.testing.assert_allclose(
        Hl, central_difference(lambda l: model.predict(pose, l), landmark), atol=1e-7
    )


@pytest.mark.parametrize(("pose", "landmark"), cases())
def test_inverse_jacobians_match_finite_differences(pose: np.ndarray, landmark: np.ndarray) -> None:
    model = RelativePosition()
    z = model.predict(pose, landmark)
    Lx, Lz = model.inverse_jacobians(pose, z)
    assert Lx.shape == (2, 3) and Lz.shape == (2, 2)
    np.testing.assert_allclose(
        Lx, central_difference(lambda p: model.inverse(p, z), pose), atol=1e-7
    )
    np.testing.assert_allclose(
        Lz, central_difference(lambda zz: model.inverse(pose, zz), z), atol=1e-7
    )
    # L_z inverts the landmark Jacobian, and L_x = −L_z H_pose (differentiate h(x, g(x, z)) = z)
    Hp, Hl = model.jacobians(pose, landmark)
    np.testing.assert_allclose(Hl @ Lz, np.eye(2), atol=1e-12)
    np.testing.assert_allclose(Lx, -Lz @ Hp, atol=1e-12)


def test_hand_values() -> None:
    model = RelativePosition()
    # facing +y from (1, 2): a landmark at (1, 5) is 3 m straight ahead
    np.testing.assert_allclose(
        model.predict([1.0, 2.0, np.pi / 2], [1.0, 5.0]), [3.0, 0.0], atol=1e-15
    )
    # facing +x from the origin: (0, 2) is 2 m to the left
    np.testing.assert_allclose(model.predict([0, 0, 0], [0.0, 2.0]), [0.0, 2.0])
    # facing -x: (-1, 0) ahead, (0, 1) to the right
    np.testing.assert_allclose(
        model.predict([0, 0, np.pi], [[-1.0, 0.0], [0.0, 1.0]]), [[1, 0], [0, -1]], atol=1e-15
    )
    # at (1, 1) facing +y: H_l = R(θ)ᵀ = [[0, 1], [-1, 0]], H_pose = [[0, -1, zy], [1, 0, -zx]]
    Hp, Hl = model.jacobians([1.0, 1.0, np.pi / 2], [3.0, 5.0])  # z = (4, -2)
    np.testing.assert_allclose(Hl, [[0, 1], [-1, 0]], atol=1e-15)
    np.testing.assert_allclose(Hp, [[0, -1, -2], [1, 0, -4]], atol=1e-15)
    # inverse: the point pose ⊕ z
    np.testing.assert_allclose(
        model.inverse([1.0, 1.0, np.pi / 2], [4.0, -2.0]), [3.0, 5.0], atol=1e-15
    )
    # no wrapping in the residual: the components are lengths
    np.testing.assert_allclose(model.residual([4.0, 0.0], [-3.0, 0.0]), [7.0, 0.0])


def test_agrees_with_the_se2_point_maps_over_batches() -> None:
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-5, 5, (6, 2)), rng.uniform(-4, 4, 6)])
    landmarks = rng.uniform(-20, 20, (6, 9, 2))
    model = RelativePosition()
    z = model.predict(poses[:, None, :], landmarks)
    assert z.shape == (6, 9, 2)
    np.testing.assert_allclose(
        z, pose2.inverse_transform_points(poses[:, None, :], landmarks), atol=1e-12
    )
    np.testing.assert_allclose(model.inverse(poses[:, None, :], z), landmarks, atol=1e-12)
    Hp, Hl = model.jacobians(poses[:, None, :], landmarks)
    Lx, Lz = model.inverse_jacobians(poses[:, None, :], z)
    assert Hp.shape == (6, 9, 2, 3) and Hl.shape == Lz.shape == (6, 9, 2, 2)
    assert Lx.shape == (6, 9, 2, 3)
    # one pose against many landmarks broadcasts too
    np.testing.assert_allclose(model.predict(poses[0], landmarks[0]), z[0], atol=1e-12)


def test_sample_statistics() -> None:
    model = RelativePosition()
    cov = np.array([[0.04, 0.01], [0.01, 0.09]])
    rng = np.random.default_rng(11)
    pose, landmark = np.array([2.0, -1.0, 0.7]), np.array([-4.0, 6.0])
    z = model.sample(pose, np.broadcast_to(landmark, (40000, 2)), cov, rng)
    d = z - model.predict(pose, landmark)
    # mean within ~4 standard errors, covariance within 3 %
    assert np.all(np.abs(d.mean(axis=0)) < 4 * np.sqrt(np.diag(cov) / 40000))
    np.testing.assert_allclose(np.cov(d.T), cov, rtol=0.03, atol=1e-3)


def test_bad_input() -> None:
    model = RelativePosition()
    with pytest.raises(ShapeError):
        model.predict([0.0, 0.0], [1.0, 1.0])
    with pytest.raises(ShapeError):
        model.inverse(np.zeros((3, 3)), np.zeros((4, 2)))


def test_position_sensor_kind() -> None:
    spec = LandmarkSensorSpec("position", np.diag([0.01, 0.04]))
    assert spec.dim == 2
    assert isinstance(spec.model(), RelativePosition)
    with pytest.raises(InputError, match="'position'"):
        LandmarkSensorSpec("xy", np.eye(2))  # type: ignore[arg-type]
    with pytest.raises(ShapeError):
        LandmarkSensorSpec("position", np.eye(1))
