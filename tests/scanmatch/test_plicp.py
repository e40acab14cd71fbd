"""Point-to-line ICP: the closed-form step, recovery of known motions on simulated scans of
the rooms world, the typed failures, the covariance against Monte-Carlo scatter, and the
compiled kernels (numba) against the NumPy path."""

from __future__ import annotations

import contextlib
import json
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from scipy.spatial import cKDTree

from slamkit.backend import AVAILABLE, SEAM, Backend
from slamkit.errors import ConfigError, MatchError, NonFiniteError, ShapeError
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.pose2 import between, compose, inverse_transform_points
from slamkit.scanmatch import PlIcpConfig, compiled, icp, kernels, plicp, prepare_scan
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


# --- the compiled kernels (numba) against the NumPy path ---------------------------------------

needs_numba = pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")


def _both_paths(reference, current, init, config=None):
    """``plicp`` through the kernels and through NumPy: per path the result or the reason."""
    out = []
    for numpy_only in (False, True):
        with SEAM.use(Backend.NUMPY) if numpy_only else contextlib.nullcontext():
            assert (SEAM.backend is Backend.NUMPY) is numpy_only
            try:
                out.append(plicp(reference, current, init, config))
            except MatchError as exc:
                out.append(exc.reason)
    return out


def _assert_same(compiled, numpy_result):
    if isinstance(numpy_result, str):
        assert compiled == numpy_result
        return
    assert not isinstance(compiled, str), compiled
    assert compiled.iterations == numpy_result.iterations
    assert compiled.inlier_fraction == numpy_result.inlier_fraction
    np.testing.assert_allclose(compiled.pose, numpy_result.pose, rtol=0, atol=1e-9)
    scale = np.abs(numpy_result.cov).max()
    np.testing.assert_allclose(compiled.cov, numpy_result.cov, rtol=0, atol=1e-9 * scale)


@needs_numba
def test_compiled_and_numpy_paths_agree_on_simulated_pairs():
    """40 pairs from random offsets up to ~0.5 m / 20°, and the failures (corridor, far
    guess, iteration limit): the same reasons, iterations and inlier fractions, poses to
    1e-9 m/rad and covariances to 1e-9 of their largest entry."""
    rng = np.random.default_rng(10)
    n_ok = 0
    for pair in _pairs(40, seed=11):
        offset = np.r_[rng.normal(0.0, 0.25, 2), rng.normal(0.0, 0.15)]
        compiled, numpy_result = _both_paths(
            pair.reference, pair.current, compose(pair.T_ref_cur, offset)
        )
        _assert_same(compiled, numpy_result)
        n_ok += not isinstance(compiled, str)
    assert n_ok >= 30
    corridor = simulated_scan_pair(
        corridor_world(), [0, 0, 0.1], [0.3, 0.05, 0.15], BEAMS, 20.0, 0.01,
        np.random.default_rng(0),
    )  # fmt: skip
    pair = _pairs(1, seed=12)[0]
    cases = [
        (corridor.reference, corridor.current, corridor.T_ref_cur, None, "degenerate"),
        (pair.reference, pair.current, compose(pair.T_ref_cur, [50.0, 0.0, 0.0]), None,
         "too_few_correspondences"),
        (pair.reference, pair.current, compose(pair.T_ref_cur, OFFSET),
         PlIcpConfig(max_iterations=2), "no_convergence"),
    ]  # fmt: skip
    for ref, cur, init, cfg, reason in cases:
        assert _both_paths(ref, cur, init, cfg) == [reason, reason]


@needs_numba
@pytest.mark.realdata
def test_compiled_and_numpy_paths_agree_on_intel_pairs(data_root):
    from slamkit.datasets import load_dataset
    from slamkit.datasets.stream import LaserScan
    from slamkit.scanmatch import scan_points

    data = load_dataset("intel")
    scans = [ev for ev in data.events if isinstance(ev, LaserScan)]
    truth = data.truth.poses
    rng = np.random.default_rng(13)
    for k in range(0, len(scans) - 1, 15):
        ref, cur = (
            scan_points(s.ranges, data.laser.beam_angles, data.laser.max_range)
            for s in scans[k : k + 2]
        )
        offset = np.r_[rng.normal(0.0, 0.2, 2), rng.normal(0.0, 0.1)]
        init = compose(between(truth[k], truth[k + 1]), offset)
        _assert_same(*_both_paths(ref, cur, init))


