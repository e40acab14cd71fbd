"""Plaza 1: range-only localization with four radio beacons (CMU, Djugash et al.).

Djugash, Singh, Kantor and Zhang, "Range-only SLAM for robots operating cooperatively with
sensor networks", ICRA 2006; data from the Field Robotics Center, Carnegie Mellon University
(``http://www.frc.ri.cmu.edu/projects/emergencyresponse/RangeData/``). A robot drives about
1.9 km over 32 minutes on a plaza while ranging to four radio beacons placed around it.

Files under ``landmarks/plaza/`` (white space separated, ``#`` comments; the ``.csv`` files
are text exports of the variables of ``Plaza1_.mat``):

====================  ========================================================================
``Plaza1_DR.txt``     ``time distance heading_change`` — odometry increments since the
                      previous row [s, m, rad], about 5 Hz
``Plaza1_TD.txt``     ``time sender beacon range`` — range readings [s, -, -, m]
``Plaza1_GT.csv``     ``time x y heading`` — the true path [s, m, m, rad]
``Plaza1_TL.csv``     ``beacon x y`` — surveyed beacon positions [m]
``Plaza1_DRp.csv``    ``time x y heading`` — the path dead-reckoned by the authors (not read
                      by the loader; used by the tests)
====================  ========================================================================

Conversion (:func:`load_plaza1`):

* **Controls.** Row ``k`` of ``DR`` is the motion over ``(t_{k-1}, t_k]`` (the first row's
  interval starts at the first true pose). It becomes ``Control(t_k, u = (d / dt, dtheta /
  dt), dt)`` for :class:`~slamkit.models.UnicycleArc`: the distance is driven as an arc
  while the heading turns by ``dtheta`` at a constant rate. This reproduces what can be
  reproduced of ``Plaza1_DRp.csv``: its heading column is ``theta_0 + cumsum(dtheta)`` to
  1e-15 rad, and its step lengths equal ``d`` to 1e-8 m, while the arc's chords are shorter
  by ``d dtheta² / 24`` (under 1e-4 m a step). The *positions* of ``Plaza1_DRp.csv`` cannot be
  reproduced from ``DR``: its direction of travel drifts away from its own heading column by
  −7e-5 rad a step (−0.56 rad over the run, 42 m apart at worst), so it was integrated from
  a heading that is not in the files. The heading column of ``Plaza1_GT.csv`` is the same
  cumulative heading, and integrating ``DR`` stays within 4.5 m of the true path (RMS 1.9 m)
  where ``Plaza1_DRp.csv`` strays 45 m (RMS 20 m).
* **Readings between odometry rows.** The robot covers about 0.2 m between rows, so with
  ``split_at_readings`` (default) a control whose interval contains reading times is cut
  there into pieces with the same ``(v, omega)`` (exact for the arc): every reading then sees
  the pose at its own time stamp.
* **Readings.** ``TD`` is sorted by time (the file jumps back twice, by 64 s and 50 s, into
  stretches whose stamps agree with the true path); readings at the same stamp form one
  range-only :class:`LandmarkReadings` event with ids = beacon ids of ``Plaza1_TL.csv``
  (0, 1, 5, 6); readings of beacons not in it are dropped and counted. Ranges are multiplied
  by ``range_scale`` (below).
* **Truth and prior.** ``truth`` holds the path of ``Plaza1_GT.csv`` (headings wrapped) and
  the beacon map, which is also ``known_landmarks``. The prior is the first true pose with a
  small covariance, the published setting (the start is known). Times are those of the files.

**Range calibration** (measured against the truth): the recorded ranges are 7.0 % longer than
the distances from the true position (interpolated to the reading time) to the surveyed
beacon. A robust (soft-L1) fit over all 3529 readings gives ``z = 1.0700 d``; per beacon
1.068–1.071; an affine fit gives ``1.0692 d + 0.035 m``. Raw residuals: median +2.84 m,
MAD-based sigma 1.22 m. After dividing by 1.070: median −0.003 m, MAD-based sigma 0.494 m,
standard deviation 0.505 m, 0.37 % of readings beyond 3 sigma and none beyond 2 m. Hence
``range_scale = 1 / 1.070`` and ``sigma_range = 0.5`` m by default; ``range_scale = 1`` gives
the ranges as recorded (then the noise is far from zero-mean: choose ``sigma_range``
accordingly). The calibration is one number fitted on this run's ground truth: results with
it are for a calibrated sensor.

**Odometry noise** (measured against the truth): integrating ``DR`` between true poses ``n``
rows apart and comparing with the true relative motion, the along-track error has MAD-based
sigma 0.028 m over 25 rows (5 s), 0.073 m over 50 and 0.20 m over 100; cross-track 0.070,
0.127 and 0.27 m. A random walk with per-row sigmas 0.010 m along track and 0.0033 rad in
heading matches the 50-row values, and the 25- and 100-row ones within a factor 2; at 0.2 s
a row, that is ``sigma_v = 0.05`` m/s and ``sigma_omega = 0.017`` rad/s. (The heading error
itself cannot be measured: the true headings are the odometry's.) A control cut into pieces
draws the noise of each piece, ``(sigma dt_piece)²``, so a cut interval gets 2/3 of its
variance on average.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray, check_unique_ids
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.assemble import assemble_events, control_events, reading_events
from slamkit.datasets.paths import data_root as resolve_data_root
from slamkit.datasets.stream import (
    Dataset,
    GroundTruth,
    LandmarkReadings,
    LandmarkSensorSpec,
    MotionSpec,
)
from slamkit.datasets.text import NumericTable, integer_column, integer_values, read_table
from slamkit.errors import ConfigError, DataNotFoundError, DatasetFormatError
from slamkit.geometry import wrap_angle
from slamkit.maps import LandmarkMap
from slamkit.models import UnicycleArc

__all__ = [
    "DRP_FILE",
    "DR_FILE",
    "FOLDER",
    "GT_FILE",
    "PLAZA1_FILES",
    "RANGE_SCALE",
    "TD_FILE",
    "TL_FILE",
    "Plaza1Options",
    "load_plaza1",
]

FOLDER = "landmarks/plaza"
DR_FILE = f"{FOLDER}/Plaza1_DR.txt"
TD_FILE = f"{FOLDER}/Plaza1_TD.txt"
GT_FILE = f"{FOLDER}/Plaza1_GT.csv"
TL_FILE = f"{FOLDER}/Plaza1_TL.csv"
DRP_FILE = f"{FOLDER}/Plaza1_DRp.csv"
PLAZA1_FILES = (DR_FILE, TD_FILE, GT_FILE, TL_FILE)
"""The files :func:`load_plaza1` reads, relative to the data root."""

RANGE_SCALE = 1.0 / 1.070
"""Default factor applied to the recorded ranges (see the module docstring)."""


@dataclass(frozen=True)
class Plaza1Options:
    """Options of :func:`load_plaza1` (units: metres, radians, seconds)."""

    sigma_v: float = 0.05
    """Nominal speed noise [m/s] (0.010 m per 0.2 s odometry row; measured)."""
    sigma_omega: float = 0.017
    """Nominal turn-rate noise [rad/s] (0.0033 rad per row; measured)."""
    sigma_range: float = 0.5
    """Nominal range noise [m]: the robust spread of the calibrated ranges (measured)."""
    range_scale: float = RANGE_SCALE
    """Every recorded range is multiplied by this (1/1.070: calibrated; 1: as recorded)."""
    initial_sigma_xy: float = 0.05
    """Prior standard deviation of the start position about the first true pose [m]."""
    initial_sigma_theta: float = 0.02
    """Prior standard deviation of the start heading [rad]."""
    split_at_readings: bool = True
    """Cut controls at the reading times so that each reading sees the pose of its time."""
    max_duration_s: float | None = None
    """Keep only the first this many seconds after the first true pose (all when ``None``)."""

    def __post_init__(self) -> None:
        for name in ("sigma_v", "sigma_omega", "initial_sigma_xy", "initial_sigma_theta"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        for name in ("sigma_range", "range_scale"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a number > 0, got {getattr(self, name)}")
        if self.max_duration_s is not None and not self.max_duration_s > 0:
            raise ConfigError(f"max_duration_s: expected a number > 0, got {self.max_duration_s}")


def _require(root: Path, relative: str) -> Path:
    path = root / relative
    if not path.exists():
        raise DataNotFoundError(f"{path}: not found (needed under the data folder, SLAMKIT_DATA)")
    return path


def _check_increasing(table: NumericTable, path: Path, *, strict: bool) -> None:
    step = np.diff(table.values[:, 0])
    bad = np.flatnonzero(step <= 0 if strict else step < 0)
    if bad.size:
        what = "increasing" if strict else "non-decreasing"
        line = int(table.line_numbers[bad[0] + 1])
        raise DatasetFormatError(f"expected {what} times", path, line)


def _beacons(table: NumericTable, path: Path) -> LandmarkMap:
    ids = integer_column(table, 0, "beacon id", path)
    check_unique_ids(ids, table.line_numbers, "beacon id", path)
    return LandmarkMap(table.values[:, 1:3].copy(), ids)


def cut_intervals(
    t_start: FloatArray, t_end: FloatArray, cuts: FloatArray
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Cut the intervals ``(t_start[k], t_end[k]]`` at the times ``cuts`` that fall strictly
    inside one. Returns the end time, duration and interval index of every piece, in order."""
    k = np.searchsorted(t_end, cuts, side="left")
    inside = k < t_end.size
    inside[inside] &= (cuts[inside] > t_start[k[inside]]) & (cuts[inside] < t_end[k[inside]])
    ends = np.concatenate([t_end, cuts[inside]])
    owner = np.concatenate([np.arange(t_end.size), k[inside]])
    order = np.lexsort((ends, owner))
    ends, owner = ends[order], owner[order]
    first = np.ones(ends.size, dtype=bool)
    first[1:] = owner[1:] != owner[:-1]
    starts = np.where(first, t_start[owner], np.roll(ends, 1))
    return ends, ends - starts, owner


