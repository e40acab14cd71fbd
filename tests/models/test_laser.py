"""Laser ray casting (segments and grids) and the scanner simulator."""

from __future__ import annotations

import numpy as np
import pytest

import slamkit.models.laser as laser_module
from slamkit.errors import InputError, NonFiniteError, ShapeError
from slamkit.maps import OccupancyGrid, SegmentMap
from slamkit.models import LaserScanner, cast_rays_grid, cast_rays_segments

HALF = 5.0
ROOM = SegmentMap(
    np.array(
        [
            [[-HALF, -HALF], [HALF, -HALF]],
            [[HALF, -HALF], [HALF, HALF]],
            [[HALF, HALF], [-HALF, HALF]],
            [[-HALF, HALF], [-HALF, -HALF]],
        ]
    )
)
BOX = (1.0, -2.0, 2.5, -0.5)  # xmin, ymin, xmax, ymax of a pillar inside the room


def box_segments(xmin: float, ymin: float, xmax: float, ymax: float) -> np.ndarray:
    c = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
    return np.stack([c, np.roll(c, -1, axis=0)], axis=1)


ROOM_WITH_BOX = SegmentMap(np.concatenate([ROOM.segments, box_segments(*BOX)]))


def rasterised_room(resolution: float = 0.1, pillar: bool = True) -> OccupancyGrid:
    """The room (and pillar) as a grid whose cell boundaries lie on the walls: cells outside
    the room or inside the pillar are occupied (1), the rest free (0)."""
    grid = OccupancyGrid.empty(-6.0, -6.0, 6.0, 6.0, resolution, 0.0)
    rows, cols = grid.shape
    centres = grid.cell_to_world(
        np.stack(np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij"), -1)
    )
    x, y = centres[..., 0], centres[..., 1]
    outside = (np.abs(x) > HALF) | (np.abs(y) > HALF)
    xmin, ymin, xmax, ymax = BOX
    inside_pillar = pillar & (x > xmin) & (x < xmax) & (y > ymin) & (y < ymax)
    return OccupancyGrid(np.where(outside | inside_pillar, 1.0, 0.0), resolution, grid.origin_xy)


GRID = rasterised_room()  # room and pillar, like ROOM_WITH_BOX
EMPTY_ROOM_GRID = rasterised_room(pillar=False)  # like ROOM


@pytest.mark.parametrize("world", ["segments", "grid"])
def test_centre_of_square_room(world: str) -> None:
    beams = np.array([0.0, np.pi / 4, np.pi / 2, 3 * np.pi / 4, np.pi, -np.pi / 2, -np.pi / 4])
    expected = np.array([5, 5 * np.sqrt(2), 5, 5 * np.sqrt(2), 5, 5, 5 * np.sqrt(2)])
    for heading in [0.0, np.pi / 2, -np.pi]:  # the room is symmetric under quarter turns
        if world == "segments":
            r = cast_rays_segments([0.0, 0.0, heading], beams, ROOM, 20.0)
        else:
            r = cast_rays_grid(
                [0.0, 0.0, heading], beams, rasterised_room(0.25, pillar=False), 20.0
            )
        assert r.shape == (7,)
        np.testing.assert_allclose(r, expected, atol=1e-9)


def test_off_centre_hand_values() -> None:
    beams = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2])
    r = cast_rays_segments([2.0, 1.0, 0.0], beams, ROOM, 20.0)
    np.testing.assert_allclose(r, [3.0, 4.0, 7.0, 6.0])
    r = cast_rays_grid([2.0, 1.0, 0.0], beams, EMPTY_ROOM_GRID, 20.0)
    np.testing.assert_allclose(r, [3.0, 4.0, 7.0, 6.0], atol=1e-9)
    # with the pillar, looking down (-y) from (2, 1) hits its top face at y = -0.5
    r = cast_rays_grid([2.0, 1.0, 0.0], beams, GRID, 20.0)
    np.testing.assert_allclose(r, [3.0, 4.0, 7.0, 1.5], atol=1e-9)
    # facing +y the first beam looks along +y
    r = cast_rays_segments([2.0, 1.0, np.pi / 2], beams, ROOM, 20.0)
    np.testing.assert_allclose(r, [4.0, 7.0, 6.0, 3.0])
    # from the origin at -45 deg the ray meets the pillar's left face (x = 1) at (1, -1)
    r = cast_rays_segments([0.0, 0.0, 0.0], [-np.pi / 4, -np.pi / 2], ROOM_WITH_BOX, 20.0)
    np.testing.assert_allclose(r, [np.sqrt(2.0), 5.0])


