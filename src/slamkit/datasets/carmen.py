"""Readers for laser logs: the CARMEN format (corrected logs) and the DP-SLAM format.

Both produce the standard :class:`~slamkit.datasets.Dataset`: one :class:`Odometry` and one
:class:`LaserScan` event per scan (in that order, at the scan's time stamp), a
:class:`LaserSpec`, an odometry :class:`MotionSpec` and, for the corrected CARMEN logs, the
corrected laser poses as ground truth.

**CARMEN** (``*.log`` or ``*.log.gz``, gzip detected from the content). Lines::

    # comment
    PARAM name value [ts host logger_ts]
    FLASER n r1 .. rn x y theta odom_x odom_y odom_theta ts host logger_ts
    ODOM x y theta tv rv accel ts host logger_ts
    NEFF value

Ranges are metres; ``x y theta`` is the pose of the *laser* (the beam angles are measured
from its heading). In the corrected logs both pose triples of a ``FLASER`` line hold the
SLAM-corrected pose, which we use as the true trajectory (``truth.times``/``truth.poses``).

Why the ``ODOM`` lines are not used as odometry: in these logs they do not line up with the
scans' time stamps (their relative motions between two scans disagree with the corrected ones
by as much as the motions themselves; see ``DATA.md``), so integrating them would make any
filter look bad for reasons that have nothing to do with the filter. Instead the odometry is
*derived from the corrected poses with known added noise*: the motion between consecutive
scans as ``(rot1, trans, rot2)`` (:func:`~slamkit.models.odometry_control`) plus Gaussian noise
of the standard deviations in :class:`CarmenOptions`, integrated from the first corrected pose.
The data set's :class:`MotionSpec` carries exactly that noise covariance, so an estimator's
noise model is correct by construction. The noise comes from ``np.random.default_rng(seed)``.
``ODOM`` lines are still checked for their form and counted in ``metadata``.

Beam geometry: ``fov_deg``/``angular_resolution_deg`` from the options, else from the
``PARAM`` lines ``laser_front_laser_fov`` and ``laser_front_laser_resolution`` where present,
else from the beam count (180 or 181 beams = 180° at 1°, 360 or 361 = 180° at 0.5°). Beam
``i`` points at ``-fov/2 + i * resolution`` (from the right, counter-clockwise). A scan whose
beam count disagrees with that geometry is a format error.

Max range: readings ``>= max_range`` mean "no return" and are stored as exactly
``max_range`` (the :class:`LaserScan` convention). ``max_range`` is the option if given, else
``PARAM robot_front_laser_max``, else 80 m (SICK LMS).

Errors: a malformed line (wrong number of fields, a field that is not a number, a NaN,
infinite or negative range, a beam count that disagrees with the geometry) raises
:class:`~slamkit.errors.DatasetFormatError` naming the file and the line. With
``lenient=True`` such lines are skipped instead and counted in
``metadata["skipped_lines"]`` (with the first few line numbers and reasons).

Time stamps: a scan whose time stamp is not later than the previous one (four in the Intel
log, out of order by up to 0.9 s while the poses show the file order is the driving order)
keeps its place in the file and gets the previous time plus 1 ms; the number of such repairs
is ``metadata["timestamps_repaired"]``.

**DP-SLAM** (``loop5.log.gz``): alternating ``Odometry x y theta`` and
``Laser 181 r1 .. r181`` lines (180° at 1°, metres), raw odometry and no ground truth. The
log has no time stamps: scan ``k`` is placed at ``t = k * scan_period``. The laser is a SICK
LMS in its 8 m mode, which reports error codes just above 8.18 m (8183 mm "value above the
maximum", 8187, 8191); every reading ``>= max_range`` (default 8.183 m) is "no return".

The line parsing (file reading, number blocks, beam geometry, the CARMEN lines) lives in
:mod:`slamkit.datasets.carmen_parse`; this module turns parsed logs into data sets and holds
the registry's loaders.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from slamkit._validation import FloatArray
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.assemble import assemble_events, odometry_events, scan_events
from slamkit.datasets.carmen_parse import (
    SKIPPED_SHOWN,
    CarmenLog,
    LineProblems,
    LogGeometry,
    beam_angles_from_geometry,
    ignored_lines,
    log_geometry,
    parse_carmen_log,
    parse_floats,
    read_lines,
    resolve_geometry,
)
from slamkit.datasets.paths import data_root as resolve_data_root
from slamkit.datasets.paths import require_file
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.reading import ReadingSummary, check_dropped_share
from slamkit.datasets.stamps import RESTAMP_REASON, StampRepair, repair_stamps
from slamkit.datasets.stream import (
    Dataset,
    GroundTruth,
    LaserSpec,
    MotionSpec,
)
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.geometry.angles import wrap_angle
from slamkit.models import OdometryModel, integrate_odometry, odometry_control

__all__ = [
    "CARMEN_FILES",
    "DEFAULT_MAX_RANGE",
    "CarmenLog",
    "CarmenOptions",
    "DpSlamOptions",
    "beam_angles_from_geometry",
    "carmen_dataset",
    "load_aces",
    "load_freiburg079",
    "load_intel",
    "load_loop5",
    "parse_carmen_log",
    "read_carmen_log",
    "read_dpslam_log",
]

DEFAULT_MAX_RANGE = 80.0
"""Max range of a SICK LMS [m] when a log does not say otherwise."""

CARMEN_FILES: dict[str, str] = {
    "intel": "laser/corrected_carmen/intel-corrected.log.gz",
    "aces": "laser/corrected_carmen/aces-corrected.log.gz",
    "freiburg-079": "laser/corrected_carmen/freiburg-079-corrected.log.gz",
    "loop5": "laser/dpslam/loop5.log.gz",
}
"""Registered data set name → file under the data root."""

STAMP_PERIOD = 1.0
"""[s] between scans of a log whose stamps carry no timing (all zero, or one rounded value),
re-made from the line order: the corrected logs keep a scan every 1-5 s."""


# --------------------------------------------------------------------------------------------
# options
# --------------------------------------------------------------------------------------------


def _check_positive_or_none(value: float | None, name: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{name}: expected a finite number > 0 or nothing, got {value!r}")


def _check_sigma(value: float, name: str) -> None:
    if not (math.isfinite(value) and value >= 0):
        raise ConfigError(f"{name}: expected a finite number >= 0, got {value!r}")


@dataclass(frozen=True)
class CarmenOptions:
    """How to read a corrected CARMEN log. Units: metres, seconds, degrees where named."""

    max_range: float | None = None
    """Readings at or beyond this are "no return" [m]; None: ``PARAM robot_front_laser_max``,
    else 80 m."""
    fov_deg: float | None = None
    """Field of view [deg]; None: ``PARAM laser_front_laser_fov``, else from the beam count."""
    angular_resolution_deg: float | None = None
    """Angle between beams [deg]; None: ``PARAM laser_front_laser_resolution``, else from the
    beam count."""
    range_sigma: float = 0.01
    """Nominal range noise stored in the :class:`LaserSpec` [m] (the log does not say)."""
    odometry_sigma_trans: float = 0.02
    """Standard deviation of the noise added to each step's translation [m]."""
    odometry_sigma_rot_deg: float = 1.0
    """Standard deviation of the noise added to each step's two rotations [deg]."""
    lenient: bool = False
    """Skip malformed lines (and count them) instead of raising DatasetFormatError."""

    def __post_init__(self) -> None:
        _check_positive_or_none(self.max_range, "max_range")
        _check_positive_or_none(self.fov_deg, "fov_deg")
        _check_positive_or_none(self.angular_resolution_deg, "angular_resolution_deg")
        _check_sigma(self.range_sigma, "range_sigma")
        _check_sigma(self.odometry_sigma_trans, "odometry_sigma_trans")
        _check_sigma(self.odometry_sigma_rot_deg, "odometry_sigma_rot_deg")

    def odometry_cov(self) -> FloatArray:
        """Covariance of the added ``(rot1, trans, rot2)`` noise per step (rad², m², rad²)."""
        sr = math.radians(self.odometry_sigma_rot_deg)
        return np.diag([sr**2, self.odometry_sigma_trans**2, sr**2])


