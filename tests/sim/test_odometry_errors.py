"""The odometry error model: systematic errors exact, noise statistics within χ² bounds,
glitches where and as large as reported."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

from slamkit.datasets.stream import (
    Control,
    Dataset,
    GroundTruth,
    LaserScan,
    LaserSpec,
    MotionSpec,
    Odometry,
)
from slamkit.errors import ConfigError, InputError
from slamkit.geometry import wrap_angle
from slamkit.models import OdometryModel, UnicycleEuler, integrate_odometry, odometry_control
from slamkit.sim.odometry_errors import OdometryErrorModel, corrupt_odometry

N_BEAMS = 5


def true_path(n: int, seed: int = 0) -> np.ndarray:
    """``n`` poses of a wandering drive: steps of 0.2-0.5 m, turns of a few degrees, and
    every 25th step a turn on the spot."""
    rng = np.random.default_rng(seed)
    u = np.zeros((n - 1, 3))
    u[:, 1] = rng.uniform(0.2, 0.5, n - 1)
    u[:, 0] = rng.normal(0.0, 0.05, n - 1)
    u[:, 2] = rng.normal(0.0, 0.05, n - 1)
    spot = np.arange(n - 1) % 25 == 24
    u[spot, 1] = 0.0
    u[spot, 0] = 0.0
    u[spot, 2] = rng.uniform(-1.5, 1.5, int(spot.sum()))
    return integrate_odometry(np.array([1.0, 2.0, 0.3]), u)


def odometry_dataset(n: int, seed: int = 0) -> Dataset:
    """Odometry (the truth) and a dummy scan at each of ``n`` stamps 0.25 s apart."""
    poses = true_path(n, seed)
    times = 0.25 * np.arange(n)
    events = []
    for t, p in zip(times, poses, strict=True):
        events += [Odometry(float(t), p), LaserScan(float(t), np.ones(N_BEAMS))]
    return Dataset(
        name="synthetic",
        events=tuple(events),
        motion=MotionSpec(OdometryModel(), np.eye(3) * 1e-4, source="odometry"),
        laser=LaserSpec(np.linspace(-1.0, 1.0, N_BEAMS), 10.0),
        truth=GroundTruth(times=times, poses=poses),
    )


def odometry_poses(ds: Dataset, *, unique: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and poses of the Odometry events (duplicates dropped when ``unique``)."""
    odo = [ev for ev in ds.events if isinstance(ev, Odometry)]
    if unique:
        odo = [ev for i, ev in enumerate(odo) if i == 0 or ev.t != odo[i - 1].t]
    return np.array([ev.t for ev in odo]), np.array([ev.pose for ev in odo])


def path_length(poses: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T)))


def turned(poses: np.ndarray) -> float:
    return float(np.sum(np.abs(wrap_angle(np.diff(poses[:, 2])))))


def test_wheel_radius_error_lengthens_the_path_by_exactly_its_size() -> None:
    ds = odometry_dataset(500)
    out, record = corrupt_odometry(
        ds, OdometryErrorModel.exact(0.02, 0.0), np.random.default_rng(3)
    )
    assert record.wheel_radius_error == 0.02 and len(record) == 0
    truth = ds.truth.poses
    assert truth is not None
    ratio = path_length(odometry_poses(out)[1]) / path_length(truth)
    assert ratio == pytest.approx(1.02, rel=1e-9, abs=0.0)


@pytest.mark.parametrize(("eps_r", "eps_b"), [(0.0, 0.03), (0.02, -0.025)])
def test_wheel_base_error_scales_the_turned_angle(eps_r: float, eps_b: float) -> None:
    ds = odometry_dataset(500)
    model = OdometryErrorModel.exact(eps_r, eps_b)
    out, _ = corrupt_odometry(ds, model, np.random.default_rng(3))
    truth = ds.truth.poses
    assert truth is not None
    factor = turned(odometry_poses(out)[1]) / turned(truth)
    assert factor == pytest.approx((1.0 + eps_r) / (1.0 + eps_b), rel=1e-9, abs=0.0)