def test_nothing_hit_returns_max_range() -> None:
    beams = np.linspace(-np.pi, np.pi, 9)
    np.testing.assert_array_equal(cast_rays_segments([0, 0, 0], beams, ROOM, 3.0), 3.0)
    np.testing.assert_array_equal(cast_rays_grid([0, 0, 0], beams, EMPTY_ROOM_GRID, 3.0), 3.0)
    np.testing.assert_array_equal(
        cast_rays_segments([0, 0, 0], beams, np.zeros((0, 2, 2)), 7.0), 7.0
    )
    # a single wall behind the robot: every forward beam misses
    wall = np.array([[[-1.0, -3.0], [-1.0, 3.0]]])
    r = cast_rays_segments([0, 0, 0], [0.0, 0.5, -0.5, np.pi], wall, 10.0)
    np.testing.assert_allclose(r, [10.0, 10.0, 10.0, 1.0])
    # an empty grid: rays leave it without a hit
    empty = OccupancyGrid.empty(-2, -2, 2, 2, 0.1, 0.0)
    np.testing.assert_array_equal(cast_rays_grid([0, 0, 0.3], beams, empty, 50.0), 50.0)
    # unknown cells (0.5) are not obstacles at the default threshold
    unknown = OccupancyGrid.empty(-2, -2, 2, 2, 0.1)
    np.testing.assert_array_equal(cast_rays_grid([0, 0, 0], beams, unknown, 50.0), 50.0)
    np.testing.assert_array_equal(cast_rays_grid([0, 0, 0], beams, unknown, 50.0, 0.5), 0.0)


def test_segment_and_grid_casting_agree_on_a_rasterised_room() -> None:
    rng = np.random.default_rng(8)
    poses = np.column_stack([rng.uniform(-4.8, 4.8, (60, 2)), rng.uniform(-np.pi, np.pi, 60)])
    xmin, ymin, xmax, ymax = BOX
    in_pillar = (
        (poses[:, 0] > xmin) & (poses[:, 0] < xmax) & (poses[:, 1] > ymin) & (poses[:, 1] < ymax)
    )
    poses = poses[~in_pillar]
    beams = np.linspace(-np.pi, np.pi, 181, endpoint=False)
    r_seg = cast_rays_segments(poses, beams, ROOM_WITH_BOX, 30.0)
    r_grid = cast_rays_grid(poses, beams, GRID, 30.0)
    assert r_seg.shape == r_grid.shape == (poses.shape[0], 181)
    assert np.all(np.abs(r_seg - r_grid) <= GRID.resolution)
    assert np.median(np.abs(r_seg - r_grid)) < 1e-9  # walls on cell boundaries: exact


def test_grid_casting_on_an_unaligned_rasterisation_never_overshoots() -> None:
    """Walls rasterised by dense sampling (not on cell boundaries): the ray crosses each wall
    inside an occupied cell, so the grid range is never longer than the segment range, and
    typically within one cell (grazing beams enter the wall's cells earlier)."""
    res = 0.1
    grid = OccupancyGrid.empty(-6.03, -6.07, 6.0, 6.0, res, 0.0)
    prob = grid.prob.copy()
    t = np.linspace(0.0, 1.0, 4000)[:, None]
    for a, b in ROOM_WITH_BOX.segments:
        cells = grid.world_to_cell(a + t * (b - a))
        prob[cells[:, 0], cells[:, 1]] = 1.0
    grid = OccupancyGrid(prob, res, grid.origin_xy)
    rng = np.random.default_rng(9)
    poses = np.column_stack([rng.uniform(-4.5, 4.5, (40, 2)), rng.uniform(-np.pi, np.pi, 40)])
    poses = poses[
        ~((poses[:, 0] > 0.8) & (poses[:, 0] < 2.7) & (poses[:, 1] > -2.2) & (poses[:, 1] < -0.3))
    ]
    beams = np.linspace(-np.pi, np.pi, 120, endpoint=False)
    r_seg = cast_rays_segments(poses, beams, ROOM_WITH_BOX, 30.0)
    r_grid = cast_rays_grid(poses, beams, grid, 30.0)
    assert np.all(r_grid <= r_seg + 1e-9)
    assert np.median(r_seg - r_grid) <= res


def test_grid_rays_from_outside_and_inside_obstacles() -> None:
    # from outside the grid, looking in: enters at x = -6 straight into the outer wall cells
    r = cast_rays_grid([-8.0, 0.05, 0.0], [0.0, np.pi], GRID, 20.0)
    np.testing.assert_allclose(r, [2.0, 20.0])
    # starting inside an occupied cell reads 0
    np.testing.assert_allclose(cast_rays_grid([5.5, 0.0, 0.0], [0.0, 1.0], GRID, 20.0), 0.0)
    # the grid range stops at max_range even when a wall lies beyond it
    np.testing.assert_allclose(cast_rays_grid([0.0, 0.0, 0.0], [0.0], GRID, 4.99), [4.99])


def test_batches_equal_loops_and_chunking(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-4, 4, (6, 2)), rng.uniform(-3, 3, 6)]).reshape(2, 3, 3)
    p0 = poses.copy()
    beams = np.linspace(-2.0, 2.0, 11)
    for cast, world in [(cast_rays_segments, ROOM_WITH_BOX), (cast_rays_grid, GRID)]:
        r = cast(poses, beams, world, 30.0)
        assert r.shape == (2, 3, 11)
        for i in np.ndindex(2, 3):
            np.testing.assert_array_equal(r[i], cast(poses[i], beams, world, 30.0))
    np.testing.assert_array_equal(poses, p0)
    # blocks of a few (ray, segment) pairs give the same answer as one block
    full = cast_rays_segments(poses, beams, ROOM_WITH_BOX, 30.0)
    monkeypatch.setattr(laser_module, "_PAIRS_PER_BLOCK", 5)
    np.testing.assert_array_equal(cast_rays_segments(poses, beams, ROOM_WITH_BOX, 30.0), full)


