"""UTIAS MRCLAM: one robot of the Multi-Robot Cooperative Localization and Mapping data set.

Leung, Halpern, Barfoot and Liu, "The UTIAS Multi-Robot Cooperative Localization and Mapping
Dataset", IJRR 30(8), 2011. Five small robots drive among 15 landmark tubes indoors; each
robot logs its *commanded* velocities and camera readings (range, bearing) of barcodes on the
landmarks and on the other robots; a Vicon system surveyed the landmarks.

Files under ``landmarks/utias_mrclam/MRCLAM_Dataset<n>/`` (white space separated, ``#``
headers; the robot files may be gzip-compressed, ``.gz``):

==============================  =============================================================
``Barcodes.dat``                ``subject barcode`` — subjects 1–5 are the robots, 6–20 the
                                landmarks
``Landmark_Groundtruth.dat``    ``subject x y sx sy`` — Vicon landmark positions [m] and
                                their standard deviations
``Robot<r>_Odometry.dat``       ``time v omega`` — commanded speed [m/s] and turn rate
                                [rad/s], about 100 Hz, time in UNIX seconds
``Robot<r>_Measurement.dat``    ``time barcode range bearing`` [s, -, m, rad]
==============================  =============================================================

Conversion (:func:`load_mrclam`):

* **Controls.** Odometry sample ``k`` is the command held until sample ``k + 1``: it becomes
  ``Control(t_{k+1}, u = (v_k, omega_k), dt = t_{k+1} - t_k)`` for the
  :class:`~slamkit.models.UnicycleArc` model, whose constant-velocity arc is the exact motion
  under a piecewise-constant command (the Euler step would be off by half a step's turn
  wherever the log has gaps — 44 gaps over 0.2 s, up to 1 s, in Dataset 1). The last sample
  has no successor and gives no control.
* **Readings.** Barcodes are mapped to subjects through ``Barcodes.dat``; the landmark id of a
  reading is its *subject* number (6–20), the id used by the landmark map, after the label
  corrections below. Readings of other robots (subjects 1–5), of barcodes missing from
  ``Barcodes.dat``, of subjects without a surveyed position and readings earlier than the
  first odometry sample are dropped and counted in ``metadata["dropped"]``. Bearings are
  wrapped to ``[-pi, pi)``. Readings with the same time stamp form one
  :class:`LandmarkReadings` event, placed after the control that ends at that time. A
  reading between two odometry samples sees the pose of the earlier one: the robot moves at
  most 1 cm (99th percentile) and 6.6 cm (worst, in a gap) in that time in Dataset 1, well
  below the range noise.
* **Times** are seconds since the first odometry sample, rounded to the microsecond to
  drop the float rounding of the 1.2e9-second UNIX stamps (the files have millisecond
  resolution); ``metadata["start_time_unix_s"]`` keeps the absolute start.
* **Label corrections** (:data:`LABEL_CORRECTIONS`, option ``correct_labels``). In Dataset 1
  the readings that ``Barcodes.dat`` attributes to subject 11 (barcode 18) are of the landmark
  that ``Landmark_Groundtruth.dat`` places at subject 17's position, and those of subject 17
  (barcode 61) are of subject 11's: the two labels are swapped, so the loader swaps them back.
  Evidence, against the Vicon poses of the snapshots described below (Robot 1 readings within
  0.3 s of a snapshot): placed through the true pose, the 59 readings labelled 11 land
  (median) at (0.11, −2.72), 0.14 m from landmark 17 and 5.9 m from landmark 11; the 16
  labelled 17 land at (3.20, 2.39), 0.05 m from landmark 11 and 6.1 m from landmark 17 — while
  the readings of every other landmark land within 0.15 m of it. As labelled, every one of
  them misses by 2–4.7 m in range or 0.5–3 rad in bearing, so the snapshot conversion removed
  them as outliers (its files hold no reading of either landmark). With the labels swapped
  back, the median residuals of subjects 11 and 17 over the whole run (against the EKF track)
  are 1–2 cm and at most 0.003 rad, like the other landmarks'; 776 of Robot 1's 4771 landmark
  readings are relabelled. The Robot 1 files are the only evidence here: the correction is
  applied to Dataset 1 only (any robot, since ``Barcodes.dat`` and the landmark file are
  shared), and to no other data set until it has been checked there.
  ``metadata["label_corrections"]`` records what was applied.
* **Maps and truth.** ``known_landmarks`` and ``truth.landmarks`` are the Vicon landmark map
  (ids = subjects); with ``landmarks_known=False`` (for SLAM) the map is ground truth only
  and ``known_landmarks`` is ``None``. The robots' true trajectories are not part of the
  files here, so the data set has no true trajectory, and no prior pose: the start is
  unknown (localize globally, or from the first readings).

Nominal noise — measured, not taken from the paper (which gives no such numbers). The
Triangulation Toolbox conversion of Dataset 1 (``landmarks/utias_mrclam/triangulation_toolbox``)
holds Vicon poses of the robots at moments when they stood still; its experiments 1–1085 are
Robot 1's (every one of their readings appears, with equal values, in
``Robot1_Measurement.dat`` within 1.5 s). Against those true poses:

* readings (3419, outliers already removed by the conversion): range residual median
  −0.024 m, MAD-based sigma 0.135 m, RMS 0.148 m; bearing residual median −0.010 rad,
  standard deviation 0.031 rad, RMS 0.034 rad → ``sigma_range = 0.15`` m,
  ``sigma_bearing = 0.035`` rad (the values of :mod:`slamkit.datasets.mrclam_snapshots`).
  The stream here is *not* cleaned. Of the 641 readings of Robot 1 within 0.3 s of a
  snapshot, 13 % lie more than 3 sigma from the truth in range or bearing with the labels of
  the files, nearly all of them (75 of 86) readings of the swapped subjects 11 and 17; with
  the labels corrected, 2.2 % (14). At the true poses the NIS per degree of freedom of these
  641 readings, with these sigmas, is then 1.13 on average. Gate the remaining outliers.
  The errors are not white, though: the range error depends on where the landmark is in the
  image (median −0.25 m beyond 0.45 rad of bearing, +0.07 to +0.09 m within 0.15 rad of the
  axis) and the bearing bias drifts by up to ±0.04 rad from one stretch of the run to the
  next. A filter that treats them as white follows them: the EKF on this stream has a NIS
  per degree of freedom of about 0.5 while its pose NEES at the snapshot poses is about 11
  (3 dof).
* controls: the commanded motion integrated between two true poses 0.5–40 s apart (about
  77,000 pairs) misses the true relative motion by an RMS of 0.008–0.085 m along the path and
  0.016–0.10 rad in heading. Treating the velocity error as white noise on each 10 ms
  command, the spread after ``T`` seconds is ``sigma * sqrt(0.01 s * T)``; matching the
  measured heading and along-track errors over 1–40 s gives 0.08–0.23 for both, so
  ``sigma_v = 0.2`` m/s and ``sigma_omega = 0.2`` rad/s *per command* (2 cm and 0.02 rad after
  1 s, 6 cm and 0.06 rad after 10 s). Over a minute and more the real errors are larger and
  systematic (about 10 % of the distance driven): estimators must use the landmarks. Since
  the covariance of a step scales with ``dt²``, the rare long gaps get a generous share.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray, check_unique_ids
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.assemble import assemble_events, control_events, reading_events
from slamkit.datasets.paths import data_root as resolve_data_root
from slamkit.datasets.stamps import MAX_PLAUSIBLE_STAMP
from slamkit.datasets.stream import (
    Dataset,
    GroundTruth,
    LandmarkReadings,
    LandmarkSensorSpec,
    MotionSpec,
)
from slamkit.datasets.text import NumericTable, integer_column, read_table
from slamkit.errors import ConfigError, DataNotFoundError, DatasetFormatError
from slamkit.geometry import wrap_angle
from slamkit.maps import LandmarkMap
from slamkit.models import UnicycleArc

__all__ = [
    "LABEL_CORRECTIONS",
    "ROBOT_SUBJECTS",
    "MrclamOptions",
    "load_mrclam",
    "mrclam_files",
]

ROBOT_SUBJECTS = frozenset(range(1, 6))
"""Subject numbers of the five robots; every other subject is a landmark."""

LABEL_CORRECTIONS: Mapping[int, Mapping[int, int]] = MappingProxyType(
    {1: MappingProxyType({11: 17, 17: 11})}
)
"""Per data set, ``subject as labelled through Barcodes.dat -> subject actually seen``, applied
to the readings when ``correct_labels`` is set (Dataset 1: subjects 11 and 17 swapped; the
evidence is in the module docstring)."""

_TIME_DECIMALS = 6


@dataclass(frozen=True)
class MrclamOptions:
    """Options of :func:`load_mrclam` (units: metres, radians, seconds)."""

    dataset: int = 1
    """Which MRCLAM data set (1–9): the folder ``MRCLAM_Dataset<n>``."""
    robot: int = 1
    """Which robot (1–5): the files ``Robot<r>_Odometry.dat`` and ``Robot<r>_Measurement.dat``."""
    sigma_v: float = 0.2
    """Nominal speed noise per 10 ms command [m/s] (measured; see the module docstring)."""
    sigma_omega: float = 0.2
    """Nominal turn-rate noise per 10 ms command [rad/s] (measured; see the module docstring)."""
    sigma_range: float = 0.15
    """Nominal range noise [m] (measured against Vicon poses; see the module docstring)."""
    sigma_bearing: float = 0.035
    """Nominal bearing noise [rad] (measured against Vicon poses)."""
    max_duration_s: float | None = None
    """Keep only the events of the first this many seconds (all when ``None``)."""
    correct_labels: bool = True
    """Apply :data:`LABEL_CORRECTIONS` for this data set (Dataset 1: subjects 11 and 17 swapped
    back). ``False`` keeps the labels of ``Barcodes.dat`` as they are."""
    landmarks_known: bool = True
    """Give estimators the Vicon map as ``known_landmarks`` (localization). ``False``: the map
    is only ground truth (``truth.landmarks``), for SLAM."""

    def __post_init__(self) -> None:
        if not 1 <= self.dataset <= 9:
            raise ConfigError(f"dataset: expected 1 to 9, got {self.dataset}")
        if self.robot not in ROBOT_SUBJECTS:
            raise ConfigError(f"robot: expected 1 to 5, got {self.robot}")
        for name in ("sigma_v", "sigma_omega"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        for name in ("sigma_range", "sigma_bearing"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a number > 0, got {getattr(self, name)}")
        if self.max_duration_s is not None and not self.max_duration_s > 0:
            raise ConfigError(f"max_duration_s: expected a number > 0, got {self.max_duration_s}")


def _folder(options: MrclamOptions) -> str:
    return f"landmarks/utias_mrclam/MRCLAM_Dataset{options.dataset}"


def mrclam_files(dataset: int = 1, robot: int = 1) -> tuple[str, ...]:
    """The files a robot of a data set needs, relative to the data root (as shipped here,
    the odometry gzip-compressed; the uncompressed original is accepted as well)."""
    folder = _folder(MrclamOptions(dataset=dataset, robot=robot))
    return (
        f"{folder}/Barcodes.dat",
        f"{folder}/Landmark_Groundtruth.dat",
        f"{folder}/Robot{robot}_Measurement.dat",
        f"{folder}/Robot{robot}_Odometry.dat.gz",
    )


def _find(root: Path, relative: str) -> Path:
    """``relative`` under ``root``, or its gzip-compressed / uncompressed twin."""
    path = root / relative
    twin = path.with_suffix("") if path.suffix == ".gz" else path.with_name(path.name + ".gz")
    for p in (path, twin):
        if p.exists():
            return p
    raise DataNotFoundError(f"{path}: not found (needed under the data folder, SLAMKIT_DATA)")


def _barcode_table(table: NumericTable, path: Path) -> dict[int, int]:
    """``barcode -> subject`` from ``Barcodes.dat`` (both columns integers, barcodes unique)."""
    integer_column(table, 0, "subject", path)
    integer_column(table, 1, "barcode", path)
    out: dict[int, int] = {}
    for (subject, barcode), line in zip(table.values, table.line_numbers, strict=True):
        if int(barcode) in out:
            raise DatasetFormatError(f"barcode {int(barcode)} listed twice", path, int(line))
        out[int(barcode)] = int(subject)
    if not out:
        raise DatasetFormatError("no barcodes", path)
    return out


def _landmark_map(table: NumericTable, path: Path) -> LandmarkMap:
    ids = integer_column(table, 0, "subject", path)
    check_unique_ids(ids, table.line_numbers, "subject", path)
    if ids.size == 0:
        raise DatasetFormatError("no landmarks", path)
    return LandmarkMap(table.values[:, 1:3].copy(), ids)


def _check_stamps(table: NumericTable, path: Path) -> None:
    """Stamps must be Unix times (0 to :data:`MAX_PLAUSIBLE_STAMP`): a finite 1e308 would
    overflow the differences and the times relative to the start, and reach the data set
    as an infinite time that no longer names this file."""
    t = table.values[:, 0]
    bad = np.flatnonzero(~((t >= 0.0) & (t <= MAX_PLAUSIBLE_STAMP)))
    if bad.size:
        r = int(bad[0])
        raise DatasetFormatError(
            f"time {t[r]!r} s: not a Unix time (expected 0 to {MAX_PLAUSIBLE_STAMP:g} s)",
            path,
            int(table.line_numbers[r]),
        )


@dataclass(frozen=True)
class _Readings:
    """Robot readings converted: sorted stamps (relative to the start), ``(range, bearing)``
    rows, subject ids, and what was dropped or relabelled."""

    t: FloatArray
    z: FloatArray
    ids: NDArray[np.int64]
    dropped: dict[str, int]
    relabelled: int


def load_mrclam(
    options: Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    data_root: Path | None = None,
) -> Dataset:
    """Load one robot of an MRCLAM data set (Dataset 1, Robot 1 by default) as a
    :class:`Dataset`: unicycle-arc controls, range-bearing readings of the 15 landmarks with
    ids = subject numbers, the Vicon landmark map, no prior and no true trajectory.

    ``options`` are the fields of :class:`MrclamOptions`; ``seed`` is unused (real data);
    ``data_root`` defaults to :func:`slamkit.datasets.paths.data_root`. Raises
    :class:`DatasetFormatError` (file and line) on malformed files and
    :class:`DataNotFoundError` when a file is missing.
    """
    opts = config_from_mapping(MrclamOptions, options, "mrclam")
    root = resolve_data_root(data_root)
    folder = _folder(opts)
    files = [
        _find(root, f"{folder}/{name}")
        for name in (
            "Barcodes.dat",
            "Landmark_Groundtruth.dat",
            f"Robot{opts.robot}_Odometry.dat",
            f"Robot{opts.robot}_Measurement.dat",
        )
    ]
    p_barcodes, p_landmarks, p_odometry, p_readings = files
    barcode_to_subject = _barcode_table(read_table(p_barcodes, 2), p_barcodes)
    world = _landmark_map(read_table(p_landmarks, 5), p_landmarks)
    odo, meas = read_table(p_odometry, 3), read_table(p_readings, 4)
    _check_odometry(odo, p_odometry)
    _check_stamps(meas, p_readings)
    _check_readings(meas, p_readings)
    t_start = float(odo.values[0, 0])
    ctrl_t, ctrl_u, ctrl_dt = _controls(odo, t_start)
    corrections = dict(LABEL_CORRECTIONS.get(opts.dataset, {})) if opts.correct_labels else {}
    readings = _readings(meas, barcode_to_subject, world, corrections, t_start)
    cut = np.inf if opts.max_duration_s is None else float(opts.max_duration_s)
    n_ctrl = int(np.searchsorted(ctrl_t, cut, side="right"))
    n_read = int(np.searchsorted(readings.t, cut, side="right"))
    controls = control_events(ctrl_t[:n_ctrl], ctrl_u[:n_ctrl], ctrl_dt[:n_ctrl])
    read = reading_events(readings.t[:n_read], readings.z[:n_read], readings.ids[:n_read])
    sensor = LandmarkSensorSpec(
        kind="range-bearing",
        noise_cov=np.diag([opts.sigma_range**2, opts.sigma_bearing**2]),
    )
    return Dataset(
        name=f"mrclam{opts.dataset}",
        events=assemble_events(controls, read),
        motion=MotionSpec(UnicycleArc(), np.diag([opts.sigma_v**2, opts.sigma_omega**2])),
        landmark_sensor=sensor,
        known_landmarks=world if opts.landmarks_known else None,
        truth=GroundTruth(landmarks=world),
        description=(
            f"UTIAS MRCLAM data set {opts.dataset}, robot {opts.robot}: commanded velocities "
            "at 100 Hz, camera range-bearing readings of 15 landmarks, Vicon landmark map; "
            "no prior, no true trajectory"
        ),
        metadata=_metadata(
            opts, root, files, (odo, meas), (t_start, n_ctrl), readings, read, corrections
        ),
    )


def _check_odometry(odo: NumericTable, path: Path) -> None:
    """At least two samples, Unix stamps, never going back."""
    if len(odo) < 2:
        raise DatasetFormatError(f"expected at least 2 odometry samples, got {len(odo)}", path)
    _check_stamps(odo, path)
    back = np.flatnonzero(np.diff(odo.values[:, 0]) < 0)
    if back.size:
        raise DatasetFormatError("time goes backwards", path, int(odo.line_numbers[back[0] + 1]))


def _check_readings(meas: NumericTable, path: Path) -> None:
    """Positive ranges and integer barcodes."""
    m = meas.values
    bad_range = np.flatnonzero(~(m[:, 2] > 0))
    if bad_range.size:
        r = bad_range[0]
        raise DatasetFormatError(
            f"expected a positive range, got {m[r, 2]}", path, int(meas.line_numbers[r])
        )
    barcodes = m[:, 1]
    if np.any(barcodes != np.round(barcodes)):
        r = int(np.flatnonzero(barcodes != np.round(barcodes))[0])
        raise DatasetFormatError("expected an integer barcode", path, int(meas.line_numbers[r]))


def _controls(odo: NumericTable, t_start: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Command ``k`` holds over ``(t_k, t_{k+1}]``: the controls' end stamps, ``(v, ω)`` and
    durations, in seconds since ``t_start``."""
    t_odo = np.round(odo.values[:, 0] - t_start, _TIME_DECIMALS)
    return t_odo[1:], odo.values[:-1, 1:3], np.round(np.diff(t_odo), _TIME_DECIMALS)


