"""FastSLAM on real data: cityTrees10000 (simulated by the iSAM authors, with ground truth).

Thresholds are the measured values (seed 0, in each docstring) with a margin of about 25 %.
A particle filter is chaotic: rounding differences between machines change which particles
survive a resampling, so a run elsewhere can land anywhere in the spread measured over
seeds; the docstrings give that spread, and the thresholds sit above the worst seed where
they can.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest

from slamkit.datasets import Dataset, load_dataset
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate

pytestmark = pytest.mark.realdata


def _metrics(estimator: str, ds: Dataset, config: dict[str, Any]) -> dict[str, Any]:
    return evaluate(run(estimator, ds, config=config, seed=0), ds).metrics


def _citytrees_first_half(root: Path) -> Dataset:
    """Poses 0-4999 of cityTrees10000 (every one of the 100 trees is first seen before pose
    1400: the map is made in this half, the second only re-observes it)."""
    ds = load_dataset("citytrees10000", data_root=root)
    return dataclasses.replace(ds, events=tuple(ev for ev in ds.events if ev.t < 5000.0))


def test_fastslam2_on_citytrees10000(data_root: Path) -> None:
    """Odometry every pose, a scan every 5 poses (2.6 position readings of known trees), 100
    particles. FastSLAM 2.0's proposal covers the 5 odometry steps before each scan (each
    particle's motion since its scan as a Gaussian, see :mod:`slamkit.slam.fastslam`).

    Measured on the first 5000 poses (seed 0): ATE 3.40 m, landmark RMSE 3.33 m, median ESS
    43 of 100; seeds 1-4: ATE 2.81, 2.08, 3.40, 1.48 m, landmarks 2.32, 1.79, 3.16, 0.53 m.
    The whole run (10,000 poses, seeds 0-4): ATE 1.1-3.4 m, landmarks 0.5-3.2 m; 300 and
    1000 particles do not do much better (seed 0: 2.69 m and 2.28 m). EKF-SLAM on the same
    half: ATE 1.61 m, landmarks 0.075 m. FastSLAM's map error is fixed while the trees are
    first mapped: with ~600 resamplings per 5000 poses every particle descends from one
    ancestor a few hundred poses back, so the drift of that ancestor's path is in every
    particle's early landmarks, where EKF-SLAM's correlations let later loop closures
    correct them. Odometry alone: ATE 28.5 m (whole run).

    Before the proposal covered every step (the four earlier odometry steps sampled
    blindly, the proposal built from the last one alone), the weights collapsed at almost
    every scan (median ESS 1.0) and the filter diverged: ATE 57.3 m, landmarks 34.6 m (whole
    run); FastSLAM 1.0 diverges the same way (32.3 m, ESS 1.0), and more particles do not
    make it reliable (whole run, seeds 0-4, median ATE 3.5 m at 300 particles, 5.5 m at
    1000, 9.4 m at 3000, the worst seeds 18-58 m)."""
    ds = _citytrees_first_half(data_root)
    m = _metrics("fastslam2", ds, {})
    assert m["ate"]["rmse"] < 4.25 and m["ate"]["median"] < 3.2
    assert m["landmarks_matched_by"] == "id"
    assert m["landmarks"]["n_matched"] == 100 and m["landmarks"]["rmse"] < 4.2
    assert m["diagnostics"]["ess_median"] > 30.0