@dataclass(frozen=True)
class DpSlamOptions:
    """How to read a DP-SLAM log (raw odometry, no ground truth)."""

    max_range: float = 8.183
    """Readings at or beyond this are "no return" [m] (SICK 8 m mode error codes)."""
    fov_deg: float = 180.0
    """Field of view [deg] of the 181 beams (1° apart)."""
    scan_period: float = 1.0
    """The log has no time stamps: scan k is placed at ``k * scan_period`` [s]."""
    range_sigma: float = 0.01
    """Nominal range noise stored in the :class:`LaserSpec` [m]."""
    odometry_sigma_trans: float = 0.05
    """Nominal per-step translation noise of the raw odometry [m] (for the MotionSpec)."""
    odometry_sigma_rot_deg: float = 2.0
    """Nominal per-step rotation noise of the raw odometry [deg] (for the MotionSpec)."""
    lenient: bool = False
    """Skip malformed lines (and count them) instead of raising DatasetFormatError."""

    def __post_init__(self) -> None:
        for name in ("max_range", "fov_deg", "scan_period"):
            _check_positive_or_none(getattr(self, name), name)
        for name in ("range_sigma", "odometry_sigma_trans", "odometry_sigma_rot_deg"):
            _check_sigma(getattr(self, name), name)

    def odometry_cov(self) -> FloatArray:
        sr = math.radians(self.odometry_sigma_rot_deg)
        return np.diag([sr**2, self.odometry_sigma_trans**2, sr**2])