def test_drawn_systematic_errors_lie_in_the_stated_range_and_follow_the_seed() -> None:
    ds = odometry_dataset(50)
    model = OdometryErrorModel()
    drawn = [corrupt_odometry(ds, model, np.random.default_rng(s))[1] for s in range(40)]
    eps = np.array([[r.wheel_radius_error, r.wheel_base_error] for r in drawn])
    assert np.all((np.abs(eps) >= 0.01) & (np.abs(eps) <= 0.03))
    assert 0 < np.sum(eps > 0) < eps.size  # both signs occur
    a, ra = corrupt_odometry(ds, model, np.random.default_rng(7))
    b, rb = corrupt_odometry(ds, model, np.random.default_rng(7))
    assert ra == rb
    np.testing.assert_array_equal(odometry_poses(a)[1], odometry_poses(b)[1])


def test_noise_has_the_stated_standard_deviations() -> None:
    """Normalised per-step errors of 2000 steps: their sample variance times (n - 1) is
    χ²(n - 1) distributed; the bounds hold with probability 99.9 % each."""
    n_steps = 2000
    ds = odometry_dataset(n_steps + 1, seed=1)
    model = replace(
        OdometryErrorModel(k_trans=0.02, k_rot=0.04, k_drift=0.01).without_glitches(),
        wheel_radius_error=0.0,
        wheel_base_error=0.0,
    )
    out, _ = corrupt_odometry(ds, model, np.random.default_rng(11))
    truth = ds.truth.poses
    assert truth is not None
    u_true = odometry_control(truth[:-1], truth[1:])
    odom = odometry_poses(out)[1]
    d_true, a_true = u_true[:, 1], wrap_angle(u_true[:, 0] + u_true[:, 2])
    d_odo = np.hypot(*np.diff(odom[:, :2], axis=0).T)
    a_odo = wrap_angle(np.diff(odom[:, 2]))
    sigma_t, sigma_a = model.step_sigmas(d_true, a_true)
    moving = d_true > 0  # on-the-spot turns have no translation noise
    z_t = (d_odo - d_true)[moving] / sigma_t[moving]
    z_a = wrap_angle(a_odo - a_true) / sigma_a
    for z in (z_t, z_a):
        n = z.size
        lo, hi = (math.sqrt(chi2.ppf(p, n - 1) / (n - 1)) for p in (0.0005, 0.9995))
        assert lo < 0.95 and hi < 1.06  # the bound is ~5 % at n ~ 2000
        assert lo <= float(np.std(z, ddof=1)) <= hi
        assert abs(float(np.mean(z))) <= 3.3 / math.sqrt(n)


def glitchy_model() -> OdometryErrorModel:
    return OdometryErrorModel(
        heading_jump_rate=0.01, stall_rate=0.01, duplicate_rate=0.01, out_of_order_rate=0.01
    )


