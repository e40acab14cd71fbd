"""Motion models: hand-computed steps, Jacobians against finite differences, sampling
statistics, batch shapes and input validation."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamkit.errors import CovarianceError, GeometryError, InputError, NonFiniteError, ShapeError
from slamkit.geometry import pose2, wrap_angle
from slamkit.models import (
    Ackermann,
    DifferentialDrive,
    MotionModel,
    OdometryModel,
    UnicycleArc,
    UnicycleEuler,
    integrate_odometry,
    odometry_control,
    odometry_noise_cov,
    propagate_gaussian,
)

# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------


def pose_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` for poses, heading difference wrapped."""
    d = np.asarray(a, float) - np.asarray(b, float)
    d[..., 2] = wrap_angle(d[..., 2])
    return d


def numeric_jacobian(
    f: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, eps: float = 1e-6
) -> np.ndarray:
    """Central differences of a pose-valued ``f`` (heading differences wrapped)."""
    x0 = np.asarray(x0, float)
    cols = []
    for i in range(x0.size):
        step = np.zeros_like(x0)
        step[i] = eps
        cols.append(pose_diff(f(x0 + step), f(x0 - step)) / (2 * eps))
    return np.stack(cols, axis=-1)


MODELS: dict[str, MotionModel] = {
    "euler": UnicycleEuler(),
    "arc": UnicycleArc(),
    "diff": DifferentialDrive(0.45),
    "diff-exact": DifferentialDrive(0.45, exact=True),
    "odometry": OdometryModel(),
    "ackermann": Ackermann(2.0),
    "ackermann-vp": Ackermann(2.83, (3.78, 0.5), 0.76),
    "ackermann-right": Ackermann(1.5, (-0.4, -0.3), -0.5),
}


def random_control(name: str, rng: np.random.Generator) -> np.ndarray:
    if name.startswith("ackermann"):
        return np.array([rng.uniform(-3, 6), rng.uniform(-0.5, 0.5)])
    if name == "odometry":
        return np.array([rng.uniform(-3, 3), rng.uniform(0, 2), rng.uniform(-3, 3)])
    if name.startswith("diff"):
        return rng.uniform(-2, 2, 2)
    return np.array([rng.uniform(-2, 2), rng.uniform(-2, 2)])


def special_controls(name: str) -> list[np.ndarray]:
    """Controls at the edges of each model: straight lines, tiny turn rates."""
    if name.startswith("ackermann"):
        return [np.array([4.0, 0.0]), np.array([4.0, 1e-9]), np.array([-2.0, -1e-9])]
    if name == "odometry":
        return [np.array([0.0, 0.0, 0.3]), np.array([3.1, 1.0, -3.1])]
    if name.startswith("diff"):
        return [np.array([1.0, 1.0]), np.array([1.0, 1.0 + 0.45e-9]), np.array([-1.0, 1.0])]
    return [np.array([1.5, 0.0]), np.array([1.5, 1e-9]), np.array([-0.7, -1e-9])]


def jacobian_cases() -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    rng = np.random.default_rng(7)
    cases = []
    for name in MODELS:
        controls = [random_control(name, rng) for _ in range(4)] + special_controls(name)
        for u in controls:
            x = np.array([rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(-np.pi, np.pi)])
            dt = float(rng.choice([0.05, 0.4, 1.0]))
            cases.append((name, x, u, dt))
    return cases