def _noisy_odometry(poses: FloatArray, cov: FloatArray, rng: np.random.Generator) -> FloatArray:
    """Odometry poses ``(N, 3)``: the true steps ``(rot1, trans, rot2)`` plus N(0, cov) noise,
    integrated from the first true pose (:func:`~slamkit.models.integrate_odometry`)."""
    steps = odometry_control(poses[:-1], poses[1:])
    noisy = steps + rng.standard_normal(steps.shape) * np.sqrt(np.diag(cov))
    return integrate_odometry(poses[0], noisy)


def _reading_summary(log: CarmenLog, stamps: StampRepair, note: str | None) -> ReadingSummary:
    """What reading the log did: the scans kept of the FLASER lines, the lines dropped (a
    lenient read) and the stamps repaired, by reason."""
    flaser = int(log.counts.get("FLASER", log.n_scans))
    dropped = _skipped_by_reason(log.skipped)
    check_dropped_share(log.path, flaser, flaser - log.n_scans)
    notes = [] if note is None else [note]
    if stamps.restamped:
        notes.append(
            f"{log.n_scans} stamps carry no timing: re-made from the line order, "
            f"{stamps.period:g} s apart"
        )
    return ReadingSummary(
        file=log.path.name,
        records=flaser,
        used=log.n_scans,
        dropped=dropped,
        repaired={k: v for k, v in stamps.counts.items() if k != RESTAMP_REASON},
        notes=tuple(notes),
        ignored=ignored_lines(log.counts),
    )


def _skipped_by_reason(skipped: tuple[tuple[int, str], ...]) -> dict[str, int]:
    """Dropped lines by reason: the message of each line up to its first colon, so that
    ``FLASER: ranges must be finite and >= 0, got -1.0`` counts as ``FLASER``'s kind of
    problem, not one reason per value."""
    out: dict[str, int] = {}
    for _, message in skipped:
        head, _, rest = message.partition(": ")
        reason = f"{head}: {rest.split(',')[0]}" if rest else head
        out[reason] = out.get(reason, 0) + 1
    return out