def load_plaza1(
    options: Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    data_root: Path | None = None,
) -> Dataset:
    """Load CMU Plaza 1 as a :class:`Dataset`: unicycle-arc controls from the odometry
    increments, range-only readings of four beacons (ids 0, 1, 5, 6), the true path, and
    the first true pose as the prior.

    ``options`` are the fields of :class:`Plaza1Options`; ``seed`` is unused (real data);
    ``data_root`` defaults to :func:`slamkit.datasets.paths.data_root`. Raises
    :class:`DatasetFormatError` (file and line) on malformed files and
    :class:`DataNotFoundError` when a file is missing.
    """
    opts = config_from_mapping(Plaza1Options, options, "plaza1")
    root = resolve_data_root(data_root)
    p_dr, p_td, p_gt, p_tl = (_require(root, f) for f in PLAZA1_FILES)
    dr, td, gt = read_table(p_dr, 3), read_table(p_td, 4), read_table(p_gt, 4)
    beacons = _beacons(read_table(p_tl, 3), p_tl)
    for table, path in ((dr, p_dr), (gt, p_gt)):
        if len(table) < 2:
            raise DatasetFormatError(f"expected at least 2 rows, got {len(table)}", path)
    _check_increasing(dr, p_dr, strict=True)
    _check_increasing(gt, p_gt, strict=False)
    gt_t = gt.values[:, 0]
    gt_pose = np.column_stack([gt.values[:, 1:3], wrap_angle(gt.values[:, 3])])
    t0 = float(gt_t[0])
    _check_odometry_start(dr, p_dr, t0, p_gt)
    cut = np.inf if opts.max_duration_s is None else t0 + float(opts.max_duration_s)
    t_end = dr.values[:, 0]
    t_begin = np.concatenate([[t0], t_end[:-1]])
    rates = _rates(dr, p_dr, t_end - t_begin)
    r_t, r_z, r_id, known = _ranges(td, p_td, beacons, opts.range_scale)
    n_read = int(np.searchsorted(r_t, cut, side="right"))
    readings = reading_events(r_t[:n_read], r_z[:n_read], r_id[:n_read])
    if opts.split_at_readings:
        group_t = np.asarray([ev.t for ev in readings], dtype=np.float64)
        ends, dts, owner = cut_intervals(t_begin, t_end, group_t)
    else:
        ends, dts, owner = t_end, t_end - t_begin, np.arange(t_end.size)
    n_ctrl = int(np.searchsorted(ends, cut, side="right"))
    controls = control_events(ends[:n_ctrl], rates[owner[:n_ctrl]], dts[:n_ctrl])
    n_truth = int(np.searchsorted(gt_t, cut, side="right"))
    s_xy, s_th = opts.initial_sigma_xy, opts.initial_sigma_theta
    return Dataset(
        name="plaza1",
        events=assemble_events(controls, readings),
        motion=MotionSpec(UnicycleArc(), np.diag([opts.sigma_v**2, opts.sigma_omega**2])),
        landmark_sensor=LandmarkSensorSpec(
            kind="range", noise_cov=np.array([[opts.sigma_range**2]])
        ),
        initial_pose=gt_pose[0],
        initial_cov=np.diag([s_xy**2, s_xy**2, s_th**2]),
        known_landmarks=beacons,
        truth=GroundTruth(times=gt_t[:n_truth], poses=gt_pose[:n_truth], landmarks=beacons),
        description=(
            "CMU Plaza 1: odometry increments at 5 Hz, range-only readings of 4 radio "
            "beacons (calibrated, see slamkit.datasets.plaza), true path; known start"
        ),
        metadata=_metadata(opts, dr, td, n_ctrl, readings, known, cut),
    )


