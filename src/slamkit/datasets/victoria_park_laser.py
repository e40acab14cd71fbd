"""Victoria Park's raw laser: the truck's 361-beam scans with its speed and steering, and GPS.

The same drive as :mod:`slamkit.datasets.victoria_park` (Guivant and Nebot's ACFR truck in
Sydney's Victoria Park), from the ASCII release in ``landmarks/victoria_park/raw_laser/``:
the scans the trees were extracted from, not the extracted trees. Estimators that read laser
scans (laser odometry, occupancy mapping, grid-based SLAM) run on it; the trees are in the
scans as small arcs of 0.1–0.5 m.

===================================  =======================================================
``laser.txt.gz``                     ``time_s r_0 .. r_360`` [s, m]: 7,230 scans, 180° at
                                     0.5°, beam 0 on the right (−90°), every 0.214 s
``drs.txt.gz``                       ``time_s speed steering`` [s, m/s, rad]: 61,763
                                     samples every 25 ms (the dead-reckoning sensors)
``gps.txt.gz``                       ``time_s north east`` [s, m, m]: 948 fixes, local
                                     metres (the first at the origin), gaps up to 181 s
``sensors_manager.txt.gz``           ``time_s sensor index``: the order the 69,941 readings
                                     arrived in (sensor 1 GPS, 2 DRS, 3 laser; index 1-based)
===================================  =======================================================

Times are seconds from the start of the log (0 to 1545.2 s). The ACFR files of
``victoria-park`` run on a clock 20.967 s ahead: the DRS samples are the first 61,763 of
``aa3_dr`` (speeds equal to the last digit; ``aa3_dr`` has 182 more at the end), and the GPS
fixes are 948 of ``aa3_gpsx``'s 4,466, less its first fix and with the **columns swapped**
(equal to 5 mm): ``documentation.txt`` names them ``GPSLat GPSLon``, north then east. The
loader gives GPS as ``(east, north)`` like ``victoria-park``. Read in the file's order the
track is mirrored: dead reckoning fits it with an RMSE of 9.57 m over the first 200 s,
against 2.62 m as ``(east, north)`` (the first 100 s are nearly straight and fit either
way).

The **steering is raw**: ``aa3_dr``'s steering is ``0.94412 x - 0.00246`` of this file's ``x``
(a least-squares fit, residual at most 5e-5 rad, the rounding), a calibration applied in the
ACFR release. The loader keeps the raw value: dead reckoning fits the GPS better with it
(whole-run RMSE 57.3 m, against 81.9 m with the calibration applied, same fixes), in
agreement with ``victoria-park``'s finding that its calibrated steering wants
``+0.0035..+0.0059`` rad more.

Conversion (:func:`load_victoria_park_laser`):

* **Controls**, exactly as ``victoria-park`` makes them from its odometry
  (:func:`~slamkit.datasets.victoria_park.read_odometry`,
  :func:`~slamkit.datasets.victoria_park.odometry_controls`,
  :func:`~slamkit.datasets.victoria_park.ackermann_motion`): DRS sample ``k`` is held over
  ``(t_k, t_{k+1}]`` as ``Control(t, (speed_k, steering_k), dt)`` for the
  :class:`~slamkit.models.Ackermann` model of the rear-axle centre (wheelbase 2.83 m, speed
  from the rear left wheel 0.76 m left of the centre line, steering positive to the left),
  cut at every scan time strictly inside an interval so that each scan sees the pose of its
  own time stamp. The nominal noise is that of ``victoria-park``.
* **Scans.** One :class:`LaserScan` per line. Beam ``i`` points at ``-90° + 0.5° i`` in the
  laser frame (x ahead, y left). The laser sits ``mounting = (a, b, 0) = (3.78, 0.50, 0)``
  on the vehicle (ahead of and left of the rear-axle centre:
  :data:`~slamkit.datasets.victoria_park.LASER_OFFSET`, whose sign convention and value are
  checked on the tree detections in that module). ``info.txt`` of the ACFR release says
  ranges above 8000 cm are "no reflexion": every reading of 80 m or more is stored as the
  :class:`LaserSpec`'s ``max_range`` = 80 m (:data:`~slamkit.datasets.victoria_park.
  LASER_MAX_RANGE`), the :class:`LaserScan` convention for no return. In this file that is
  the 81.91 m marker (2,017,831 readings), the SICK LMS error codes just below it (81.83,
  81.86, 81.87, 81.89 m: 148,476 readings; 81.87 m occurs in all but one scan, so it is no
  range) and 107 readings from 80 m up to 81.83 m.
* **Time order and ties.** A scan at the time of a DRS sample comes after the control that
  ends then, so it sees the pose at its time. ``sensors_manager`` gives the order in which
  readings arrived; it is read and checked against the three files (same readings, same
  times) but does not set the order: the pose at a time depends only on the samples before
  it, so the arrival order of a scan and a DRS sample of the same stamp (286 such ties)
  changes nothing, and GPS fixes are not events.
* **Scans outside the DRS samples.** The first scan (0.852 s) comes before the first DRS
  sample (0.973 s) and the last (1545.182 s) after the last (1545.023 s). Where the truck
  stands at that end (speed 0, as here) such a scan is kept — it sees the start or the end
  pose — and counted as repaired; where it moves, it is dropped and counted (its pose is not
  known).
* **GPS** is ``truth.position_times``/``truth.positions``, every fix as recorded, as in
  ``victoria-park``; :func:`slamkit.eval.gps.gps_error` rejects outliers and aligns.
* **Prior**: pose ``(0, 0, 0)`` with zero covariance, the start defines the frame.

``max_duration_s`` keeps the first that many seconds after the first DRS sample. What was
read, kept and repaired is in ``Dataset.reading`` (a
:class:`~slamkit.datasets.reading.ReadingSummary` of the laser file, with notes on the
others). Malformed lines (a wrong number of fields, a field that is not a number, a negative
range, times out of order, a steering angle the vehicle cannot take, a
``sensors_manager`` line that does not match) raise :class:`DatasetFormatError` naming the
file and the line.

**Checked on the data** (``tests/datasets/test_victoria_park_laser.py``): dead reckoning
of these controls fits the GPS over the first 60 s with an RMSE of 0.56 m (88 fixes) under a
rotation of 35.8° (the truck's initial heading in the GPS frame); aligned there, it ends
235.6 m from the last GPS fix (``victoria-park``'s odometry: 194.8 m; the truck ends 21.7 m
from where it started, dead reckoning 215 m). With the ACFR calibration applied to the
steering, dead reckoning here ends 1.3 m from ``victoria-park``'s at the same instant after
1545 s (2 cm after 100 s): the two loaders turn the same samples into the same motion.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.assemble import assemble_events, control_events, scan_events
from slamkit.datasets.carmen_parse import beam_angles_from_geometry
from slamkit.datasets.paths import data_root as resolve_data_root
from slamkit.datasets.reading import ReadingSummary, check_dropped_share
from slamkit.datasets.stream import Dataset, GroundTruth, LaserSpec
from slamkit.datasets.text import NumericTable, check_times, raise_at_first, read_table
from slamkit.datasets.victoria_park import (
    FOLDER,
    LASER_MAX_RANGE,
    LASER_OFFSET,
    ackermann_motion,
    odometry_controls,
    read_odometry,
)
from slamkit.errors import ConfigError, DataNotFoundError, DatasetFormatError

__all__ = [
    "DRS_FILE",
    "LASER_RANGE_SIGMA",
    "NO_RETURN_MARKER",
    "N_BEAMS",
    "RAW_GPS_FILE",
    "SCANS_FILE",
    "SENSORS_FILE",
    "VICTORIA_PARK_LASER_FILES",
    "VictoriaParkLaserOptions",
    "load_victoria_park_laser",
]

RAW_FOLDER = f"{FOLDER}/raw_laser"
SCANS_FILE = f"{RAW_FOLDER}/laser.txt.gz"
DRS_FILE = f"{RAW_FOLDER}/drs.txt.gz"
RAW_GPS_FILE = f"{RAW_FOLDER}/gps.txt.gz"
SENSORS_FILE = f"{RAW_FOLDER}/sensors_manager.txt.gz"
VICTORIA_PARK_LASER_FILES = (SCANS_FILE, DRS_FILE, RAW_GPS_FILE, SENSORS_FILE)
"""The files :func:`load_victoria_park_laser` reads, relative to the data root."""

N_BEAMS = 361
"""Beams per scan: 180° at 0.5°, both ends included."""
NO_RETURN_MARKER = 81.91
"""The range the file writes for no return [m] (8191 cm, the SICK LMS's 13-bit maximum)."""
SICK_ERROR_CODES = 81.83
"""From here up to :data:`NO_RETURN_MARKER` the SICK LMS writes error codes, not ranges [m]
(counted apart in the notes; all are above :data:`LASER_MAX_RANGE` and so no return)."""
LASER_RANGE_SIGMA = 0.05
"""Range noise of the :class:`LaserSpec` [m]: the range residual of the tree detections
measured in :mod:`slamkit.datasets.victoria_park` (MAD-based sigma 0.05 m)."""

_SENSORS = {1: "GPS", 2: "DRS", 3: "laser"}


@dataclass(frozen=True)
class VictoriaParkLaserOptions:
    """Options of :func:`load_victoria_park_laser` (units: seconds, radians)."""

    max_duration_s: float | None = None
    """Keep only the first this many seconds after the first DRS sample (all: None)."""
    steering_offset: float = 0.0
    """Added to every steering reading [rad], as ``victoria-park``'s option of the same name
    (the data there suggest +0.0035 to +0.0059)."""

    def __post_init__(self) -> None:
        if self.max_duration_s is not None and not self.max_duration_s > 0:
            raise ConfigError(f"max_duration_s: expected a number > 0, got {self.max_duration_s}")
        if not np.isfinite(self.steering_offset):
            raise ConfigError(
                f"steering_offset: expected a finite number, got {self.steering_offset}"
            )


def _require(root: Path, relative: str) -> Path:
    path = root / relative
    if not path.exists():
        raise DataNotFoundError(f"{path}: not found (needed under the data folder, SLAMKIT_DATA)")
    return path


def _read_scans(path: Path) -> NumericTable:
    """The scans: ``1 + N_BEAMS`` columns, strictly increasing times, ranges >= 0."""
    scans = read_table(path, 1 + N_BEAMS)
    check_times(scans, path, strict=True)
    negative = scans.values[:, 1:] < 0
    rows = negative.any(axis=1)
    if rows.any():
        r = int(np.argmax(rows))
        beam = int(np.argmax(negative[r]))
        raise DatasetFormatError(
            f"beam {beam}: expected a range >= 0 m, got {scans.values[r, 1 + beam]:g}",
            path,
            int(scans.line_numbers[r]),
        )
    return scans


def _check_sensors(
    table: NumericTable, path: Path, times: Mapping[int, np.ndarray], files: Mapping[int, str]
) -> dict[str, int]:
    """Check that ``sensors_manager`` lists exactly the readings of the three files: each
    sensor's lines numbered 1, 2, ... in order, at the time of that row of its file (to half
    a millisecond: both are written with three decimals). Returns counts for the metadata."""
    v = table.values
    check_times(table, path, strict=False)
    sensor = v[:, 1]
    raise_at_first(
        table,
        ~np.isin(sensor, list(_SENSORS)),
        path,
        "expected sensor 1 (GPS), 2 (DRS) or 3 (laser), got {1:g}",
    )
    for k, t_file in times.items():
        rows = np.flatnonzero(sensor == k)
        n = min(rows.size, t_file.size)
        index_ok = v[rows[:n], 2] == np.arange(1, n + 1)
        time_ok = np.abs(v[rows[:n], 0] - t_file[:n]) <= 5e-4
        bad = np.zeros(v.shape[0], dtype=bool)
        bad[rows[:n]] = ~(index_ok & time_ok)
        raise_at_first(
            table,
            bad,
            path,
            f"{_SENSORS[k]} reading {{2:g}} at {{0:g}} s does not match {files[k]}",
        )
        if rows.size != t_file.size:
            raise DatasetFormatError(
                f"lists {rows.size} {_SENSORS[k]} readings, {files[k]} holds {t_file.size}", path
            )
    ties = int(np.count_nonzero(np.diff(v[:, 0]) == 0))
    return {"arrivals": len(table), "same_time_as_previous": ties}


_DESCRIPTION = (
    "Victoria Park raw laser: 361-beam scans (180°, laser 3.78 m ahead of the rear axle), "
    "40 Hz Ackermann speed/steering, GPS positions as reference"
)


@dataclass(frozen=True)
class _Use:
    """Which scans the data set keeps (``use``), the cut, and the counts for the summary:
    the scans dropped by reason, those kept outside the DRS samples, the readings that are
    no return (all, the file's marker, the SICK error codes), the DRS samples used, the
    controls and the GPS fixes."""

    use: NDArray[np.bool_]
    cut: float
    dropped: dict[str, int]
    kept_outside: int
    n_far: int = 0
    n_marker: int = 0
    n_codes: int = 0
    n_drs_used: int = 0
    n_ctrl: int = 0
    n_gps: int = 0


def load_victoria_park_laser(
    options: Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    data_root: Path | None = None,
) -> Dataset:
    """Load Victoria Park's raw laser as a :class:`Dataset`: 361-beam scans from the laser
    mounted at ``(3.78, 0.50)`` m on the truck, Ackermann controls of the rear-axle centre
    from the speed and steering, GPS positions as reference, start at the origin.

    ``options`` are the fields of :class:`VictoriaParkLaserOptions`; ``seed`` is unused (real
    data); ``data_root`` defaults to :func:`slamkit.datasets.paths.data_root`. Raises
    :class:`DatasetFormatError` (file and line) on malformed lines and
    :class:`DataNotFoundError` when a file is missing. See the module docstring.
    """
    opts = config_from_mapping(VictoriaParkLaserOptions, options, "victoria-park-laser")
    root = resolve_data_root(data_root)
    p_scans, p_drs, p_gps, p_sensors = (_require(root, f) for f in VICTORIA_PARK_LASER_FILES)
    scans = _read_scans(p_scans)
    drs = read_odometry(p_drs, steering_offset=opts.steering_offset, unit="s")
    gps = read_table(p_gps, 3)
    check_times(gps, p_gps, strict=True)
    t_scan, t_drs, t_gps = scans.values[:, 0], drs.values[:, 0], gps.values[:, 0]
    arrivals = _check_sensors(
        read_table(p_sensors, 3),
        p_sensors,
        {1: t_gps, 2: t_drs, 3: t_scan},
        {1: p_gps.name, 2: p_drs.name, 3: p_scans.name},
    )
    use = _scans_used(t_scan, drs, opts.max_duration_s, p_scans)
    raw = scans.values[use.use, 1:]
    ranges = np.where(raw >= LASER_MAX_RANGE, LASER_MAX_RANGE, raw)  # info.txt: no return
    times_used = t_scan[use.use]
    # Controls cut at the scan times (as victoria-park's odometry).
    ends, dts, u = odometry_controls(
        t_drs, drs.values[:, 1:3], times_used, steering_offset=opts.steering_offset
    )
    n_ctrl = int(np.searchsorted(ends, use.cut, side="right"))
    use = replace(
        use,
        n_far=int(np.count_nonzero(raw >= LASER_MAX_RANGE)),
        n_marker=int(np.count_nonzero(raw >= NO_RETURN_MARKER)),
        n_codes=int(np.count_nonzero((raw >= SICK_ERROR_CODES) & (raw < NO_RETURN_MARKER))),
        n_drs_used=int(np.searchsorted(t_drs[1:], use.cut, side="right")),
        n_ctrl=n_ctrl,
        n_gps=int(np.searchsorted(t_gps, use.cut, side="right")),
    )
    a, b = LASER_OFFSET
    controls = control_events(ends[:n_ctrl], u[:n_ctrl], dts[:n_ctrl])
    return Dataset(
        name="victoria-park-laser",
        events=assemble_events(controls, scan_events(times_used, ranges)),
        motion=ackermann_motion(),
        laser=LaserSpec(
            beam_angles_from_geometry(N_BEAMS, 180.0, 0.5),
            LASER_MAX_RANGE,
            LASER_RANGE_SIGMA,
            mounting=(a, b, 0.0),
        ),
        initial_pose=np.zeros(3),
        initial_cov=np.zeros((3, 3)),
        truth=GroundTruth(
            position_times=t_gps[: use.n_gps],
            positions=gps.values[: use.n_gps, 2:0:-1].copy(),  # the file's columns: north, east
        ),
        description=_DESCRIPTION,
        metadata=_metadata(opts, use, (len(scans), len(drs)), arrivals),
        reading=_summary(use, len(scans), (p_drs.name, len(drs)), (p_gps.name, len(gps)), opts),
    )


def _scans_used(
    t_scan: FloatArray, drs: NumericTable, max_duration_s: float | None, path: Path
) -> _Use:
    """Scans outside the DRS samples are kept where the truck stands (its pose is known)
    and dropped where it moves; the rest up to the cut (``max_duration_s`` after the first
    DRS sample)."""
    t_drs = drs.values[:, 0]
    t0, t_last = float(t_drs[0]), float(t_drs[-1])
    before, after = t_scan < t0, t_scan > t_last
    drop_before = before & (drs.values[0, 1] != 0.0)  # a moving truck: pose unknown
    drop_after = after & (drs.values[-1, 1] != 0.0)
    drop = drop_before | drop_after
    dropped: dict[str, int] = {}
    for reason, mask in (
        ("before the first speed/steering sample, truck moving", drop_before),
        ("after the last speed/steering sample, truck moving", drop_after),
    ):
        if mask.any():
            dropped[reason] = int(np.count_nonzero(mask))
    check_dropped_share(path, t_scan.size, int(np.count_nonzero(drop)))
    cut = np.inf if max_duration_s is None else t0 + max_duration_s
    return _Use(
        use=~drop & (t_scan <= cut),
        cut=float(cut),
        dropped=dropped,
        kept_outside=int(np.count_nonzero((before | after) & ~drop)),
    )


def _summary(
    use: _Use,
    n_scans: int,
    drs: tuple[str, int],
    gps: tuple[str, int],
    opts: VictoriaParkLaserOptions,
) -> ReadingSummary:
    n_far, n_marker, n_codes = use.n_far, use.n_marker, use.n_codes
    notes = [
        f"{n_far} readings of {LASER_MAX_RANGE:g} m or more are no return (info.txt: beyond "
        f"8000 cm), stored as {LASER_MAX_RANGE:g} m: {n_marker} of {NO_RETURN_MARKER} m, "
        f"{n_codes} SICK error codes ({SICK_ERROR_CODES}-{NO_RETURN_MARKER} m), "
        f"{n_far - n_marker - n_codes} other",
        f"{drs[0]}: {use.n_drs_used} of {drs[1]} speed/steering samples used as {use.n_ctrl} "
        f"controls; {gps[0]}: {use.n_gps} of {gps[1]} GPS fixes",
    ]
    if opts.max_duration_s is not None:
        notes.append(f"cut at {use.cut:g} s (max_duration_s = {opts.max_duration_s:g})")
    repaired: dict[str, int] = {}
    if use.kept_outside:
        repaired["outside the speed/steering samples, truck standing: kept"] = use.kept_outside
    return ReadingSummary(
        file=SCANS_FILE,
        records=n_scans,
        used=int(np.count_nonzero(use.use)),
        dropped=use.dropped,
        repaired=repaired,
        notes=tuple(notes),
    )


def _metadata(
    opts: VictoriaParkLaserOptions,
    use: _Use,
    sizes: tuple[int, int],
    arrivals: dict[str, int],
) -> dict[str, Any]:
    a, b = LASER_OFFSET
    return {
        "kind": "real",
        "source": "Victoria Park, ACFR (Guivant & Nebot 2001), raw laser ASCII release",
        "files": list(VICTORIA_PARK_LASER_FILES),
        "time_origin": "seconds from the start of the log (not the clock of victoria-park)",
        "scans_in_file": sizes[0],
        "scans_used": int(np.count_nonzero(use.use)),
        "no_return_readings": use.n_far,
        "no_return_marker_readings": use.n_marker,
        "sick_error_code_readings": use.n_codes,
        "drs_samples": sizes[1],
        "drs_samples_used": use.n_drs_used,
        "controls": use.n_ctrl,
        "controls_added_by_splitting": use.n_ctrl - use.n_drs_used,
        "gps_fixes": use.n_gps,
        "sensor_arrivals": arrivals,
        "vehicle": {"laser_mounting": [a, b, 0.0], "state": "rear-axle centre"},
        "cut_at_s": None if opts.max_duration_s is None else float(use.cut),
        "options": config_to_dict(opts),
    }
