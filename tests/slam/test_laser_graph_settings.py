"""graph-slam's settings: the budget of issue 32 (at most 30), the removed ones named in the
error, and the effect of the front end's and the scan's settings (the loop settings are
exercised in ``test_laser_graph.py``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamkit.config import RENAMED, config_from_mapping, describe_settings
from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Control, LaserScan
from slamkit.errors import ConfigError
from slamkit.geometry.pose2 import transform_points
from slamkit.pipeline.registry import get_estimator_entry
from slamkit.slam.laser_graph import FrontEndSettings, LaserGraphConfig, LaserGraphSlam, Tracker
from slamkit.slam.laser_graph.frontend import within_gate

BUDGET = 30
"""Issue 32: graph-slam exposes at most this many settings."""


@pytest.fixture(scope="module")
def loop_world():
    return load_dataset("corridor-loop-laser", seed=0)


def test_graph_slam_keeps_to_its_budget_of_settings() -> None:
    """Counted as ``slamkit config show graph-slam`` prints them: every leaf, the sections'
    included (17 on 2026-12-07, from 83)."""
    config_type = get_estimator_entry("graph-slam").config_type()
    assert config_type is LaserGraphConfig
    leaves = describe_settings(config_type)
    assert len(leaves) <= BUDGET
    assert {d.key for d in leaves} >= {
        "min_range", "max_range", "mounting", "map_resolution", "frontend.keyframe_distance",
        "loops.enabled", "loops.max_radius", "loops.max_angle_deg", "loops.min_score",
    }  # fmt: skip


REMOVED = [
    ("frontend", "map_keyframes"), ("frontend", "voxel"), ("frontend", "min_overlap"),
    ("frontend", "cov_floor_xy"), ("frontend", "cov_floor_deg"), ("loops", "radius"),
    ("loops", "angle_deg"), ("loops", "max_candidates"), ("loops", "submap_keyframes"),
    ("loops", "resolution"), ("loops", "sigma"), ("loops", "min_inliers"),
    ("loops", "max_refinement_xy"), ("loops", "max_refinement_deg"), ("loops", "pair_keyframes"),
    ("loops", "pair_xy"), ("loops", "pair_deg"), ("loops", "max_chi2"),
    ("loops", "max_edge_chi2"), ("loops", "rejudge"), ("loops", "cov_scale"),
    ("loops", "optimize_every"), ("", "optimizer"), ("", "plicp"), ("", "normal_icp"),
    ("", "map"),
]  # fmt: skip


@pytest.mark.parametrize(("section", "name"), REMOVED)
def test_a_removed_setting_is_named_in_the_error(section: str, name: str) -> None:
    values = {section: {name: 1}} if section else {name: {}}
    with pytest.raises(ConfigError, match=rf"{name} \(graph SLAM.*: removed 2026-12-07"):
        config_from_mapping(LaserGraphConfig, values, "graph-slam")


def test_a_removed_name_of_a_section_explains_nothing_elsewhere() -> None:
    """``loops.resolution`` was removed from graph SLAM's loops; an unknown ``resolution``
    in another section gets no graph SLAM hint."""
    assert "loops.resolution" in RENAMED and "resolution" not in RENAMED
    with pytest.raises(ConfigError) as raised:
        config_from_mapping(FrontEndSettings, {"resolution": 1.0}, "graph-slam.frontend")
    assert "graph SLAM" not in str(raised.value)


def _first_keyframe_points(data, **settings) -> np.ndarray:
    est = LaserGraphSlam(data, LaserGraphConfig(**settings), np.random.default_rng(0))
    scan = next(e for e in data.events if isinstance(e, LaserScan))
    est.handle(scan)
    return est.keyframes[0].points


def test_the_range_limits_and_the_mounting_shape_the_scan(loop_world) -> None:
    """``min_range`` and ``max_range`` drop the readings outside them; ``mounting`` puts the
    scan in the robot frame (the ring's laser sits at the robot's centre)."""
    assert loop_world.laser.mounting == (0.0, 0.0, 0.0)
    points = _first_keyframe_points(loop_world)
    r = np.hypot(*points.T)
    low, high = np.quantile(r, [0.25, 0.75])
    near = _first_keyframe_points(loop_world, max_range=float(high))
    far = _first_keyframe_points(loop_world, min_range=float(low))
    assert np.hypot(*near.T).max() < high and len(near) == np.count_nonzero(r < high)
    assert np.hypot(*far.T).min() > low and len(far) == np.count_nonzero(r > low)
    mounting = (0.3, -0.1, math.radians(20.0))
    moved = _first_keyframe_points(loop_world, mounting=mounting)
    np.testing.assert_allclose(moved, transform_points(np.array(mounting), points), atol=1e-12)


def test_keyframe_spacing_decides_when_a_scan_becomes_a_keyframe() -> None:
    """A scan 0.3 m and 10° from its keyframe: not yet one at 0.4 m / 12°, one at 0.25 m or
    at 8°."""
    due = []
    for settings in (
        FrontEndSettings(),
        FrontEndSettings(keyframe_distance=0.25),
        FrontEndSettings(keyframe_angle_deg=8.0),
    ):
        tracker = Tracker(None, None, settings)
        tracker.offset = np.array([0.3, 0.0, math.radians(10.0)])
        due.append(tracker.keyframe_due())
    assert due == [False, True, True]


def test_the_gate_bounds_the_correction_of_the_prediction() -> None:
    prior = np.array([1.0, 2.0, 0.5])
    pose = prior + np.array([0.3, 0.3, math.radians(15.0)])  # 0.42 m, 15°
    assert within_gate(prior, pose, FrontEndSettings())
    assert not within_gate(prior, pose, FrontEndSettings(max_correction_xy=0.4))
    assert not within_gate(prior, pose, FrontEndSettings(max_correction_deg=14.0))


def test_motion_cov_scale_multiplies_the_odometry_covariance(loop_world) -> None:
    """The wheels' covariance since the keyframe (the local map's prior, the edge of a failed
    match) is linear in the control noise: scaled 4 times with it."""
    motion = loop_world.motion
    controls = [e for e in loop_world.events if isinstance(e, Control)][:10]
    covs = []
    for scale in (1.0, 4.0):
        tracker = Tracker(motion.model, motion.noise_cov, FrontEndSettings(motion_cov_scale=scale))
        for c in controls:
            tracker.predict(c.u, c.dt)
        covs.append(tracker.odometry_cov)
    assert np.trace(covs[0]) > 0.0
    np.testing.assert_allclose(covs[1], 4.0 * covs[0], rtol=1e-12)
