"""The grid RBPF's guard on a hand-made grid: the fit of a scan to the map's walls and the
relocation over every heading."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamkit.geometry.pose2 import between
from slamkit.maps import OccupancyGrid
from slamkit.maps.likelihood_field import LikelihoodField
from slamkit.scanmatch.relocate import REFUTED_FIT
from slamkit.scanmatch.to_map import MapMatchConfig
from slamkit.slam.grid_rbpf import map_fit, relocate_on_map
from slamkit.slam.grid_rbpf.guard import NEAR_SEARCH, TURN_RATIO, WIDE_TURN, refuse_wide_turn

RES = 0.05


def _room() -> tuple[LikelihoodField, np.ndarray]:
    """A 10 m × 8 m room (walls one cell thick) with a pillar, on a 5 cm grid from (-6,
    -5): the inside seen free (p = 0.05), the walls occupied (0.95), the rest unknown (0.5).
    Also the wall cells' centres."""
    rows, cols = 200, 240
    prob = np.full((rows, cols), 0.5)
    origin = np.array([-6.0, -5.0])

    def cell(x: float, y: float) -> tuple[int, int]:
        return int((y - origin[1]) / RES), int((x - origin[0]) / RES)

    r0, c0 = cell(-4.0, -3.0)
    r1, c1 = cell(6.0 - RES, 5.0 - RES)
    prob[r0 : r1 + 1, c0 : c1 + 1] = 0.05
    prob[r0, c0 : c1 + 1] = prob[r1, c0 : c1 + 1] = 0.95
    prob[r0 : r1 + 1, c0] = prob[r0 : r1 + 1, c1] = 0.95
    pr, pc = cell(1.0, 1.0)
    prob[pr : pr + 16, pc : pc + 10] = 0.95  # a pillar 0.5 m × 0.8 m: no symmetry left
    grid = OccupancyGrid(prob, RES, origin)
    field = LikelihoodField.from_grid(grid, 0.05, max_range=20.0, free_threshold=1.0)
    walls = grid.cell_to_world(np.argwhere(prob > 0.9))
    return field, walls


def _in_robot_frame(world: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """World points ``(K, 2)`` as a scan taken from ``pose``: ``R(θ)ᵀ (p - t)``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    out: np.ndarray = (world - pose[:2]) @ np.array([[c, -s], [s, c]])
    return out


def test_map_fit_counts_the_end_points_on_the_walls() -> None:
    field, walls = _room()
    pose = np.array([0.4, -0.3, math.radians(35.0)])
    world = walls[::4].copy()
    assert map_fit(field, _in_robot_frame(world, pose), pose) == 1.0
    # a third of them in the middle of the free room, a metre or more from every wall
    third = world.shape[0] // 3
    world[:third] = np.random.default_rng(1).uniform([-2.0, -2.0], [-1.0, -1.0], (third, 2))
    fit = map_fit(field, _in_robot_frame(world, pose), pose)
    assert fit == pytest.approx(1.0 - third / world.shape[0], abs=1e-12)
    assert map_fit(field, np.zeros((0, 2)), pose) == 0.0


def test_relocation_finds_a_scan_turned_half_a_circle_away() -> None:
    field, walls = _room()
    true = np.array([0.4, -0.3, math.radians(35.0)])
    points = _in_robot_frame(walls[::3], true)
    points += np.random.default_rng(0).normal(0.0, 0.005, points.shape)
    wrong = np.array([0.9, 0.2, true[2] + math.radians(150.0)])
    assert map_fit(field, points, wrong) < REFUTED_FIT
    found = relocate_on_map(field, points, wrong, MapMatchConfig(sigma_hit=0.05))
    assert found is not None and found.fit > 0.9
    err = between(true, found.match.pose)
    assert math.hypot(err[0], err[1]) < 0.03 and abs(math.degrees(err[2])) < 0.5


def _box(partition: bool) -> LikelihoodField:
    """An 8 m × 6 m room (x, y within ± 4, ± 3 m) on a 5 cm grid, the same under a half turn
    about its centre (0, 0) — or, with ``partition``, not: a 3 m wall from the west wall at
    y = 1."""
    prob = np.full((200, 240), 0.5)
    origin = np.array([-6.0, -5.0])
    prob[40 : 200 - 39, 40 : 240 - 39] = 0.05
    prob[40, 40:201] = prob[160, 40:201] = 0.95
    prob[40:161, 40] = prob[40:161, 200] = 0.95
    if partition:
        prob[120, 40:100] = 0.95
    grid = OccupancyGrid(prob, RES, origin)
    return LikelihoodField.from_grid(grid, 0.05, max_range=20.0, free_threshold=1.0)


def _seen(field: LikelihoodField, pose: np.ndarray, reach: float) -> np.ndarray:
    """The wall cells within ``reach`` of ``pose``, as its scan (robot frame)."""
    walls = field.grid.cell_to_world(np.argwhere(field.grid.prob > 0.9))
    near = walls[np.hypot(*(walls - pose[:2]).T) <= reach]
    return _in_robot_frame(near, pose)


def test_a_half_turn_that_fits_no_better_than_the_wheels_side_is_refused() -> None:
    """In a room that looks the same turned round, the twin pose (half a turn about the
    centre) fits as well as the true one: a relocation there is refused, and the pose on the
    wheels' side (the true one, within a cell and half a degree) is judged instead."""
    field = _box(partition=False)
    true = np.array([-2.0, 0.7, math.radians(80.0)])
    points = _seen(field, true, 4.0)
    match = MapMatchConfig(sigma_hit=0.05)
    twin = np.array([-true[0], -true[1], true[2] + math.pi])
    turned = relocate_on_map(field, points, twin, match, NEAR_SEARCH)
    assert turned is not None and turned.fit > 0.95
    assert abs(between(true, turned.match.pose)[2]) > WIDE_TURN
    side = refuse_wide_turn(field, points, true, match, turned)
    assert side is not None and side.fit >= TURN_RATIO * turned.fit
    err = between(true, side.match.pose)
    assert math.hypot(err[0], err[1]) < RES and abs(math.degrees(err[2])) < 0.5


def test_a_half_turn_that_the_map_confirms_is_kept() -> None:
    """With the partition, the scan near it fits only the true pose: wheels turned 150°
    away are overridden by the relocation, and the wheels' side (± 60°) holds no pose that
    fits 80 % as well."""
    field = _box(partition=True)
    true = np.array([-2.5, 0.5, math.radians(80.0)])
    points = _seen(field, true, 3.0)
    match = MapMatchConfig(sigma_hit=0.05)
    wheels = true + np.array([0.0, 0.0, math.radians(150.0)])
    turned = relocate_on_map(field, points, wheels, match)
    assert turned is not None and turned.fit > 0.95
    err = between(true, turned.match.pose)
    assert math.hypot(err[0], err[1]) < RES and abs(math.degrees(err[2])) < 0.5
    assert refuse_wide_turn(field, points, wheels, match, turned) is None
