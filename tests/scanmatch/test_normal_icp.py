"""Point-to-normal ICP against a point map, and the point map itself."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import MatchError, ShapeError
from slamkit.geometry.pose2 import between, compose
from slamkit.scanmatch.normal_icp import NormalCloud, NormalIcpConfig, normal_icp, surface_fit
from slamkit.scanmatch.point_map import PointMap, scan_normals
from slamkit.sim import rooms_world
from slamkit.sim.scans import corridor_world, random_scan_pairs, simulated_scan_pair

BEAMS = np.deg2rad(np.arange(-90.0, 90.5, 1.0))


def _cloud_of(pose: np.ndarray, points: np.ndarray, voxel: float = 0.05) -> NormalCloud:
    m = PointMap(voxel)
    m.insert(pose, points)
    return m.near(pose[:2], 50.0)


def test_recovers_known_motions_from_an_offset_start() -> None:
    """20 seeded pairs of rooms-world scans (0.3 m and 10° apart, 1 cm range noise), the
    reference in a point map at its true pose, the start 0.15 m and 5° off the truth."""
    rng = np.random.default_rng(7)
    pairs = random_scan_pairs(
        rooms_world(), 20, rng, beam_angles=BEAMS, max_range=12.0, range_sigma=0.01
    )
    errors = []
    for pair in pairs:
        cloud = _cloud_of(np.zeros(3), pair.reference)
        start = compose(pair.T_ref_cur, [0.1, -0.11, np.deg2rad(5.0)])
        try:
            result = normal_icp(cloud, pair.current, start)
        except MatchError as exc:  # a corridor view of the rooms: refused, never wrong
            assert exc.reason == "degenerate"
            continue
        e = between(pair.T_ref_cur, result.pose)
        errors.append((np.hypot(e[0], e[1]), abs(e[2])))
        assert result.method == "normal-icp" and 0.5 < result.inlier_fraction <= 1.0
    err = np.array(errors)
    assert len(err) >= 15
    assert np.median(err[:, 0]) < 0.01 and err[:, 0].max() < 0.03
    assert np.median(err[:, 1]) < np.deg2rad(0.2) and err[:, 1].max() < np.deg2rad(0.6)


def test_covariance_is_consistent_over_seeds() -> None:
    """The NEES of 100 matches of one pair with fresh range noise (3 dof): within a factor 2
    of 3 on average."""
    world = rooms_world()
    pose_ref = np.array([6.0, 9.5, 0.3])
    pose_cur = compose(pose_ref, [0.25, 0.05, 0.1])
    nees = []
    for seed in range(100):
        rng = np.random.default_rng(seed)
        pair = simulated_scan_pair(world, pose_ref, pose_cur, BEAMS, 12.0, 0.01, rng)
        cloud = _cloud_of(np.zeros(3), pair.reference)
        result = normal_icp(cloud, pair.current, pair.T_ref_cur + np.array([0.05, -0.05, 0.02]))
        e = between(pair.T_ref_cur, result.pose)
        nees.append(float(e @ np.linalg.solve(result.cov, e)))
    assert 1.5 < np.mean(nees) < 6.0


def test_corridor_and_empty_scans_are_refused() -> None:
    corridor = corridor_world()
    rng = np.random.default_rng(0)
    pair = simulated_scan_pair(corridor, [0, 0, 0], [0.3, 0, 0], BEAMS, 12.0, 0.01, rng)
    cloud = _cloud_of(np.zeros(3), pair.reference)
    with pytest.raises(MatchError) as info:
        normal_icp(cloud, pair.current, [0.1, 0.0, 0.0])
    assert info.value.reason == "degenerate"
    with pytest.raises(MatchError) as info:
        normal_icp(cloud, np.zeros((0, 2)), np.zeros(3))
    assert info.value.reason == "too_few_points"
    with pytest.raises(MatchError) as info:  # every current point far from the map
        normal_icp(cloud, pair.current + 100.0, np.zeros(3))
    assert info.value.reason == "too_few_correspondences"
    with pytest.raises(ShapeError):
        normal_icp(cloud, np.zeros((20, 3)), np.zeros(3))


def test_a_prior_apart_from_the_start_holds_the_corridor_axis() -> None:
    """Corridor scans 0.3 m along the axis from their reference (five seeds): the walls
    fix y and the heading, a prior of 1 cm along the axis fixes x. Started 0.2 m short,
    the match lands within 1.5 cm of the prior's x when ``prior_pose`` puts it at 0.3 m,
    and within 2.5 cm of the start when the prior sits at the start (no ``prior_pose``).
    (The walls alone are not quite flat along the axis: their sampled points and noisy
    normals leave shallow minima there, so a prior this tight is what holds x.)"""
    lam = np.diag([1 / 0.01**2, 1 / 0.05**2, 1 / np.deg2rad(1.0) ** 2])
    start = np.array([0.1, 0.02, 0.01])
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pair = simulated_scan_pair(corridor_world(), [0, 0, 0], [0.3, 0, 0], BEAMS, 12.0, 0.01, rng)
        cloud = _cloud_of(np.zeros(3), pair.reference)
        held = normal_icp(
            cloud, pair.current, start, prior_information=lam, prior_pose=[0.3, 0.0, 0.0]
        )
        assert abs(held.pose[0] - 0.3) < 0.015
        assert abs(held.pose[1]) < 0.01 and abs(held.pose[2]) < np.deg2rad(0.2)
        at_start = normal_icp(cloud, pair.current, start, prior_information=lam)
        assert abs(at_start.pose[0] - 0.1) < 0.025
    with pytest.raises(ShapeError, match="prior pose"):
        normal_icp(cloud, pair.current, start, prior_information=lam, prior_pose=[0.3, 0.0])


def test_point_map_keeps_the_first_point_of_a_voxel_and_rotates_normals() -> None:
    # a straight wall 2 m ahead, seen twice: the second scan, 1 cm further, adds nothing new
    ys = np.linspace(-1.0, 1.0, 41)
    wall = np.column_stack([np.full_like(ys, 2.03), ys])
    m = PointMap(0.1)
    first = m.insert(np.zeros(3), wall)
    assert first == len(m) and 20 <= first <= 22  # 0.05 m spacing, 0.1 m voxels
    assert m.insert(np.array([-0.01, 0.0, 0.0]), wall) == 0
    # turned by 90°: the wall's normal turns with it, from ±x to ±y
    m2 = PointMap(0.1)
    m2.insert(np.array([0.0, 0.0, np.pi / 2]), wall)
    points, normals = m2.arrays()
    np.testing.assert_allclose(points[:, 1], 2.03, atol=1e-12)
    np.testing.assert_allclose(np.abs(normals[:, 1]), 1.0, atol=1e-9)
    near = m2.near([0.0, 2.03], 0.5)
    within = np.hypot(points[:, 0], points[:, 1] - 2.03) <= 0.5
    assert near.points.shape[0] == np.count_nonzero(within)


def test_point_map_insert_many_equals_one_by_one_with_or_without_known_normals() -> None:
    rng = np.random.default_rng(3)
    pairs = random_scan_pairs(
        rooms_world(), 6, rng, beam_angles=BEAMS, max_range=12.0, range_sigma=0.01
    )
    scans = [p.reference for p in pairs] + [np.zeros((2, 2))]  # the last: too few points
    poses = np.column_stack([rng.uniform(-0.5, 0.5, (7, 2)), rng.uniform(-0.3, 0.3, 7)])
    one = PointMap(0.05)
    added = sum(one.insert(poses[a], scans[a]) for a in range(7))
    many = PointMap(0.05)
    known = [scan_normals(s) if s.shape[0] >= 3 else None for s in scans]
    assert many.insert_many(poses, scans, known) == added == len(one) == len(many)
    for a, b in zip(one.arrays(), many.arrays(), strict=True):
        np.testing.assert_array_equal(a, b)
    assert PointMap(0.05).insert_many(poses[:1], scans[-1:]) == 0


def test_config_is_validated() -> None:
    from slamkit.errors import ConfigError

    with pytest.raises(ConfigError, match="huber_k"):
        NormalIcpConfig(huber_k=0.0)
    with pytest.raises(ConfigError, match="max_iterations"):
        NormalIcpConfig(max_iterations=0)


def test_the_robust_scale_median_is_numpys() -> None:
    from slamkit.scanmatch.covariance import median

    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 10, 11, 180, 181):
        for _ in range(50):
            x = rng.standard_normal(n) * rng.uniform(1e-3, 10.0)
            assert median(x) == float(np.median(x))


def test_surface_fit_counts_the_points_on_the_map_surfaces() -> None:
    """A scan at its true pose lies on the map built from itself (1 cm noise, 5 cm
    tolerance: all but the edge points); turned 15° about the sensor, most of it is off;
    points far from every map point (new ground) and an empty scan count as off."""
    rng = np.random.default_rng(3)
    pair = random_scan_pairs(
        rooms_world(), 1, rng, beam_angles=BEAMS, max_range=12.0, range_sigma=0.01
    )[0]
    cloud = _cloud_of(np.zeros(3), pair.reference)
    at_truth = surface_fit(cloud, pair.current, pair.T_ref_cur)
    turned = surface_fit(cloud, pair.current, compose(pair.T_ref_cur, [0.0, 0.0, np.deg2rad(15)]))
    assert at_truth > 0.85 and turned < 0.4, (at_truth, turned)
    far = surface_fit(cloud, pair.current + 100.0, pair.T_ref_cur)
    assert far == 0.0
    assert surface_fit(cloud, np.zeros((0, 2)), np.zeros(3)) == 0.0
