"""Correlative scan matching: branch and bound against the exhaustive search, recovery of
known transforms, the response covariance, degenerate corridors and bad input."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from slamkit.backend import AVAILABLE, SEAM, Backend
from slamkit.errors import ConfigError, InputError, MatchError
from slamkit.geometry.pose2 import between, inverse_transform_points
from slamkit.maps import SegmentMap
from slamkit.maps.likelihood_field import LikelihoodField
from slamkit.models.laser import LaserScanner
from slamkit.scanmatch import (
    CorrelativeConfig,
    CorrelativeReference,
    compiled,
    correlative_match,
    scan_points,
)
from slamkit.scanmatch.lookup import (
    QUANTUM,
    join_consecutive,
    log_likelihood_of_distance,
    lookup_from_log_table,
)
from slamkit.sim.worlds import rasterize_segments, rooms_world

MAX_RANGE = 12.0
# Free spots of rooms_world (corridor and the four rooms) to put the robot at.
SPOTS = np.array([[5.0, 6.0], [15.0, 6.2], [4.5, 2.5], [15.0, 2.0], [5.0, 9.5], [16.0, 9.5]])


def _points(world: SegmentMap, pose: np.ndarray, rng: np.random.Generator, beams: int = 360):
    fov = 2 * np.pi if beams == 360 else np.pi
    laser = LaserScanner.from_fov(fov, beams, MAX_RANGE, 0.01)
    ranges = laser.simulate(np.asarray(pose, float), world, rng)
    return scan_points(ranges, laser.beam_angles, MAX_RANGE)


def _pair(seed: int, max_xy: float = 0.4, max_theta: float = 0.3):
    """Two scans of rooms_world from nearby poses: (reference points, current points, truth
    T_ref_cur)."""
    rng = np.random.default_rng(seed)
    spot = SPOTS[seed % len(SPOTS)]
    pa = np.array([*spot, rng.uniform(-np.pi, np.pi)])
    pb = pa + np.array([*rng.uniform(-max_xy, max_xy, 2), rng.uniform(-max_theta, max_theta)])
    world = rooms_world()
    return _points(world, pa, rng), _points(world, pb, rng, beams=180), between(pa, pb)


# A coarse angular step keeps the exhaustive searches of the tests short.
SMALL = CorrelativeConfig(window_xy=0.5, window_theta=0.35, angular_step=0.01, max_flatness=None)


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("levels", [2, 3, 4])
def test_branch_and_bound_equals_exhaustive_scan_to_scan(seed: int, levels: int) -> None:
    ref_pts, cur, _ = _pair(seed)
    cfg = replace(SMALL, levels=levels)
    ref = CorrelativeReference.from_points(ref_pts, cfg)
    bnb = correlative_match(ref, cur, np.zeros(3), cfg)
    exh = correlative_match(ref, cur, np.zeros(3), replace(cfg, search="exhaustive"))
    assert np.array_equal(bnb.pose, exh.pose)  # the same fine cell and rotation
    assert bnb.score == exh.score
    assert bnb.iterations == levels and exh.iterations == 1


@pytest.mark.parametrize("seed", [7, 8])
def test_branch_and_bound_equals_exhaustive_against_a_map(seed: int) -> None:
    rng = np.random.default_rng(seed)
    world = rooms_world()
    grid = rasterize_segments(world, 0.05, padding=1.025)
    truth = np.array([*SPOTS[seed % len(SPOTS)], rng.uniform(-np.pi, np.pi)])
    cur = _points(world, truth, rng, beams=180)
    guess = truth + np.array([0.3, -0.35, 0.2])
    cfg = replace(SMALL, levels=4)
    ref = CorrelativeReference.from_grid(grid, cfg)
    bnb = correlative_match(ref, cur, guess, cfg)
    exh = correlative_match(ref, cur, guess, replace(cfg, search="exhaustive"))
    assert np.array_equal(bnb.pose, exh.pose)
    assert bnb.score == exh.score


def test_ties_break_the_same_way_in_both_searches() -> None:
    # A corridor map: every translation along the corridor scores the same.
    ref, cur, guess = _corridor()
    cfg = SMALL  # the levels the corridor reference was built with
    bnb = correlative_match(ref, cur, guess, cfg)
    exh = correlative_match(ref, cur, guess, replace(cfg, search="exhaustive"))
    assert np.array_equal(bnb.pose, exh.pose)
    assert bnb.score == exh.score


@pytest.mark.parametrize("seed", [11, 12, 13, 14])
def test_recovers_a_large_offset(seed: int) -> None:
    """No initial guess (identity) for a true motion of up to 0.5 m and 15°: the answer is
    within one cell (0.05 m) and two angular steps of the truth."""
    rng = np.random.default_rng(seed)
    world = rooms_world()
    pa = np.array([*SPOTS[seed % len(SPOTS)], rng.uniform(-np.pi, np.pi)])
    sign = rng.choice([-1.0, 1.0], 3)
    pb = pa + sign * np.array([0.5, 0.35, math.radians(15.0)])
    ref_pts, cur = _points(world, pa, rng), _points(world, pb, rng)
    truth = between(pa, pb)
    cfg = CorrelativeConfig(window_xy=0.6)
    r = correlative_match(ref_pts, cur, np.zeros(3), cfg)
    r_max = float(np.sqrt((cur**2).sum(axis=1)).max())
    step = cfg.resolution / r_max
    assert abs(r.pose[0] - truth[0]) <= cfg.resolution
    assert abs(r.pose[1] - truth[1]) <= cfg.resolution
    assert abs(r.pose[2] - truth[2]) <= 2 * step
    assert r.score > 0.5 and r.inlier_fraction > 0.8


def test_recovers_a_pose_in_a_map_from_every_kind_of_reference() -> None:
    rng = np.random.default_rng(21)
    world = rooms_world()
    grid = rasterize_segments(world, 0.05, padding=1.025)
    truth = np.array([14.7, 2.3, 2.1])
    cur = _points(world, truth, rng)
    guess = truth + np.array([-0.43, 0.38, -math.radians(15.0)])
    field = LikelihoodField.from_grid(grid, 0.05)
    for reference in (grid, field, CorrelativeReference.from_grid(grid)):
        r = correlative_match(reference, cur, guess)
        assert np.hypot(*(r.pose[:2] - truth[:2])) <= 0.05
        assert abs(r.pose[2] - truth[2]) <= 0.01


def test_exact_transform_of_the_reference_is_recovered_exactly() -> None:
    """Frame convention p = R(θ) q + t: points q = T⁻¹ p of the reference itself, for a T on
    the search grid, come back as T with a near-perfect score (a point on a cell boundary
    may fall into the neighbouring cell after the round trip)."""
    rng = np.random.default_rng(3)
    p = _points(rooms_world(), np.array([5.0, 9.0, 0.3]), rng)
    T = np.array([0.2, -0.15, 0.1])
    q = inverse_transform_points(T, p)
    cfg = CorrelativeConfig(angular_step=0.01)
    r = correlative_match(p, q, np.zeros(3), cfg)
    np.testing.assert_allclose(r.pose, T, atol=1e-9)
    assert r.score > 0.99
    assert r.inlier_fraction == 1.0
    assert r.method == "correlative"


def test_covariance_of_a_constrained_match_is_about_one_grid_step() -> None:
    """In a room the response is sharp: the covariance is the discretisation term
    diag(res², res², Δθ²)/12 plus a small spread, symmetric and positive definite."""
    ref_pts, cur, _ = _pair(2)
    cfg = CorrelativeConfig(angular_step=0.005)
    r = correlative_match(ref_pts, cur, np.zeros(3), cfg)
    np.testing.assert_array_equal(r.cov, r.cov.T)
    assert np.all(np.linalg.eigvalsh(r.cov) > 0)
    floor = np.array([cfg.resolution**2, cfg.resolution**2, 0.005**2]) / 12
    assert np.all(np.diag(r.cov) >= floor * (1 - 1e-12))
    assert np.all(np.diag(r.cov) <= 4 * floor)


def _corridor():
    """A 2 m wide, 80 m long corridor map, a 360-beam scan with an 8 m range from its middle,
    and an initial guess 0.2 m off along it."""
    walls = SegmentMap(np.array([[[-40.0, 0.0], [40.0, 0.0]], [[-40.0, 2.0], [40.0, 2.0]]]))
    grid = rasterize_segments(walls, 0.05, padding=1.025)
    laser = LaserScanner.from_fov(2 * np.pi, 360, 8.0, 0.01)
    truth = np.array([0.3, 1.1, 0.05])
    ranges = laser.simulate(truth, walls, np.random.default_rng(5))
    cur = scan_points(ranges, laser.beam_angles, 8.0)
    return CorrelativeReference.from_grid(grid, SMALL), cur, truth + np.array([0.2, 0.05, 0.02])


def test_featureless_corridor_raises_degenerate() -> None:
    ref, cur, guess = _corridor()
    with pytest.raises(MatchError) as err:
        correlative_match(ref, cur, guess, replace(SMALL, max_flatness=0.5))
    assert err.value.reason == "degenerate"


def test_featureless_corridor_covariance_is_elongated_along_it() -> None:
    ref, cur, guess = _corridor()
    r = correlative_match(ref, cur, guess, SMALL)  # max_flatness=None: no raise
    w, v = np.linalg.eigh(r.cov[:2, :2])
    assert abs(v[0, -1]) > 0.999  # the major axis is the corridor's (x)
    assert math.sqrt(w[-1] / w[0]) > 5.0
    # Across the corridor and in heading the match is as sharp as in a room.
    assert abs(r.pose[1] - 1.1) <= 0.05 and abs(r.pose[2] - 0.05) <= 0.02


def test_empty_or_tiny_scans_raise() -> None:
    ref_pts, cur, _ = _pair(0)
    with pytest.raises(MatchError) as err:
        correlative_match(ref_pts, np.empty((0, 2)), np.zeros(3))
    assert err.value.reason == "too_few_points"
    with pytest.raises(MatchError) as err:
        correlative_match(ref_pts, cur[:5], np.zeros(3))
    assert err.value.reason == "too_few_points"
    with pytest.raises(MatchError) as err:
        CorrelativeReference.from_points(np.empty((0, 2)))
    assert err.value.reason == "too_few_points"


def test_low_score_raises() -> None:
    ref_pts, cur, _ = _pair(1)
    far = cur + 30.0  # nowhere near the reference
    with pytest.raises(MatchError) as err:
        correlative_match(ref_pts, far, np.zeros(3), CorrelativeConfig(min_score=0.2))
    assert err.value.reason == "low_score"


def test_prepared_reference_fixes_its_grid() -> None:
    ref_pts, cur, _ = _pair(0)
    ref = CorrelativeReference.from_points(ref_pts, CorrelativeConfig(window_xy=0.3))
    with pytest.raises(InputError, match="sigma"):
        correlative_match(ref, cur, np.zeros(3), CorrelativeConfig(window_xy=0.3, sigma=0.1))
    # Any window is fine (the tables do not depend on it) and gives the same answer as a
    # fresh reference.
    for window in (0.2, 1.0):
        other = CorrelativeConfig(window_xy=window)
        a = correlative_match(ref, cur, np.zeros(3), other)
        b = correlative_match(ref_pts, cur, np.zeros(3), other)
        np.testing.assert_array_equal(a.pose, b.pose)
        assert a.score == b.score


@pytest.mark.parametrize(
    "bad",
    [
        {"window_xy": -0.1},
        {"window_theta": math.nan},
        {"resolution": 0.0},
        {"sigma": -1.0},
        {"angular_step": 0.0},
        {"floor_likelihood": 1.0},
        {"levels": 0},
        {"levels": 2.5},
        {"search": "greedy"},
        {"max_flatness": 0.0},
        {"min_points": 0},
        {"min_score": 1.5},
        {"join_gap": -1.0},
    ],
)
def test_config_is_validated(bad: dict) -> None:
    with pytest.raises(ConfigError):
        CorrelativeConfig(**bad)


def test_max_tables_bound_every_block() -> None:
    rng = np.random.default_rng(0)
    table = rng.uniform(-3.0, 0.0, (13, 17))
    lk = lookup_from_log_table(
        table, np.zeros(2), 0.1, floor=-3.0, inlier_log=-1.0, levels=4, pad=2
    )
    fine = lk.tables[0]
    rows, cols = fine.shape
    # Values are rounded to the quantum, nothing more: the padding reads the floor.
    assert np.abs(fine[2:-2, 2:-2] - table).max() <= QUANTUM / 2 and np.all(fine[:2] == -3.0)
    assert np.array_equal(np.round(fine / QUANTUM) * QUANTUM, fine)
    for h in range(1, 4):
        w = 1 << h
        expect = np.empty_like(fine)
        for r in range(rows):
            for c in range(cols):
                expect[r, c] = fine[r : min(r + w, rows), c : min(c + w, cols)].max()
        np.testing.assert_array_equal(lk.tables[h], expect)


@pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_scores_equal_numpy_to_the_last_bit(seed: int) -> None:
    # Quantised tables make every score an exact sum: the compiled loop (sequential) and
    # NumPy (pairwise) must agree bitwise, so results never hang on summation order.
    rng = np.random.default_rng(seed)
    world = rooms_world()
    pose = np.array([*SPOTS[seed], 0.3])
    ref = _points(world, pose, rng)
    cur = _points(world, pose + np.array([0.2, -0.15, 0.08]), rng)
    initial = np.array([0.0, 0.0, 0.0])
    cfg = CorrelativeConfig(window_xy=0.6, window_theta=math.radians(10), max_flatness=None)
    reference = CorrelativeReference.from_points(ref, cfg)
    fast = correlative_match(reference, cur, initial, cfg)
    with SEAM.use(Backend.NUMPY):
        slow = correlative_match(reference, cur, initial, cfg)
    assert np.array_equal(fast.pose, slow.pose) and fast.score == slow.score
    assert np.array_equal(fast.cov, slow.cov)


@pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")
@pytest.mark.parametrize("seed", [3, 4, 5])
def test_depth_first_search_equals_the_rounds_in_a_loop_closure_window(seed: int) -> None:
    # A loop closure's window (metres, tens of degrees, five levels): the compiled search
    # (depth first from rotation groups) and the NumPy one (rounds of top nodes, level by
    # level) take the nodes in different orders and must still reach the same leaf.
    rng = np.random.default_rng(seed)
    world = rooms_world()
    pose = np.array([*SPOTS[seed % len(SPOTS)], rng.uniform(-np.pi, np.pi)])
    ref = _points(world, pose, rng)
    moved = pose + np.array([0.6, -0.8, 0.2])
    cur = _points(world, moved, rng, beams=180)
    cfg = CorrelativeConfig(window_xy=1.5, window_theta=math.radians(25), levels=5)
    reference = CorrelativeReference.from_points(ref, cfg)
    fast = correlative_match(reference, cur, np.zeros(3), cfg)
    with SEAM.use(Backend.NUMPY):
        slow = correlative_match(reference, cur, np.zeros(3), cfg)
    assert np.array_equal(fast.pose, slow.pose) and fast.score == slow.score
    assert np.abs(fast.pose - between(pose, moved)).max() < 0.1  # it found the motion


@pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")
def test_integer_scores_equal_float_scores_to_the_last_bit() -> None:
    # The tables in quanta (int16) summed as integers give the float sums exactly, with the
    # same -inf below a threshold, inside and outside the table.
    rng = np.random.default_rng(3)
    ref = _points(rooms_world(), np.array([*SPOTS[0], 0.2]), rng)
    lk = CorrelativeReference.from_points(ref, CorrelativeConfig()).lookup
    assert lk.counts is not None and lk.counts[0].dtype == np.int16
    rows = rng.integers(-20, lk.shape[0] + 20, (7, 180))
    cols = rng.integers(-20, lk.shape[1] + 20, (7, 180))
    k, di, dj = rng.integers(0, 7, 500), rng.integers(-9, 9, 500), rng.integers(-9, 9, 500)
    for level in (0, lk.levels - 1):
        full = np.empty(500)
        compiled.bounded_sums(lk.tables[level], rows, cols, k, di, dj, -np.inf, full)
        mid = float(np.median(full))
        for threshold in (-np.inf, mid, mid + 0.3 * QUANTUM, float(full.max())):
            a, b = np.empty(500), np.empty(500)
            compiled.bounded_sums(lk.tables[level], rows, cols, k, di, dj, threshold, a)
            q = -(2**62) if math.isinf(threshold) else math.ceil(threshold / QUANTUM)
            compiled.bounded_counts(lk.counts[level], rows, cols, k, di, dj, q, QUANTUM, b)
            assert np.array_equal(a, b) and (b > -np.inf).any()
    unquantised = lookup_from_log_table(
        np.full((4, 4), -0.5), np.zeros(2), 0.1, floor=-2.0, inlier_log=-0.1, levels=2, pad=2
    )
    assert unquantised.counts is not None  # -0.5 is a multiple of the quantum
    pairs = zip(unquantised.counts, unquantised.tables, strict=True)
    assert all(np.array_equal(c * QUANTUM, t) for c, t in pairs)
    off = replace(unquantised, tables=(unquantised.tables[0] + 1e-6,), counts=None)
    assert off.counts is None  # not multiples of the quantum: the float sums are used
    with pytest.raises(InputError, match="counts"):
        replace(unquantised, tables=(unquantised.tables[0],))  # two levels of counts, one table


@pytest.mark.parametrize("seed", [0, 3])
def test_branch_and_bound_equals_exhaustive_with_rotation_groups(seed: int) -> None:
    # At the default angular step no point moves more than a cell per rotation, so groups
    # of rotations are bounded through the dilated top table (compiled.group_bounds).
    ref_pts, cur, _ = _pair(seed, max_theta=0.1)
    cfg = CorrelativeConfig(window_xy=0.6, window_theta=0.12, levels=4, max_flatness=None)
    ref = CorrelativeReference.from_points(ref_pts, cfg)
    bnb = correlative_match(ref, cur, np.zeros(3), cfg)
    exh = correlative_match(ref, cur, np.zeros(3), replace(cfg, search="exhaustive"))
    assert np.array_equal(bnb.pose, exh.pose) and bnb.score == exh.score


def test_dilated_counts_are_the_window_max() -> None:
    rng = np.random.default_rng(4)
    ref = _points(rooms_world(), np.array([*SPOTS[1], 0.4]), rng)
    lk = CorrelativeReference.from_points(ref, CorrelativeConfig()).lookup
    assert lk.counts is not None
    for level, spread in ((lk.levels - 1, 2), (0, 3)):
        counts, w = lk.counts[level], 2 * spread + 1
        dilated = lk.dilated_counts(level, spread)
        # Padded by w cells of the floor, every window's max; cell (r + spread + 1, c +
        # spread + 1) of the dilated table centred on (r, c) of the counts.
        padded = np.pad(counts, w, constant_values=counts[0, 0])
        windows = np.lib.stride_tricks.sliding_window_view(padded, (w, w)).max(axis=(2, 3))
        rows, cols = counts.shape
        assert np.array_equal(dilated, windows[: rows + w + 1, : cols + w + 1])
        assert dilated[0, 0] == counts[0, 0] and lk.dilated_counts(level, spread) is dilated


@pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")
def test_rotation_group_bounds_hold_for_every_member() -> None:
    rng = np.random.default_rng(5)
    world = rooms_world()
    lk = CorrelativeReference.from_points(
        _points(world, np.array([*SPOTS[2], 0.0]), rng), CorrelativeConfig()
    ).lookup
    assert lk.counts is not None
    cur = _points(world, np.array([*(SPOTS[2] + [0.1, -0.1]), 0.05]), rng, beams=180)
    step = lk.resolution / float(np.hypot(*cur.T).max())  # the default angular step
    theta = np.arange(23) * step
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    world_pts = np.stack([c * cur[:, 0] - s * cur[:, 1], s * cur[:, 0] + c * cur[:, 1]], -1)
    rows, cols = lk.cells(world_pts)
    spread, level = 2, lk.levels - 1
    size = 2 * spread + 1
    groups = -(-rows.shape[0] // size)
    near = np.ones(groups, dtype=bool)
    for g in range(groups):
        k = np.arange(g * size, min(g * size + size, rows.shape[0]))
        mid = (k[0] + k[-1]) // 2
        moved = max(np.abs(rows[k] - rows[mid]).max(), np.abs(cols[k] - cols[mid]).max())
        assert moved <= spread  # a cell per rotation at most
    near[1] = False  # no bound for that group: +inf
    off = np.arange(-24, 25, 8)
    ks, ii, jj = np.meshgrid(np.arange(rows.shape[0]), off, off, indexing="ij")
    full = np.empty(ks.size)
    compiled.bounded_counts(
        lk.counts[level], rows, cols, ks.ravel(), ii.ravel(), jj.ravel(), -(2**62), 1.0, full
    )
    threshold = int(np.median(full))
    out = np.empty(groups * off.size**2, dtype=np.int64)
    compiled.group_bounds(
        lk.dilated_counts(level, spread), spread, near, rows, cols, off, off, threshold, out
    )
    bound = out.reshape(groups, off.size, off.size)
    for g in range(groups):
        members = full.reshape(-1, off.size, off.size)[g * size : g * size + size]
        top = members.max(axis=0)
        if not near[g]:
            assert np.all(bound[g] == compiled.NO_BOUND)
            continue
        assert np.all((bound[g] >= top) | ((bound[g] == compiled.BELOW) & (top < threshold)))
    assert (bound == compiled.BELOW).any() and (np.abs(bound) < compiled.NO_BOUND).any()


@pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")
@pytest.mark.parametrize(("resolution", "sigma"), [(0.05, 0.05), (0.03, 0.05), (0.05, 0.02)])
def test_stamped_tables_equal_the_distance_transforms(resolution: float, sigma: float) -> None:
    # Compiled, the table is stamped around each marked cell from the quantised values by
    # squared cell distance; the NumPy path takes the distance transform: the same counts.
    rng = np.random.default_rng(6)
    pts = _points(rooms_world(), np.array([*SPOTS[3], 1.0]), rng)
    cfg = CorrelativeConfig(resolution=resolution, sigma=sigma)
    fast = CorrelativeReference.from_points(pts, cfg).lookup
    with SEAM.use(Backend.NUMPY):
        slow = CorrelativeReference.from_points(pts, cfg).lookup
    assert fast.counts is not None and slow.counts is not None
    for a, b in zip(fast.counts, slow.counts, strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert all(np.array_equal(a, b) for a, b in zip(fast.tables, slow.tables, strict=True))
    assert (fast.floor, fast.inlier_log) == (slow.floor, slow.inlier_log)
    assert np.array_equal(fast.origin_xy, slow.origin_xy)


def test_smear_values() -> None:
    sigma, f = 0.05, 0.1
    d = np.array([0.0, sigma, 2 * sigma, 100.0])
    expect = np.log(f + (1 - f) * np.exp(-0.5 * np.array([0.0, 1.0, 4.0, 4e6])))
    np.testing.assert_allclose(log_likelihood_of_distance(d, sigma, f), expect, rtol=1e-14)
    assert log_likelihood_of_distance(np.array(0.0), sigma, f) == 0.0
    np.testing.assert_allclose(log_likelihood_of_distance(np.array(1e3), sigma, f), math.log(f))


def test_join_consecutive() -> None:
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]])
    out = join_consecutive(pts, max_gap=2.0, spacing=0.25)
    # (0,0)-(1,0) joined by samples 0.25 apart; (1,0)-(5,0) is a gap and stays open.
    np.testing.assert_allclose(out[:3], pts)
    np.testing.assert_allclose(out[3:], [[0.25, 0.0], [0.5, 0.0], [0.75, 0.0]])