def test_many_poses_stay_fast() -> None:
    rng = np.random.default_rng(4)
    poses = np.column_stack([rng.uniform(-4, 4, (2000, 2)), rng.uniform(-3, 3, 2000)])
    beams = np.linspace(-np.pi / 2, np.pi / 2, 61)
    r_seg = cast_rays_segments(poses, beams, ROOM, 30.0)
    r_grid = cast_rays_grid(poses, beams, EMPTY_ROOM_GRID, 30.0)
    assert r_seg.shape == r_grid.shape == (2000, 61)
    assert np.all((r_seg > 0) & (r_seg <= 10 * np.sqrt(2)))
    assert np.all(np.abs(r_seg - r_grid) <= EMPTY_ROOM_GRID.resolution)


def test_scanner_from_fov() -> None:
    s = LaserScanner.from_fov(np.pi, 181, 30.0, 0.01)
    assert s.n_beams == 181
    np.testing.assert_allclose(s.beam_angles[[0, 90, 180]], [-np.pi / 2, 0.0, np.pi / 2])
    full = LaserScanner.from_fov(2 * np.pi, 360, 30.0, 0.01)
    assert full.n_beams == 360
    np.testing.assert_allclose(np.diff(full.beam_angles), 2 * np.pi / 360)  # no duplicate at ±pi
    assert full.beam_angles[0] == -np.pi and full.beam_angles[-1] < np.pi
    np.testing.assert_array_equal(LaserScanner.from_fov(1.0, 1, 5.0, 0.0).beam_angles, [0.0])
    with pytest.raises(ValueError):
        s.beam_angles[0] = 1.0  # read-only


@pytest.mark.parametrize("world", [ROOM, GRID], ids=["segments", "grid"])
def test_scanner_simulate(world: SegmentMap | OccupancyGrid) -> None:
    scanner = LaserScanner.from_fov(2 * np.pi, 720, 6.0, 0.05)
    pose = np.array([0.5, -0.3, 0.2])
    true = scanner.expected_ranges(pose, world)
    a = scanner.simulate(pose, world, np.random.default_rng(1))
    b = scanner.simulate(pose, world, np.random.default_rng(1))
    np.testing.assert_array_equal(a, b)
    assert a.shape == (720,)
    assert np.all((a >= 0) & (a <= 6.0))
    no_return = true >= 6.0
    assert 0 < no_return.sum() < 720  # corners are beyond 6 m
    np.testing.assert_array_equal(a[no_return], 6.0)
    hits = ~no_return & (true < 6.0 - 0.5)
    err = a[hits] - true[hits]
    assert abs(err.mean()) < 4 * 0.05 / np.sqrt(hits.sum())
    assert 0.9 * 0.05 < err.std() < 1.1 * 0.05
    exact = LaserScanner(scanner.beam_angles, 6.0, 0.0)
    np.testing.assert_array_equal(exact.simulate(pose, world, np.random.default_rng(1)), true)
    many = scanner.simulate(np.stack([pose, pose]), world, np.random.default_rng(1))
    assert many.shape == (2, 720) and not np.array_equal(many[0], many[1])


def test_bad_inputs_raise_typed_errors() -> None:
    with pytest.raises(NonFiniteError):
        cast_rays_segments([0.0, np.nan, 0.0], [0.0], ROOM, 10.0)
    with pytest.raises(NonFiniteError):
        cast_rays_grid([0.0, 0.0, np.inf], [0.0], GRID, 10.0)
    with pytest.raises(ShapeError):
        cast_rays_segments([0.0, 0.0], [0.0], ROOM, 10.0)
    with pytest.raises(ShapeError):
        cast_rays_segments([0.0, 0.0, 0.0], [[0.0, 1.0]], ROOM, 10.0)
    with pytest.raises(ShapeError):
        cast_rays_segments([0.0, 0.0, 0.0], [0.0], np.zeros((3, 2)), 10.0)
    with pytest.raises(InputError):
        cast_rays_segments([0.0, 0.0, 0.0], [0.0], ROOM, 0.0)
    with pytest.raises(InputError):
        cast_rays_grid([0.0, 0.0, 0.0], [0.0], ROOM, 10.0)  # type: ignore[arg-type]
    with pytest.raises(ShapeError):
        LaserScanner(np.array([]), 10.0, 0.1)
    with pytest.raises(InputError):
        LaserScanner(np.zeros(3), 10.0, -0.1)
    with pytest.raises(InputError):
        LaserScanner.from_fov(np.pi, 0, 10.0, 0.1)
