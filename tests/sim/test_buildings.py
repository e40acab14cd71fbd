"""Generated buildings: deterministic by seed, routes of the stated length that revisit
places and never pass through a wall, scans that see people, glass and open space."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets.registry import load_dataset
from slamkit.datasets.stream import Dataset, LaserScan, Odometry
from slamkit.models import cast_rays_segments
from slamkit.sim.buildings import (
    BuildingConfig,
    build_building_dataset,
    corpus_buildings,
    drive_route,
    generate_building,
    simulate_building_scans,
)

CORPUS = corpus_buildings()


@pytest.fixture(scope="module")
def drives() -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """The true stamps and poses of every corpus building's drive."""
    return {seed: drive_route(generate_building(seed)) for seed in CORPUS}


@pytest.fixture(scope="module")
def small() -> Dataset:
    """The data set of building 11 (the smallest of the corpus: 33 m × 14 m, ~700 scans)."""
    return build_building_dataset(11)


def crossings(path: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """Which steps ``path[k] -> path[k + 1]`` (``(N, 2)``) cross or touch a wall ``(S, 2, 2)``:
    the two end points of each lie on opposite sides of (or on) the other's line."""
    p, r = path[:-1, None, :], (path[1:] - path[:-1])[:, None, :]
    q, s = walls[None, :, 0], (walls[:, 1] - walls[:, 0])[None]

    def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    d1, d2 = cross(s, p - q), cross(s, p + r - q)
    d3, d4 = cross(r, q - p), cross(r, q + s - p)
    return ((d1 * d2 <= 0) & (d3 * d4 <= 0)).any(axis=1)


def test_same_seed_same_building_and_path_other_seeds_differ() -> None:
    a, b, c = generate_building(3), generate_building(3), generate_building(4)
    np.testing.assert_array_equal(a.walls.segments, b.walls.segments)
    np.testing.assert_array_equal(a.glass.segments, b.glass.segments)
    np.testing.assert_array_equal(a.route, b.route)
    np.testing.assert_array_equal(a.walkers.ends, b.walkers.ends)
    np.testing.assert_array_equal(drive_route(a)[1], drive_route(b)[1])
    assert a.walls.segments.shape != c.walls.segments.shape or not np.array_equal(
        a.walls.segments, c.walls.segments
    )
    plans = {generate_building(s).walls.segments.tobytes() for s in CORPUS}
    assert len(plans) == len(CORPUS)


def test_routes_are_100_to_500_m_long(drives: dict[int, tuple[np.ndarray, np.ndarray]]) -> None:
    lengths = [float(np.sum(np.hypot(*np.diff(p[:, :2], axis=0).T))) for _, p in drives.values()]
    assert min(lengths) >= 100.0 and max(lengths) <= 500.0
    # A scan after 0.3 m of travel or 10 degrees of turning; the control steps are
    # 0.5 m/s × 0.2 s = 0.1 m (σ 6 mm), so a gap is at most 0.3 m + one step.
    for _, poses in drives.values():
        steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        assert float(np.max(steps)) <= 0.3 + 0.1 + 4 * 0.006
        assert 0.25 <= float(np.median(steps)) <= 0.4


def test_routes_revisit_places(drives: dict[int, tuple[np.ndarray, np.ndarray]]) -> None:
    """Some pair of poses more than 30 s apart lies within 1 m, in every building; and more
    than a tenth of the route is driven again (a loop closure per lap, not one lucky pass)."""
    for seed, (times, poses) in drives.items():
        d = np.hypot(*(poses[:, None, :2] - poses[None, :, :2]).transpose(2, 0, 1))
        later = (times[None, :] - times[:, None]) > 30.0
        revisited = np.any(later & (d < 1.0), axis=1)
        assert revisited.any(), seed
        assert revisited.mean() > 0.1, (seed, revisited.mean())


def test_no_step_passes_through_a_wall(drives: dict[int, tuple[np.ndarray, np.ndarray]]) -> None:
    """Every step between consecutive true poses stays clear of every wall, glass pane and
    piece of clutter; the robot (a point) keeps 0.2 m from all of them."""
    for seed, (_, poses) in drives.items():
        building = generate_building(seed)
        walls = building.static_map.segments
        assert not crossings(poses[:, :2], walls).any(), seed
        # Distance from every pose to every segment.
        a, e = walls[:, 0], walls[:, 1] - walls[:, 0]
        w = poses[:, None, :2] - a[None]
        t = np.clip(np.sum(w * e, axis=-1) / np.sum(e * e, axis=-1), 0.0, 1.0)
        gap = np.hypot(*(w - t[..., None] * e).transpose(2, 0, 1))
        assert float(gap.min()) > 0.2, seed


def test_crossing_check_catches_a_step_through_a_wall() -> None:
    walls = np.array([[[0.0, 0.0], [0.0, 2.0]]])
    path = np.array([[-1.0, 1.0], [-0.1, 1.0], [0.1, 1.0], [0.1, 3.0]])
    np.testing.assert_array_equal(crossings(path, walls), [False, True, False])


def test_scans_see_people_glass_and_open_space() -> None:
    building = generate_building(11)
    times, poses = drive_route(building)
    laser = BuildingConfig().laser_spec()
    with_people = simulate_building_scans(building, poses, times, laser, np.random.default_rng(0))
    without = simulate_building_scans(
        building, poses, times, laser, np.random.default_rng(0), people=False
    )
    # People only occlude: never a longer reading, and hundreds of beams shortened by them.
    assert np.all(with_people <= without)
    blocked = without - with_people > 0.05
    assert blocked.sum() > 200 and blocked.any(axis=1).mean() > 0.05
    # Open space: beams through windows and down long corridors read max range.
    assert 0.01 < float(np.mean(without == laser.max_range)) < 0.3
    # Glass returns some beams and lets others through.
    opaque = cast_rays_segments(poses, laser.beam_angles, building.walls, laser.max_range)
    pane = cast_rays_segments(poses, laser.beam_angles, building.glass, laser.max_range)
    glass_first = pane < opaque - 0.2
    at_glass = np.abs(without - pane) < 0.05
    beyond = np.abs(without - opaque) < 0.05
    assert glass_first.sum() > 1000
    share = float(np.mean(at_glass[glass_first]))
    assert 0.1 < share < 0.9
    assert np.all(at_glass[glass_first] | beyond[glass_first])


def test_the_dataset_carries_scans_odometry_and_truth(small: Dataset) -> None:
    ds = small
    assert ds.counts()["Odometry"] == ds.counts()["LaserScan"]
    truth = ds.truth
    assert truth.poses is not None and truth.walls is not None and ds.laser is not None
    odo = np.array([ev.pose for ev in ds.events if isinstance(ev, Odometry)])
    np.testing.assert_array_equal(odo, truth.poses)  # clean odometry
    assert ds.laser.n_beams == 181 and ds.laser.max_range == 30.0
    scans = [ev.t for ev in ds.events if isinstance(ev, LaserScan)]
    np.testing.assert_array_equal(scans, truth.times)
    assert truth.walls.segments.shape[0] == generate_building(11).static_map.segments.shape[0]


def test_registry_building_has_the_typical_odometry_errors() -> None:
    ds = load_dataset("building", seed=11)
    errors = ds.metadata["odometry_errors"]
    assert 0.01 <= abs(errors["wheel_radius_error"]) <= 0.03
    assert ds.metadata["building_seed"] == 11
    clean = load_dataset("building", seed=11, options={"odometry_errors": False})
    assert clean.metadata["odometry"] == "clean (the true poses)"
    assert corpus_buildings(3) == [0, 1, 2]