def _check_odometry_start(dr: NumericTable, p_dr: Path, t0: float, p_gt: Path) -> None:
    if dr.values[0, 0] <= t0:
        raise DatasetFormatError(
            f"the first odometry row ({dr.values[0, 0]}) is not after the first true pose "
            f"({t0} in {p_gt.name})",
            p_dr,
            int(dr.line_numbers[0]),
        )


def _rates(dr: NumericTable, path: Path, span: FloatArray) -> FloatArray:
    """Odometry increments → constant ``(v, ω)`` over each row's interval ``span``."""
    with np.errstate(over="ignore"):  # an overflow is reported below, by its line
        rates = dr.values[:, 1:3] / span[:, None]  # (d / dt, dtheta / dt)
    bad = np.flatnonzero(~np.all(np.isfinite(rates), axis=1))
    if bad.size:
        r = int(bad[0])
        raise DatasetFormatError(
            f"the increment ({dr.values[r, 1]:g}, {dr.values[r, 2]:g}) over {span[r]:g} s "
            "overflows as a rate: expected increments of a plausible size",
            path,
            int(dr.line_numbers[r]),
        )
    return rates


def _ranges(
    td: NumericTable, path: Path, beacons: LandmarkMap, range_scale: float
) -> tuple[FloatArray, FloatArray, NDArray[np.int64], NDArray[np.bool_]]:
    """The readings of known beacons sorted by time: stamps, scaled ranges ``(K, 1)``, ids,
    and which rows of the file were of a known beacon."""
    m = td.values
    bad = np.flatnonzero(~(m[:, 3] > 0))
    if bad.size:
        r = int(bad[0])
        raise DatasetFormatError(
            f"expected a positive range, got {m[r, 3]}", path, int(td.line_numbers[r])
        )
    ids = integer_values(m[:, 2], td.line_numbers, "beacon id", path)
    known = np.isin(ids, beacons.ids)
    order = np.argsort(m[known, 0], kind="stable")
    r_z = (range_scale * m[known, 3][order])[:, None]
    return m[known, 0][order], r_z, ids[known][order], known


def _metadata(
    opts: Plaza1Options,
    dr: NumericTable,
    td: NumericTable,
    n_ctrl: int,
    readings: list[LandmarkReadings],
    known: NDArray[np.bool_],
    cut: float,
) -> dict[str, Any]:
    rows_used = int(np.searchsorted(dr.values[:, 0], cut, side="right"))
    return {
        "kind": "real",
        "source": "CMU Plaza 1 (Djugash et al., ICRA 2006)",
        "files": list(PLAZA1_FILES),
        "odometry_rows": len(dr),
        "odometry_rows_used": rows_used,
        "controls": n_ctrl,
        "controls_added_by_splitting": n_ctrl - rows_used,
        "readings_in_file": len(td),
        "readings_kept": sum(ev.ids.size for ev in readings),
        "reading_events": len(readings),
        "reading_time_jumps_back": int(np.count_nonzero(np.diff(td.values[:, 0]) < 0)),
        "dropped": {"unknown_beacon": int(np.count_nonzero(~known))},
        "senders": sorted({int(s) for s in np.unique(td.values[:, 1])}),
        "range_scale": opts.range_scale,
        "cut_at_s": None if opts.max_duration_s is None else cut,
        "options": config_to_dict(opts),
    }