@needs_numba
def test_nearest_points_are_the_kd_tree_answer():
    """The bearing walk returns exactly the KD-tree's nearest point, or M beyond the
    distance bound, for scans, for unordered clouds all around the origin, for points on one
    ray and for queries at and near the origin."""
    rng = np.random.default_rng(14)
    pair = _pairs(1, seed=15)[0]
    ring = rng.uniform(0.5, 8.0, (300, 1)) * np.column_stack(
        [np.cos(a := rng.uniform(-np.pi, np.pi, 300)), np.sin(a)]
    )
    ray = np.column_stack([np.linspace(0.0, 5.0, 40), np.zeros(40)])  # one bearing, and 0
    turn = np.linspace(1.7, 1.7 + 2 * np.pi, 360, endpoint=False)  # a full turn from 97°
    full_scan = (4.0 + np.sin(3 * turn))[:, None] * np.column_stack([np.cos(turn), np.sin(turn)])
    clouds = [pair.reference, ring, rng.uniform(-3, 3, (200, 2)), ray, full_scan]
    for points in clouds:
        queries = np.vstack(
            [
                points + rng.normal(0.0, 0.05, points.shape),
                rng.uniform(-6, 6, (300, 2)),
                rng.normal(0.0, 0.2, (50, 2)),
                np.zeros((1, 2)),
            ]
        )
        for bound in (0.1, 1.0, 100.0):
            _, expected = cKDTree(points).query(queries, distance_upper_bound=bound)
            np.testing.assert_array_equal(kernels.nearest_points(points, queries, bound), expected)


@needs_numba
def test_nearest_points_hand_computed_ties_and_bound():
    points = np.array([[1.0, 0.0], [3.0, 0.0], [0.0, 2.0]])
    queries = np.array([[2.0, 0.0], [0.0, 0.0], [0.0, 1.6], [10.0, 10.0]])
    # (2, 0) is 1 from points 0 and 1: the smaller index wins; (0, 0) is 1 from point 0 and
    # 2 from point 2; (0, 1.6) is 0.4 from point 2; (10, 10) is out of range.
    np.testing.assert_array_equal(kernels.nearest_points(points, queries, 1.5), [0, 0, 2, 3])
    # Exactly at the bound is out of range, as for the KD-tree.
    np.testing.assert_array_equal(kernels.nearest_points(points, queries, 1.0), [3, 3, 2, 3])
    _, expected = cKDTree(points).query(queries, distance_upper_bound=1.0)
    np.testing.assert_array_equal(expected, [3, 3, 2, 3])


@needs_numba
def test_scan_tables_equal_the_numpy_oracle():
    from slamkit.scanmatch.icp import scan_tables_numpy

    for pair in _pairs(5, seed=16):
        pts = pair.reference
        normals, ok, gaps, seg = kernels.scan_tables(pts, 7, 0.5)
        normals_np, ok_np, gaps_np, seg_np = scan_tables_numpy(pts, 7, 0.5)
        np.testing.assert_array_equal(ok, ok_np)
        assert ok.sum() > 150  # most of the 180 beams have a normal
        np.testing.assert_allclose(normals, normals_np, rtol=0, atol=1e-9)
        np.testing.assert_allclose(gaps, gaps_np, rtol=1e-15)
        np.testing.assert_allclose(seg, seg_np, rtol=0, atol=1e-15)
        tangent = np.diff(pts, axis=0)
        np.testing.assert_allclose(
            seg, np.column_stack([-tangent[:, 1], tangent[:, 0]]) / gaps[:, None], atol=1e-15
        )


@needs_numba
def test_compiled_covariance_equals_the_numpy_oracle():
    """The compiled covariance against :func:`point_to_line_covariance_numpy` on the pairs
    of a solved match (each current point with its nearest reference point and the next),
    some dropped from H: to 1e-9 of the largest entry (BLAS sums in another order)."""
    from slamkit.scanmatch.covariance import point_to_line_covariance_numpy
    from slamkit.scanmatch.kernel_covariance import point_to_line_cov

    rng = np.random.default_rng(22)
    for pair in _pairs(5, seed=23):
        ref = pair.reference
        pose = plicp(ref, pair.current, pair.T_ref_cur).pose
        c, s = math.cos(pose[2]), math.sin(pose[2])
        moved = pair.current @ np.array([[c, s], [-s, c]]) + pose[:2]
        _, j1 = cKDTree(ref).query(moved)
        j2 = np.where(j1 + 1 < len(ref), j1 + 1, j1 - 1)
        kept = rng.random(len(j1)) < 0.9
        args = (pair.current, ref[j1], ref[j2], j1, j2, len(ref), pose, kept)
        compiled_cov = point_to_line_cov(*args)
        numpy_cov = point_to_line_covariance_numpy(*args)
        scale = np.abs(numpy_cov).max()
        assert 0.0 < scale < 0.1  # a confident match: metres² and radians² well below 1
        np.testing.assert_allclose(compiled_cov, numpy_cov, rtol=0, atol=1e-9 * scale)


