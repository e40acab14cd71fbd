"""Occupancy-grid mapping with known poses: log odds, the inverse model, Bresenham, the two
update paths, the computational options, map quality, the estimator, the app and the command
(the maps of real buildings: tests/mapping/test_building_maps.py)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from slamkit.datasets import LaserScan, LaserSpec, load_dataset
from slamkit.errors import ConfigError, InputError, NonFiniteError, ShapeError
from slamkit.io.rosmap import read_ros_map
from slamkit.mapping import (
    FREE,
    NO_INFORMATION,
    OCCUPIED,
    InverseSensorModel,
    LogOddsGrid,
    OccupancyMapper,
    OccupancyMapping,
    OccupancyMappingConfig,
    bresenham_line,
    bresenham_rays,
    build_occupancy_map,
    clamp_log_odds,
    classify_cells,
    even_odd_agreement,
    expit,
    known_pose_at,
    log_odds_update,
    logit,
    map_agreement,
    map_entropy,
    map_quality,
    nearest_beam,
    occupied_precision_recall,
    polar_table,
    ray_extents,
    scan_cells_cell,
    scan_cells_ray,
    scan_cells_table,
)
from slamkit.mapping.bresenham import MAX_SEGMENT_STEPS, bresenham_segments, minor_steps
from slamkit.mapping.occupancy import check_ranges, data_bounds
from slamkit.mapping.quality import even_odd_maps
from slamkit.maps import UNKNOWN, OccupancyGrid
from slamkit.pipeline.registry import EstimatorEntry
from slamkit.pipeline.runner import run


@pytest.fixture(scope="module")
def rooms():
    """The simulated laser tour with its true occupancy rasterised at 5 cm."""
    return load_dataset("rooms-laser", seed=0)


@pytest.fixture(scope="module")
def rooms_10cm():
    return load_dataset("rooms-laser", seed=0, options={"grid_resolution": 0.1})


# --------------------------------------------------------------------------------------------
# log odds
# --------------------------------------------------------------------------------------------


def test_logit_and_expit_hand_values():
    np.testing.assert_allclose(logit([0.5, 0.75, 0.2]), [0.0, math.log(3.0), -math.log(4.0)])
    np.testing.assert_allclose(expit([0.0, math.log(3.0), -math.log(4.0)]), [0.5, 0.75, 0.2])
    p = np.linspace(0.001, 0.999, 101)
    np.testing.assert_allclose(expit(logit(p)), p, rtol=1e-12)
    # No overflow and the right limits far out; tiny probabilities keep relative precision.
    np.testing.assert_array_equal(expit([-800.0, 800.0]), [0.0, 1.0])
    assert expit(-40.0) == pytest.approx(math.exp(-40.0), rel=1e-12)
    with pytest.raises(InputError, match="strictly between"):
        logit([0.0, 0.5])


def test_log_odds_update_is_the_notes_rule():
    # l_t = logit(p(m|z)) + l_{t-1} - l_0
    assert float(log_odds_update(0.0, 0.75, 0.5)) == pytest.approx(math.log(3.0))
    assert float(log_odds_update(0.0, 0.75, 0.2)) == pytest.approx(math.log(12.0))
    assert float(log_odds_update(1.0, 0.4, 0.5)) == pytest.approx(1.0 + math.log(2.0 / 3.0))
    # The clamp bounds the result.
    assert float(log_odds_update(3.5, 0.9, 0.5, -2.0, 4.0)) == 4.0
    np.testing.assert_array_equal(clamp_log_odds([-9.0, 0.5, 9.0], -2.0, 3.0), [-2.0, 0.5, 3.0])
    with pytest.raises(InputError):
        clamp_log_odds([0.0], 1.0, 1.0)


def test_grid_clamps_repeated_updates():
    model = InverseSensorModel(p_occ=0.9, p_min=0.1, p_max=0.95).resolve(0.1, [0.0], 5.0)
    grid = LogOddsGrid(0.1, 0, 0, 2, 2)
    cells = np.array([0, 3])
    for _ in range(50):
        grid.apply(cells, np.array([model.delta_occ, model.delta_free]), model)
    flat = grid.log_odds.reshape(-1)
    assert flat[0] == pytest.approx(logit(0.95), rel=1e-6)
    assert flat[3] == pytest.approx(logit(0.1), rel=1e-6)
    np.testing.assert_allclose(grid.probabilities().reshape(-1)[[0, 1, 3]], [0.95, 0.5, 0.1])


def test_model_config_is_validated():
    for bad in ({"p_occ": 0.4}, {"p_free": 0.6}, {"alpha": -1.0}, {"p_max": 0.4}):
        with pytest.raises(ConfigError):
            InverseSensorModel(**bad)
    with pytest.raises(ConfigError, match="precompute"):
        OccupancyMappingConfig(precompute=True)
    with pytest.raises(ConfigError, match="beam_stride"):
        OccupancyMappingConfig(beam_stride=0)
    with pytest.raises(InputError, match="increasing"):
        InverseSensorModel().resolve(0.1, [0.2, 0.1], 5.0)


# --------------------------------------------------------------------------------------------
# Bresenham
# --------------------------------------------------------------------------------------------

# (row, col) from (0, 0); worked by hand from the exact line, rounding the minor coordinate
# to the nearest cell (a half away from the start).
OCTANTS = {
    (2, 5): [(0, 0), (0, 1), (1, 2), (1, 3), (2, 4), (2, 5)],
    (-2, 5): [(0, 0), (0, 1), (-1, 2), (-1, 3), (-2, 4), (-2, 5)],
    (2, -5): [(0, 0), (0, -1), (1, -2), (1, -3), (2, -4), (2, -5)],
    (-2, -5): [(0, 0), (0, -1), (-1, -2), (-1, -3), (-2, -4), (-2, -5)],
    (5, 2): [(0, 0), (1, 0), (2, 1), (3, 1), (4, 2), (5, 2)],
    (5, -2): [(0, 0), (1, 0), (2, -1), (3, -1), (4, -2), (5, -2)],
    (-5, 2): [(0, 0), (-1, 0), (-2, 1), (-3, 1), (-4, 2), (-5, 2)],
    (-5, -2): [(0, 0), (-1, 0), (-2, -1), (-3, -1), (-4, -2), (-5, -2)],
    (3, 7): [(0, 0), (0, 1), (1, 2), (1, 3), (2, 4), (2, 5), (3, 6), (3, 7)],
    (1, 2): [(0, 0), (1, 1), (1, 2)],  # the tie at col 1 (row 0.5) goes away from the start
    (3, 3): [(0, 0), (1, 1), (2, 2), (3, 3)],
    (-3, 3): [(0, 0), (-1, 1), (-2, 2), (-3, 3)],
    (4, 0): [(0, 0), (1, 0), (2, 0), (3, 0), (4, 0)],
    (-4, 0): [(0, 0), (-1, 0), (-2, 0), (-3, 0), (-4, 0)],
    (0, 3): [(0, 0), (0, 1), (0, 2), (0, 3)],
    (0, -3): [(0, 0), (0, -1), (0, -2), (0, -3)],
    (0, 0): [(0, 0)],
}


@pytest.mark.parametrize("end", list(OCTANTS))
def test_bresenham_hand_worked_lines(end):
    expected = np.array(OCTANTS[end])
    np.testing.assert_array_equal(bresenham_line(0, 0, *end), expected)
    np.testing.assert_array_equal(bresenham_rays([[0, 0]], [list(end)]).cells, expected)
    # Shifting the start shifts the cells.
    shifted = expected + np.array([7, -3])
    np.testing.assert_array_equal(bresenham_line(7, -3, end[0] + 7, end[1] - 3), shifted)


def test_bresenham_vectorised_equals_incremental_on_random_lines(rng):
    starts = rng.integers(-60, 60, size=(400, 2))
    ends = rng.integers(-60, 60, size=(400, 2))
    rays = bresenham_rays(starts, ends)
    expected = [bresenham_line(*a, *b) for a, b in zip(starts, ends, strict=True)]
    np.testing.assert_array_equal(rays.cells, np.concatenate(expected))
    np.testing.assert_array_equal(rays.n_steps + 1, [len(e) for e in expected])
    np.testing.assert_array_equal(rays.ray, np.repeat(np.arange(400), rays.n_steps + 1))
    # Every step moves to an 8-neighbour and the end cells are included.
    for e, a, b in zip(expected[:60], starts[:60], ends[:60], strict=True):
        assert np.all(np.abs(np.diff(e, axis=0)).max(axis=1) == 1) or len(e) == 1
        np.testing.assert_array_equal(e[0], a)
        np.testing.assert_array_equal(e[-1], b)
    # One start for all rays (a scan) takes a faster path with the same answer.
    shared = np.broadcast_to(starts[0], ends.shape)
    expected = [bresenham_line(*starts[0], *b) for b in ends]
    np.testing.assert_array_equal(bresenham_rays(shared, ends).cells, np.concatenate(expected))


def test_bresenham_segments_equal_the_incremental_lines(rng):
    # Runs of consecutive steps of random lines, as flat indices of a 500-column grid.
    n_cols = 500
    starts = rng.integers(-60, 60, size=(300, 2))
    ends = rng.integers(-60, 60, size=(300, 2))
    lines = [bresenham_line(*a, *b) for a, b in zip(starts, ends, strict=True)]
    d_row, d_col = (ends - starts).T
    col_major = np.abs(d_col) >= np.abs(d_row)
    n = np.maximum(np.abs(d_row), np.abs(d_col))
    slope = np.minimum(np.abs(d_row), np.abs(d_col)) / np.maximum(n, 1)
    major = np.where(col_major, np.sign(d_col), np.sign(d_row) * n_cols)
    minor = np.where(col_major, np.sign(d_row) * n_cols, np.sign(d_col))
    first = (rng.random(300) * (n + 1)).astype(np.int64)
    lengths = (rng.random(300) * (n - first + 2)).astype(np.int64)  # 0 .. to the end cell
    got = bresenham_segments(
        lengths, first.astype(float), slope, major.astype(float), minor.astype(float),
        (starts[:, 0] * n_cols + starts[:, 1]).astype(float),
    )  # fmt: skip
    expected = np.concatenate(
        [
            line[f : f + k, 0] * n_cols + line[f : f + k, 1]
            for line, f, k in zip(lines, first, lengths, strict=True)
        ]
    )
    np.testing.assert_array_equal(got, expected)
    assert bresenham_segments(np.zeros(3, dtype=np.int64), *np.zeros((5, 3))).size == 0


def test_minor_steps_are_exact_up_to_the_longest_ray(rng):
    # q_i = floor((2 i m + n) / (2 n)) in integers against the floating-point form, over
    # random rays up to MAX_SEGMENT_STEPS - 1 steps and on exact halves (the ties).
    n = rng.integers(1, MAX_SEGMENT_STEPS, size=200_000)
    m = (rng.random(n.size) * (n + 1)).astype(np.int64)
    i = (rng.random(n.size) * (n + 1)).astype(np.int64)
    half = n - n % 2  # m = n/2 and odd i: (2 i m + n) / (2 n) = (i + 1) / 2 exactly
    n = np.concatenate([n, half, [MAX_SEGMENT_STEPS - 1] * 3])
    m = np.concatenate([m, half // 2, [MAX_SEGMENT_STEPS - 1, 1, MAX_SEGMENT_STEPS - 2]])
    i = np.concatenate([i, (i // 2) * 2 + 1, [MAX_SEGMENT_STEPS - 1] * 3])
    i = np.minimum(i, n)
    expected = (2 * i * m + n) // (2 * n)
    np.testing.assert_array_equal(minor_steps(i.astype(float), m / n), expected)


def test_range_grows_along_a_bresenham_ray(rng):
    """What the block path relies on: along a Bresenham ray from the sensor's cell, the squared
    range of the cell centres from the sensor grows by at least 2 i cells² at step i -> i + 1,
    wherever the sensor sits in its cell."""
    for _ in range(400):
        sensor = rng.random(2) - 0.5  # offset of the start cell's centre, in cells
        end = rng.integers(-150, 151, size=2)
        cells = bresenham_line(0, 0, *end).astype(float)
        r2 = np.sum((cells - sensor) ** 2, axis=1)
        i = np.arange(r2.size - 1)
        assert np.all(np.diff(r2) >= 2 * i - 1e-9)


# --------------------------------------------------------------------------------------------
# the inverse sensor model
# --------------------------------------------------------------------------------------------


def _hand_model():
    # Three beams at -10°, 0°, +10°; 0.2 m obstacles; 10° beams; 5 m usable range.
    beams = np.deg2rad([-10.0, 0.0, 10.0])
    model = InverseSensorModel(alpha=0.2, beta=np.deg2rad(10.0), max_range=5.0).resolve(
        0.05, beams, 8.0
    )
    return beams, np.array([2.0, 3.0, 8.0]), model  # beam +10° reads max range: no return


@pytest.mark.parametrize(
    ("r", "phi_deg", "region"),
    [
        (1.0, 0.0, FREE),  # in front of the return
        (2.89, 0.0, FREE),  # just before r_k - alpha/2 = 2.9
        (2.95, 0.0, OCCUPIED),  # |r - r_k| < alpha/2
        (3.0, 2.0, OCCUPIED),
        (3.08, 0.0, OCCUPIED),  # beyond r_k but within alpha/2: the errata's correction
        (3.15, 0.0, NO_INFORMATION),  # beyond r_k + alpha/2
        (1.85, -10.0, FREE),
        (2.05, -12.0, OCCUPIED),
        (3.0, 6.0, FREE),  # nearest beam +10° (no return): clears up to r_max
        (4.96, 10.0, FREE),  # a max-range reading marks nothing occupied
        (5.01, 10.0, NO_INFORMATION),  # beyond the usable range
        (1.0, 16.0, NO_INFORMATION),  # more than beta/2 from the nearest beam
        (1.0, -90.0, NO_INFORMATION),
    ],
)
def test_inverse_model_three_regions_on_a_hand_scan(r, phi_deg, region):
    beams, ranges, model = _hand_model()
    got = classify_cells(np.array([r]), np.deg2rad([phi_deg]), ranges, beams, model)
    assert int(got[0]) == region


def test_ray_extents_and_resolved_numbers():
    model = _hand_model()[2]
    assert model.r_max == 5.0 and model.alpha == 0.2
    assert model.delta_occ == pytest.approx(math.log(3.0))  # p_occ 0.75, prior 0.5
    assert model.delta_free == pytest.approx(math.log(0.45 / 0.55))
    d_occ, d_end = ray_extents(np.array([2.0, 4.95, 8.0, 0.05]), model)
    np.testing.assert_allclose(d_occ, [1.9, 4.85, 5.0, 0.0])
    np.testing.assert_allclose(d_end, [2.1, 5.0, 5.0, 0.15])
    # Defaults: alpha = one cell, beta = the beam spacing, r_max = the sensor's.
    default = InverseSensorModel().resolve(0.05, np.deg2rad([0.0, 1.0, 2.0]), 12.0)
    assert (default.alpha, default.r_max) == (0.05, 12.0)
    assert default.beta == pytest.approx(np.deg2rad(1.0))


def test_nearest_beam_wraps_on_a_full_circle_and_matches_the_general_path():
    beams = -np.pi + 2 * np.pi * np.arange(8) / 8  # 45° apart, -180° .. 135°
    k, d = nearest_beam(np.array([np.pi - 0.1, -np.pi + 0.1, 3.0 * np.pi / 4 + 0.3]), beams)
    np.testing.assert_array_equal(k, [0, 0, 7])
    np.testing.assert_allclose(d, [0.1, 0.1, 0.3])
    fan = np.deg2rad(np.arange(-90.0, 90.0))  # 180 beams, -90° .. 89°
    uneven = fan + np.r_[0.0, np.full(179, 1e-7)]  # forces the searchsorted path
    phi = np.linspace(-np.pi, np.pi, 2001)
    k1, d1 = nearest_beam(phi, fan)
    k2, d2 = nearest_beam(phi, uneven)
    np.testing.assert_array_equal(k1, k2)
    np.testing.assert_allclose(d1, d2, atol=1e-6)
    # Behind the sensor the nearer end beam is the nearest.
    k3, _ = nearest_beam(np.deg2rad([100.0, -100.0, 179.0]), fan)
    np.testing.assert_array_equal(k3, [179, 0, 179])


# --------------------------------------------------------------------------------------------
# the two update paths
# --------------------------------------------------------------------------------------------


def _classes(cells: np.ndarray, regions: np.ndarray) -> dict[tuple[int, int], int]:
    out: dict[tuple[int, int], int] = {}
    for (r, c), g in zip(map(tuple, cells.tolist()), regions.tolist(), strict=True):
        out[(r, c)] = max(out.get((r, c), 0), g)
    return out


def test_ray_and_cell_paths_agree_on_simulated_scans(rooms):
    """Agreement, defined: (1) of the cells the Bresenham path touches (merged per scan, occupied
    winning), the per-cell path puts at least 97 % in the same region; (2) within the range
    where neighbouring rays are at most one cell apart (res / beam spacing = 2.86 m), the rays
    reach at least 92 % (95 % on average) of the cells the per-cell path updates (beyond that
    the per-cell model's beam width fills the gaps between diverging rays, which single-cell
    rays cannot)."""
    res = 0.05
    beams = rooms.laser.beam_angles
    model = InverseSensorModel().resolve(res, beams, rooms.laser.max_range)
    scans = [ev for ev in rooms.events if isinstance(ev, LaserScan)]
    dense = res / (beams[1] - beams[0])
    coverage = []
    # Every 25th scan of the tour (21 scans). Measured (seed 0): same 0.978-0.999, covered
    # 0.936-0.979 with mean 0.961.
    for k in range(0, len(scans), 25):
        pose = known_pose_at(rooms.truth.times, rooms.truth.poses, scans[k].t)
        ray_cells, ray_regions, _ = scan_cells_ray(pose, scans[k].ranges, beams, model, res)
        cell_cells, cell_regions = scan_cells_cell(pose, scans[k].ranges, beams, model, res)
        a, b = _classes(ray_cells, ray_regions), _classes(cell_cells, cell_regions)
        same = sum(b.get(x, NO_INFORMATION) == g for x, g in a.items()) / len(a)
        near = [
            x
            for x in b
            if math.hypot((x[1] + 0.5) * res - pose[0], (x[0] + 0.5) * res - pose[1]) <= dense
        ]
        covered = sum(x in a for x in near) / len(near)
        assert same >= 0.97, (k, same)
        assert covered >= 0.92, (k, covered)
        assert len(b) > len(a)  # the beam width reaches cells between the rays
        coverage.append(covered)
    assert np.mean(coverage) >= 0.95


def test_ray_and_cell_maps_agree_over_the_whole_tour(rooms):
    ray = build_occupancy_map(rooms, OccupancyMappingConfig(method="ray"))
    cell = build_occupancy_map(rooms, OccupancyMappingConfig(method="cell"), bounds=ray.bounds)
    agree = map_agreement(ray.grid, cell.grid)
    assert agree["agreement"] >= 0.995  # measured 0.9986
    assert agree["occupied_agreement"] >= 0.9  # measured 0.958
    # Both know ≥ 90 % of the 20 m × 12 m floor at 5 cm (96,000 cells); measured 97,129.
    assert agree["both_known"] > 0.9 * (20 * 12) / 0.05**2


def test_precomputed_model_matches_the_exact_per_cell_model(rooms):
    res = 0.05
    beams = rooms.laser.beam_angles
    model = InverseSensorModel().resolve(res, beams, rooms.laser.max_range)
    table = polar_table(res, model.r_max + model.alpha)
    assert polar_table(res, model.r_max + model.alpha) is table  # cached
    scans = [ev for ev in rooms.events if isinstance(ev, LaserScan)]
    for k in (50, 250):
        pose = known_pose_at(rooms.truth.times, rooms.truth.poses, scans[k].t)
        exact = _classes(*scan_cells_cell(pose, scans[k].ranges, beams, model, res))
        cached = _classes(*scan_cells_table(table, pose, scans[k].ranges, beams, model))
        keys = set(exact) | set(cached)
        same = sum(exact.get(x, 0) == cached.get(x, 0) for x in keys) / len(keys)
        assert same >= 0.95, same  # the sensor snapped to its cell centre moves ≤ 3.5 cm


def test_per_reading_merge_counts_every_ray():
    # Five rays through the same cells: per scan one free update each, per reading five.
    beams = np.deg2rad(np.linspace(-0.4, 0.4, 5))
    cfg_scan = OccupancyMappingConfig(resolution=0.1, bounds="grow")
    cfg_read = OccupancyMappingConfig(resolution=0.1, bounds="grow", merge="per-reading")
    from slamkit.datasets import LaserSpec

    laser = LaserSpec(beams, 10.0)
    pose = np.array([0.05, 0.05, 0.0])
    ranges = np.full(5, 2.0)
    per_scan, per_reading = OccupancyMapper(laser, cfg_scan), OccupancyMapper(laser, cfg_read)
    per_scan.integrate(pose, ranges)
    per_reading.integrate(pose, ranges)
    d_free = per_scan.model.delta_free
    g1, g2 = per_scan.occupancy_grid(), per_reading.occupancy_grid()
    cell = g1.world_to_cell([0.55, 0.05])
    assert g1.prob[tuple(cell)] == pytest.approx(expit(d_free))
    assert g2.prob[tuple(g2.world_to_cell([0.55, 0.05]))] == pytest.approx(expit(5 * d_free))
    hit = g1.world_to_cell([2.05, 0.05])
    assert g1.prob[tuple(hit)] == pytest.approx(0.75)


def test_apply_free_occupied_hand_case():
    model = InverseSensorModel(p_min=0.1, p_max=0.95).resolve(0.1, [0.0], 5.0)
    grid = LogOddsGrid(0.1, 0, 0, 3, 4)
    # free cells 1, 5, 1, 6, 5; occupied 2, 6, 6: four distinct cells, and cell 6, free and
    # occupied in the same scan, gets the occupied increment once
    flat = np.array([1, 5, 1, 6, 5, 2, 6, 6])
    assert grid.apply_free_occupied(flat, 5, model) == 4
    expected = np.zeros(12, dtype=np.float32)
    expected[[1, 5]] = np.float32(model.delta_free)
    expected[[2, 6]] = np.float32(model.delta_occ)
    np.testing.assert_array_equal(grid.log_odds.reshape(-1), expected)
    for _ in range(40):  # clamped at logit(p_min) and logit(p_max)
        grid.apply_free_occupied(flat, 5, model)
    np.testing.assert_allclose(
        grid.probabilities().reshape(-1)[[0, 1, 2, 5, 6]], [0.5, 0.1, 0.95, 0.1, 0.95]
    )
    assert grid.nbytes == grid.log_odds.nbytes  # the counting needs no scratch array


def test_probabilities_in_blocks_equal_expit(rng):
    grid = LogOddsGrid(0.1, -3, 7, 300, 700, 0.2)  # 210,000 cells: more than one block
    grid.log_odds = rng.normal(0.0, 2.0, size=grid.shape).astype(np.float32)
    np.testing.assert_array_equal(grid.probabilities(), expit(grid.log_odds))


def _per_scan_reference(dataset, cfg, bounds, scans):
    """The Bresenham model scan by scan, from public pieces only: scan_cells_ray, one merged
    region per cell and scan (occupied wins), then l <- clamp(l + delta) in float32."""
    laser = dataset.laser
    beams = laser.beam_angles[:: cfg.beam_stride]
    model = cfg.model.resolve(cfg.resolution, beams, laser.max_range)
    m = cfg.margin
    grid = LogOddsGrid.covering(
        bounds[0] - m, bounds[1] - m, bounds[2] + m, bounds[3] + m, cfg.resolution, model.l0
    )
    events = [ev for ev in dataset.events if isinstance(ev, LaserScan)]
    values = grid.log_odds.reshape(-1)
    increment = np.array([0.0, model.delta_free, model.delta_occ], dtype=np.float32)
    count = 0
    for k in scans:
        pose = known_pose_at(dataset.truth.times, dataset.truth.poses, events[k].t)
        cells, regions, _ = scan_cells_ray(
            pose, events[k].ranges[:: cfg.beam_stride], beams, model, cfg.resolution
        )
        flat, inside = grid.flat_index(cells)
        assert np.all(inside)
        order = np.lexsort((regions, flat))  # by cell, the largest region last
        flat, regions = flat[order], regions[order]
        last = np.r_[flat[1:] != flat[:-1], True]
        cell, region = flat[last], regions[last]
        new = values[cell] + increment[region]
        values[cell] = np.clip(new, np.float32(model.l_min), np.float32(model.l_max))
        count += cell.size
    return grid, count


@pytest.mark.parametrize(
    "kwargs",
    [
        {},  # 5 cm, the default model
        {"resolution": 0.1, "beam_stride": 3},
        {"model": InverseSensorModel(alpha=0.4, max_range=6.0)},  # thick walls: long tails
        {"model": InverseSensorModel(max_range=3.0)},  # mostly max-range readings
        {"resolution": 0.1, "model": InverseSensorModel(p_prior=0.3, p_occ=0.8, p_free=0.2)},
    ],
)
def test_block_path_equals_the_per_scan_model_exactly(rooms, kwargs):
    cfg = OccupancyMappingConfig(**kwargs)
    scans = range(0, 522, 7)
    fast = build_occupancy_map(rooms, cfg, scans=list(scans))
    ref, count = _per_scan_reference(rooms, cfg, fast.bounds, scans)
    assert (fast.log_odds.row0, fast.log_odds.col0) == (ref.row0, ref.col0)
    np.testing.assert_array_equal(fast.log_odds.log_odds, ref.log_odds)
    assert fast.stats.cell_updates == count


@pytest.mark.parametrize("kwargs", [{}, {"model": InverseSensorModel(alpha=0.4, max_range=6.0)}])
def test_block_path_without_the_tail_shortcut(rooms, kwargs, monkeypatch):
    """With no margin on the tail, nearly every ray's free run is found by testing every
    step (the exhaustive branch, normally never needed): the same exact map."""
    import slamkit.mapping.occupancy.rays as rays

    monkeypatch.setattr(rays, "TAIL_MARGIN", 0)
    cfg = OccupancyMappingConfig(**kwargs)
    scans = range(3, 522, 11)
    fast = build_occupancy_map(rooms, cfg, scans=list(scans))
    ref, count = _per_scan_reference(rooms, cfg, fast.bounds, scans)
    np.testing.assert_array_equal(fast.log_odds.log_odds, ref.log_odds)
    assert fast.stats.cell_updates == count


def _stats(mapper):
    out = mapper.stats.as_dict()
    out.pop("seconds"), out.pop("cell_updates_per_second")
    return out


@pytest.mark.parametrize(
    ("kwargs", "bounds"),
    [
        ({"scan_stride": 2, "min_travel": 0.3, "min_rotation_deg": 10.0}, None),
        ({"bounds": "grow", "margin": 0.1}, None),  # grows in the middle of blocks
        ({"margin": 0.0}, (2.0, 2.0, 12.0, 8.0)),  # fixed bounds cut many scans
    ],
)
def test_offer_many_equals_offer_scan_by_scan(rooms, kwargs, bounds):
    cfg = OccupancyMappingConfig(resolution=0.1, **kwargs)
    scans = [ev for ev in rooms.events if isinstance(ev, LaserScan)]
    poses = known_pose_at(rooms.truth.times, rooms.truth.poses, [ev.t for ev in scans])
    ranges = np.stack([ev.ranges for ev in scans])
    one, many = OccupancyMapper(rooms.laser, cfg, bounds), OccupancyMapper(rooms.laser, cfg, bounds)
    used_one = [one.offer(p, r) for p, r in zip(poses, ranges, strict=True)]
    used_many = np.concatenate(
        [many.offer_many(poses[k : k + 50], ranges[k : k + 50]) for k in range(0, len(scans), 50)]
    )
    np.testing.assert_array_equal(used_many, used_one)
    a, b = one.log_odds_grid(), many.log_odds_grid()
    assert (a.row0, a.col0) == (b.row0, b.col0)
    np.testing.assert_array_equal(a.log_odds, b.log_odds)
    assert _stats(one) == _stats(many)
    if bounds is not None:  # the cut scans were mapped too, up to the edge
        assert one.stats.cell_updates > 0 and a.shape == (61, 101)


def test_too_long_rays_take_the_general_path(rooms, monkeypatch):
    import slamkit.mapping.occupancy.rays as rays

    cfg = OccupancyMappingConfig(resolution=0.1)
    fast = build_occupancy_map(rooms, cfg, scans=slice(0, 100))
    monkeypatch.setattr(rays, "MAX_SEGMENT_STEPS", 20)  # most rays now count as too long
    general = build_occupancy_map(rooms, cfg, scans=slice(0, 100))
    np.testing.assert_array_equal(general.log_odds.log_odds, fast.log_odds.log_odds)
    assert general.stats.cell_updates == fast.stats.cell_updates


# --------------------------------------------------------------------------------------------
# whole maps: the simulated rooms
# --------------------------------------------------------------------------------------------


def test_simulated_rooms_walls_recovered_at_10cm(rooms_10cm):
    """Precision and recall of occupied cells against the rasterised walls, with a one-cell
    tolerance band. Why a band: the walls lie at whole metres, i.e. exactly on cell
    boundaries, so the rasteriser puts a wall in the cell on one side while returns from the
    other side land in the cell on that side; and the simulated range noise (σ = 3 cm) plus the
    obstacle thickness (alpha/2 = 5 cm) spread returns by up to about one cell."""
    res = build_occupancy_map(rooms_10cm, OccupancyMappingConfig(resolution=0.1))
    pr = occupied_precision_recall(res.grid, rooms_10cm.truth.occupancy, tolerance_cells=1)
    assert pr["precision"] >= 0.99  # measured 0.9995
    assert pr["recall"] >= 0.98  # measured 0.991
    exact = occupied_precision_recall(res.grid, rooms_10cm.truth.occupancy, tolerance_cells=0)
    assert exact["precision"] < 0.6  # without the band half the wall cells are "wrong"


def test_simulated_rooms_walls_recovered_at_5cm(rooms):
    """At 5 cm the same 10 cm band is two cells: precision and recall ≥ 0.95 with
    ``tolerance_cells=2`` (one cell is not enough: 3 cm noise is 0.6 cells)."""
    res = build_occupancy_map(rooms, OccupancyMappingConfig(resolution=0.05))
    pr = occupied_precision_recall(res.grid, rooms.truth.occupancy, tolerance_cells=2)
    assert pr["precision"] >= 0.99  # measured 0.9992
    assert pr["recall"] >= 0.98  # measured 0.989
    q = map_quality(res.grid)
    # Walls: ~90 m of wall (outer, corridor, rooms, pillars) about 2 cells thick over a
    # ~22 m × 14 m grid; measured 0.038.
    assert 0.01 < q.occupied_fraction < 0.06
    assert q.free_fraction > 0.3


def test_grow_mode_builds_the_same_map(rooms):
    cfg = OccupancyMappingConfig(resolution=0.1)
    fixed = build_occupancy_map(rooms, cfg)
    grown = build_occupancy_map(rooms, OccupancyMappingConfig(resolution=0.1, bounds="grow"))
    assert grown.stats.grid_growths > 0
    agree = map_agreement(fixed.grid, grown.grid)
    assert agree["agreement"] == 1.0
    # Same lattice: the common cells hold identical probabilities.
    a, b = fixed.grid, grown.grid
    off = np.round((b.origin_xy - a.origin_xy) / 0.1).astype(int)
    r0, c0 = max(0, off[1]), max(0, off[0])
    r1 = min(a.shape[0], off[1] + b.shape[0])
    c1 = min(a.shape[1], off[0] + b.shape[1])
    np.testing.assert_array_equal(
        a.prob[r0:r1, c0:c1], b.prob[r0 - off[1] : r1 - off[1], c0 - off[0] : c1 - off[0]]
    )


def test_subsampling_and_selective_updating(rooms):
    base = build_occupancy_map(rooms, OccupancyMappingConfig(resolution=0.1))
    n = base.stats.scans_used
    strided = build_occupancy_map(rooms, OccupancyMappingConfig(resolution=0.1, scan_stride=3))
    assert strided.stats.scans_used == -(-n // 3)
    assert strided.stats.scans_skipped_stride == n - strided.stats.scans_used
    beams = build_occupancy_map(rooms, OccupancyMappingConfig(resolution=0.1, beam_stride=4))
    assert beams.stats.readings_used == n * 46  # 181 beams -> every 4th: 46
    moved = build_occupancy_map(
        rooms, OccupancyMappingConfig(resolution=0.1, min_travel=0.5, min_rotation_deg=20.0)
    )
    assert 0 < moved.stats.scans_used < n / 2
    assert moved.stats.scans_skipped_motion == n - moved.stats.scans_used
    # Cell-level selective updating skips writes that would not change a cell: far fewer
    # writes, nearly the same map.
    sel = build_occupancy_map(rooms, OccupancyMappingConfig(resolution=0.1, min_change=0.01))
    assert sel.stats.cell_updates < 0.6 * base.stats.cell_updates
    assert map_agreement(base.grid, sel.grid)["agreement"] >= 0.99
    for r in (strided, beams, moved):
        assert map_agreement(base.grid, r.grid)["agreement"] >= 0.97


def test_known_pose_lookup():
    times = np.array([0.0, 1.0, 3.0])
    poses = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 0.0, -np.pi + 0.1], [2.0, 4.0, 0.0]])
    np.testing.assert_allclose(known_pose_at(times, poses, 1.0), poses[1])
    mid = known_pose_at(times, poses, 0.5)  # the heading crosses ±π the short way
    np.testing.assert_allclose(mid[:2], [1.0, 0.0])
    assert abs(abs(mid[2]) - np.pi) < 1e-12
    np.testing.assert_allclose(known_pose_at(times, poses, 2.0), [2.0, 2.0, (-np.pi + 0.1) / 2])
    with pytest.raises(InputError, match="outside"):
        known_pose_at(times, poses, 3.5)


# --------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------


def _mapper(beam_stride: int = 1) -> OccupancyMapper:
    laser = LaserSpec(np.linspace(-np.pi / 2, np.pi / 2, 181), 30.0)
    return OccupancyMapper(laser, OccupancyMappingConfig(resolution=0.1, beam_stride=beam_stride))


def test_nan_and_negative_ranges_are_rejected_before_anything_is_mapped():
    """An all-NaN scan once gave 34,837 cell updates (NaN compared like a max-range reading);
    now it, a negative reading, an infinite one and a wrong beam count raise typed errors that
    name the scan and the beam, and the mapper counts and writes nothing."""
    mapper = _mapper(beam_stride=2)
    ok = np.full(181, 5.0)
    with pytest.raises(NonFiniteError, match=r"scan 0, beam 0: expected a finite range >= 0"):
        mapper.offer(np.zeros(3), np.full(181, np.nan))
    bad = np.stack([ok, ok, ok])
    bad[2, 7] = -0.5
    with pytest.raises(InputError, match=r"scan 2, beam 7: .* got -0\.5") as err:
        mapper.offer_many(np.zeros((3, 3)), bad)
    assert not isinstance(err.value, NonFiniteError)
    with pytest.raises(NonFiniteError, match=r"scan 0, beam 90: .* got inf"):
        mapper.integrate(np.zeros(3), np.where(np.arange(181) == 90, np.inf, ok))
    # 182 readings leave 91 after the stride, as 181 do: the count is checked before it
    with pytest.raises(ShapeError, match=r"expected 181 ranges \(the laser's beams\), got 182"):
        mapper.integrate(np.zeros(3), np.full(182, 5.0))
    assert mapper.grid is None
    stats = mapper.stats
    assert stats.scans_seen == stats.scans_used == stats.cell_updates == 0
    # after two good scans the next bad one is numbered in the order offered
    mapper.offer_many(np.zeros((2, 3)), np.stack([ok, ok]))
    with pytest.raises(NonFiniteError, match=r"scan 2, beam 3"):
        mapper.offer(np.zeros(3), np.where(np.arange(181) == 3, np.nan, ok))
    assert mapper.stats.scans_seen == 2


def test_check_ranges_names_scan_time_and_beam():
    R = np.ones((4, 5))
    assert check_ranges(R) is R  # a good float64 array passes through, uncopied
    R[3, 1] = np.nan
    with pytest.raises(NonFiniteError, match=r"scan 13 \(t=2\.500000 s\), beam 1: .* got nan"):
        check_ranges(R, first_scan=10, times=[1.0, 1.5, 2.0, 2.5])
    with pytest.raises(ShapeError, match="expected"):
        check_ranges(np.ones((2, 2, 2)))
    for fn in (scan_cells_ray, scan_cells_cell):  # the one-scan paths check too
        with pytest.raises(InputError, match="beam 1"):
            fn(np.zeros(3), [1.0, -1.0], [0.0, 0.1], _mapper().model, 0.1)


def test_build_rejects_a_negative_reading_in_a_data_set(rooms):
    """A negative range names the data set's scan and its time (or, if the data set checks
    its stream itself, the event)."""

    events = list(rooms.events)
    scan_events = [i for i, ev in enumerate(events) if isinstance(ev, LaserScan)]
    i = scan_events[3]
    ranges = events[i].ranges.copy()  # type: ignore[union-attr]
    ranges[7] = -0.25
    events[i] = LaserScan(events[i].t, ranges)
    t = events[i].t
    with pytest.raises(InputError, match=rf"scan 3 \(t={t:.6f} s\), beam 7|event {i} \("):
        build_occupancy_map(dataclasses.replace(rooms, events=tuple(events)))


# --------------------------------------------------------------------------------------------
# quality numbers
# --------------------------------------------------------------------------------------------


def test_quality_numbers_on_a_hand_grid():
    grid = OccupancyGrid(np.array([[0.0, 1.0], [UNKNOWN, UNKNOWN], [0.1, 0.9]]), 0.5)
    q = map_quality(grid)
    assert (q.occupied_fraction, q.free_fraction, q.unknown_fraction) == (2 / 6, 2 / 6, 2 / 6)
    h = -(0.1 * math.log2(0.1) + 0.9 * math.log2(0.9))
    assert map_entropy(grid) == pytest.approx(2.0 + 2 * h)
    assert q.area_known_m2 == pytest.approx(4 * 0.25)


def test_map_agreement_on_shifted_grids():
    a = OccupancyGrid(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, UNKNOWN]]), 1.0, np.zeros(2))
    b = OccupancyGrid(np.array([[1.0, 1.0], [0.0, 0.0]]), 1.0, np.array([1.0, 0.0]))
    # b's cells are a's columns 1..2: a = [1, 0 | 0, ?], b = [1, 1 | 0, 0]
    out = map_agreement(a, b)
    assert out["both_known"] == 3
    assert out["agreement"] == pytest.approx(2 / 3)
    assert out["occupied_agreement"] == pytest.approx(1 / 2)
    with pytest.raises(InputError, match="line up"):
        map_agreement(a, OccupancyGrid(np.zeros((2, 2)), 1.0, np.array([0.5, 0.0])))


def test_even_odd_maps_share_one_grid_and_the_even_map_is_the_stride_2_map(rooms_10cm):
    cfg = OccupancyMappingConfig(resolution=0.1)
    even, odd = even_odd_maps(rooms_10cm, cfg)
    assert even.grid.shape == odd.grid.shape and even.bounds == odd.bounds
    assert even.bounds == data_bounds(rooms_10cm, cfg)
    n_scans = sum(isinstance(ev, LaserScan) for ev in rooms_10cm.events)
    assert (even.stats.scans_used, odd.stats.scans_used) == ((n_scans + 1) // 2, n_scans // 2)
    strided = build_occupancy_map(
        rooms_10cm, dataclasses.replace(cfg, scan_stride=2), bounds=even.bounds
    )
    np.testing.assert_array_equal(strided.grid.prob, even.grid.prob)
    agree = even_odd_agreement(rooms_10cm, cfg, bounds=even.bounds)
    assert agree == {
        **map_agreement(even.grid, odd.grid),
        "scans_even": even.stats.scans_used,
        "scans_odd": odd.stats.scans_used,
    }
    assert agree["agreement"] >= 0.98


def test_precision_recall_hand_case():
    truth = OccupancyGrid(np.zeros((5, 5)), 1.0)
    truth.prob[2, :] = 1.0  # a wall along row 2
    prob = np.full((5, 5), 0.2)
    prob[3, 0:4] = 0.9  # mapped one row off, four of five cells …
    prob[0, 4] = 0.9  # … and one stray cell
    grid = OccupancyGrid(prob, 1.0)
    strict = occupied_precision_recall(grid, truth, tolerance_cells=0)
    assert strict["precision"] == 0.0 and strict["recall"] == 0.0
    band = occupied_precision_recall(grid, truth, tolerance_cells=1)
    assert band["precision"] == pytest.approx(4 / 5)
    assert band["recall"] == pytest.approx(5 / 5)  # cell (2, 4) has (3, 3) as a neighbour


# --------------------------------------------------------------------------------------------
# the estimator, the app, the command
# --------------------------------------------------------------------------------------------

ENTRY = EstimatorEntry(
    "occupancy-mapping",
    "occupancy grid from known poses",
    "slamkit.mapping.occupancy:OccupancyMapping",
    "slamkit.mapping.occupancy:OccupancyMappingConfig",
    requires=("laser",),
    known_poses=True,
)


def test_estimator_reports_known_poses_and_returns_the_map(rooms):
    result = run(ENTRY, rooms, config={"resolution": 0.1, "bounds": "grow"}, seed=1)
    truth = rooms.truth
    np.testing.assert_allclose(result.poses, known_pose_at(truth.times, truth.poses, result.times))
    grid = result.output.grid
    assert grid is not None
    direct = build_occupancy_map(rooms, OccupancyMappingConfig(resolution=0.1, bounds="grow"))
    np.testing.assert_array_equal(grid.prob, direct.grid.prob)
    np.testing.assert_array_equal(grid.origin_xy, direct.grid.origin_xy)
    diag = result.output.diagnostics["mapping"]
    n_scans = sum(isinstance(ev, LaserScan) for ev in rooms.events)
    assert diag["scans_used"] == n_scans and diag["pose_source"] == "truth"
    json.dumps(result.output.diagnostics)  # JSON-able


def test_estimator_needs_truth_or_odometry(rooms):
    from slamkit.datasets import GroundTruth

    blind = dataclasses.replace(rooms, truth=GroundTruth())
    with pytest.raises(InputError, match="true trajectory"):
        OccupancyMapping(blind, OccupancyMappingConfig(), np.random.default_rng(0))
    with pytest.raises(InputError, match="no odometry"):
        build_occupancy_map(blind, OccupancyMappingConfig(pose_source="odometry"))
    with pytest.raises(InputError, match="empty"):
        build_occupancy_map(rooms, scans=[])


def test_occupancy_map_job_writes_files(tmp_path, rooms_10cm):
    from slamkit.app.mapping import occupancy_map_job

    report = occupancy_map_job(rooms_10cm, 0.1, tmp_path / "m", config={"scan_stride": 2})
    assert report.files == (
        "config.json", "map.pgm", "map.png", "map.yaml", "map_view.png", "quality.json"
    )  # fmt: skip
    quality = json.loads((tmp_path / "m" / "quality.json").read_text())
    assert quality["map"]["cells"] == report.grid.prob.size
    assert quality["even_odd"]["agreement"] >= 0.98
    assert quality["truth"]["tolerance_1"]["precision"] >= 0.98
    n_scans = sum(isinstance(ev, LaserScan) for ev in rooms_10cm.events)
    assert quality["stats"]["scans_used"] == (n_scans + 1) // 2  # scan_stride 2
    config = json.loads((tmp_path / "m" / "config.json").read_text())
    assert config["mapping"]["resolution"] == 0.1 and config["mapping"]["scan_stride"] == 2
    assert config["dataset"]["name"] == "rooms-laser"
    back = read_ros_map(tmp_path / "m" / "map.yaml")
    np.testing.assert_array_equal(back.prob == 1.0, report.grid.prob >= 0.65)
    np.testing.assert_allclose(back.origin_xy, report.grid.origin_xy)
    with pytest.raises(ConfigError, match="resolution"):
        occupancy_map_job(rooms_10cm, -1.0, tmp_path / "bad")


def _map_cli():
    import typer

    from slamkit.cli.map_cmd import map_app

    app = typer.Typer()
    app.add_typer(map_app, name="map")  # as the main app mounts it

    @app.callback()
    def _main() -> None: ...

    return app


def test_map_command(tmp_path):
    from typer.testing import CliRunner

    app = _map_cli()
    out = tmp_path / "cli"
    args = ["map", "occupancy", "--data", "rooms-laser", "--resolution", "0.2", "--out", str(out)]
    res = CliRunner().invoke(app, [*args, "--no-agreement"])
    assert res.exit_code == 0, res.output
    assert (out / "map.pgm").exists() and "occupied cells" in res.output
    # the command's usable range, 30 m, is recorded (the simulated laser's 8 m is shorter)
    config = json.loads((out / "config.json").read_text())
    assert config["mapping"]["model"]["max_range"] == 30.0
    res = CliRunner().invoke(app, ["map", "occupancy", "--data", "nowhere", "--out", str(out)])
    assert res.exit_code == 1
    assert "unknown dataset 'nowhere'" in res.output


def test_map_command_usable_range_options(tmp_path):
    """``--max-range`` beats the config file, which beats the 30 m default; ``sensor`` leaves
    the sensor's own range (null in config.json); anything else is a one-line error."""
    from typer.testing import CliRunner

    app = _map_cli()
    cfg = tmp_path / "c.toml"
    cfg.write_text("[mapping]\nresolution = 0.25\n[mapping.model]\nmax_range = 5.0\n")
    base = ["map", "occupancy", "--data", "rooms-laser", "--no-agreement", "--config", str(cfg)]
    for flag, expected in (
        ([], 5.0),
        (["--max-range", "6.5"], 6.5),
        (["--max-range", "sensor"], None),
    ):
        out = tmp_path / f"m{expected}"
        res = CliRunner().invoke(app, [*base, *flag, "--out", str(out)])
        assert res.exit_code == 0, res.output
        config = json.loads((out / "config.json").read_text())
        assert config["mapping"]["model"]["max_range"] == expected
        assert config["mapping"]["resolution"] == 0.25
    res = CliRunner().invoke(app, [*base, "--max-range", "-3", "--out", str(tmp_path / "x")])
    assert res.exit_code == 1
    assert "--max-range: expected metres > 0 or 'sensor', got '-3'" in res.output
    # an error message naming a table keeps its brackets (rich markup would swallow them)
    cfg.write_text("mapping = 3\n")
    res = CliRunner().invoke(app, [*base, "--out", str(tmp_path / "y")])
    assert res.exit_code == 1
    assert "[mapping] must be a table of settings" in res.output


def test_map_command_help_shows_units_and_tables():
    """typer renders help as rich markup, which swallowed "[m]" and "[mapping]" ("Cell size
    ."); the help must show them."""
    from typer.testing import CliRunner

    res = CliRunner().invoke(_map_cli(), ["map", "occupancy", "--help"], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())  # undo rich's line wrapping
    assert "Cell size [m]" in text
    assert "TOML/JSON file with [mapping] and [dataset] tables" in text
    assert "Usable range r_max of the laser [m], or 'sensor'" in text
    assert "Default 30 m (unless the config file sets [mapping.model] max_range)" in text


def test_a_grid_too_large_is_refused_with_its_size(rooms):
    """A resolution typo (1e-4 m) must not reach MemoryError: the size is checked first."""
    with pytest.raises(InputError, match=r"above the limit of 1,000 cells \(max_cells\)"):
        build_occupancy_map(rooms, OccupancyMappingConfig(resolution=0.1, max_cells=1000))
    with pytest.raises(ConfigError, match="max_cells"):
        OccupancyMappingConfig(max_cells=0)
