"""Scan-to-map matching on MCL's likelihood field: the interpolated distance field, recovery
of known poses on a rasterised rooms_world, the covariance, and the failure modes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamkit.errors import ConfigError, InputError, MatchError
from slamkit.maps import SegmentMap
from slamkit.maps.likelihood_field import LikelihoodField, interpolate_distance
from slamkit.models.laser import LaserScanner
from slamkit.scanmatch import (
    CorrelativeReference,
    MapMatchConfig,
    match_to_map,
    scan_points,
)
from slamkit.sim.worlds import rasterize_segments, rooms_world

RES = 0.05
MAX_RANGE = 12.0
# Walls of rooms_world lie on whole metres: a padding of 1 m + half a cell puts them on cell
# centres, so the rasterised map has no half-cell bias.
GRID = rasterize_segments(rooms_world(), RES, padding=1.0 + RES / 2)
FIELD = LikelihoodField.from_grid(GRID, 0.05)
POSES = np.array([[5.0, 6.0, 0.1], [15.0, 3.0, 2.0], [3.0, 9.0, -1.0], [16.0, 9.5, 2.9]])

# Tolerances on the recovered pose, for 1 cm range noise on a 5 cm grid.
TOL_XY = 0.02  # m
TOL_THETA = 0.01  # rad


def _points(pose: np.ndarray, seed: int, beams: int = 360, world: SegmentMap | None = None):
    fov = 2 * np.pi if beams == 360 else np.pi
    laser = LaserScanner.from_fov(fov, beams, MAX_RANGE, 0.01)
    ranges = laser.simulate(
        np.asarray(pose, float), world or rooms_world(), np.random.default_rng(seed)
    )
    return scan_points(ranges, laser.beam_angles, MAX_RANGE)


def test_interpolated_distance_hits_the_cell_centres() -> None:
    rows, cols = GRID.shape
    r, c = np.meshgrid(np.arange(1, rows - 1, 7), np.arange(1, cols - 1, 9), indexing="ij")
    cells = np.column_stack([r.ravel(), c.ravel()])
    d, _ = interpolate_distance(FIELD, GRID.cell_to_world(cells))
    np.testing.assert_allclose(d, FIELD.distances[cells[:, 0], cells[:, 1]], atol=1e-12)


def test_interpolated_gradient_matches_finite_differences() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform([0.5, 0.5], [19.5, 11.5], (200, 2))
    _, g = interpolate_distance(FIELD, pts)
    h = 1e-7
    for axis in range(2):
        e = np.zeros(2)
        e[axis] = h
        dp, _ = interpolate_distance(FIELD, pts + e)
        dm, _ = interpolate_distance(FIELD, pts - e)
        np.testing.assert_allclose(g[:, axis], (dp - dm) / (2 * h), atol=1e-5)


def test_interpolated_distance_far_outside_is_the_outside_value() -> None:
    d, g = interpolate_distance(FIELD, np.array([[-50.0, 3.0], [5.0, 400.0]]))
    np.testing.assert_array_equal(d, [FIELD.outside_distance] * 2)
    np.testing.assert_array_equal(g, np.zeros((2, 2)))


@pytest.mark.parametrize("k", range(len(POSES)))
@pytest.mark.parametrize("beams", [180, 360])
def test_recovers_a_known_pose_from_an_offset(k: int, beams: int) -> None:
    truth = POSES[k]
    cur = _points(truth, seed=k, beams=beams)
    r = match_to_map(FIELD, cur, truth + np.array([0.15, -0.1, 0.08]))
    assert np.hypot(*(r.pose[:2] - truth[:2])) < TOL_XY
    assert abs(r.pose[2] - truth[2]) < TOL_THETA
    assert r.score > 0.9 and r.inlier_fraction > 0.95
    assert r.method == "to_map" and r.iterations >= 1


@pytest.mark.parametrize("k", range(len(POSES)))
def test_correlative_start_recovers_a_large_offset(k: int) -> None:
    truth = POSES[k]
    cur = _points(truth, seed=10 + k)
    coarse = CorrelativeReference.from_likelihood_field(FIELD)
    r = match_to_map(FIELD, cur, truth + np.array([0.45, -0.35, math.radians(15.0)]), coarse=coarse)
    assert np.hypot(*(r.pose[:2] - truth[:2])) < TOL_XY
    assert abs(r.pose[2] - truth[2]) < TOL_THETA
    assert r.method == "correlative+to_map"


def test_a_grid_is_the_same_as_its_likelihood_field() -> None:
    truth = POSES[0]
    cur = _points(truth, seed=3)
    guess = truth + np.array([0.05, 0.05, 0.02])
    a = match_to_map(GRID, cur, guess, MapMatchConfig(sigma_hit=0.05))
    b = match_to_map(FIELD, cur, guess)
    np.testing.assert_array_equal(a.pose, b.pose)
    np.testing.assert_array_equal(a.cov, b.cov)


def test_noise_free_scan_at_the_truth_scores_near_one() -> None:
    laser = LaserScanner.from_fov(2 * np.pi, 360, MAX_RANGE, 0.0)
    truth = POSES[2]
    ranges = laser.simulate(truth, rooms_world(), np.random.default_rng(0))
    r = match_to_map(FIELD, scan_points(ranges, laser.beam_angles, MAX_RANGE), truth)
    assert r.score > 0.95
    assert np.hypot(*(r.pose[:2] - truth[:2])) < 0.01


def test_covariance_is_elongated_along_the_corridor() -> None:
    """In rooms_world's corridor (along x) the walls pin y far better than x."""
    cur = _points(POSES[0], seed=1, beams=180)
    r = match_to_map(FIELD, cur, POSES[0] + np.array([0.05, 0.0, 0.0]))
    np.testing.assert_allclose(r.cov, r.cov.T, atol=1e-15)
    assert np.all(np.linalg.eigvalsh(r.cov) > 0)
    assert r.cov[0, 0] > 2.0 * r.cov[1, 1]


def test_featureless_corridor_is_degenerate() -> None:
    walls = SegmentMap(np.array([[[-40.0, 0.0], [40.0, 0.0]], [[-40.0, 2.0], [40.0, 2.0]]]))
    grid = rasterize_segments(walls, RES, padding=1.0 + RES / 2)
    laser = LaserScanner.from_fov(2 * np.pi, 360, 8.0, 0.01)
    truth = np.array([0.3, 1.1, 0.05])
    cur = scan_points(
        laser.simulate(truth, walls, np.random.default_rng(5)), laser.beam_angles, 8.0
    )
    with pytest.raises(MatchError) as err:
        match_to_map(grid, cur, truth + np.array([0.05, 0.05, 0.02]))
    assert err.value.reason == "degenerate"


def test_scan_outside_the_map_raises() -> None:
    cur = _points(POSES[0], seed=0)
    with pytest.raises(MatchError) as err:
        match_to_map(FIELD, cur, np.array([100.0, 100.0, 0.0]))
    assert err.value.reason == "too_few_correspondences"


def test_empty_scan_raises() -> None:
    with pytest.raises(MatchError) as err:
        match_to_map(FIELD, np.empty((0, 2)), POSES[0])
    assert err.value.reason == "too_few_points"


def test_bad_arguments() -> None:
    cur = _points(POSES[0], seed=0)
    with pytest.raises(InputError):
        match_to_map(np.zeros((10, 10)), cur, POSES[0])  # type: ignore[arg-type]
    for bad in ({"sigma_hit": 0.0}, {"max_iterations": 0}, {"max_std_xy": -1.0}):
        with pytest.raises(ConfigError):
            MapMatchConfig(**bad)  # type: ignore[arg-type]
