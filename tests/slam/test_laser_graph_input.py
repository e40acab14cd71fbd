"""Graph SLAM on inputs that are thin or empty: scans a metre apart map; odometry that says
nothing is set aside for the laser, with a warning; a laser that gives nothing to match
ends the run with one line saying why."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slamkit.datasets import LaserScan, load_dataset
from slamkit.datasets.stream import Dataset, Odometry
from slamkit.errors import MatchError
from slamkit.estimation.health import usable_motion
from slamkit.geometry.pose2 import interpolate_poses
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.sim.buildings import build_building_dataset
from slamkit.sim.odometry_errors import OdometryErrorModel, corrupt_odometry
from slamkit.slam.laser_graph.estimator import NO_ODOMETRY


def _thinned(data: Dataset, spacing: float) -> Dataset:
    """``data`` with only the scans at least ``spacing`` metres (true travel) apart."""
    assert data.truth.times is not None and data.truth.poses is not None
    events, last = [], None
    for e in data.events:
        if isinstance(e, LaserScan):
            p = interpolate_poses(data.truth.times, data.truth.poses, np.array([e.t]))[0]
            if last is not None and np.hypot(*(p[:2] - last[:2])) < spacing:
                continue
            last = p
        events.append(e)
    return dataclasses.replace(data, events=tuple(events))


def test_a_log_with_scans_a_metre_apart_maps() -> None:
    """Generated building 5 with the corpus's odometry errors (seed 1), keeping one scan per
    metre of travel (262 of 986): graph SLAM maps it within 0.2 m ATE (0.104 m measured;
    0.051 m with every scan), a third of the wheels' own error or less."""
    data, _ = corrupt_odometry(
        build_building_dataset(5), OdometryErrorModel(), np.random.default_rng(1)
    )
    sparse = _thinned(data, 1.0)
    scans = sum(isinstance(e, LaserScan) for e in sparse.events)
    assert 200 < scans < 300
    ate = evaluate(run("graph-slam", sparse, seed=0), sparse).scores.ate.rmse
    wheels = evaluate(run("dead-reckoning", sparse, seed=0), sparse).scores.ate.rmse
    assert ate < 0.2 and ate < wheels / 3.0


@pytest.fixture(scope="module")
def loop_world() -> Dataset:
    return load_dataset("corridor-loop-laser", seed=0)


def _still(data: Dataset) -> Dataset:
    """``data`` whose odometry reports the start pose forever (a stuck encoder)."""
    first = next(e.pose for e in data.events if isinstance(e, Odometry))
    events = [
        dataclasses.replace(e, pose=first) if isinstance(e, Odometry) else e for e in data.events
    ]
    return dataclasses.replace(data, events=tuple(events))


def test_odometry_that_never_moves_is_set_aside_for_the_laser() -> None:
    building = build_building_dataset(11)  # its odometry: poses, the shortest route
    assert building.motion is not None and building.motion.source == "odometry"
    still = _still(building)
    motion, why = usable_motion(still)
    assert motion is None and why is not None and "never moves" in why
    assert usable_motion(building) == (building.motion, None)
    gone = dataclasses.replace(
        building, events=tuple(e for e in building.events if not isinstance(e, Odometry))
    )
    assert usable_motion(gone) == (None, "the data set has no odometry readings")
    result = run("graph-slam", still, seed=0)
    assert result.output.diagnostics["odometry"] == NO_ODOMETRY
    assert [w.kind for w in result.output.warnings][:1] == ["no_odometry"]


def test_controls_that_are_all_zero_say_nothing(loop_world: Dataset) -> None:
    from slamkit.datasets.stream import Control

    assert loop_world.motion is not None and loop_world.motion.source == "control"
    events = [
        dataclasses.replace(e, u=np.zeros_like(e.u)) if isinstance(e, Control) else e
        for e in loop_world.events
    ]
    still = dataclasses.replace(loop_world, events=tuple(events))
    motion, why = usable_motion(still)
    assert motion is None and why is not None and "zero" in why
    assert usable_motion(loop_world) == (loop_world.motion, None)
    result = run("graph-slam", still, seed=0)
    assert result.output.diagnostics["odometry"] == NO_ODOMETRY
    assert "no_odometry" in [w.kind for w in result.output.warnings]


def test_a_laser_that_sees_nothing_ends_the_run_in_one_line(loop_world: Dataset) -> None:
    """Every beam at the laser's max range: no scan has points to match. The run does not
    hand back the wheels' path as a SLAM result; it stops with one line saying why."""
    assert loop_world.laser is not None
    far = loop_world.laser.max_range
    events = [
        dataclasses.replace(e, ranges=np.full_like(e.ranges, far))
        if isinstance(e, LaserScan)
        else e
        for e in loop_world.events
    ]
    blind = dataclasses.replace(loop_world, events=tuple(events))
    scans = sum(isinstance(e, LaserScan) for e in events)
    with pytest.raises(MatchError, match=f"nothing to match in {scans} scans") as info:
        run("graph-slam", blind, seed=0)
    assert info.value.reason == "laser_unusable" and "\n" not in str(info.value)
