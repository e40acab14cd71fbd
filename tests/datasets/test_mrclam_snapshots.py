"""The MRCLAM snapshot loader and single-shot localization on its 9782 snapshots."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import LandmarkReadings
from slamkit.datasets.mrclam_snapshots import (
    FOLDER,
    GROUNDTRUTH_FILE,
    LANDMARK_FILE,
    MEASUREMENT_FILE,
    SIGMA_BEARING,
    SIGMA_RANGE,
    load_mrclam_snapshots,
)
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.localization.least_squares import snapshot_errors

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def dataset(data_root: Path):  # type: ignore[no-untyped-def]
    return load_mrclam_snapshots({}, seed=0, data_root=data_root)


def test_counts_and_conventions(dataset) -> None:  # type: ignore[no-untyped-def]
    assert len(dataset.events) == 9782
    assert dataset.metadata["readings"] == 32970
    assert len(dataset.known_landmarks) == 15
    np.testing.assert_array_equal(dataset.known_landmarks.ids, np.arange(1, 16))
    assert dataset.motion is None and dataset.initial_pose is None
    assert dataset.landmark_sensor.kind == "range-bearing"
    np.testing.assert_allclose(
        np.diag(dataset.landmark_sensor.noise_cov), [SIGMA_RANGE**2, SIGMA_BEARING**2]
    )
    np.testing.assert_array_equal(dataset.truth.times, np.arange(1.0, 9783.0))
    assert "synthetic" in dataset.metadata["time"]
    first = dataset.events[0]
    assert isinstance(first, LandmarkReadings) and first.t == 1.0
    # The first rows of mrclam1_measurement.csv: experiment 1 sees landmarks 1, 7 and 8.
    np.testing.assert_array_equal(first.ids, [1, 7, 8])
    np.testing.assert_allclose(first.z, [[8.21, -0.19], [3.801, -0.238], [2.841, 0.101]])
    np.testing.assert_allclose(dataset.truth.poses[0], [2.296599181, -2.4799305, 1.322459259])
    counts = np.bincount([len(ev.ids) for ev in dataset.events])
    assert counts[:3].sum() == 0 and counts.sum() == 9782  # at least 3 readings each


def test_max_experiments_option(data_root: Path) -> None:
    ds = load_mrclam_snapshots({"max_experiments": 10}, seed=0, data_root=data_root)
    assert len(ds.events) == 10 and ds.truth.times is not None and ds.truth.times.size == 10
    with pytest.raises(ConfigError):
        load_mrclam_snapshots({"sigma_range": -1.0}, seed=0, data_root=data_root)
    with pytest.raises(ConfigError, match="unknown"):
        load_mrclam_snapshots({"sigma": 1.0}, seed=0, data_root=data_root)


def test_snapshot_localization_accuracy(dataset) -> None:  # type: ignore[no-untyped-def]
    # Every 8th snapshot (1223 of them) keeps the test fast; the distribution is the same.
    # Measured on this subset: position error median 0.0454 m, 90th percentile 0.1289 m
    # (max 0.597 m); heading error median 0.00967 rad, 90th percentile 0.0224 rad; none
    # refused; mean NEES 4.02. Over all 9782 snapshots: 0.0451 / 0.1283 / 0.597 m and
    # 0.00948 / 0.0222 / 0.107 rad, mean NEES 3.95, none refused.
    subset = dataclasses.replace(dataset, events=dataset.events[::8])
    se = snapshot_errors(subset)
    assert se.times.size == 1223 and se.refused_times.size == 0
    pos, head = se.position_errors, se.heading_errors
    assert np.median(pos) < 0.056
    assert np.percentile(pos, 90) < 0.16
    assert np.median(head) < 0.012
    assert np.percentile(head, 90) < 0.028
    assert float(np.mean(se.nees)) < 5.0


def _copy_files(data_root: Path, tmp_path: Path) -> Path:
    target = tmp_path / FOLDER
    target.mkdir(parents=True)
    for rel in (GROUNDTRUTH_FILE, LANDMARK_FILE, MEASUREMENT_FILE):
        shutil.copy(data_root / rel, tmp_path / rel)
    return tmp_path


def _replace_line(path: Path, line: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[line - 1] = text
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize(
    ("rel", "line", "text", "match"),
    [
        (MEASUREMENT_FILE, 5, "2 1 abc -0.19", "column 3: expected a number"),
        (MEASUREMENT_FILE, 7, "2 99 2.8 0.1", "landmark 99"),
        (GROUNDTRUTH_FILE, 4, "3 2.29 -2.47", "expected 4 columns, got 3"),
        (LANDMARK_FILE, 3, "2 nan 5.5", "finite"),
        (LANDMARK_FILE, 4, "2 3.7 4.5", r"landmark id 2 is listed twice \(first on line 3\)"),
        (MEASUREMENT_FILE, 3, "1 7.5 3.801 -0.238", "expected an integer landmark id"),
    ],
)
def test_malformed_rows_name_file_and_line(
    data_root: Path, tmp_path: Path, rel: str, line: int, text: str, match: str
) -> None:
    root = _copy_files(data_root, tmp_path)
    _replace_line(root / rel, line, text)
    with pytest.raises(DatasetFormatError, match=match) as info:
        load_mrclam_snapshots({}, seed=0, data_root=root)
    assert info.value.line == line
    assert info.value.path == root / rel
    assert f"{Path(rel).name}:{line}:" in str(info.value)


def test_a_measurement_file_with_only_its_header_is_refused(
    data_root: Path, tmp_path: Path
) -> None:
    root = _copy_files(data_root, tmp_path)
    path = root / MEASUREMENT_FILE
    header = [ln for ln in path.read_text().splitlines() if ln.startswith("#")]
    path.write_text("\n".join(header) + "\n")
    with pytest.raises(DatasetFormatError, match="expected at least 1 data row") as info:
        load_mrclam_snapshots({}, seed=0, data_root=root)
    assert info.value.path == path
