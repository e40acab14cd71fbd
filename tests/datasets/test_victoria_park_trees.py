"""``victoria-park-trees``: the raw laser's trunks as a landmark data set, against the
published detections (skipped when the data folder is absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import Control, LandmarkReadings, load_dataset
from slamkit.datasets.registry import dataset_available, get_dataset_entry
from slamkit.datasets.victoria_park_trees import (
    load_victoria_park_trees,
    match_published,
    scan_trees,
)
from slamkit.errors import ConfigError
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate

SPAN = {"max_duration_s": 60.0}


@pytest.fixture(scope="module")
def trees(data_root):
    if not dataset_available(get_dataset_entry("victoria-park-trees"), data_root):
        pytest.skip("Victoria Park's raw laser is not under SLAMKIT_DATA")
    return load_dataset("victoria-park-trees", options=SPAN, data_root=data_root)


def test_first_minute_counts_and_stream(trees):
    meta = trees.metadata
    assert (meta["scans"], meta["reading_events"], meta["detections"]) == (282, 282, 3426)
    assert meta["median_diameter_m"] == pytest.approx(0.405, abs=0.001)
    readings = [ev for ev in trees.events if isinstance(ev, LandmarkReadings)]
    assert all((ev.ids == -1).all() for ev in readings)
    z = np.concatenate([ev.z for ev in readings])
    assert z[:, 0].max() < 40.0 + np.hypot(3.78, 0.5)  # the extractor's range limit
    assert np.abs(z[:, 1]).max() <= np.pi
    # The controls are the raw-laser loader's, unchanged.
    laser = load_dataset("victoria-park-laser", options=SPAN)
    ours = [ev for ev in trees.events if isinstance(ev, Control)]
    raw = [ev for ev in laser.events if isinstance(ev, Control)]
    assert len(ours) == len(raw) == 2672
    assert np.array_equal([(c.t, *c.u, c.dt) for c in ours], [(c.t, *c.u, c.dt) for c in raw])
    assert "3426 trunks found in 282 of 282 scans" in trees.reading.lines()[1]


def test_published_detections_reproduced(trees, data_root):
    published = load_dataset("victoria-park", options=SPAN, data_root=data_root)
    m = match_published(trees, published)
    assert (m.scans, m.published, m.not_compared) == (281, 2557, 0)
    assert m.reproduced == 2356  # 92.1 % within 0.5 m
    assert (m.ours, m.extra) == (3417, 1054)


def test_diameters_are_the_signature(trees):
    found = scan_trees(load_dataset("victoria-park-laser", options=SPAN))
    diam = np.concatenate([s.trees.diameters for s in found])
    assert diam.size == 3426
    assert diam.min() >= 0.1 and diam.max() <= 1.0


def test_ekf_slam_end_to_end_first_minute(trees):
    result = run("ekf-slam", trees, seed=0)
    m = evaluate(result, trees).metrics
    assert m["gps"]["rmse"] == pytest.approx(0.566, abs=0.01)
    assert m["diagnostics"]["n_landmarks"] == 100  # 99 before EKF-SLAM's landmark management


def test_bad_option_is_refused():
    """Refused before any file is read (the loader itself, so the data need not be here)."""
    with pytest.raises(ConfigError, match="sigma_range"):
        load_victoria_park_trees({"sigma_range": 0.0}, data_root=Path("/nonexistent"))
