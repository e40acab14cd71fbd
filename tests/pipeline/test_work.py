"""The work a run's progress counts: the events the estimator spends its time on."""

from __future__ import annotations

import numpy as np

from slamkit.app import RunRequest, run_job
from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset, LaserScan, LaserSpec, MotionSpec, Odometry
from slamkit.models import OdometryModel
from slamkit.pipeline import get_estimator_entry, run, work_measure


def _ten_scans_and_a_hundred_odometry_readings() -> Dataset:
    """Odometry at 100 Hz for one second, a scan every tenth reading (at the same time)."""
    events: list[Odometry | LaserScan] = []
    for k in range(100):
        t = 0.01 * (k + 1)
        events.append(Odometry(t, np.array([0.1 * t, 0.0, 0.0])))
        if k % 10 == 9:
            events.append(LaserScan(t, np.full(8, 2.0)))
    return Dataset(
        "ten-scans",
        tuple(events),
        motion=MotionSpec(OdometryModel(), np.diag([1e-4, 1e-4, 1e-4]), source="odometry"),
        laser=LaserSpec(np.linspace(-np.pi / 2, np.pi / 2, 8), max_range=4.0),
        initial_pose=np.zeros(3),
    )


def test_a_laser_estimator_counts_the_scans_not_the_odometry():
    ds = _ten_scans_and_a_hundred_odometry_readings()
    assert len(ds) == 110
    laser = work_measure(get_estimator_entry("laser-odometry"), ds)
    assert (laser.unit, laser.total) == ("scans", 10)
    # the weights mark exactly the scans, in stream order
    assert np.flatnonzero(laser.weights).tolist() == [10 + 11 * k for k in range(10)]
    # an estimator without a costlier kind of event counts every event
    dead = work_measure(get_estimator_entry("dead-reckoning"), ds)
    assert (dead.unit, dead.total) == ("events", 110)
    # a landmark estimator on a data set without landmark readings falls back to events
    ekf = work_measure(get_estimator_entry("ekf-slam"), ds)
    assert (ekf.unit, ekf.total) == ("events", 110)


def test_landmark_estimators_count_the_readings():
    ds = load_dataset("five-features", seed=0)
    measure = work_measure(get_estimator_entry("ekf-slam"), ds)
    assert measure.unit == "readings"
    assert measure.total == 339 < len(ds) == 677  # a reading and a control per step


def test_the_runner_reports_progress_in_scans_and_names_its_last_step():
    ds = _ten_scans_and_a_hundred_odometry_readings()
    calls: list[tuple[int, int]] = []
    stages: list[str] = []
    run("dead-reckoning", ds, progress=lambda d, t: calls.append((d, t)), stage=stages.append)
    assert calls[-1] == (110, 110) and stages == ["finishing dead-reckoning"]
    calls.clear()
    rooms = load_dataset("rooms-laser", seed=0)
    scans = sum(isinstance(ev, LaserScan) for ev in rooms.events)
    run("occupancy-mapping", rooms, progress=lambda d, t: calls.append((d, t)))
    assert scans == 522 < len(rooms)
    assert calls[-1] == (522, 522) and all(t == 522 for _, t in calls)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


def test_run_job_says_what_it_counts_and_reports_the_steps_after_the_run_in_order(tmp_path):
    units: list[str] = []
    stages: list[str] = []
    calls: list[tuple[int, int]] = []
    report = run_job(
        RunRequest("ekf-slam", "five-features", tmp_path / "out"),
        lambda d, t: calls.append((d, t)),
        stages.append,
        lambda unit, pace: units.append(f"{unit} {pace}"),
    )
    assert units == ["readings steady"] and calls[-1] == (339, 339)
    plots = sum(name.endswith(".png") for name in report.files)
    assert plots >= 3
    assert stages == [
        "finishing ekf-slam",
        "scoring the run",
        "drawing the plots",
        "writing the result files",
        f"writing {plots} plots",
        "writing the report page",
    ]


def test_graph_slam_says_its_pace_grows_and_a_run_that_speeds_up_gets_one_figure():
    from slamkit.pipeline.eta import TimeLeft

    rooms = load_dataset("rooms-laser", seed=0)
    assert work_measure(get_estimator_entry("graph-slam"), rooms).pace == "growing"
    assert work_measure(get_estimator_entry("laser-odometry"), rooms).pace == "steady"
    # time per scan falling (T(x) = 0.05 x − 1e-5 x²): the fitted rise is held at 0
    left = TimeLeft("growing")
    for done in range(0, 2001, 50):
        left.add(0.05 * done - 1e-5 * done**2, done)
    low, high = left.estimate(2500) or (0.0, 1.0)
    assert low == high > 0
    assert TimeLeft("growing").estimate(10) is None  # no count, no rate