def _max_range_source(options: CarmenOptions, log: CarmenLog) -> tuple[float, str]:
    if options.max_range is not None:
        return options.max_range, "option max_range"
    declared = log.param_float("robot_front_laser_max")
    if declared is not None:
        return declared, "PARAM robot_front_laser_max"
    return DEFAULT_MAX_RANGE, "SICK LMS default (80 m)"


def carmen_dataset(
    log: CarmenLog,
    options: CarmenOptions,
    *,
    seed: int,
    name: str,
    description: str = "",
) -> Dataset:
    """The :class:`Dataset` of a parsed corrected CARMEN log (see the module docstring)."""
    if log.n_scans < 1:
        raise DatasetFormatError("no valid FLASER scans", log.path)
    geometry = log.geometry or log_geometry(
        log.n_beams, log.params, log.param_lines, log.path, options.fov_deg,
        options.angular_resolution_deg,
    )  # fmt: skip
    if geometry is None:  # parse_carmen_log already checked this; a hand-made log may not be
        raise DatasetFormatError(
            f"{log.n_beams} beams do not match the declared field of view", log.path
        )
    max_range, max_source = _max_range_source(options, log)
    ranges = np.where(log.ranges >= max_range, max_range, log.ranges)
    times, stamps = repair_stamps(log.times, STAMP_PERIOD)
    truth_poses = log.laser_poses.copy()
    truth_poses[:, 2] = wrap_angle(truth_poses[:, 2])
    rng = np.random.default_rng(seed)
    cov = options.odometry_cov()
    odom = _noisy_odometry(truth_poses, cov, rng)
    events = assemble_events(odometry_events(times, odom), scan_events(times, ranges))
    angles = beam_angles_from_geometry(log.n_beams, geometry.fov_deg, geometry.resolution_deg)
    return Dataset(
        name=name,
        events=events,
        motion=MotionSpec(OdometryModel(), cov, source="odometry"),
        laser=LaserSpec(angles, max_range, options.range_sigma),
        initial_pose=truth_poses[0].copy(),
        initial_cov=np.diag([1e-4, 1e-4, math.radians(0.5) ** 2]),
        truth=GroundTruth(times=times, poses=truth_poses),
        description=description or f"CARMEN log {log.path.name} ({log.n_scans} scans)",
        metadata=_carmen_metadata(log, geometry, (max_range, max_source), stamps.repaired),
        reading=_reading_summary(log, stamps, geometry.note),
        provenance=Provenance(options=config_to_dict(options)),
    )


def _carmen_metadata(
    log: CarmenLog, geometry: LogGeometry, max_range: tuple[float, str], repaired: int
) -> dict[str, Any]:
    return {
        "kind": "real",
        "format": "carmen",
        "file": log.path.name,
        "scans": log.n_scans,
        "beams": log.n_beams,
        "fov_deg": geometry.fov_deg,
        "angular_resolution_deg": geometry.resolution_deg,
        "geometry_from": geometry.source,
        "max_range": max_range[0],
        "max_range_from": max_range[1],
        "max_range_readings": int(np.count_nonzero(log.ranges >= max_range[0])),
        "message_counts": dict(log.counts),
        "odom_lines_ignored": int(log.counts.get("ODOM", 0)),
        "odometry": "corrected poses + known Gaussian noise (ODOM lines not used)",
        "timestamps_repaired": repaired,
        "skipped_lines": {
            "count": len(log.skipped),
            "first": [{"line": n, "reason": m} for n, m in log.skipped[:SKIPPED_SHOWN]],
        },
    }


def read_carmen_log(
    path: str | Path,
    options: CarmenOptions | Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    name: str | None = None,
) -> Dataset:
    """Read a corrected CARMEN log into a :class:`Dataset` (see the module docstring)."""
    opts = (
        options
        if isinstance(options, CarmenOptions)
        else config_from_mapping(CarmenOptions, options, "carmen options")
    )
    log = parse_carmen_log(
        path,
        lenient=opts.lenient,
        fov_deg=opts.fov_deg,
        angular_resolution_deg=opts.angular_resolution_deg,
    )
    return carmen_dataset(log, opts, seed=seed, name=name or Path(path).name.split(".")[0])


