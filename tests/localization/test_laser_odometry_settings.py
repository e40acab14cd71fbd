"""Laser odometry's settings: at most twenty, each one read by the estimator, the removed
ones named in the error an old config gets (issue 32)."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from slamkit.app.runconfig import config_toml
from slamkit.config import config_from_mapping, describe_settings
from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset
from slamkit.errors import ConfigError
from slamkit.localization.laser_odometry import LaserOdometryConfig
from slamkit.pipeline import Result, run

BUDGET = 20

# One value off the default for every setting: each must change the run (its path, its
# map, or what its diagnostics count).
CHANGED: dict[str, Any] = {
    "reference": "keyframe",
    "map_radius": 2.0,
    "voxel": 0.3,
    "keyframe_distance": 0.2,
    "keyframe_angle_deg": 3.0,
    "min_overlap": 0.99,
    "max_correction_xy": 0.002,
    "max_correction_deg": 0.05,
    "min_range": 1.5,
    "max_range": 3.0,
    "motion_cov_scale": 100.0,
    "mounting": (0.1, 0.0, 0.0),
    "map.enabled": False,
    "map.resolution": 0.1,
    "map.max_range": 2.0,
}

REMOVED = ("matcher", "odometry_prior", "plicp", "normal_icp", "icp")


def test_the_settings_keep_to_the_budget() -> None:
    """What ``slamkit config show laser-odometry`` lists (one leaf a setting): 15 (45
    before 2026-12-07, 28 of them the three matchers' own)."""
    keys = [d.key for d in describe_settings(LaserOdometryConfig)]
    assert len(keys) <= BUDGET
    assert set(keys) == set(CHANGED)
    shown = config_toml("laser-odometry", None)
    assert all(f"{k.split('.')[-1]} =" in shown for k in keys)


@pytest.mark.parametrize("name", REMOVED)
def test_a_removed_setting_is_named_in_the_error(name: str) -> None:
    with pytest.raises(ConfigError, match=rf"{name} \(.*laser odometry: removed"):
        config_from_mapping(LaserOdometryConfig, {name: 1})


@pytest.fixture(scope="module")
def short_rooms() -> Dataset:
    """The simulated rooms' first 30 s."""
    data = load_dataset("rooms-laser", seed=0)
    return dataclasses.replace(data, events=tuple(e for e in data.events if e.t <= 30.0))


def _config(name: str, value: Any) -> dict[str, Any]:
    section, _, key = name.rpartition(".")
    return {section: {key: value}} if section else {name: value}


def _fingerprint(result: Result) -> tuple[Any, ...]:
    out = result.output
    d = out.diagnostics
    grid = out.grid
    return (
        result.poses.round(9).tobytes(),
        None if grid is None else (grid.resolution, grid.prob.shape, grid.prob.sum().round(6)),
        d["keyframes"],
        d["matched"],
        d["gated"],
    )


@pytest.fixture(scope="module")
def default_run(short_rooms: Dataset) -> tuple[Any, ...]:
    return _fingerprint(run("laser-odometry", short_rooms, seed=0))


@pytest.mark.parametrize("name", sorted(CHANGED))
def test_every_setting_changes_the_run(short_rooms, default_run, name: str) -> None:
    """No setting is dead: the value in :data:`CHANGED` gives another run than the
    default (the estimator is deterministic, so any difference is the setting's)."""
    result = run("laser-odometry", short_rooms, seed=0, config=_config(name, CHANGED[name]))
    changed = _fingerprint(result)
    assert changed != default_run
    if name == "map.enabled":
        assert changed[1] is None
    if name == "map.resolution":
        assert changed[1] is not None and changed[1][0] == pytest.approx(0.1)
    if name.startswith("max_correction"):
        assert changed[4] > default_run[4]
    if name == "keyframe_distance":
        assert changed[2] > default_run[2]