@needs_numba
def test_select_kth_is_the_sorted_entry():
    rng = np.random.default_rng(20)
    for n in (1, 2, 3, 10, 181):
        for values in (rng.normal(size=n), rng.integers(0, 4, n).astype(float)):  # with ties
            values = np.where(rng.random(n) < 0.1, np.inf, values)  # as invalid errors
            for k in range(n):
                work = values.copy()
                assert kernels.select_kth(work, k) == np.sort(values)[k]
                np.testing.assert_array_equal(np.sort(work), np.sort(values))  # a permutation


@needs_numba
def test_median_in_place_is_numpys_median():
    rng = np.random.default_rng(21)
    for n in (1, 2, 3, 4, 10, 181, 182):
        for values in (rng.normal(size=n), rng.integers(0, 4, n).astype(float)):  # with ties
            assert compiled.median_in_place(values.copy()) == np.median(values)


@needs_numba
def test_min_eigenvalue_sym3_is_eigvalsh():
    rng = np.random.default_rng(21)
    for _ in range(300):
        a = rng.normal(size=(3, 3)) * rng.uniform(1e-3, 1e3, 3)
        h = a @ a.T if rng.random() < 0.7 else a + a.T  # also indefinite
        expected = np.linalg.eigvalsh(h)[0]
        assert kernels.min_eigenvalue_sym3(h) == pytest.approx(
            expected, rel=0, abs=1e-13 * np.abs(h).max()
        )
    assert kernels.min_eigenvalue_sym3(np.diag([2.0, 0.5, 1.0])) == 0.5
    corridor = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # y unconstrained
    assert kernels.min_eigenvalue_sym3(corridor) == 0.0


@needs_numba
def test_ieee_remainder_is_math_remainder():
    rng = np.random.default_rng(17)
    xs = np.r_[rng.uniform(-50, 50, 500), 3.0, 5.0, -3.0, 7.0, 1.0, 0.0, -0.0, 2 * np.pi]
    for y in (2.0 * np.pi, 2.0):
        for x in xs:
            assert kernels.ieee_remainder(float(x), y) == math.remainder(float(x), y)
    assert kernels.ieee_remainder(3.0, 2.0) == -1.0  # half-way: to the even multiple, 2
    assert kernels.ieee_remainder(5.0, 2.0) == 1.0


@needs_numba
def test_root_of_multiplier_is_largest_real_root():
    rng = np.random.default_rng(18)
    for _ in range(200):
        a = rng.normal(size=(2, 2))
        S = a @ a.T * rng.uniform(0.1, 1e3) + rng.normal() * np.eye(2)
        h = rng.normal(size=2) * rng.uniform(0.1, 1e3)
        args = (S[0, 0], S[0, 1], S[1, 1], h[0], h[1])
        assert kernels.root_of_multiplier(*args) == pytest.approx(
            largest_real_root(*args), rel=1e-12, abs=1e-12 * np.abs(S).max()
        )


def test_the_seam_switches_the_path_and_restores_it():
    before = SEAM.backend
    assert before is SEAM.default is (Backend.NUMBA if AVAILABLE else Backend.NUMPY)
    with pytest.raises(RuntimeError), SEAM.use(Backend.NUMPY):
        assert SEAM.backend is Backend.NUMPY
        raise RuntimeError
    assert SEAM.backend is before


def test_without_numba_the_numpy_path_gives_the_same_numbers():
    """A fresh interpreter where ``import numba`` fails: the module selects NumPy at import
    and PLICP returns the same pose and covariance as in this process."""
    pair = _pairs(1, seed=19)[0]
    init = compose(pair.T_ref_cur, OFFSET)
    here = plicp(pair.reference, pair.current, init)
    script = textwrap.dedent(
        f"""
        import json, sys
        import numpy as np
        sys.modules["numba"] = None  # import numba now raises ImportError
        from slamkit.backend import AVAILABLE, SEAM
        from slamkit.scanmatch import plicp
        ref = np.array({pair.reference.tolist()!r})
        cur = np.array({pair.current.tolist()!r})
        r = plicp(ref, cur, {init.tolist()!r})
        print(json.dumps([AVAILABLE, SEAM.backend.value, r.pose.tolist(),
                          r.cov.tolist(), r.iterations]))
        """
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, check=True
    )
    available, enabled, pose, cov, iterations = json.loads(done.stdout)
    assert available is False and enabled == "numpy"
    assert iterations == here.iterations
    np.testing.assert_allclose(pose, here.pose, rtol=0, atol=1e-9)
    np.testing.assert_allclose(cov, here.cov, rtol=0, atol=1e-9 * np.abs(here.cov).max())