def test_glitches_are_where_and_as_large_as_reported() -> None:
    ds = odometry_dataset(1500, seed=2)
    model = glitchy_model()
    out, record = corrupt_odometry(ds, model, np.random.default_rng(5))
    clean, clean_record = corrupt_odometry(ds, model.without_glitches(), np.random.default_rng(5))
    assert len(clean_record) == 0
    assert clean_record.wheel_radius_error == record.wheel_radius_error
    kinds = {g.kind for g in record}
    assert kinds == {"heading_jump", "stall", "duplicate", "out_of_order"}

    stamps = np.array([ev.t for ev in ds.events if isinstance(ev, Odometry)])
    _, odom = odometry_poses(out)
    _, odom_clean = odometry_poses(clean)
    assert odom.shape == odom_clean.shape == (stamps.size, 3)
    turn = wrap_angle(np.diff(odom[:, 2]))
    turn_clean = wrap_angle(np.diff(odom_clean[:, 2]))
    step = np.hypot(*np.diff(odom[:, :2], axis=0).T)
    step_clean = np.hypot(*np.diff(odom_clean[:, :2], axis=0).T)

    touched = np.zeros(stamps.size - 1, dtype=bool)  # increments a glitch changed
    truth = ds.truth.poses
    assert truth is not None
    true_step = np.hypot(*np.diff(truth[:, :2], axis=0).T)
    for g in record.of_kind("heading_jump"):
        assert math.radians(30.0) <= abs(g.size) <= math.radians(90.0)
        assert g.time == stamps[g.step]
        assert wrap_angle(turn[g.step - 1] - turn_clean[g.step - 1]) == pytest.approx(
            g.size, abs=1e-9
        )
        touched[g.step - 1] = True
    for g in record.of_kind("stall"):
        span = slice(g.step - 1, g.step - 1 + g.n_steps)
        assert 1 <= g.n_steps <= 10
        np.testing.assert_array_equal(step[span], 0.0)
        np.testing.assert_array_equal(turn[span], 0.0)
        assert g.size == pytest.approx(float(np.sum(true_step[span])), rel=1e-12)
        touched[span] = True
    # Every increment no glitch touched is the clean one.
    np.testing.assert_allclose(turn[~touched], turn_clean[~touched], atol=1e-9)
    np.testing.assert_allclose(step[~touched], step_clean[~touched], atol=1e-9)

    odo_events = [ev for ev in out.events if isinstance(ev, Odometry)]
    assert len(odo_events) == stamps.size + len(record.of_kind("duplicate"))
    for g in record.of_kind("duplicate"):
        same = [ev for ev in odo_events if ev.t == g.time]
        assert len(same) == 2
        np.testing.assert_array_equal(same[0].pose, same[1].pose)
    for g in record.of_kind("out_of_order"):
        assert g.raw_time is not None
        assert g.time == pytest.approx(stamps[g.step - 1] + 1e-3)
        assert 0.05 <= g.size <= 1.0
        assert g.raw_time == pytest.approx(stamps[g.step - 1] - g.size)
        (ev,) = [ev for ev in odo_events if ev.t == g.time]
        np.testing.assert_array_equal(ev.pose, odom[g.step])
    # The scans are untouched and the stream stays in time order.
    scans = [ev for ev in out.events if isinstance(ev, LaserScan)]
    assert [ev.t for ev in scans] == list(stamps)
    times = [ev.t for ev in out.events]
    assert times == sorted(times)


def test_typical_rates_give_about_two_glitches_in_500_steps() -> None:
    """Four kinds at 0.001 per step: 2.0 expected in 500 steps (a stall hides the jumps
    inside it, a little fewer); the mean of 100 logs has a standard error of ~0.14."""
    ds = odometry_dataset(501)
    counts = [len(corrupt_odometry(ds, OdometryErrorModel(), np.random.default_rng(s))[1])
              for s in range(100)]  # fmt: skip
    assert 1.5 <= float(np.mean(counts)) <= 2.5


def test_control_driven_data_get_odometry_at_the_scan_stamps() -> None:
    poses = true_path(30)
    times = 0.25 * np.arange(30)
    events: list = [LaserScan(0.0, np.ones(N_BEAMS))]
    for k in range(1, 30):
        events += [Control(float(times[k]), np.array([1.0, 0.0]), 0.25),
                   LaserScan(float(times[k]), np.ones(N_BEAMS))]  # fmt: skip
    ds = Dataset(
        name="controls",
        events=tuple(events),
        motion=MotionSpec(UnicycleEuler(), np.eye(2) * 1e-3),
        laser=LaserSpec(np.linspace(-1.0, 1.0, N_BEAMS), 10.0),
        truth=GroundTruth(times=times, poses=poses),
    )
    out, _ = corrupt_odometry(ds, OdometryErrorModel.exact(), np.random.default_rng(0))
    assert out.counts() == {"Odometry": 30, "LaserScan": 30}
    assert out.motion is not None and out.motion.source == "odometry"
    np.testing.assert_allclose(odometry_poses(out)[1], poses, atol=1e-12)


def test_bad_input_is_refused() -> None:
    ds = odometry_dataset(10)
    no_truth = Dataset(name="x", events=ds.events, motion=ds.motion, laser=ds.laser)
    with pytest.raises(InputError, match="no true path"):
        corrupt_odometry(no_truth, OdometryErrorModel(), np.random.default_rng(0))
    with pytest.raises(ConfigError, match=r"odometry_errors\.heading_jump_deg"):
        OdometryErrorModel(heading_jump_deg=(90.0, 30.0))
    with pytest.raises(ConfigError, match=r"odometry_errors\.stall_rate"):
        OdometryErrorModel(stall_rate=1.5)
