"""Point-to-line ICP: the closed-form step, recovery of known motions on simulated scans of
the rooms world, the typed failures, and the covariance against Monte-Carlo scatter."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.errors import ConfigError, MatchError, NonFiniteError, ShapeError
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.pose2 import between, compose, inverse_transform_points
from slamkit.scanmatch import PlIcpConfig, icp, plicp, prepare_scan
from slamkit.scanmatch.plicp import lagrange_quartic, largest_real_root, point_to_line_step
from slamkit.sim import corridor_world, random_scan_pairs, rooms_world, simulated_scan_pair

BEAMS = np.linspace(-np.pi / 2, np.pi / 2, 180)  # 180 beams over 180°, as the Intel log
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


def _error(pose, truth):
    e = between(truth, pose)
    return float(np.hypot(e[0], e[1])), abs(float(e[2]))


def test_largest_real_root_is_the_largest_real_root_of_the_quartic():
    rng = np.random.default_rng(3)
    for _ in range(200):
        a = rng.normal(size=(2, 2))
        S = a @ a.T * rng.uniform(0.1, 1e3) + rng.normal() * np.eye(2)  # any symmetric S
        h = rng.normal(size=2) * rng.uniform(0.1, 1e3)
        lam = largest_real_root(S[0, 0], S[0, 1], S[1, 1], h[0], h[1])
        roots = np.roots(lagrange_quartic(S, h))
        real = roots[np.abs(roots.imag) <= 1e-6 * np.abs(roots).max()].real
        assert lam == pytest.approx(real.max(), rel=1e-7, abs=1e-7 * np.abs(roots).max())
        c = np.linalg.solve(S + lam * np.eye(2), h)
        assert np.linalg.norm(c) == pytest.approx(1.0, rel=1e-6)


def test_point_to_line_step_recovers_an_exact_pose():
    rng = np.random.default_rng(4)
    truth = np.array([0.4, -0.7, 0.6])
    normals = rng.normal(size=(50, 2))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    ref = rng.uniform(-5, 5, (50, 2))
    # Current points anywhere on the lines (ref + tangent offsets), seen from the true pose.
    on_line = ref + rng.uniform(-0.3, 0.3, (50, 1)) * normals[:, ::-1] * [1.0, -1.0]
    cur = inverse_transform_points(truth, on_line)
    np.testing.assert_allclose(point_to_line_step(cur, ref, normals), truth, atol=1e-10)


def test_point_to_line_step_is_the_constrained_minimum():
    rng = np.random.default_rng(5)
    normals = rng.normal(size=(40, 2))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    ref, cur = rng.uniform(-4, 4, (40, 2)), rng.uniform(-4, 4, (40, 2))  # no exact solution

    def cost(pose):
        moved = cur @ np.array(
            [[np.cos(pose[2]), np.sin(pose[2])], [-np.sin(pose[2]), np.cos(pose[2])]]
        )
        return float(np.sum(np.einsum("ij,ij->i", normals, moved + pose[:2] - ref) ** 2))

    best = point_to_line_step(cur, ref, normals)
    # Brute force over θ, t solved by linear least squares at each θ.
    grid = np.linspace(-np.pi, np.pi, 20001)
    costs = []
    for th in grid:
        moved = cur @ np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
        t, *_ = np.linalg.lstsq(normals, np.einsum("ij,ij->i", normals, ref - moved), rcond=None)
        costs.append(cost(np.array([t[0], t[1], th])))
    assert cost(best) <= min(costs) + 1e-9
    assert abs(wrap_angle(best[2] - grid[int(np.argmin(costs))])) < 1e-3


def test_recovers_known_motion_in_the_rooms_world():
    """20 simulated pairs, 1 cm range noise, initial guess 0.3 m and 10° off the truth."""
    errors = []
    for pair in _pairs(20, seed=1):
        result = plicp(pair.reference, pair.current, compose(pair.T_ref_cur, OFFSET))
        errors.append(_error(result.pose, pair.T_ref_cur))
        assert result.method == "plicp"
        assert 0.7 < result.inlier_fraction <= 1.0
    errors_arr = np.array(errors)
    assert errors_arr[:, 0].max() < 0.02  # 2 cm
    assert np.rad2deg(errors_arr[:, 1].max()) < 0.5  # 0.5°
    assert np.median(errors_arr[:, 0]) < 0.005


def test_converges_in_fewer_iterations_than_point_to_point():
    it_line, it_point = [], []
    for pair in _pairs(20, seed=2):
        init = compose(pair.T_ref_cur, OFFSET)
        it_line.append(plicp(pair.reference, pair.current, init).iterations)
        it_point.append(icp(pair.reference, pair.current, init).iterations)
    assert np.median(it_line) < np.median(it_point)
    assert np.median(it_line) <= 12


def test_same_scan_gives_the_identity():
    pair = _pairs(1, seed=3)[0]
    result = plicp(pair.reference, pair.reference, (0.1, -0.05, 0.05))
    np.testing.assert_allclose(result.pose, 0.0, atol=1e-9)
    assert result.inlier_fraction > 0.9


def test_a_prepared_reference_gives_the_same_result():
    pair = _pairs(1, seed=4)[0]
    init = compose(pair.T_ref_cur, OFFSET)
    ref = prepare_scan(pair.reference)
    a = plicp(ref, pair.current, init)
    b = plicp(pair.reference, pair.current, init)
    np.testing.assert_array_equal(a.pose, b.pose)
    np.testing.assert_array_equal(a.cov, b.cov)


def test_corridor_is_degenerate():
    pair = simulated_scan_pair(
        corridor_world(), [0, 0, 0.1], [0.3, 0.05, 0.15], BEAMS, 20.0, 0.01,
        np.random.default_rng(0),
    )  # fmt: skip
    with pytest.raises(MatchError) as info:
        plicp(pair.reference, pair.current, pair.T_ref_cur)
    assert info.value.reason == "degenerate"


def test_empty_and_tiny_scans_raise_too_few_points():
    pair = _pairs(1, seed=5)[0]
    for ref, cur in ((np.zeros((0, 2)), pair.current), (pair.reference, np.zeros((0, 2)))):
        with pytest.raises(MatchError) as info:
            plicp(ref, cur)
        assert info.value.reason == "too_few_points"
    with pytest.raises(MatchError) as info:
        plicp(pair.reference, pair.current[:5])
    assert info.value.reason == "too_few_points"


def test_far_initial_guess_raises_too_few_correspondences():
    pair = _pairs(1, seed=6)[0]
    with pytest.raises(MatchError) as info:
        plicp(pair.reference, pair.current, compose(pair.T_ref_cur, [50.0, 0.0, 0.0]))
    assert info.value.reason == "too_few_correspondences"


def test_segments_longer_than_max_gap_are_not_used():
    pair = _pairs(1, seed=7)[0]
    smallest_gap = float(prepare_scan(pair.reference).gaps.min())
    with pytest.raises(MatchError) as info:
        plicp(pair.reference, pair.current, pair.T_ref_cur, PlIcpConfig(max_gap=smallest_gap / 2))
    assert info.value.reason == "too_few_correspondences"


def test_iteration_limit_raises_no_convergence():
    pair = _pairs(1, seed=8)[0]
    with pytest.raises(MatchError) as info:
        plicp(
            pair.reference,
            pair.current,
            compose(pair.T_ref_cur, OFFSET),
            PlIcpConfig(max_iterations=2),
        )
    assert info.value.reason == "no_convergence"


def test_bad_input_raises_typed_errors():
    pair = _pairs(1, seed=9)[0]
    bad = pair.current.copy()
    bad[3, 0] = np.nan
    with pytest.raises(NonFiniteError):
        plicp(pair.reference, bad)
    with pytest.raises(NonFiniteError):
        plicp(bad, pair.current)
    with pytest.raises(ShapeError):
        plicp(pair.reference, pair.current[:, :1])
    with pytest.raises(ShapeError):
        plicp(pair.reference.ravel(), pair.current)
    with pytest.raises(ShapeError):
        plicp(pair.reference, pair.current, initial=(0.0, 0.0))


@pytest.mark.parametrize(
    "field, value",
    [
        ("max_iterations", 0),
        ("max_correspondence_distance", -1.0),
        ("max_gap", 0.0),
        ("outlier_multiplier", float("nan")),
        ("trim_fraction", 1.5),
        ("min_correspondences", 3),
        ("min_eigenvalue", 2.0),
    ],
)
def test_config_is_validated(field, value):
    with pytest.raises(ConfigError, match=field):
        PlIcpConfig(**{field: value})


def test_covariance_matches_monte_carlo_scatter():
    """200 seeds of the same pair of poses (1 cm range noise): the mean NEES of the pose
    against its reported covariance is within a factor 2 of its expected value 3 (χ²(3)),
    and the reported standard deviations are within a factor 2 of the scatter."""
    pose_ref = np.array([5.0, 2.5, 0.3])
    pose_cur = compose(pose_ref, [0.2, 0.1, 0.1])
    world = rooms_world()
    errors, covs = [], []
    for seed in range(200):
        pair = simulated_scan_pair(
            world, pose_ref, pose_cur, BEAMS, 20.0, 0.01, np.random.default_rng(seed)
        )
        result = plicp(pair.reference, pair.current, compose(pair.T_ref_cur, [0.1, -0.1, 0.05]))
        e = result.pose - pair.T_ref_cur
        e[2] = wrap_angle(e[2])
        errors.append(e)
        covs.append(result.cov)
    E, C = np.array(errors), np.array(covs)
    nees = np.einsum("ni,ni->n", E, np.linalg.solve(C, E[:, :, None])[:, :, 0])
    assert 1.5 < nees.mean() < 6.0
    ratio = E.std(axis=0) / np.sqrt(np.diagonal(C.mean(axis=0)))
    assert np.all((ratio > 0.5) & (ratio < 2.0))