# --------------------------------------------------------------------------------------------
# Jacobians
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "x", "u", "dt"), jacobian_cases())
def test_jacobians_match_finite_differences(
    name: str, x: np.ndarray, u: np.ndarray, dt: float
) -> None:
    model = MODELS[name]
    G, V = model.jacobians(x, u, dt)
    assert G.shape == (3, 3)
    assert V.shape == (3, model.control_dim)
    G_num = numeric_jacobian(lambda xx: model.apply(xx, u, dt), x)
    V_num = numeric_jacobian(lambda uu: model.apply(x, uu, dt), u)
    np.testing.assert_allclose(G, G_num, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(V, V_num, rtol=1e-6, atol=1e-6)


def test_arc_jacobians_at_exactly_zero_turn_rate_are_finite_and_right() -> None:
    model = UnicycleArc()
    x, u, dt = np.array([1.0, 2.0, 0.7]), np.array([2.0, 0.0]), 0.5
    G, V = model.jacobians(x, u, dt)
    assert np.all(np.isfinite(G)) and np.all(np.isfinite(V))
    c, s = np.cos(0.7), np.sin(0.7)
    # limit omega -> 0: d/d omega of the arc is v dt² (-sin, cos) / 2
    np.testing.assert_allclose(V[:, 1], [-2.0 * 0.25 * s / 2, 2.0 * 0.25 * c / 2, 0.5], atol=1e-15)
    np.testing.assert_allclose(V[:, 0], [0.5 * c, 0.5 * s, 0.0], atol=1e-15)
    np.testing.assert_allclose(G[:, 2], [-2.0 * 0.5 * s, 2.0 * 0.5 * c, 1.0], atol=1e-15)


def test_arc_series_branch_joins_the_closed_form() -> None:
    """Either side of the series switch the arc matches the textbook closed form."""
    x = np.array([0.3, -0.2, 1.1])
    v, dt = 2.0, 1.0
    for phi in [1e-3 * (1 - 1e-9), 1e-3 * (1 + 1e-9), 2e-3, 5e-4, 0.3, -2.5]:
        w = phi / dt
        closed = np.array(
            [
                x[0] + v / w * (np.sin(x[2] + phi) - np.sin(x[2])),
                x[1] + v / w * (np.cos(x[2]) - np.cos(x[2] + phi)),
                wrap_angle(x[2] + phi),
            ]
        )
        # the closed form itself loses ~1e-16/phi relative precision at small phi
        np.testing.assert_allclose(UnicycleArc().apply(x, [v, w], dt), closed, atol=1e-11)


# --------------------------------------------------------------------------------------------
# hand-computed steps
# --------------------------------------------------------------------------------------------


def test_unicycle_euler_hand_values() -> None:
    np.testing.assert_allclose(UnicycleEuler().apply([0, 0, 0], [1, 0], 1.0), [1, 0, 0])
    # heading pi/2, v = 2, omega = 0.5, dt = 0.1: moves 0.2 along +y, turns 0.05
    out = UnicycleEuler().apply([1.0, 1.0, np.pi / 2], [2.0, 0.5], 0.1)
    np.testing.assert_allclose(out, [1.0, 1.2, np.pi / 2 + 0.05], atol=1e-15)
    # Euler is not the arc: the step uses the heading at the start of the step only
    G, V = UnicycleEuler().jacobians([0, 0, 0], [2.0, 0.5], 0.1)
    np.testing.assert_allclose(G, [[1, 0, 0], [0, 1, 0.2], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(V, [[0.1, 0], [0, 0], [0, 0.1]], atol=1e-15)


def test_unicycle_arc_quarter_and_full_circle() -> None:
    # radius v / omega = 1, omega dt = pi/2: quarter circle to (1, 1) facing +y
    out = UnicycleArc().apply([0, 0, 0], [np.pi / 2, np.pi / 2], 1.0)
    np.testing.assert_allclose(out, [1.0, 1.0, np.pi / 2], atol=1e-12)
    # full circle comes back to the start, heading wrapped back to 0
    out = UnicycleArc().apply([2.0, -1.0, 0.4], [2 * np.pi, 2 * np.pi], 1.0)
    np.testing.assert_allclose(pose_diff(out, [2.0, -1.0, 0.4]), 0.0, atol=1e-12)
    # omega = 0 is the straight line
    out = UnicycleArc().apply([0, 0, np.pi / 6], [2.0, 0.0], 1.5)
    np.testing.assert_allclose(out, [3 * np.cos(np.pi / 6), 3 * np.sin(np.pi / 6), np.pi / 6])


def test_heading_is_wrapped() -> None:
    out = UnicycleEuler().apply([0, 0, 3.0], [0.0, 1.0], 1.0)
    assert -np.pi <= out[2] < np.pi
    np.testing.assert_allclose(out[2], 4.0 - 2 * np.pi)


def test_differential_drive_hand_values() -> None:
    dd = DifferentialDrive(0.5)
    # equal wheel speeds: straight ahead along the heading
    out = dd.apply([0, 0, 0.3], [2.0, 2.0], 0.5)
    np.testing.assert_allclose(out, [np.cos(0.3), np.sin(0.3), 0.3], atol=1e-15)
    # opposite speeds: turn on the spot, counter-clockwise when the right wheel is faster
    out = DifferentialDrive(0.5, exact=True).apply([1, 2, 0], [-1.0, 1.0], 0.1)
    np.testing.assert_allclose(out, [1, 2, 0.4], atol=1e-15)
    # v = (vl + vr)/2, omega = (vr - vl)/d
    v, w = dd.body_velocity([1.0, 3.0])
    assert (float(v), float(w)) == (2.0, 4.0)
    # the exact form equals the arc model on (v, omega)
    x, u = np.array([0.2, 0.1, -1.0]), np.array([0.3, 1.1])
    np.testing.assert_allclose(
        DifferentialDrive(0.5, exact=True).apply(x, u, 0.7),
        UnicycleArc().apply(x, [0.7, 1.6], 0.7),
        atol=1e-15,
    )


def test_differential_drive_control_jacobian_is_the_chain_rule() -> None:
    d = 0.5
    x, u, dt = np.array([0.0, 0.0, 0.25]), np.array([0.8, 1.2]), 0.2
    _, V = DifferentialDrive(d).jacobians(x, u, dt)
    _, V_vw = UnicycleEuler().jacobians(x, [1.0, 0.8], dt)
    np.testing.assert_allclose(V, V_vw @ np.array([[0.5, 0.5], [-1 / d, 1 / d]]), atol=1e-15)
    # both wheels drive forward: the x/y rows have the same sign for both wheels
    assert V[0, 0] > 0 and V[0, 1] > 0 and V[1, 0] > 0 and V[1, 1] > 0


def test_odometry_control_hand_values_and_round_trip() -> None:
    u = odometry_control([1.0, 1.0, 0.0], [1.0, 2.0, np.pi / 2])
    np.testing.assert_allclose(u, [np.pi / 2, 1.0, 0.0], atol=1e-15)
    rng = np.random.default_rng(3)
    a = np.column_stack([rng.uniform(-5, 5, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    b = np.column_stack([rng.uniform(-5, 5, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    u = odometry_control(a, b)
    assert u.shape == (50, 3)
    assert np.all(u[:, 1] >= 0)
    assert np.all(np.abs(u[:, [0, 2]]) <= np.pi)
    np.testing.assert_allclose(pose_diff(OdometryModel().apply(a, u, 0.0), b), 0.0, atol=1e-12)


def test_integrate_odometry_inverts_odometry_control_and_matches_the_model() -> None:
    rng = np.random.default_rng(4)
    path = np.column_stack([rng.uniform(-5, 5, (40, 2)), rng.uniform(-np.pi, np.pi, 40)])
    u = odometry_control(path[:-1], path[1:])
    poses = integrate_odometry(path[0], u)
    assert poses.shape == (40, 3)
    np.testing.assert_allclose(pose_diff(poses, path), 0.0, atol=1e-9)
    stepwise = [path[0]]
    for step in u:  # one application of the model per step gives the same poses
        stepwise.append(OdometryModel().apply(stepwise[-1], step, 0.0))
    np.testing.assert_allclose(pose_diff(poses, np.array(stepwise)), 0.0, atol=1e-9)
    np.testing.assert_array_equal(
        integrate_odometry([1.0, 2.0, 3.0], np.zeros((0, 3))), [[1, 2, 3]]
    )


def test_odometry_control_without_translation_puts_all_rotation_in_rot2() -> None:
    u = odometry_control([1.0, 1.0, 3.0], [1.0, 1.0, -3.0])
    np.testing.assert_allclose(u, [0.0, 0.0, -6.0 + 2 * np.pi], atol=1e-15)
    u = odometry_control([1.0, 1.0, 0.2], [1.0 + 1e-12, 1.0, 0.5])
    np.testing.assert_allclose(u, [0.0, 1e-12, 0.3], atol=1e-15)


def test_odometry_model_ignores_dt_and_matches_compose() -> None:
    u = np.array([0.4, 1.5, -0.9])
    x = np.array([2.0, -1.0, 2.5])
    expected = pose2.compose(x, pose2.compose([0, 0, u[0]], [u[1], 0, u[2]]))
    np.testing.assert_allclose(OdometryModel().apply(x, u, 123.0), expected, atol=1e-14)
    np.testing.assert_allclose(OdometryModel().apply(x, u, 0.0), expected, atol=1e-14)


def test_odometry_noise_cov() -> None:
    cov = odometry_noise_cov([[0.5, 2.0, -0.1]], [0.1, 0.01, 0.2, 0.05])
    expected = np.diag(
        [0.1 * 0.25 + 0.01 * 4, 0.2 * 4 + 0.05 * (0.25 + 0.01), 0.1 * 0.01 + 0.01 * 4]
    )
    np.testing.assert_allclose(cov, expected[None], atol=1e-15)
    with pytest.raises(InputError):
        odometry_noise_cov([0.5, 2.0, -0.1], [0.1, -0.01, 0.2, 0.05])


def test_ackermann_straight_and_hand_values() -> None:
    # zero offsets, zero steering: straight along the heading
    out = Ackermann(2.5).apply([1.0, 2.0, np.pi / 3], [3.0, 0.0], 0.5)
    np.testing.assert_allclose(
        out, [1 + 1.5 * np.cos(np.pi / 3), 2 + 1.5 * np.sin(np.pi / 3), np.pi / 3]
    )
    # encoder on the left wheel H = 0.5, L = 2, tan(alpha) = 0.4: D = 1 - 0.4*0.5/2 = 0.9, so
    # v_c = 0.9 / 0.9 = 1 and omega = v_c tan(alpha) / L = 0.2
    out = Ackermann(2.0, encoder_offset=0.5).apply([0, 0, 0], [0.9, np.arctan(0.4)], 1.0)
    np.testing.assert_allclose(out, [1.0, 0.0, 0.2], atol=1e-15)
    # sensor 1 m ahead and 0.5 m left: omega × r = 0.2 * (-0.5, 1) adds to v_c (1, 0)
    out = Ackermann(2.0, (1.0, 0.5), 0.5).apply([0, 0, 0], [0.9, np.arctan(0.4)], 1.0)
    np.testing.assert_allclose(out, [1.0 - 0.1, 0.2, 0.2], atol=1e-15)


def test_ackermann_sensor_pose_tracks_the_rear_axle() -> None:
    """Over a short step the sensor point moves rigidly with the rear axle: the axle pose
    recovered from the predicted sensor pose matches the zero-offset model (to O(dt²)).
    A wrong sign of ``b`` would leave a first-order error."""
    offset = np.array([3.78, 0.5])
    car = Ackermann(2.83, tuple(offset), 0.76)
    axle = Ackermann(2.83, (0.0, 0.0), 0.76)
    T_axle = np.array([4.0, -2.0, 0.8])
    T_sensor = pose2.compose(T_axle, [*offset, 0.0])
    u, dt = np.array([5.0, 0.3]), 1e-3
    T_sensor_next = car.apply(T_sensor, u, dt)
    T_axle_next = pose2.compose(T_sensor_next, pose2.inverse([*offset, 0.0]))
    moved = np.linalg.norm(T_sensor_next[:2] - T_sensor[:2])
    err = np.linalg.norm(pose_diff(T_axle_next, axle.apply(T_axle, u, dt)))
    assert err < 1e-3 * moved


def test_ackermann_degenerate_steering_raises() -> None:
    with pytest.raises(GeometryError):
        Ackermann(2.0).apply([0, 0, 0], [1.0, np.pi / 2], 0.1)
    # tan(alpha) = L / H puts the left encoder wheel on the centre of rotation
    with pytest.raises(GeometryError):
        Ackermann(2.0, encoder_offset=1.0).jacobians([0, 0, 0], [1.0, np.arctan(2.0)], 0.1)


# --------------------------------------------------------------------------------------------
# sampling
# --------------------------------------------------------------------------------------------


SAMPLE_CASES = [
    ("euler", [1.0, 0.3], np.diag([0.01, 0.004])),
    ("arc", [1.0, 1e-9], np.array([[0.01, 0.002], [0.002, 0.004]])),
    ("diff-exact", [0.9, 1.1], np.diag([0.003, 0.002])),
    ("odometry", [0.3, 1.0, -0.2], np.diag([1e-3, 4e-3, 1e-3])),
    ("ackermann-vp", [4.0, 0.1], np.diag([0.02, 1e-4])),
]


@pytest.mark.parametrize(("name", "u", "Q"), SAMPLE_CASES)
def test_sample_covariance_matches_linearisation(name: str, u: list[float], Q: np.ndarray) -> None:
    model = MODELS[name]
    x = np.array([1.0, -2.0, 0.6])
    dt = 0.1
    n = 20_000
    scale = 0.05  # small noise: the linearisation is accurate
    samples = model.sample(
        np.broadcast_to(x, (n, 3)), u, dt, scale**2 * Q, np.random.default_rng(11)
    )
    assert samples.shape == (n, 3)
    d = pose_diff(samples, model.apply(x, u, dt))
    S = np.cov(d, rowvar=False)
    _, V = model.jacobians(x, u, dt)
    C = V @ (scale**2 * Q) @ V.T
    # compare correlations-scaled entries: sampling error of a covariance is ~sqrt(2/n) ≈ 1 %
    std = np.sqrt(np.maximum(np.diag(C), 1e-300))
    active = np.diag(C) > 1e-12 * np.max(np.diag(C))
    ok = np.outer(active, active)
    np.testing.assert_allclose(
        (S / np.outer(std, std))[ok], (C / np.outer(std, std))[ok], atol=0.05
    )
    # components with no predicted spread do not move at all
    assert np.all(np.abs(d[:, ~active]) < 1e-9)
    np.testing.assert_allclose(d.mean(axis=0), 0.0, atol=5 * np.max(std) / np.sqrt(n) + 1e-12)


def test_sample_is_reproducible_and_zero_noise_is_apply() -> None:
    model = UnicycleArc()
    x = np.zeros((100, 3))
    Q = np.diag([0.1, 0.05])
    a = model.sample(x, [1.0, 0.5], 0.1, Q, np.random.default_rng(5))
    b = model.sample(x, [1.0, 0.5], 0.1, Q, np.random.default_rng(5))
    c = model.sample(x, [1.0, 0.5], 0.1, Q, np.random.default_rng(6))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    assert np.unique(a[:, 0]).size == 100  # independent draws per particle
    z = model.sample(x, [1.0, 0.5], 0.1, np.zeros((2, 2)), np.random.default_rng(5))
    np.testing.assert_array_equal(z, model.apply(x, [1.0, 0.5], 0.1))


def test_sample_accepts_per_element_control_covariance() -> None:
    u = np.array([[0.1, 1.0, 0.0], [0.0, 0.0, 0.0]])
    cov = odometry_noise_cov(u, [0.1, 0.1, 0.1, 0.1])
    out = OdometryModel().sample(np.zeros(3), u, 0.0, cov, np.random.default_rng(0))
    assert out.shape == (2, 3)
    np.testing.assert_array_equal(out[1], np.zeros(3))  # no motion, no noise


# --------------------------------------------------------------------------------------------
# batches, broadcasting, immutability
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("batch", [(5,), (2, 3)])
def test_batches_equal_per_element_loops(name: str, batch: tuple[int, ...]) -> None:
    model = MODELS[name]
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-3, 3, (*batch, 2)), rng.uniform(-3, 3, (*batch, 1))], -1)
    u = np.stack([random_control(name, rng) for _ in range(int(np.prod(batch)))]).reshape(
        *batch, model.control_dim
    )
    x0, u0 = x.copy(), u.copy()
    out = model.apply(x, u, 0.3)
    G, V = model.jacobians(x, u, 0.3)
    assert out.shape == (*batch, 3)
    assert G.shape == (*batch, 3, 3) and V.shape == (*batch, 3, model.control_dim)
    for i in np.ndindex(*batch):
        np.testing.assert_allclose(out[i], model.apply(x[i], u[i], 0.3), atol=1e-15)
        Gi, Vi = model.jacobians(x[i], u[i], 0.3)
        np.testing.assert_allclose(G[i], Gi, atol=1e-15)
        np.testing.assert_allclose(V[i], Vi, atol=1e-15)
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_array_equal(u, u0)
    # one control broadcast over many poses, and one pose under many controls
    np.testing.assert_allclose(
        model.apply(x, u[(0,) * len(batch)], 0.3)[(0,) * len(batch)], out[(0,) * len(batch)]
    )
    np.testing.assert_allclose(
        model.apply(x[(0,) * len(batch)], u, 0.3)[(0,) * len(batch)], out[(0,) * len(batch)]
    )


def test_models_satisfy_the_protocol() -> None:
    for model in MODELS.values():
        assert isinstance(model, MotionModel)
        assert len(model.control_names) == model.control_dim
    assert UnicycleEuler().control_names == ("v", "omega")
    assert DifferentialDrive(1.0).control_names == ("v_left", "v_right")
    assert OdometryModel().control_names == ("rot1", "trans", "rot2")
    assert Ackermann(1.0).control_names == ("speed", "steering")


@settings(max_examples=60, deadline=None)
@given(
    name=st.sampled_from(list(MODELS)),
    theta=st.floats(-50, 50),
    turn=st.floats(-1e-6, 1e-6) | st.floats(-0.5, 0.5),
    dt=st.floats(0, 2),
)
def test_heading_range_and_finite_jacobians(
    name: str, theta: float, turn: float, dt: float
) -> None:
    model = MODELS[name]
    u = np.array([1.3, turn, 0.2][: model.control_dim])
    if name.startswith("diff"):
        u = np.array([1.0, 1.0 + turn])
    x = np.array([0.5, -0.5, theta])
    out = model.apply(x, u, dt)
    G, V = model.jacobians(x, u, dt)
    assert -np.pi <= out[2] < np.pi
    assert np.all(np.isfinite(out)) and np.all(np.isfinite(G)) and np.all(np.isfinite(V))


# --------------------------------------------------------------------------------------------
# Gaussian propagation
# --------------------------------------------------------------------------------------------


def test_propagate_gaussian_matches_the_formula() -> None:
    model = DifferentialDrive(0.5, exact=True)
    mean = np.array([1.0, 2.0, 0.3])
    A = np.array([[0.2, 0.01, 0.0], [0.05, 0.1, 0.0], [0.01, -0.02, 0.05]])
    P = A @ A.T
    Q = np.diag([0.01, 0.02])
    u, dt = np.array([0.9, 1.3]), 0.2
    m1, P1 = propagate_gaussian(model, mean, P, u, dt, Q)
    G, V = model.jacobians(mean, u, dt)
    np.testing.assert_allclose(m1, model.apply(mean, u, dt))
    np.testing.assert_allclose(P1, G @ P @ G.T + V @ Q @ V.T, atol=1e-15)
    np.testing.assert_array_equal(P1, P1.T)
    # a known start with noise-free controls stays known
    _, P0 = propagate_gaussian(model, mean, np.zeros((3, 3)), u, dt, np.zeros((2, 2)))
    np.testing.assert_array_equal(P0, 0.0)
    # dead reckoning: uncertainty grows step after step
    m, C = mean, np.zeros((3, 3))
    traces = []
    for _ in range(20):
        m, C = propagate_gaussian(model, m, C, u, dt, Q)
        traces.append(np.trace(C))
    assert np.all(np.diff(traces) > 0)


def test_propagate_gaussian_batches() -> None:
    model = UnicycleEuler()
    means = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    covs = np.stack([np.eye(3) * 0.1, np.eye(3) * 0.2])
    m, P = propagate_gaussian(model, means, covs, [1.0, 0.1], 0.5, np.eye(2) * 0.01)
    assert m.shape == (2, 3) and P.shape == (2, 3, 3)
    for i in range(2):
        mi, Pi = propagate_gaussian(model, means[i], covs[i], [1.0, 0.1], 0.5, np.eye(2) * 0.01)
        np.testing.assert_allclose(m[i], mi)
        np.testing.assert_allclose(P[i], Pi)


# --------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------


def test_bad_inputs_raise_typed_errors() -> None:
    model = UnicycleEuler()
    rng = np.random.default_rng(0)
    with pytest.raises(NonFiniteError):
        model.apply([0.0, np.nan, 0.0], [1.0, 0.0], 0.1)
    with pytest.raises(NonFiniteError):
        model.jacobians([0.0, 0.0, 0.0], [np.inf, 0.0], 0.1)
    with pytest.raises(ShapeError):
        model.apply([0.0, 0.0], [1.0, 0.0], 0.1)
    with pytest.raises(ShapeError):
        model.apply([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.1)
    with pytest.raises(ShapeError):
        model.apply(np.zeros((4, 3)), np.zeros((3, 2)), 0.1)
    with pytest.raises(InputError):
        model.apply([0.0, 0.0, 0.0], [1.0, 0.0], -0.1)
    with pytest.raises(InputError):
        model.apply([0.0, 0.0, 0.0], [1.0, 0.0], float("nan"))
    with pytest.raises(CovarianceError):
        model.sample([0, 0, 0], [1.0, 0.0], 0.1, [[1.0, 0.0], [0.0, -0.1]], rng)
    with pytest.raises(CovarianceError):
        model.sample([0, 0, 0], [1.0, 0.0], 0.1, [[1.0, 0.5], [0.0, 1.0]], rng)
    with pytest.raises(ShapeError):
        model.sample([0, 0, 0], [1.0, 0.0], 0.1, np.eye(3), rng)
    with pytest.raises(CovarianceError):
        propagate_gaussian(model, [0, 0, 0], -np.eye(3), [1.0, 0.0], 0.1, np.eye(2))
    with pytest.raises(InputError):
        DifferentialDrive(0.0)
    with pytest.raises(InputError):
        Ackermann(-1.0)
    with pytest.raises(ShapeError):
        Ackermann(1.0, (1.0, 2.0, 3.0))  # type: ignore[arg-type]
    with pytest.raises(ShapeError):
        odometry_control([0, 0, 0], [[0, 0]])


@pytest.mark.parametrize(
    "model",
    [UnicycleEuler(), UnicycleArc(), DifferentialDrive(0.5), OdometryModel(),
     Ackermann(2.83, (3.78, 0.5), 0.76)],
    ids=repr,
)  # fmt: skip
def test_single_pose_step_agrees_with_the_batched_kernels(model):
    rng = np.random.default_rng(5)
    for w in (0.0, 1e-9, 0.3, -0.5):  # Ackermann steering must stay below pi/2
        x = np.array([*rng.normal(0, 5, 2), rng.uniform(-np.pi, np.pi)])
        u = np.array([0.8, w, 0.1][: model.control_dim])
        g, G, V = model.step_single(x, u, 0.1)
        np.testing.assert_allclose(g, model.apply(x, u, 0.1), rtol=0, atol=1e-12)
        G_ref, V_ref = model.jacobians(x, u, 0.1)
        np.testing.assert_allclose(G, G_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(V, V_ref, rtol=0, atol=1e-12)