# --------------------------------------------------------------------------------------------
# DP-SLAM
# --------------------------------------------------------------------------------------------


@dataclass
class _DpSlamLines:
    """The scans of a DP-SLAM log: each ``Laser`` line's ranges with the pose of the
    ``Odometry`` line before it, the scans' line numbers and the count of every type."""

    odom_rows: list[list[float]] = field(default_factory=list)
    range_rows: list[list[float]] = field(default_factory=list)
    numbers: list[int] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)


DPSLAM_BEAMS = 181
"""Beams of a DP-SLAM log's ``Laser`` line (180° at 1°)."""


def read_dpslam_log(
    path: str | Path,
    options: DpSlamOptions | Mapping[str, Any] | None = None,
    *,
    name: str | None = None,
) -> Dataset:
    """Read a DP-SLAM log (alternating ``Odometry x y theta`` / ``Laser n r1 .. rn``) into a
    :class:`Dataset` with raw odometry and no ground truth (see the module docstring). Each
    ``Laser`` line is paired with the ``Odometry`` line before it."""
    opts = (
        options
        if isinstance(options, DpSlamOptions)
        else config_from_mapping(DpSlamOptions, options, "dpslam options")
    )
    p = Path(path)
    problems = LineProblems(p, opts.lenient)
    geometry = resolve_geometry(DPSLAM_BEAMS, opts.fov_deg, None, "declared")
    if geometry is None:  # pragma: no cover - 181 beams always resolve
        raise ConfigError(f"fov_deg {opts.fov_deg} does not fit 181 beams")
    fov_deg, res_deg, _ = geometry
    found = _dpslam_lines(p, problems)
    if not found.range_rows:
        raise DatasetFormatError("no Laser scans found", p)
    raw = np.asarray(found.range_rows, dtype=np.float64)
    ranges = np.where(raw >= opts.max_range, opts.max_range, raw)
    odom = np.asarray(found.odom_rows, dtype=np.float64)
    odom[:, 2] = wrap_angle(odom[:, 2])
    times = opts.scan_period * np.arange(ranges.shape[0], dtype=np.float64)
    events = assemble_events(odometry_events(times, odom), scan_events(times, ranges))
    return Dataset(
        name=name or p.name.split(".")[0],
        events=events,
        motion=MotionSpec(OdometryModel(), opts.odometry_cov(), source="odometry"),
        laser=LaserSpec(
            beam_angles_from_geometry(DPSLAM_BEAMS, fov_deg, res_deg),
            opts.max_range,
            opts.range_sigma,
        ),
        initial_pose=odom[0].copy(),
        initial_cov=np.diag([1e-4, 1e-4, math.radians(0.5) ** 2]),
        description=f"DP-SLAM log {p.name} ({ranges.shape[0]} scans, raw odometry)",
        metadata={
            "kind": "real",
            "format": "dpslam",
            "file": p.name,
            "scans": int(ranges.shape[0]),
            "beams": DPSLAM_BEAMS,
            "fov_deg": fov_deg,
            "angular_resolution_deg": res_deg,
            "max_range": opts.max_range,
            "max_range_readings": int(np.count_nonzero(raw >= opts.max_range)),
            "message_counts": found.counts,
            "first_line_numbers": found.numbers[:3],
            "skipped_lines": problems.metadata(),
        },
        provenance=Provenance(options=config_to_dict(opts)),
    )


def _dpslam_lines(path: Path, problems: LineProblems) -> _DpSlamLines:
    """One pass over a DP-SLAM log: each good ``Laser`` line paired with the ``Odometry``
    line before it; a malformed line, a scan without odometry or another type reported."""
    out = _DpSlamLines()
    pending: list[float] | None = None
    for number, line in enumerate(read_lines(path), start=1):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        kind = tokens[0]
        out.counts[kind] = out.counts.get(kind, 0) + 1
        if kind == "Odometry":
            values = parse_floats(tokens[1:]) if len(tokens) == 4 else None
            if values is None or not all(math.isfinite(v) for v in values):
                problems.report(number, "Odometry: expected three finite numbers x y theta")
                continue
            pending = values
        elif kind == "Laser":
            ranges = _dpslam_ranges(tokens)
            if isinstance(ranges, str) or pending is None:
                problems.report(number, ranges if isinstance(ranges, str) else _NO_ODOMETRY)
                continue
            out.odom_rows.append(pending)
            out.range_rows.append(ranges)
            out.numbers.append(number)
            pending = None
        else:
            problems.report(number, f"unknown message {kind!r}: expected Odometry or Laser")
    return out


