"""The grid RBPF's settings: at most twenty, each one read by the filter, the removed ones
named in the error an old config gets (issue 32)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from slamkit.app.runconfig import config_toml
from slamkit.config import config_from_mapping, describe_settings
from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset
from slamkit.errors import ConfigError
from slamkit.pipeline import Result, run
from slamkit.slam.grid_rbpf import GridRbpfConfig

BUDGET = 20

# One value off the default for every setting: each must change the run (its path, its
# map, its snapshots or what its diagnostics count).
CHANGED: dict[str, Any] = {
    "particles": 4,
    "proposal": "mode",
    "update_distance": 0.25,
    "update_angle_deg": 10.0,
    "resolution": 0.1,
    "max_range": 3.0,
    "sigma_hit": 0.1,
    "likelihood_temperature": 1.0,
    "beam_stride": 4,
    "motion_trans_per_m": 0.3,
    "motion_trans_per_rad": 0.2,
    "motion_rot_per_m": 0.2,
    "motion_rot_per_rad": 0.3,
    "max_correction_xy": 0.005,
    "max_correction_deg": 0.1,
    "recovery_score": 0.99,
    "min_range": 1.5,
    "mounting": (0.1, 0.0, 0.0),
    "snapshots": 2,
}

REMOVED = (
    "map_range",
    "match_range",
    "tile_cells",
    "match_iterations",
    "match_tolerance_xy",
    "match_tolerance_deg",
    "proposal_temperature",
    "stencil_sigmas",
    "mode_noise_xy",
    "mode_noise_deg",
    "motion_floor_xy",
    "motion_floor_deg",
    "recovery_window_xy",
    "recovery_window_deg",
    "resample_threshold",
    "max_updates",
)


def test_the_settings_keep_to_the_budget() -> None:
    """What ``slamkit config show grid-rbpf`` lists (one leaf a setting): 19 (34 before
    2026-12-07)."""
    keys = [d.key for d in describe_settings(GridRbpfConfig)]
    assert len(keys) <= BUDGET
    assert set(keys) == set(CHANGED)
    shown = config_toml("grid-rbpf", None)
    assert all(f"{k} =" in shown for k in keys)


@pytest.mark.parametrize("name", REMOVED)
def test_a_removed_setting_is_named_in_the_error(name: str) -> None:
    with pytest.raises(ConfigError, match=rf"{name} \(grid RBPF: (removed|now max_range)"):
        config_from_mapping(GridRbpfConfig, {name: 1})


@pytest.fixture(scope="module")
def short_rooms() -> Dataset:
    """The simulated rooms' first 30 s (about 40 updates)."""
    data = load_dataset("rooms-laser", seed=0)
    return dataclasses.replace(data, events=tuple(e for e in data.events if e.t <= 30.0))


def _run(data: Dataset, **changed: Any) -> Result:
    return run("grid-rbpf", data, seed=0, config={"particles": 3, **changed})


def _fingerprint(result: Result) -> tuple[Any, ...]:
    out = result.output
    d = out.diagnostics
    grid = out.grid
    return (
        result.poses.round(9).tobytes(),
        None if grid is None else (grid.resolution, grid.prob.shape, grid.prob.sum().round(6)),
        len(out.particle_snapshots),
        d["particles"],
        d["updates"],
        d["recovered"],
        tuple(sorted(d["proposal_failures"].items())),
    )


@pytest.fixture(scope="module")
def default_run(short_rooms: Dataset) -> tuple[Any, ...]:
    return _fingerprint(_run(short_rooms))


@pytest.mark.parametrize("name", sorted(CHANGED))
def test_every_setting_changes_the_run(short_rooms, default_run, name: str) -> None:
    """No setting is dead: the value in :data:`CHANGED` gives another run than the
    default (the filter is deterministic for a seed, so any difference is the setting's)."""
    changed = _fingerprint(_run(short_rooms, **{name: CHANGED[name]}))
    assert changed != default_run
    if name == "snapshots":
        assert changed[2] == 2
    if name == "resolution":
        assert changed[1] is not None and changed[1][0] == pytest.approx(0.1)
    if name == "max_correction_xy":
        assert dict(changed[6]).get("gated", 0) > 0
    if name == "recovery_score":
        assert changed[5] > default_run[5]
    assert np.isfinite(np.frombuffer(changed[0])).all()
