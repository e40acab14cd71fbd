"""Localization data sets in maps slamkit builds (:mod:`slamkit.mapping.built_maps`), on the
simulated laser tour; the Intel data set itself is tested in
``tests/localization/test_mcl_real.py``."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import Dataset, LaserScan, load_dataset
from slamkit.errors import ConfigError, InputError
from slamkit.mapping.built_maps import (
    BuiltMapOptions,
    build_localization_map,
    crop_to_occupied,
    localization_dataset,
)
from slamkit.maps import OccupancyGrid


@pytest.fixture(scope="module")
def rooms() -> Dataset:
    return load_dataset("rooms-laser", seed=1)


def test_crop_keeps_the_occupied_box_and_the_lattice() -> None:
    prob = np.full((20, 30), 0.5)
    prob[5, 7] = prob[12, 20] = 0.9  # occupied
    prob[2:18, 3:25] = np.where(prob[2:18, 3:25] == 0.5, 0.2, prob[2:18, 3:25])  # free around
    grid = OccupancyGrid(prob, 0.1, np.array([-1.0, 2.0]))
    out = crop_to_occupied(grid, margin=0.2)  # two cells
    assert out.shape == (12, 18)  # rows 3..14, cols 5..22
    np.testing.assert_allclose(out.origin_xy, [-1.0 + 0.5, 2.0 + 0.3])
    np.testing.assert_array_equal(out.prob, prob[3:15, 5:23])
    # The same world point falls in cells of equal value in both grids.
    for xy in ([-0.25, 2.55], [1.05, 3.25]):
        r, c = grid.world_to_cell(np.array(xy))
        r2, c2 = out.world_to_cell(np.array(xy))
        assert out.prob[r2, c2] == grid.prob[r, c]
    # A margin past the edge is clipped; a grid without obstacles comes back unchanged.
    assert crop_to_occupied(grid, margin=100.0).shape == grid.shape
    empty = OccupancyGrid(np.full((4, 4), 0.3), 0.1)
    assert crop_to_occupied(empty, 1.0) is empty
    with pytest.raises(InputError):
        crop_to_occupied(grid, -1.0)


def test_localization_dataset_from_a_built_map(rooms: Dataset) -> None:
    grid, info = build_localization_map(rooms, resolution=0.1, crop_margin=0.5)
    assert grid.resolution == 0.1
    assert info["shape"] == list(grid.shape) and info["occupied_cells"] > 0
    # The building's walls (20 m × 12 m) bound the cut map: the margin past them is 0.5 m.
    assert rooms.truth.walls is not None
    x0, y0, x1, y1 = grid.bounds()
    assert (x0, y0) == pytest.approx((-0.5 - 0.1, -0.5 - 0.1), abs=0.11)
    assert (x1, y1) == pytest.approx((20.5 + 0.1, 12.5 + 0.1), abs=0.11)
    assert info["free_area_m2"] > 150.0
    data = localization_dataset(rooms, grid, max_scans=40, name="rooms-built", map_info=info)
    assert data.name == "rooms-built" and data.known_grid is grid
    assert data.initial_pose is None and data.initial_cov is None
    scans = [ev for ev in data.events if isinstance(ev, LaserScan)]
    assert len(scans) == 40 and data.events[-1] is scans[-1]
    assert data.truth.times is not None and data.truth.times[-1] <= scans[-1].t
    assert data.metadata["map"] == info and data.metadata["max_scans"] == 40
    tracking = localization_dataset(rooms, grid, known_start=True)
    assert tracking.initial_pose is not None
    np.testing.assert_array_equal(tracking.initial_pose, rooms.initial_pose)  # type: ignore[arg-type]
    assert len(tracking.events) == len(rooms.events)


def test_options_and_inputs_are_checked(rooms: Dataset) -> None:
    with pytest.raises(ConfigError):
        BuiltMapOptions(resolution=0.0)
    with pytest.raises(ConfigError):
        BuiltMapOptions(max_scans=0)
    with pytest.raises(ConfigError):
        BuiltMapOptions(odometry_sigma_trans=-0.1)
    with pytest.raises(InputError, match="no laser"):
        localization_dataset(load_dataset("five-features"), OccupancyGrid(np.zeros((2, 2)), 1.0))