_NO_ODOMETRY = "Laser: no Odometry line before this scan"


def _dpslam_ranges(tokens: list[str]) -> list[float] | str:
    """The ranges of a ``Laser`` line, or what is wrong with it."""
    try:
        n = int(tokens[1]) if len(tokens) > 1 else -1
    except ValueError:
        n = -1
    if n != DPSLAM_BEAMS:
        return f"Laser: {n} beams disagree with the declared {DPSLAM_BEAMS} beams"
    values = parse_floats(tokens[2:]) if len(tokens) == n + 2 else None
    if values is None:
        return f"Laser: expected {n} numbers after the count"
    bad = [v for v in values if not (math.isfinite(v) and v >= 0.0)]
    if bad:
        return f"Laser: ranges must be finite and >= 0, got {bad[0]!r}"
    return values


# --------------------------------------------------------------------------------------------
# registry loaders: (options, *, seed, data_root) -> Dataset
# --------------------------------------------------------------------------------------------


def _carmen_loader(
    name: str,
    description: str,
    options: Mapping[str, Any],
    seed: int,
    data_root: Path | None,
    defaults: Mapping[str, Any] | None = None,
) -> Dataset:
    opts = config_from_mapping(CarmenOptions, {**(defaults or {}), **dict(options)}, name)
    path = require_file(CARMEN_FILES[name], resolve_data_root(data_root))
    log = parse_carmen_log(
        path,
        lenient=opts.lenient,
        fov_deg=opts.fov_deg,
        angular_resolution_deg=opts.angular_resolution_deg,
    )
    return carmen_dataset(log, opts, seed=seed, name=name, description=description)


def load_intel(options: Mapping[str, Any], *, seed: int, data_root: Path | None = None) -> Dataset:
    """Intel Research Lab (Seattle), corrected CARMEN log: 910 scans of 180 beams."""
    return _carmen_loader(
        "intel",
        "Intel Research Lab, corrected poses as truth, odometry = truth + known noise",
        options,
        seed,
        data_root,
    )


def load_aces(options: Mapping[str, Any], *, seed: int, data_root: Path | None = None) -> Dataset:
    """ACES building (Austin), corrected CARMEN log: 440 scans of 180 beams.

    Its readings pile up at exactly 50 m (620 readings, against ~10 between 49 and 50 m): the
    scanner or the logger clipped them there, so 50 m is this log's max range by default.
    """
    return _carmen_loader(
        "aces",
        "ACES building, corrected poses as truth, odometry = truth + known noise",
        options,
        seed,
        data_root,
        defaults={"max_range": 50.0},
    )


def load_freiburg079(
    options: Mapping[str, Any], *, seed: int, data_root: Path | None = None
) -> Dataset:
    """Freiburg building 079, corrected CARMEN log: 4791 scans of 360 beams (0.5°)."""
    return _carmen_loader(
        "freiburg-079",
        "Freiburg building 079, corrected poses as truth, odometry = truth + known noise",
        options,
        seed,
        data_root,
    )


def load_loop5(options: Mapping[str, Any], *, seed: int, data_root: Path | None = None) -> Dataset:
    """DP-SLAM ``loop5``: 551 scans of 181 beams with raw odometry, no ground truth."""
    path = require_file(CARMEN_FILES["loop5"], resolve_data_root(data_root))
    return read_dpslam_log(path, config_from_mapping(DpSlamOptions, options, "loop5"), name="loop5")
