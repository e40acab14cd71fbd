"""The result files of a run beyond ``trajectory.tum``, ``metrics.json`` and
``config.json``: everything the run knows, in formats other tools read.

* ``landmarks.csv`` — the estimated landmark map (id, x, y, covariance entries;
  :mod:`slamkit.io.landmarks`) of every run that has one;
* ``groundtruth.tum`` — the data set's true path, when it has one (and, beside a
  ``landmarks.csv``, ``groundtruth_landmarks.csv``: its true landmarks);
* ``trajectory.kitti`` + ``times.txt`` — the trajectory in KITTI format, on request
  (``formats`` holds ``"kitti"``);
* ``graph.g2o`` — the pose graph of a graph run;
* ``map.pgm`` + ``map.yaml`` — the occupancy grid of a run that built one, for ROS's
  ``map_server`` (:mod:`slamkit.io.rosmap`).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from slamkit.datasets.stream import Dataset
from slamkit.errors import ConfigError
from slamkit.io import write_kitti, write_landmarks_csv, write_tum
from slamkit.pipeline import Result

__all__ = ["TRAJECTORY_FORMATS", "check_formats", "write_result_files"]

TRAJECTORY_FORMATS = ("tum", "kitti")
"""The trajectory formats a run can write (TUM always)."""


def check_formats(formats: Iterable[str]) -> tuple[str, ...]:
    """The formats, checked: each one of :data:`TRAJECTORY_FORMATS`."""
    out = tuple(formats)
    bad = [f for f in out if f not in TRAJECTORY_FORMATS]
    if bad:
        raise ConfigError(
            f"trajectory format(s) {', '.join(bad)}: expected {', '.join(TRAJECTORY_FORMATS)}"
        )
    return out


def write_result_files(
    folder: Path, result: Result, dataset: Dataset, formats: Iterable[str] = ()
) -> None:
    """Write the files of the module docstring that apply to this run into ``folder``."""
    formats = check_formats(formats)
    estimate = result.output.landmarks
    if estimate is not None:
        write_landmarks_csv(folder / "landmarks.csv", estimate.landmarks, estimate.covariances)
    truth = dataset.truth
    if truth is not None and truth.times is not None and truth.poses is not None:
        write_tum(folder / "groundtruth.tum", truth.times, truth.poses)
    if estimate is not None and truth is not None and truth.landmarks is not None:
        write_landmarks_csv(folder / "groundtruth_landmarks.csv", truth.landmarks)
    if "kitti" in formats:
        write_kitti(
            folder / "trajectory.kitti",
            result.poses,
            times=result.times,
            times_path=folder / "times.txt",
        )
    if result.output.graph is not None:  # a pose-graph estimator's graph, for other tools
        from slamkit.io.posegraph import write_graph

        write_graph(result.output.graph, folder / "graph.g2o", family="g2o")
    if result.output.grid is not None:
        from slamkit.io.rosmap import write_ros_map

        write_ros_map(result.output.grid, folder / "map.pgm", folder / "map.yaml")
