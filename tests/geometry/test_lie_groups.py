"""SO(2), SE(2), SO(3), SE(3): one property suite over every group and batch shape, then
hand-computed values, conventions and input checking.

Group elements are compared through their matrices, which also makes the SO(3) double cover
(``q`` and ``-q``) irrelevant. The exponential map is checked against ``scipy.linalg.expm`` of
a ``hat`` written out here, independently of the library, which pins the tangent orderings.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from slamkit.errors import InputError, NonFiniteError, ShapeError
from slamkit.geometry.se2 import SE2
from slamkit.geometry.se3 import SE3
from slamkit.geometry.so2 import SO2
from slamkit.geometry.so3 import SO3

GROUPS = [SO2, SE2, SO3, SE3]
BATCH_SHAPES = [(), (1,), (5,), (2, 3)]
CASES = [
    pytest.param(group, shape, id=f"{group.__name__}-{shape}")
    for group in GROUPS
    for shape in BATCH_SHAPES
]
PROPERTY = settings(max_examples=25, deadline=None)
SEEDS = st.integers(min_value=0, max_value=2**32 - 1)
# Rotation magnitudes of tangent vectors: exactly zero, tiny, both sides of the Taylor-series
# switch (1e-3 rad for θ; 2e-3 rad for the SO(3) log, which switches on sin(θ/2)) and large
# but below π, where the logarithm is the inverse of exp.
ROTATION_SCALES = st.sampled_from(
    [0.0, 1e-12, 1e-8, 1e-5, 0.999e-3, 1.001e-3, 1.999e-3, 2.001e-3, 0.1, 1.0, 3.0, 3.14]
)
TOL = 1e-10


# --------------------------------------------------------------------- helpers


def rotation_slice(group: type) -> slice:
    """Where the rotation part sits in a tangent vector of ``group``."""
    return {SO2: slice(0, 1), SE2: slice(2, 3), SO3: slice(0, 3), SE3: slice(3, 6)}[group]


def sample_tangent(
    group: type, rng: np.random.Generator, batch_shape: tuple[int, ...], rot_scale: float
) -> np.ndarray:
    """Tangents whose rotation part has norm exactly ``rot_scale``; translations ~ N(0, 1)."""
    xi = rng.standard_normal((*batch_shape, group.tangent_dim))
    rot = xi[..., rotation_slice(group)]
    rot *= rot_scale / np.linalg.norm(rot, axis=-1, keepdims=True)
    return xi


def hat(group: type, xi: np.ndarray) -> np.ndarray:
    """The Lie-algebra matrix of ``xi``, written out independently of the library."""
    n = group.matrix_dim
    out = np.zeros((*xi.shape[:-1], n, n))

    def skew3(w: np.ndarray) -> np.ndarray:
        s = np.zeros((*w.shape[:-1], 3, 3))
        s[..., 0, 1], s[..., 0, 2] = -w[..., 2], w[..., 1]
        s[..., 1, 0], s[..., 1, 2] = w[..., 2], -w[..., 0]
        s[..., 2, 0], s[..., 2, 1] = -w[..., 1], w[..., 0]
        return s

    if group is SO2:
        out[..., 0, 1], out[..., 1, 0] = -xi[..., 0], xi[..., 0]
    elif group is SE2:  # (vx, vy, ω)
        out[..., 0, 1], out[..., 1, 0] = -xi[..., 2], xi[..., 2]
        out[..., :2, 2] = xi[..., :2]
    elif group is SO3:
        out[...] = skew3(xi)
    else:  # SE3: (v, ω)
        out[..., :3, :3] = skew3(xi[..., 3:])
        out[..., :3, 3] = xi[..., :3]
    return out


def assert_same(a: object, b: object, atol: float = TOL) -> None:
    assert type(a) is type(b)
    np.testing.assert_allclose(a.as_matrix(), b.as_matrix(), rtol=0, atol=atol)


def homogeneous(points: np.ndarray) -> np.ndarray:
    return np.concatenate([points, np.ones((*points.shape[:-1], 1))], axis=-1)


def act_by_matrix(group: type, x: object, points: np.ndarray) -> np.ndarray:
    M = x.as_matrix()
    if group in (SO2, SO3):
        return (M @ points[..., None])[..., 0]
    return (M @ homogeneous(points)[..., None])[..., :-1, 0]


# --------------------------------------------------------------------- property suite


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS)
def test_identity(group: type, batch_shape: tuple[int, ...], seed: int) -> None:
    x = group.sample_uniform(np.random.default_rng(seed), batch_shape)
    e = group.identity(batch_shape)
    assert e.batch_shape == batch_shape == x.batch_shape
    assert_same(e @ x, x, atol=0)
    assert_same(x @ group.identity(), x, atol=0)
    np.testing.assert_array_equal(
        e.as_matrix(),
        np.broadcast_to(
            np.eye(group.matrix_dim), (*batch_shape, group.matrix_dim, group.matrix_dim)
        ),
    )
    np.testing.assert_array_equal(e.log(), np.zeros((*batch_shape, group.tangent_dim)))


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS)
def test_associativity(group: type, batch_shape: tuple[int, ...], seed: int) -> None:
    rng = np.random.default_rng(seed)
    a, b, c = (group.sample_uniform(rng, batch_shape) for _ in range(3))
    assert_same((a @ b) @ c, a @ (b @ c))


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS)
def test_inverse(group: type, batch_shape: tuple[int, ...], seed: int) -> None:
    x = group.sample_uniform(np.random.default_rng(seed), batch_shape)
    e = group.identity(batch_shape)
    assert_same(x @ x.inverse(), e)
    assert_same(x.inverse() @ x, e)
    np.testing.assert_allclose(x.inverse().as_matrix(), np.linalg.inv(x.as_matrix()), atol=TOL)
    assert_same(x.inverse().inverse(), x)


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS, rot_scale=ROTATION_SCALES)
def test_exp_log_round_trip(
    group: type, batch_shape: tuple[int, ...], seed: int, rot_scale: float
) -> None:
    rng = np.random.default_rng(seed)
    xi = sample_tangent(group, rng, batch_shape, rot_scale)
    back = group.exp(xi).log()
    assert back.shape == xi.shape
    rot = rotation_slice(group)
    # The rotation part relative to its size, so that 1e-12 rad is checked to many digits too.
    # Planar angles pass through wrap_angle, whose (a + π) mod 2π - π rounds an angle to a
    # multiple of ulp(π) (absolute error <= 2.3e-16); SO(3) has no such step.
    wrap_loss = 2.3e-16 if group in (SO2, SE2) else 0.0
    np.testing.assert_allclose(
        back[..., rot], xi[..., rot], rtol=1e-9, atol=1e-12 * rot_scale + wrap_loss
    )
    np.testing.assert_allclose(back, xi, rtol=1e-9, atol=TOL)
    x = group.sample_uniform(rng, batch_shape)
    assert_same(group.exp(x.log()), x)


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS, rot_scale=ROTATION_SCALES)
def test_exp_matches_matrix_exponential(
    group: type, batch_shape: tuple[int, ...], seed: int, rot_scale: float
) -> None:
    xi = sample_tangent(group, np.random.default_rng(seed), batch_shape, rot_scale)
    np.testing.assert_allclose(group.exp(xi).as_matrix(), expm(hat(group, xi)), rtol=0, atol=TOL)


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS)
def test_matrix_form_is_a_homomorphism(
    group: type, batch_shape: tuple[int, ...], seed: int
) -> None:
    rng = np.random.default_rng(seed)
    a, b = group.sample_uniform(rng, batch_shape), group.sample_uniform(rng, batch_shape)
    np.testing.assert_allclose((a @ b).as_matrix(), a.as_matrix() @ b.as_matrix(), atol=TOL)
    assert_same(group.from_matrix(a.as_matrix()), a)
    # A single element broadcasts against a batch, on either side.
    c = group.sample_uniform(rng)
    np.testing.assert_allclose((c @ a).as_matrix(), c.as_matrix() @ a.as_matrix(), atol=TOL)
    np.testing.assert_allclose((a @ c).as_matrix(), a.as_matrix() @ c.as_matrix(), atol=TOL)


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS)
def test_action_agrees_with_matrix(group: type, batch_shape: tuple[int, ...], seed: int) -> None:
    rng = np.random.default_rng(seed)
    x = group.sample_uniform(rng, batch_shape)
    points = rng.standard_normal((*batch_shape, group.space_dim))
    moved = x @ points
    assert moved.shape == points.shape
    np.testing.assert_allclose(moved, act_by_matrix(group, x, points), atol=TOL)
    np.testing.assert_allclose(x.apply(points), moved, atol=0)
    np.testing.assert_allclose(x.inverse() @ moved, points, atol=TOL)
    # One element acting on a cloud of points.
    cloud = rng.standard_normal((7, group.space_dim))
    single = group.sample_uniform(rng)
    np.testing.assert_allclose(single @ cloud, act_by_matrix(group, single, cloud), atol=TOL)


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS, rot_scale=ROTATION_SCALES)
def test_adjoint(group: type, batch_shape: tuple[int, ...], seed: int, rot_scale: float) -> None:
    rng = np.random.default_rng(seed)
    x = group.sample_uniform(rng, batch_shape)
    xi = sample_tangent(group, rng, batch_shape, rot_scale)
    Ad = x.adjoint()
    assert Ad.shape == (*batch_shape, group.tangent_dim, group.tangent_dim)
    # x exp(ξ) = exp(Ad_x ξ) x
    assert_same(x @ group.exp(xi), group.exp((Ad @ xi[..., None])[..., 0]) @ x)


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS, rot_scale=ROTATION_SCALES)
def test_box_plus_box_minus(
    group: type, batch_shape: tuple[int, ...], seed: int, rot_scale: float
) -> None:
    rng = np.random.default_rng(seed)
    x, y = group.sample_uniform(rng, batch_shape), group.sample_uniform(rng, batch_shape)
    assert_same(y.box_plus(x.box_minus(y)), x)
    delta = sample_tangent(group, rng, batch_shape, rot_scale)
    np.testing.assert_allclose(x.box_plus(delta).box_minus(x), delta, rtol=1e-9, atol=1e-9)
    assert_same(x.box_plus(delta), x @ group.exp(delta), atol=0)
    np.testing.assert_allclose(
        x.box_minus(x), np.zeros((*batch_shape, group.tangent_dim)), atol=1e-15
    )


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@PROPERTY
@given(seed=SEEDS, rot_scale=st.sampled_from([0.0, 1e-300, 1e-150, 1e-12, 1e-8, 1e-4]))
def test_finite_near_zero_rotation(
    group: type, batch_shape: tuple[int, ...], seed: int, rot_scale: float
) -> None:
    rng = np.random.default_rng(seed)
    xi = sample_tangent(group, rng, batch_shape, rot_scale)
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        x = group.exp(xi)
        results = [x.parameters, x.log(), x.adjoint(), x.as_matrix(), x.box_minus(x)]
        results.append(group.identity(batch_shape).box_plus(xi).parameters)
    for r in results:
        assert np.all(np.isfinite(r))
    np.testing.assert_allclose(x.as_matrix(), expm(hat(group, xi)), rtol=0, atol=TOL)
    np.testing.assert_allclose(x.log(), xi, rtol=1e-9, atol=TOL)


@pytest.mark.parametrize(("group", "batch_shape"), CASES)
@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_batch_indexing_and_pickling(group: type, batch_shape: tuple[int, ...], seed: int) -> None:
    x = group.sample_uniform(np.random.default_rng(seed), batch_shape)
    if batch_shape:
        np.testing.assert_array_equal(x[0].parameters, x.parameters[0])
        assert x[0].batch_shape == batch_shape[1:]
        assert x[..., 0].batch_shape == batch_shape[:-1]
        assert x[None].batch_shape == (1, *batch_shape)
    else:
        with pytest.raises(IndexError):
            x[0]
    y = pickle.loads(pickle.dumps(x))
    assert type(y) is group
    np.testing.assert_allclose(y.parameters, x.parameters, rtol=0, atol=1e-15)


@pytest.mark.parametrize("group", GROUPS)
def test_sample_uniform_is_reproducible(group: type) -> None:
    a = group.sample_uniform(np.random.default_rng(7), (4,))
    b = group.sample_uniform(np.random.default_rng(7), (4,))
    np.testing.assert_array_equal(a.parameters, b.parameters)
    assert group.sample_uniform(np.random.default_rng(7), 4).batch_shape == (4,)
    with pytest.raises(InputError, match="Generator"):
        group.sample_uniform(np.random.RandomState(7), (4,))


# --------------------------------------------------------------------- hand-computed values


def test_se2_compose_by_hand() -> None:
    a = SE2.from_xy_theta([1.0, 2.0, np.pi / 2])
    b = SE2.from_xy_theta([1.0, 0.0, 0.0])
    np.testing.assert_allclose((a @ b).xy_theta(), [1.0, 3.0, np.pi / 2], atol=1e-15)
    np.testing.assert_allclose(a @ np.array([1.0, 0.0]), [1.0, 3.0], atol=1e-15)
    np.testing.assert_allclose(a.inverse().xy_theta(), [-2.0, 1.0, -np.pi / 2], atol=1e-15)


def test_se2_exp_is_a_constant_velocity_arc() -> None:
    # Unit speed for unit time while turning a quarter circle: radius 2/π, end (r, r).
    x = SE2.exp([1.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(x.xy_theta(), [2 / np.pi, 2 / np.pi, np.pi / 2], atol=1e-15)
    np.testing.assert_allclose(SE2.from_xy_theta([3.0, -4.0, 0.0]).log(), [3.0, -4.0, 0.0])


def test_se2_heading_is_wrapped() -> None:
    np.testing.assert_allclose(SE2.from_xy_theta([0, 0, 3 * np.pi / 2]).xy_theta()[2], -np.pi / 2)
    assert SE2.from_xy_theta([0, 0, np.pi]).xy_theta()[2] == -np.pi
    assert SE2.from_xy_theta([0, 0, np.pi]).log()[2] == -np.pi
    assert SO2.from_angle(np.pi).angle() == -np.pi
    assert SO2.from_angle(2 * np.pi + 0.5).angle() == pytest.approx(0.5, abs=1e-15)


def test_se2_accessors_round_trip() -> None:
    poses = np.array([[1.0, 2.0, 0.3], [-4.0, 0.5, -3.0]])
    x = SE2.from_xy_theta(poses)
    np.testing.assert_allclose(x.xy_theta(), poses, atol=1e-15)
    np.testing.assert_allclose(x.translation(), poses[:, :2])
    np.testing.assert_allclose(x.rotation().angle(), poses[:, 2], atol=1e-15)
    y = SE2.from_rotation_and_translation(SO2.from_angle(poses[:, 2]), poses[:, :2])
    assert_same(x, y, atol=0)
    assert_same(SE2.from_translation([1.0, 2.0]), SE2.from_xy_theta([1.0, 2.0, 0.0]), atol=0)


def test_so2_by_hand() -> None:
    np.testing.assert_allclose(
        SO2.from_angle(np.pi / 2) @ np.array([1.0, 0.0]), [0.0, 1.0], atol=1e-15
    )
    np.testing.assert_allclose(SO2.from_angle([0.1, 0.2]).angle(), [0.1, 0.2])
    np.testing.assert_allclose(SO2.exp([[0.5]]).log(), [[0.5]])


def test_so3_quarter_turn_about_z_maps_x_to_y() -> None:
    R = SO3.exp([0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(R @ np.array([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(R.as_matrix(), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    s = np.sqrt(0.5)
    np.testing.assert_allclose(R.quaternion_wxyz(), [s, 0.0, 0.0, s], atol=1e-15)
    np.testing.assert_allclose(R.quaternion_xyzw(), [0.0, 0.0, s, s], atol=1e-15)
    assert_same(SO3.from_quaternion_xyzw([0.0, 0.0, s, s]), R, atol=1e-15)


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@pytest.mark.parametrize("rpy", [(0.1, 0.2, 0.3), (-3.0, 1.2, 2.5), (0.0, -1.5, -3.1)])
def test_so3_roll_pitch_yaw(rpy: tuple[float, float, float]) -> None:
    R = SO3.from_rpy_radians(rpy)
    np.testing.assert_allclose(R.as_matrix(), _rz(rpy[2]) @ _ry(rpy[1]) @ _rx(rpy[0]), atol=1e-15)
    np.testing.assert_allclose(R.as_rpy_radians(), rpy, atol=1e-12)
    np.testing.assert_allclose(
        SO3.from_rpy_radians([[0, 0, np.pi / 2]]).as_matrix()[0], _rz(np.pi / 2), atol=1e-15
    )


def test_so3_rpy_angles_are_wrapped() -> None:
    rpy = SO3.from_rpy_radians([np.pi, 0.0, 2 * np.pi - 0.25]).as_rpy_radians()
    assert np.all(rpy >= -np.pi) and np.all(rpy < np.pi)
    np.testing.assert_allclose(np.abs(rpy), [np.pi, 0.0, 0.25], atol=1e-12)


def test_so3_log_of_both_quaternion_signs_and_half_turns() -> None:
    omega = np.array([0.3, -1.1, 0.7])
    q = SO3.exp(omega).quaternion_wxyz()
    np.testing.assert_allclose(SO3(-q).log(), omega, atol=1e-14)
    # A half turn: the angle is π whichever sign is stored.
    for quat in ([0.0, 1.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [-1e-17, 0.0, 0.0, 1.0]):
        log = SO3(quat).log()
        assert np.linalg.norm(log) == pytest.approx(np.pi, abs=1e-15)
        assert_same(SO3.exp(log), SO3(quat))
    # Just below π, from both quaternion signs.
    axis = np.array([2.0, -1.0, 0.5]) / np.linalg.norm([2.0, -1.0, 0.5])
    for theta in (np.pi - 1e-6, np.pi - 1e-9):
        x = SO3.exp(theta * axis)
        np.testing.assert_allclose(x.log(), theta * axis, atol=1e-12)
        np.testing.assert_allclose(SO3(-x.wxyz).log(), theta * axis, atol=1e-12)
    # Half turns from matrices: Shepperd's branch for a vanishing w.
    for R in (np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])):
        np.testing.assert_allclose(SO3.from_matrix(R).as_matrix(), R, atol=1e-15)


def test_se3_exp_of_pure_translation() -> None:
    x = SE3.exp([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(x.translation(), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(x.quaternion_wxyz(), [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(x.log(), [1.0, 2.0, 3.0, 0.0, 0.0, 0.0])


def test_se3_planar_motion_matches_se2() -> None:
    rng = np.random.default_rng(3)
    planar = rng.standard_normal((20, 3))
    planar[:, 2] = rng.uniform(-3.0, 3.0, 20)
    xi6 = np.zeros((20, 6))
    xi6[:, :2], xi6[:, 5] = planar[:, :2], planar[:, 2]
    x2, x3 = SE2.exp(planar), SE3.exp(xi6)
    M2, M3 = x2.as_matrix(), x3.as_matrix()
    np.testing.assert_allclose(M3[:, :2, :2], M2[:, :2, :2], atol=1e-14)
    np.testing.assert_allclose(M3[:, :2, 3], M2[:, :2, 2], atol=1e-14)
    np.testing.assert_allclose(M3[:, 2, 3], 0.0, atol=0)
    np.testing.assert_allclose(x3.log()[:, [0, 1, 5]], x2.log(), atol=1e-12)


def test_se3_accessors() -> None:
    R = SO3.from_rpy_radians([0.1, 0.2, 0.3])
    x = SE3.from_rotation_and_translation(R, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(x.rotation().wxyz, R.wxyz)
    np.testing.assert_array_equal(x.translation(), [1.0, 2.0, 3.0])
    assert_same(SE3.from_quaternion_wxyz_and_translation(R.wxyz, [1.0, 2.0, 3.0]), x, atol=0)
    assert_same(
        SE3.from_translation([1.0, 2.0, 3.0]) @ SE3.from_rotation_and_translation(R, [0, 0, 0]), x
    )
    batched = SE3.from_rotation_and_translation(R, np.zeros((4, 3)))
    assert batched.batch_shape == (4,)


# --------------------------------------------------------------------- values and input checks


@pytest.mark.parametrize("group", GROUPS)
def test_values_are_immutable_and_do_not_alias(group: type) -> None:
    params = np.array(group.identity().parameters)
    x = group(params)
    params[0] = 5.0
    assert x.parameters[0] == 1.0
    with pytest.raises(ValueError, match="read-only"):
        x.parameters[0] = 2.0
    with pytest.raises(AttributeError):
        x.anything = 1
    with pytest.raises(AttributeError):
        x.parameters = params


@pytest.mark.parametrize("group", GROUPS)
def test_constructor_validation(group: type) -> None:
    p = np.array(group.identity().parameters)
    with pytest.raises(ShapeError, match=r"\(\.\.\., "):
        group(p[:-1])
    bad = p.copy()
    bad[-1] = np.nan
    with pytest.raises(NonFiniteError):
        group(bad)
    far = p.copy()
    far[0] = 1.1
    with pytest.raises(InputError, match="unit norm"):
        group(far)
    near = p.copy()
    near[0] = 1.0 + 1e-8
    assert group(near).parameters[0] == 1.0
    with pytest.raises(NonFiniteError):
        group.exp(np.full(group.tangent_dim, np.inf))
    with pytest.raises(ShapeError):
        group.exp(np.zeros(group.tangent_dim + 1))
    with pytest.raises(ShapeError):
        group.identity() @ np.zeros(group.space_dim + 1)
    with pytest.raises(ShapeError, match="do not broadcast"):
        group.identity((2,)) @ group.identity((3,))
    other = SE3 if group is not SE3 else SO2
    with pytest.raises(InputError, match=f"expected a {group.__name__}"):
        group.identity() @ other.identity()
    with pytest.raises(InputError):
        group.identity().box_minus(other.identity())


@pytest.mark.parametrize("group", GROUPS)
def test_from_matrix_rejects_non_members(group: type) -> None:
    n = group.matrix_dim
    scaled = np.eye(n)
    scaled[0, 0] = 1.01
    with pytest.raises(InputError):
        group.from_matrix(scaled)
    reflection = np.eye(n)
    reflection[0, 0] = -1.0
    with pytest.raises(InputError, match="reflection"):
        group.from_matrix(reflection)
    with pytest.raises(ShapeError):
        group.from_matrix(np.eye(n + 1))
    if group in (SE2, SE3):
        bottom = np.eye(n)
        bottom[-1, 0] = 0.5
        with pytest.raises(InputError, match="last row"):
            group.from_matrix(bottom)


def test_quaternion_constructors_normalise_near_unit_only() -> None:
    q = np.array([1.0, 2.0, 3.0, 4.0])
    with pytest.raises(InputError, match="unit norm"):
        SO3.from_quaternion_wxyz(q)
    unit = q / np.linalg.norm(q)
    x = SO3.from_quaternion_wxyz(unit * (1 + 5e-7))
    np.testing.assert_allclose(np.linalg.norm(x.wxyz), 1.0, rtol=0, atol=1e-15)
    with pytest.raises(InputError):
        SE3(np.concatenate([q, [0.0, 0.0, 0.0]]))
    with pytest.raises(InputError):
        SO2.from_unit_complex([0.5, 0.5])
    drifted = SO3.from_parameters_unchecked(unit * 1.001)
    np.testing.assert_allclose(np.linalg.norm(drifted.normalize().wxyz), 1.0, atol=1e-15)
