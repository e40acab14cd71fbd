"""Point-to-point ICP: the closed-form step, recovery of known motions on simulated scans of
the rooms world, the typed failures, the prepared reference and the covariance."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.backend import SEAM, Backend
from slamkit.errors import ConfigError, MatchError, NonFiniteError, ShapeError
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.pose2 import between, compose, inverse_transform_points
from slamkit.scanmatch import IcpConfig, icp, prepare_scan
from slamkit.scanmatch.covariance import estimate_normals, neighbour_table
from slamkit.scanmatch.icp import point_to_point_step
from slamkit.sim import corridor_world, random_scan_pairs, rooms_world, simulated_scan_pair

BEAMS = np.linspace(-np.pi / 2, np.pi / 2, 180)
OFFSET = np.array([0.3 / np.sqrt(2), -0.3 / np.sqrt(2), np.deg2rad(10.0)])  # 0.3 m, 10° off


def _pairs(n: int, seed: int, sigma: float = 0.01):
    return random_scan_pairs(
        rooms_world(),
        n,
        np.random.default_rng(seed),
        beam_angles=BEAMS,
        max_range=20.0,
        range_sigma=sigma,
    )


def test_point_to_point_step_recovers_an_exact_pose():
    rng = np.random.default_rng(0)
    truth = np.array([1.5, -0.25, -2.9])
    ref = rng.uniform(-3, 3, (30, 2))
    cur = inverse_transform_points(truth, ref)
    np.testing.assert_allclose(point_to_point_step(cur, ref), truth, atol=1e-12)


def test_point_to_point_step_hand_computed():
    # Two points swapped by a half turn about (1, 0): θ = π, t = (2, 0).
    pose = point_to_point_step(
        np.array([[0.0, 0.0], [2.0, 0.0]]), np.array([[2.0, 0.0], [0.0, 0.0]])
    )
    np.testing.assert_allclose([pose[0], pose[1], abs(pose[2])], [2.0, 0.0, np.pi], atol=1e-12)


def test_normals_of_a_wall_are_perpendicular_to_it():
    x = np.linspace(0, 2, 21)
    pts = np.column_stack([x, 0.5 * x + 1.0])  # slope 1/2
    normals, ok = estimate_normals(pts, neighbour_table(pts, None, 5), 0.5)
    assert ok.all()
    np.testing.assert_allclose(np.abs(normals @ [2.0, 1.0]) / np.sqrt(5), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)


def test_recovers_known_motion_in_the_rooms_world():
    """20 simulated pairs, 1 cm range noise, initial guess 0.3 m and 10° off the truth.
    Point-to-point matching is biased by the different sampling of the two scans, hence the
    looser bounds than point-to-line."""
    errors = []
    for pair in _pairs(20, seed=1):
        result = icp(pair.reference, pair.current, compose(pair.T_ref_cur, OFFSET))
        e = between(pair.T_ref_cur, result.pose)
        errors.append([np.hypot(e[0], e[1]), abs(e[2])])
        assert result.method == "icp"
        assert result.inlier_fraction == pytest.approx(result.score)
    errors_arr = np.array(errors)
    assert errors_arr[:, 0].max() < 0.03  # 3 cm
    assert np.rad2deg(errors_arr[:, 1].max()) < 1.0  # 1°
    assert np.median(errors_arr[:, 0]) < 0.01


def test_same_scan_gives_the_identity():
    """From the identity, and from a small offset without trimming. (With the default 10%
    trimming, a start 0.1 m / 3° off stalls about 2 cm from the identity: the trimmed pairs
    are the far points that the rotation error moves most, which are what constrain it.)"""
    pair = _pairs(1, seed=3)[0]
    result = icp(pair.reference, pair.reference)
    np.testing.assert_array_equal(result.pose, 0.0)
    assert result.inlier_fraction == 1.0  # all distances are 0: nothing is above the cut
    untrimmed = IcpConfig(trim_fraction=1.0)
    result = icp(pair.reference, pair.reference, (0.1, -0.05, 0.05), untrimmed)
    np.testing.assert_allclose(result.pose, 0.0, atol=1e-9)


def test_a_prepared_reference_gives_the_same_result_and_is_read_only():
    pair = _pairs(1, seed=4)[0]
    init = compose(pair.T_ref_cur, OFFSET)
    ref = prepare_scan(pair.reference)
    np.testing.assert_array_equal(
        icp(ref, pair.current, init).pose, icp(pair.reference, pair.current, init).pose
    )
    with pytest.raises(ValueError):
        ref.points[0, 0] = 1.0
    unordered = prepare_scan(pair.reference[::-1], ordered=False)
    # Normals from nearest neighbours agree with those from scan order along the walls.
    agree = np.abs(np.einsum("ij,ij->i", unordered.normals[::-1], ref.normals))
    assert np.median(agree) > 0.999
    assert np.mean(agree > 0.99) > 0.8


def test_the_kd_tree_of_a_prepared_scan_is_built_once_and_finds_the_nearest_points():
    pair = _pairs(1, seed=5)[0]
    for ref in (prepare_scan(pair.reference), prepare_scan(pair.reference, ordered=False)):
        assert ref.tree is ref.tree  # built on first use (or by the unordered normals), kept
        queries = pair.reference[::7] + 0.01
        dist, j = ref.tree.query(queries)
        brute = np.linalg.norm(queries[:, None, :] - pair.reference[None], axis=2)
        np.testing.assert_array_equal(j, np.argmin(brute, axis=1))
        np.testing.assert_allclose(dist, brute.min(axis=1), rtol=1e-12)


def test_prepared_scan_tables_are_the_same_with_and_without_the_kernels():
    pair = _pairs(1, seed=6)[0]
    a = prepare_scan(pair.reference)
    with SEAM.use(Backend.NUMPY):
        b = prepare_scan(pair.reference)
    np.testing.assert_array_equal(a.has_normal, b.has_normal)
    for field in ("normals", "gaps", "segment_normals"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=0, atol=1e-12)
    # ... and point-to-point ICP, which never uses the kernels, gives the same pose on both.
    init = compose(pair.T_ref_cur, OFFSET)
    np.testing.assert_allclose(icp(a, pair.current, init).pose, icp(b, pair.current, init).pose)


def test_corridor_is_degenerate():
    pair = simulated_scan_pair(
        corridor_world(), [0, 0, 0.1], [0.3, 0.05, 0.15], BEAMS, 20.0, 0.01,
        np.random.default_rng(0),
    )  # fmt: skip
    with pytest.raises(MatchError) as info:
        icp(pair.reference, pair.current, pair.T_ref_cur)
    assert info.value.reason == "degenerate"


def test_empty_scan_raises_too_few_points():
    pair = _pairs(1, seed=5)[0]
    for ref, cur in ((np.zeros((0, 2)), pair.current), (pair.reference, np.zeros((0, 2)))):
        with pytest.raises(MatchError) as info:
            icp(ref, cur)
        assert info.value.reason == "too_few_points"


def test_far_initial_guess_raises_too_few_correspondences():
    pair = _pairs(1, seed=6)[0]
    with pytest.raises(MatchError) as info:
        icp(pair.reference, pair.current, compose(pair.T_ref_cur, [50.0, 0.0, 0.0]))
    assert info.value.reason == "too_few_correspondences"


def test_iteration_limit_raises_no_convergence():
    pair = _pairs(1, seed=8)[0]
    with pytest.raises(MatchError) as info:
        icp(
            pair.reference,
            pair.current,
            compose(pair.T_ref_cur, OFFSET),
            IcpConfig(max_iterations=3),
        )
    assert info.value.reason == "no_convergence"


def test_bad_input_raises_typed_errors():
    pair = _pairs(1, seed=9)[0]
    bad = pair.current.copy()
    bad[0, 1] = np.inf
    with pytest.raises(NonFiniteError):
        icp(pair.reference, bad)
    with pytest.raises(ShapeError):
        icp(pair.reference, pair.current.T)
    with pytest.raises(ShapeError):
        icp(pair.reference, pair.current, initial=np.zeros(4))


@pytest.mark.parametrize(
    "field, value",
    [
        ("max_iterations", 1.5),
        ("max_correspondence_distance", 0.0),
        ("trim_fraction", 0.0),
        ("translation_tolerance", float("inf")),
        ("min_points", True),
    ],
)
def test_config_is_validated(field, value):
    with pytest.raises(ConfigError, match=field):
        IcpConfig(**{field: value})


def test_covariance_matches_the_noise_scatter():
    """100 seeds of one pair of poses: the reported standard deviations are within a factor
    3 of the scatter of the estimates about their mean. Point-to-point ICP also has a bias
    (a few mm here, from the two scans sampling the walls at different places) that its
    covariance, a model of the range noise, does not hold."""
    pose_ref = np.array([9.0, 9.0, -1.0])
    pose_cur = compose(pose_ref, [0.2, 0.15, 0.12])
    errors, stds = [], []
    for seed in range(100):
        pair = simulated_scan_pair(
            rooms_world(), pose_ref, pose_cur, BEAMS, 20.0, 0.01, np.random.default_rng(seed)
        )
        result = icp(pair.reference, pair.current, compose(pair.T_ref_cur, [0.1, -0.1, 0.05]))
        e = result.pose - pair.T_ref_cur
        e[2] = wrap_angle(e[2])
        errors.append(e)
        stds.append(np.sqrt(np.diag(result.cov)))
    ratio = np.array(errors).std(axis=0) / np.mean(stds, axis=0)
    assert np.all((ratio > 1 / 3) & (ratio < 3.0))