def _readings(
    meas: NumericTable,
    barcode_to_subject: Mapping[int, int],
    world: LandmarkMap,
    corrections: Mapping[int, int],
    t_start: float,
) -> _Readings:
    """Barcode → subject (label corrections applied); readings of robots, of unknown
    barcodes, of unmapped subjects and before the odometry dropped and counted; the rest
    sorted by time."""
    m = meas.values
    subjects = np.array([barcode_to_subject.get(int(b), -1) for b in m[:, 1]], dtype=np.int64)
    relabelled = np.isin(subjects, list(corrections))
    subjects[relabelled] = [corrections[int(s)] for s in subjects[relabelled]]
    unknown = subjects < 0
    robots = np.isin(subjects, list(ROBOT_SUBJECTS))
    not_mapped = ~unknown & ~robots & ~np.isin(subjects, world.ids)
    early = m[:, 0] < t_start
    keep = ~(unknown | robots | not_mapped | early)
    dropped = {
        "robot": int(robots.sum()),
        "unknown_barcode": int(unknown.sum()),
        "no_landmark_position": int(not_mapped.sum()),
        "before_odometry": int((early & ~(unknown | robots | not_mapped)).sum()),
    }
    order = np.argsort(m[keep, 0], kind="stable")
    return _Readings(
        t=np.round(m[keep, 0] - t_start, _TIME_DECIMALS)[order],
        z=np.column_stack([m[keep, 2], wrap_angle(m[keep, 3])])[order],
        ids=subjects[keep][order],
        dropped=dropped,
        relabelled=int(relabelled[keep].sum()),
    )


def _metadata(
    opts: MrclamOptions,
    root: Path,
    files: list[Path],
    tables: tuple[NumericTable, NumericTable],
    start_and_controls: tuple[float, int],
    readings: _Readings,
    events: list[LandmarkReadings],
    corrections: Mapping[int, int],
) -> dict[str, Any]:
    cut = opts.max_duration_s
    (odo, meas), (t_start, n_ctrl) = tables, start_and_controls
    return {
        "kind": "real",
        "source": f"UTIAS MRCLAM Dataset {opts.dataset}, robot {opts.robot}",
        "files": [str(p.relative_to(root)) for p in files],
        "start_time_unix_s": t_start,
        "odometry_samples": len(odo),
        "controls": n_ctrl,
        "readings_in_file": len(meas),
        "readings_kept": sum(ev.ids.size for ev in events),
        "reading_events": len(events),
        "dropped": readings.dropped,
        "label_corrections": {
            "applied": {str(k): v for k, v in sorted(corrections.items())},
            "readings_relabelled": readings.relabelled,
        },
        "cut_at_s": None if cut is None else float(cut),
        "options": config_to_dict(opts),
    }
