"""MRCLAM snapshots: the UTIAS MRCLAM data set 1 cut into stationary single-shot problems.

The Triangulation Toolbox conversion (``landmarks/utias_mrclam/triangulation_toolbox/`` under
the data root) keeps only the moments when a robot stood still (< 0.01 m, < 0.01 rad, ≤ 1 s)
and saw at least three landmarks, with outliers removed. Three whitespace-separated text files,
``#`` comment lines:

=============================  ==============================================================
``mrclam1_groundtruth.csv``    ``experiment_id x_m y_m theta_rad`` — the true robot pose
``mrclam1_landmark.csv``       ``landmark_id x_m y_m`` — the 15 landmarks (ids from 1)
``mrclam1_measurement.csv``    ``experiment_id landmark_id range_m bearing_rad``
=============================  ==============================================================

Each experiment becomes one :class:`LandmarkReadings` event at the **synthetic** time
``t = experiment_id`` seconds (the snapshots are independent; the times only order them), with
range-bearing readings ``z (K, 2)`` and the landmark ids of the file (already renumbered
1–15 by the conversion; the original MRCLAM subject ids are 6–20). The ground-truth trajectory
is the true pose of each experiment at the same times; ``known_landmarks`` (and the truth's
landmarks) is the map. There is no motion model and no prior: each snapshot must be solved on
its own (``least-squares`` estimator, or a filter initialised by
:func:`slamkit.localization.static.localize_from_readings`).

Nominal noise (:data:`SIGMA_RANGE`, :data:`SIGMA_BEARING`): the root mean square of the
residuals ``z − h(true pose, landmark)`` (range; wrapped bearing), bias included, over all
32,970 readings — 0.168 m and 0.0138 rad (std 0.164 m and 0.0127 rad, means −0.038 m and
−0.0054 rad) — rounded to 0.17 m and 0.014 rad. The error is not stationary: per block of
1000 experiments the range RMS varies from 0.06 to 0.22 m and the bearing RMS from 0.001 to
0.035 rad, the largest bearing errors being in the first block. Calibrating on the first
1000 experiments alone (0.150 m, 0.035 rad) would down-weight the bearings, which are the
precise half of the readings, and make the per-snapshot position fixes about 2.5 times worse
(median 0.115 m instead of 0.045 m). The conversion's outlier removal clips the residuals at
0.5 m and 0.1 rad.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from slamkit._validation import check_unique_ids
from slamkit.config import config_from_mapping
from slamkit.datasets.assemble import assemble_events, reading_events
from slamkit.datasets.paths import data_root as resolve_data_root
from slamkit.datasets.stream import Dataset, GroundTruth, LandmarkSensorSpec
from slamkit.datasets.text import NumericTable, integer_column, read_table
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.geometry import wrap_angle
from slamkit.maps import LandmarkMap

__all__ = [
    "FOLDER",
    "GROUNDTRUTH_FILE",
    "LANDMARK_FILE",
    "MEASUREMENT_FILE",
    "SIGMA_BEARING",
    "SIGMA_RANGE",
    "MrclamSnapshotOptions",
    "load_mrclam_snapshots",
]

FOLDER = "landmarks/utias_mrclam/triangulation_toolbox"
GROUNDTRUTH_FILE = f"{FOLDER}/mrclam1_groundtruth.csv"
LANDMARK_FILE = f"{FOLDER}/mrclam1_landmark.csv"
MEASUREMENT_FILE = f"{FOLDER}/mrclam1_measurement.csv"

SIGMA_RANGE = 0.17
"""Nominal range noise (m); see the module docstring for how it was measured."""
SIGMA_BEARING = 0.014
"""Nominal bearing noise (rad); see the module docstring for how it was measured."""


@dataclass(frozen=True)
class MrclamSnapshotOptions:
    """Options of :func:`load_mrclam_snapshots`."""

    sigma_range: float = SIGMA_RANGE
    """Range noise standard deviation written into the sensor spec (m)."""
    sigma_bearing: float = SIGMA_BEARING
    """Bearing noise standard deviation written into the sensor spec (rad)."""
    max_experiments: int | None = None
    """Keep only the first this many experiments (all when ``None``)."""

    def __post_init__(self) -> None:
        for name in ("sigma_range", "sigma_bearing"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: expected a finite number > 0, got {v!r}")
        if self.max_experiments is not None and self.max_experiments < 1:
            raise ConfigError(
                f"max_experiments: expected an integer >= 1, got {self.max_experiments!r}"
            )


def _integer_column(table: NumericTable, col: int, what: str, path: Path) -> np.ndarray:
    """Column ``col`` of ``table`` as integers (:func:`~slamkit.datasets.text.integer_column`,
    the message naming the column)."""
    return integer_column(table, col, f"{what} in column {col + 1}", path)


def _first_bad(table: NumericTable, bad: np.ndarray) -> int:
    return int(table.line_numbers[np.flatnonzero(bad)[0]])


def _read_landmarks(path: Path) -> LandmarkMap:
    table = read_table(path, 3)
    if len(table) == 0:
        raise DatasetFormatError("no landmarks in the file", path)
    ids = _integer_column(table, 0, "landmark id", path)
    check_unique_ids(ids, table.line_numbers, "landmark id", path)
    return LandmarkMap(table.values[:, 1:3].copy(), ids)


def _read_groundtruth(path: Path) -> tuple[np.ndarray, np.ndarray]:
    table = read_table(path, 4)
    if len(table) == 0:
        raise DatasetFormatError("no experiments in the file", path)
    ids = _integer_column(table, 0, "experiment id", path)
    not_increasing = np.r_[ids[0] < 1, np.diff(ids) <= 0]
    if not_increasing.any():
        raise DatasetFormatError(
            "experiment ids must be positive and increasing",
            path,
            _first_bad(table, not_increasing),
        )
    poses = table.values[:, 1:4].copy()
    poses[:, 2] = wrap_angle(poses[:, 2])
    return ids, poses


def _read_measurements(
    path: Path, experiments: np.ndarray, landmarks: LandmarkMap
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    table = read_table(path, 4)
    exp = _integer_column(table, 0, "experiment id", path)
    lid = _integer_column(table, 1, "landmark id", path)
    checks = (
        (~np.isin(exp, experiments), "experiment {e} is not in the ground truth file {g}"),
        (np.r_[False, np.diff(exp) < 0], "rows must be ordered by experiment ({e} is late)"),
        (~np.isin(lid, landmarks.ids), "landmark {l} is not in the landmark file {m}"),
        (~(table.values[:, 2] > 0), "expected a range > 0, got {r}"),
    )
    for bad, message in checks:
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            text = message.format(
                e=int(exp[i]),
                l=int(lid[i]),
                r=float(table.values[i, 2]),
                g=GROUNDTRUTH_FILE.rsplit("/", 1)[-1],
                m=LANDMARK_FILE.rsplit("/", 1)[-1],
            )
            raise DatasetFormatError(text, path, int(table.line_numbers[i]))
    z = table.values[:, 2:4].copy()
    z[:, 1] = wrap_angle(z[:, 1])
    return exp, lid, z


def load_mrclam_snapshots(
    options: Mapping[str, Any] | None, *, seed: int = 0, data_root: str | Path | None = None
) -> Dataset:
    """Load the MRCLAM 1 snapshots as a data set (see the module docstring).

    ``options`` (:class:`MrclamSnapshotOptions`): ``sigma_range``, ``sigma_bearing``,
    ``max_experiments``. ``seed`` is unused (real data). Raises
    :class:`~slamkit.errors.DataNotFoundError` if a file is missing and
    :class:`~slamkit.errors.DatasetFormatError` (file and line) on a malformed row.
    """
    cfg = config_from_mapping(MrclamSnapshotOptions, options, "mrclam-snapshots")
    root = resolve_data_root(data_root)
    landmarks = _read_landmarks(root / LANDMARK_FILE)
    exp_ids, poses = _read_groundtruth(root / GROUNDTRUTH_FILE)
    meas_exp, meas_lm, z = _read_measurements(root / MEASUREMENT_FILE, exp_ids, landmarks)
    if cfg.max_experiments is not None:
        keep = exp_ids[: cfg.max_experiments]
        exp_ids, poses = keep, poses[: keep.size]
        sel = meas_exp <= keep[-1]
        meas_exp, meas_lm, z = meas_exp[sel], meas_lm[sel], z[sel]

    # Rows are ordered by experiment (checked): one event per experiment.
    events = assemble_events(reading_events(meas_exp.astype(float), z, meas_lm))
    sensor = LandmarkSensorSpec(
        "range-bearing", np.diag([cfg.sigma_range**2, cfg.sigma_bearing**2])
    )
    times = exp_ids.astype(float)
    return Dataset(
        name="mrclam-snapshots",
        events=events,
        landmark_sensor=sensor,
        known_landmarks=landmarks,
        truth=GroundTruth(times=times, poses=poses, landmarks=landmarks),
        description=(
            "UTIAS MRCLAM 1 cut into stationary snapshots (Triangulation Toolbox): one "
            "range-bearing reading set per experiment, true pose, 15 known landmarks"
        ),
        metadata={
            "source": FOLDER,
            "experiments": int(exp_ids.size),
            "experiments_with_readings": len(events),
            "readings": int(meas_exp.size),
            "time": "synthetic: t = experiment id in seconds; snapshots are independent",
            "landmark_ids": "as in the file (renumbered 1-15 from MRCLAM subjects 6-20)",
            "noise": {
                "sigma_range_m": cfg.sigma_range,
                "sigma_bearing_rad": cfg.sigma_bearing,
                "basis": (
                    "RMS residual at the true poses over all readings"
                    if (cfg.sigma_range, cfg.sigma_bearing) == (SIGMA_RANGE, SIGMA_BEARING)
                    else "set by the options"
                ),
            },
        },
    )
