"""The grid RBPF's guard on a hand-made grid: the fit of a scan to the map's walls and the
relocation over every heading."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamkit.geometry.pose2 import between
from slamkit.localization.likelihood_field import LikelihoodField
from slamkit.maps import OccupancyGrid
from slamkit.scanmatch.relocate import REFUTED_FIT
from slamkit.scanmatch.to_map import MapMatchConfig
from slamkit.slam.grid_rbpf import map_fit, relocate_on_map

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
