"""Mapping along a given path (``slamkit map occupancy --poses FILE.tum``): the map from the
true path written as TUM is the map from the data set's truth; scans outside the path's span
are dropped and counted; a path of another clock is refused."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets import LaserScan, load_dataset
from slamkit.errors import InputError
from slamkit.io import write_tum
from slamkit.io.rosmap import read_ros_map
from slamkit.mapping.occupancy import dataset_on_path

runner = CliRunner()


@pytest.fixture(scope="module")
def rooms():
    return load_dataset("rooms-laser", seed=1)


def _cli(*args: str) -> str:
    res = runner.invoke(app, list(args))
    assert res.exit_code == 0, res.output
    return " ".join(res.output.split())


def test_path_drops_and_counts_the_scans_outside_its_span(rooms):
    t, p = rooms.truth.times, rooms.truth.poses
    keep = (t >= 10.0) & (t <= 80.0)
    scan_t = np.array([e.t for e in rooms.events if isinstance(e, LaserScan)])
    data, coverage = dataset_on_path(rooms, t[keep], p[keep], source="part.tum")
    assert coverage.before == np.count_nonzero(scan_t < 10.0) > 0
    assert coverage.after == np.count_nonzero(scan_t > 80.0) > 0
    assert coverage.used == np.count_nonzero((scan_t >= 10.0) & (scan_t <= 80.0))
    kept = [e.t for e in data.events if isinstance(e, LaserScan)]
    assert len(kept) == coverage.used and min(kept) >= 10.0 and max(kept) <= 80.0
    # the other events stay; the path is the reference the mapping reads
    others = sum(not isinstance(e, LaserScan) for e in rooms.events)
    assert sum(not isinstance(e, LaserScan) for e in data.events) == others
    np.testing.assert_array_equal(data.truth.times, t[keep])
    assert data.truth.occupancy is rooms.truth.occupancy
    assert coverage.as_dict()["dropped_before"] == coverage.before
    assert f"cover {coverage.used} of {scan_t.size} scans" in coverage.line()


@pytest.mark.parametrize(
    ("window", "shift", "message"),
    [((0.0, 0.0), 0.0, "at least two poses"), ((0.0, 200.0), 1e4, "on its clock"),
     ((0.0, 20.0), 0.0, "419 of 520 scans")],
)  # fmt: skip
def test_a_path_that_misses_most_scans_is_refused(rooms, window, shift, message):
    t, p = rooms.truth.times, rooms.truth.poses
    keep = (t >= window[0]) & (t <= window[1])
    with pytest.raises(InputError, match=message):
        dataset_on_path(rooms, t[keep] + shift, p[keep], source="x.tum")


def test_map_from_the_true_path_as_tum_is_the_map_from_the_truth(tmp_path, rooms):
    _cli("map", "occupancy", "-d", "rooms-laser", "--seed", "1", "--no-agreement",
         "--out", str(tmp_path / "truth"))  # fmt: skip
    tum = tmp_path / "path.tum"
    write_tum(tum, rooms.truth.times, rooms.truth.poses)
    out = _cli("map", "occupancy", "-d", "rooms-laser", "--seed", "1", "--no-agreement",
               "--poses", str(tum), "--out", str(tmp_path / "path"))  # fmt: skip
    n_scans = sum(isinstance(e, LaserScan) for e in rooms.events)
    assert f"cover {n_scans} of {n_scans} scans" in out
    a = read_ros_map(tmp_path / "truth" / "map.yaml")
    b = read_ros_map(tmp_path / "path" / "map.yaml")
    assert a.shape == b.shape
    np.testing.assert_allclose(a.origin_xy, b.origin_xy, atol=1e-9)
    # TUM keeps 9 significant digits of a pose and 16 of a stamp: identical maps (measured on
    # seeds 1-3, docs/map-workflow.md)
    np.testing.assert_array_equal(a.prob, b.prob)
    quality = json.loads((tmp_path / "path" / "quality.json").read_text())
    assert quality["path"]["used"] == n_scans and quality["path"]["dropped_before"] == 0
    config = json.loads((tmp_path / "path" / "config.json").read_text())
    assert config["poses"] == str(tum.resolve())
    # config.json re-runs the map along the same path
    _cli("map", "occupancy", "--config", str(tmp_path / "path" / "config.json"),
         "--no-agreement", "--out", str(tmp_path / "again"))  # fmt: skip
    assert (tmp_path / "again" / "map.pgm").read_bytes() == (
        tmp_path / "path" / "map.pgm"
    ).read_bytes()


def test_a_part_of_the_path_maps_its_scans_and_says_what_it_dropped(tmp_path, rooms):
    t, p = rooms.truth.times, rooms.truth.poses
    keep = t >= 15.0
    tum = tmp_path / "late.tum"
    write_tum(tum, t[keep], p[keep])
    out = _cli("map", "occupancy", "-d", "rooms-laser", "--seed", "1", "--no-agreement",
               "--poses", str(tum), "--out", str(tmp_path / "late"))  # fmt: skip
    scan_t = np.array([e.t for e in rooms.events if isinstance(e, LaserScan)])
    before = int(np.count_nonzero(scan_t < t[keep][0]))
    assert f"dropped {before} before and 0 after its span" in out
    quality = json.loads((tmp_path / "late" / "quality.json").read_text())
    assert quality["stats"]["scans_used"] <= scan_t.size - before
    # a path of another log: refused in one line, no folder
    write_tum(tum, t[keep] + 1e4, p[keep])
    res = runner.invoke(app, ["map", "occupancy", "-d", "rooms-laser", "--poses", str(tum),
                              "--out", str(tmp_path / "other")])  # fmt: skip
    assert res.exit_code == 1 and "is it a path of this log" in " ".join(res.output.split())
    assert not (tmp_path / "other").exists()
    res = runner.invoke(app, ["map", "occupancy", "--poses", "nowhere.tum"])
    assert res.exit_code == 1 and "expected 'truth', 'odometry' or a TUM file" in res.output


def test_scans_are_laid_from_the_laser_on_its_mounting(rooms):
    """A laser mounted 0.3 m ahead and 0.1 m left, turned 5°, on a robot whose path is the
    laser's path ⊕ mounting⁻¹: the map from the robot's poses (its truth, a TUM path of it, or
    the pipeline estimator) is the map of the laser's own poses."""
    import dataclasses

    from slamkit.geometry.pose2 import compose, inverse
    from slamkit.mapping.occupancy import OccupancyMappingConfig, build_occupancy_map
    from slamkit.pipeline import run

    mounting = (0.3, 0.1, np.deg2rad(5.0))
    robot = compose(rooms.truth.poses, inverse(np.array(mounting)))
    mounted = dataclasses.replace(
        rooms,
        laser=dataclasses.replace(rooms.laser, mounting=mounting),
        truth=dataclasses.replace(rooms.truth, poses=robot),
    )
    cfg = OccupancyMappingConfig(bounds="grow")
    want = build_occupancy_map(rooms, cfg).grid
    for data in (mounted, dataset_on_path(mounted, rooms.truth.times, robot)[0]):
        got = build_occupancy_map(data, cfg).grid
        assert got.shape == want.shape
        assert np.count_nonzero(got.prob != want.prob) <= 1e-4 * want.prob.size
    online = run("occupancy-mapping", mounted, config={"bounds": "grow"}).output.grid
    assert online is not None and online.shape == want.shape
    assert np.count_nonzero(online.prob != want.prob) <= 1e-4 * want.prob.size
    # the laser at the robot's origin instead: a different map
    off = build_occupancy_map(dataclasses.replace(mounted, laser=rooms.laser), cfg).grid
    assert off.shape != want.shape or np.count_nonzero(off.prob != want.prob) > 0.01 * off.prob.size
