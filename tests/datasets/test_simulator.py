"""The simulator: determinism, ground truth consistency, sensor limits."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import Control, LandmarkReadings, LaserScan, load_dataset
from slamkit.errors import ConfigError
from slamkit.geometry import pose2, wrap_angle
from slamkit.models import RangeBearing, UnicycleEuler
from slamkit.sim import (
    five_feature_world,
    rasterize_segments,
    rooms_world,
    simulate_motion,
    waypoint_controls,
)


def _flatten(ds):  # every number of every event, for exact comparisons
    out = []
    for ev in ds.events:
        out.append(ev.t)
        for name in ("u", "z", "ids", "ranges", "pose"):
            if hasattr(ev, name):
                out.extend(np.ravel(getattr(ev, name)).tolist())
    return np.asarray(out)


@pytest.mark.parametrize("name", ["five-features", "landmark-loop", "rooms-laser"])
def test_same_seed_same_data_and_different_seed_differs(name):
    a, b = load_dataset(name, seed=7), load_dataset(name, seed=7)
    c = load_dataset(name, seed=8)
    np.testing.assert_array_equal(_flatten(a), _flatten(b))
    np.testing.assert_array_equal(a.truth.poses, b.truth.poses)
    assert not np.array_equal(a.truth.poses, c.truth.poses)


def test_five_features_route_closes_and_readings_match_truth():
    ds = load_dataset("five-features", seed=1)
    truth = ds.truth.poses
    # The waypoint route is a loop: the robot ends within a metre of its start.
    assert np.hypot(*(truth[-1, :2] - truth[0, :2])) < 1.0
    # Each reading is the true range-bearing of its landmark plus noise of the stated size.
    t_index = {float(t): k for k, t in enumerate(ds.truth.times)}
    resid = []
    for ev in ds.of_type(LandmarkReadings):
        k = t_index[ev.t]
        expected = RangeBearing().predict(truth[k], ds.truth.landmarks.position_of(ev.ids))
        r = ev.z - expected
        r[:, 1] = wrap_angle(r[:, 1])
        resid.append(r)
    resid = np.concatenate(resid)
    sr, sb = np.sqrt(np.diag(ds.landmark_sensor.noise_cov))
    n = resid.shape[0]
    assert n > 500
    # Sample standard deviations within 10 % of the configured ones (n > 500 readings).
    assert abs(resid[:, 0].std() / sr - 1) < 0.1
    assert abs(resid[:, 1].std() / sb - 1) < 0.1
    assert abs(resid[:, 0].mean()) < 4 * sr / np.sqrt(n)


def test_controls_replay_to_truth_when_noise_is_zero():
    ds = load_dataset("five-features", seed=3, options={"sigma_v": 0.0, "sigma_omega_deg": 0.0})
    x = ds.truth.poses[0]
    model = UnicycleEuler()
    for ev in ds.of_type(Control):
        x = model.apply(x, ev.u, ev.dt)
    np.testing.assert_allclose(x, ds.truth.poses[-1], atol=1e-9)


def test_field_of_view_and_max_range_are_respected():
    opts = {"fov_deg": 90.0, "max_range": 5.0}
    ds = load_dataset("five-features", seed=2, options=opts)
    t_index = {float(t): k for k, t in enumerate(ds.truth.times)}
    for ev in ds.of_type(LandmarkReadings):
        true_rb = RangeBearing().predict(
            ds.truth.poses[t_index[ev.t]], ds.truth.landmarks.position_of(ev.ids)
        )
        assert np.all(true_rb[:, 0] <= 5.0)
        assert np.all(np.abs(true_rb[:, 1]) <= np.pi / 4)


def test_no_identities_hides_ids():
    ds = load_dataset("five-features", seed=2, options={"identities": False})
    ids = np.concatenate([ev.ids for ev in ds.of_type(LandmarkReadings)])
    assert ids.size > 0 and np.all(ids == -1)


def test_range_only_and_bearing_only_sensors():
    for kind, m in (("range", 1), ("bearing", 1)):
        ds = load_dataset("five-features", seed=2, options={"sensor": kind})
        ev = next(iter(ds.of_type(LandmarkReadings)))
        assert ev.z.shape[1] == m
        assert ds.landmark_sensor.kind == kind


def test_rooms_laser_scans_hit_the_walls():
    ds = load_dataset("rooms-laser", seed=0, options={"sigma_range": 1e-6})
    scans = list(ds.of_type(LaserScan))
    assert len(scans) == ds.truth.poses.shape[0]
    r = np.stack([s.ranges for s in scans])
    assert np.all(r > 0.0) and np.all(r <= ds.laser.max_range)
    # Only beams down the 20 m corridor find no wall within 12 m.
    assert 0 < np.mean(r == ds.laser.max_range) < 0.05
    # End points of the first scan's returns lie on the rasterised walls (within one cell).
    grid = ds.truth.occupancy
    T = ds.truth.poses[0]
    pts = pose2.transform_points(
        T,
        np.column_stack([np.cos(ds.laser.beam_angles), np.sin(ds.laser.beam_angles)])
        * scans[0].ranges[:, None],
    )
    cells = grid.world_to_cell(pts[scans[0].ranges < ds.laser.max_range])
    near = np.zeros(len(cells), bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            c = cells + np.array([dr, dc])
            near |= grid.prob[c[:, 0], c[:, 1]] == 1.0
    assert near.mean() == 1.0


def test_rasterize_marks_cells_crossed_by_walls():
    grid = rasterize_segments(rooms_world(), 0.1, padding=0.5)
    # The outer wall y = 0 from x = 0 to 20 is 200 cells long at 0.1 m.
    row = grid.world_to_cell([5.0, 0.0])[0]
    assert grid.prob[row].sum() >= 200
    assert grid.prob.sum() < grid.prob.size * 0.1


def test_waypoint_controls_reach_every_waypoint():
    wps = np.array([[5.0, 0.0], [5.0, 5.0], [0.0, 5.0]])
    u = waypoint_controls([0, 0, 0], wps, speed=1.0, dt=0.05, tolerance=0.2)
    poses = simulate_motion(
        UnicycleEuler(), [0, 0, 0], u, 0.05, np.zeros((2, 2)), np.random.default_rng(0)
    )
    for w in wps:
        assert np.min(np.hypot(*(poses[:, :2] - w).T)) < 0.2
    assert five_feature_world().positions.shape == (5, 2)


def test_bad_scenario_options_are_config_errors():
    with pytest.raises(ConfigError, match="unknown setting"):
        load_dataset("five-features", options={"spead": 2.0})
    with pytest.raises(ConfigError, match="sensor"):
        load_dataset("five-features", options={"sensor": "sonar"})
    with pytest.raises(ConfigError, match="dt"):
        load_dataset("five-features", options={"dt": -1.0})


def test_kidnapping_teleports_the_truth_once_and_commands_a_standstill():
    ds = load_dataset("five-features", seed=0, options={"kidnap_time": 10.0, "kidnap_skip": 8.0})
    step = np.hypot(*np.diff(ds.truth.poses[:, :2], axis=0).T)
    jump = int(np.argmax(step))
    assert jump == 100 and step[jump] > 3.0  # 8 s of route at 1 m/s, cut across
    assert np.sort(step)[-2] < 0.2  # every other step is a normal 0.1 s move
    controls = [ev for ev in ds.of_type(Control)]
    np.testing.assert_array_equal(controls[jump].u, [0.0, 0.0])
    assert len(controls) == ds.truth.poses.shape[0] - 1


def test_registered_variants_apply_their_presets():
    assert load_dataset("five-features-range").landmark_sensor.kind == "range"
    assert load_dataset("five-features-bearing").landmark_sensor.kind == "bearing"
    kid = load_dataset("five-features-kidnapped")
    err = kid.initial_pose - kid.truth.poses[0]
    assert np.hypot(*err[:2]) > 3.0 and abs(wrap_angle(err[2])) > np.deg2rad(55)
    glob = load_dataset("rooms-laser-global")
    assert glob.initial_pose is None and glob.known_grid is not None
    # The caller's options win over the preset.
    assert (
        load_dataset("five-features-range", options={"sensor": "bearing"}).landmark_sensor.kind
        == "bearing"
    )


def test_readings_respect_the_minimum_range():
    ds = load_dataset("landmark-loop", seed=4, options={"min_range": 1.0})
    t_index = {float(t): k for k, t in enumerate(ds.truth.times)}
    for ev in ds.of_type(LandmarkReadings):
        true_rb = RangeBearing().predict(
            ds.truth.poses[t_index[ev.t]], ds.truth.landmarks.position_of(ev.ids)
        )
        assert np.all(true_rb[:, 0] >= 1.0)
    with pytest.raises(ConfigError, match="min_range"):
        load_dataset("five-features", options={"min_range": 9.0})


def test_the_laser_robot_never_crosses_a_wall():
    # Closed-loop driving keeps the true robot on its route: no step of the true path
    # intersects a wall segment, on the plain tour and on the kidnapped one (the jump itself
    # excluded: the robot is carried).
    for name in ("rooms-laser", "rooms-laser-kidnapped"):
        ds = load_dataset(name, seed=5)
        p = ds.truth.poses[:, :2]
        a, b = p[:-1], p[1:]
        step = np.hypot(*(b - a).T)
        walls = ds.truth.walls.segments
        c, d = walls[:, 0], walls[:, 1]

        def cross(o, u, v):
            return (u[..., 0] - o[..., 0]) * (v[..., 1] - o[..., 1]) - (u[..., 1] - o[..., 1]) * (
                v[..., 0] - o[..., 0]
            )

        A, B = a[:, None], b[:, None]
        hit = (np.sign(cross(A, B, c)) != np.sign(cross(A, B, d))) & (
            np.sign(cross(c, d, A)) != np.sign(cross(c, d, B))
        )
        moving = step < 1.0  # exclude the kidnapping jump
        assert not np.any(hit[moving]), name
