"""Raw CARMEN logs (the Freiburg ``*.clf`` files, ``*.log``, ``*.log.gz``) with the robot's
raw odometry → :class:`~slamkit.datasets.Dataset`.

This is a separate reader from :func:`slamkit.datasets.carmen.read_carmen_log`, which reads the
*corrected* logs (their poses are the SLAM result, used as ground truth, and the odometry is
made from them with known noise). Here the poses of the log are what the robot's odometry
said, and they become the :class:`Odometry` events as they are. Gzip is recognised by the
content. Lines (``ts`` the IPC time stamp [s], which is the scan's time; ``host
logger_ts`` trail every message in the new format and are absent in the old one)::

    FLASER n r1..rn x y theta odom_x odom_y odom_theta ts [host logger_ts]
    ROBOTLASER1 type start fov res max_range accuracy remission_mode n r1..rn
                m e1..em laser_x laser_y laser_theta robot_x robot_y robot_theta
                tv rv forward_safety side_safety turn_axis ts [host logger_ts]
    RAWLASER1..4 type start fov res max_range accuracy remission_mode n r1..rn
                m e1..em ts [host logger_ts]
    ODOM x y theta tv rv accel ts [host logger_ts]
    PARAM name value ...

* Which laser: ``laser`` (option), else the first of ``FLASER``, ``ROBOTLASER1``,
  ``RAWLASER1``..``RAWLASER4`` the log holds; lines of the other lasers are counted and
  ignored.
* Odometry: a ``FLASER`` line's ``odom_*`` triple or a ``ROBOTLASER1`` line's robot pose is
  the robot's odometry at the scan. ``RAWLASER`` lines carry no pose: the ``ODOM`` lines are
  interpolated to the scan stamps (:mod:`slamkit.datasets.raw_odometry`: scans outside the
  odometry dropped and counted, a scan in a gap longer than ``max_odom_gap`` an error).
* Mounting: the laser pose of a line (``FLASER`` ``x y theta``, ``ROBOTLASER1``
  ``laser_*``) is the laser's pose in the odometry frame, so the laser's pose on the robot is
  ``odom ⊖ laser``; :attr:`LaserSpec.mounting` is its median over the scans (the spread is in
  ``metadata["mounting_spread"]``). ``RAWLASER``: the laser at the robot's origin.
* Beam geometry: ``ROBOTLASER1``/``RAWLASER`` lines give theirs (radians): beam ``i`` at
  ``start + i·res``; ``fov`` must be ``n·res`` or ``(n-1)·res`` to half a ``res``. ``FLASER``
  as the corrected reader: options, else ``PARAM laser_front_laser_fov``/``_resolution``
  [deg], else the beam count (180/181 or 360/361 over 180°), centred ahead. Every scan must
  have the first scan's geometry.
* Max range: the option, else the line's ``max_range`` (``ROBOTLASER1``/``RAWLASER``), else
  ``PARAM robot_front_laser_max``, else 80 m; readings at or beyond it are no return, stored
  as exactly ``max_range``.

Errors: a malformed line (field count, a field that is not a number, a NaN, infinite or
negative range, a geometry that disagrees, a scan whose stamp is not later than the one
before) raises :class:`~slamkit.errors.DatasetFormatError` naming the file and the line; with
``lenient=True`` such lines are skipped and counted in ``metadata["skipped_lines"]``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.carmen_parse import (
    LineProblems,
    beam_angles_from_geometry,
    ignored_lines,
    log_geometry,
    parse_floats,
    read_lines,
)
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.raw_odometry import (
    DEFAULT_MAX_ODOM_GAP,
    RAW_ODOMETRY_SIGMA_ROT_DEG,
    RAW_ODOMETRY_SIGMA_TRANS,
    check_gap_option,
    increasing_mask,
    odometry_at_scans,
    raw_laser_dataset,
    raw_odometry_cov,
    repeat_mask,
)
from slamkit.datasets.reading import ReadingSummary, check_dropped_share
from slamkit.datasets.stamps import StampRepair, repair_stamps
from slamkit.datasets.stream import Dataset, LaserSpec
from slamkit.errors import ConfigError, DatasetFormatError
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.pose2 import between

__all__ = [
    "LASER_MESSAGES",
    "CarmenRawLog",
    "CarmenRawOptions",
    "parse_carmen_raw",
    "read_carmen_raw_log",
]

LASER_MESSAGES = ("FLASER", "ROBOTLASER1", "RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4")
"""The laser messages read, in the order a log's laser is chosen when not given."""

DEFAULT_MAX_RANGE = 80.0
"""Max range of a SICK LMS [m] when a log does not say otherwise."""

GEOMETRY_TOLERANCE = 1e-6
"""Start angles and resolutions [rad] of two scans that agree to this are the same."""
TWO_PI = 2.0 * math.pi
ANGLE_SLACK = 1e-3
"""[rad] a laser line's start angle, field of view and beam span may exceed 2π by (the
printed values of a 360° laser round up)."""


@dataclass(frozen=True)
class CarmenRawOptions:
    """How to read a raw CARMEN log. Units: metres, seconds, degrees where named."""

    laser: str | None = None
    """The laser message to read (``FLASER``, ``ROBOTLASER1``, ``RAWLASER1``..``4``); None:
    the first of those the log holds."""
    max_range: float | None = None
    """Readings at or beyond this are no return [m]; None: the lines' max range, else
    ``PARAM robot_front_laser_max``, else 80 m."""
    fov_deg: float | None = None
    """FLASER field of view [deg]; None: ``PARAM laser_front_laser_fov``, else the count."""
    angular_resolution_deg: float | None = None
    """FLASER angle between beams [deg]; None: ``PARAM laser_front_laser_resolution``, else
    the count."""
    max_odom_gap: float = DEFAULT_MAX_ODOM_GAP
    """RAWLASER scans between two ODOM lines further apart than this [s] are an error
    (lenient: dropped); ``inf``: no limit."""
    range_sigma: float = 0.01
    """Nominal range noise stored in the LaserSpec [m] (the log does not say)."""
    odometry_sigma_trans: float = RAW_ODOMETRY_SIGMA_TRANS
    """Nominal per-step translation noise of the odometry [m] (for the MotionSpec)."""
    odometry_sigma_rot_deg: float = RAW_ODOMETRY_SIGMA_ROT_DEG
    """Nominal per-step rotation noise of the odometry [deg] (for the MotionSpec)."""
    lenient: bool = False
    """Skip malformed lines (and count them) instead of raising DatasetFormatError."""

    def __post_init__(self) -> None:
        if self.laser is not None and self.laser not in LASER_MESSAGES:
            raise ConfigError(
                f"laser: expected one of {', '.join(LASER_MESSAGES)} or nothing, got {self.laser!r}"
            )
        for name in ("max_range", "fov_deg", "angular_resolution_deg"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: expected a finite number > 0 or nothing, got {v!r}")
        check_gap_option(self.max_odom_gap)
        for name in ("range_sigma", "odometry_sigma_trans", "odometry_sigma_rot_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: expected a finite number >= 0, got {v!r}")


@dataclass(frozen=True, eq=False)
class CarmenRawLog:
    """The scans of one laser of a raw CARMEN log (what :func:`parse_carmen_raw` found).

    ``times (N,)`` the scans' ``ts``; ``ranges (N, B)`` as logged [m]; ``beam_angles (B,)``
    [rad]; ``line_max_range (N,)`` each line's max range (NaN for FLASER);
    ``laser_poses``/``odom_poses (N, 3)`` the two poses of each line, or None (RAWLASER);
    ``odom_times (M,)``/``odom_lines (M, 3)`` the ODOM lines in time order (repeats, counted
    in ``odom_repeats``, and lines stamped 0 or out of order, ``odom_unordered``, left out);
    ``line_numbers (N,)`` 1-based; ``stamps`` what repairing the scans' stamps did
    (:func:`~slamkit.datasets.stamps.repair_stamps`); ``geometry_note`` how an unusual
    FLASER geometry was read;
    ``param_max_range`` PARAM ``robot_front_laser_max``; ``counts`` lines per message type;
    ``skipped`` the malformed lines of a lenient read."""

    path: Path
    laser: str
    times: FloatArray
    ranges: FloatArray
    beam_angles: FloatArray
    line_max_range: FloatArray
    laser_poses: FloatArray | None
    odom_poses: FloatArray | None
    odom_times: FloatArray
    odom_lines: FloatArray
    line_numbers: NDArray[np.int64]
    param_max_range: float | None
    counts: dict[str, int]
    skipped: dict[str, Any]
    odom_repeats: int = 0
    odom_unordered: int = 0
    stamps: StampRepair = field(default_factory=StampRepair)
    geometry_note: str | None = None

    @property
    def n_scans(self) -> int:
        return int(self.times.size)


def _stamp_fields(tail: list[str]) -> float | None:
    """The ``ts`` of a message's trailing fields: ``ts`` (old format) or ``ts host
    logger_ts`` (new); None if they are neither."""
    if len(tail) == 1 or (len(tail) == 3 and parse_floats(tail[2:]) is not None):
        values = parse_floats(tail[:1])
        if values is not None and math.isfinite(values[0]):
            return values[0]
    return None


@dataclass(frozen=True)
class _Scan:
    t: float
    ranges: list[float]
    geometry: tuple[float, float, float] | None  # start, res [rad], max range; None: FLASER
    laser_pose: list[float] | None
    odom_pose: list[float] | None


def _parse_flaser(tokens: list[str]) -> _Scan | str:
    try:
        n = int(tokens[0])
    except (ValueError, IndexError):
        return "FLASER: expected a beam count"
    if n < 1 or len(tokens) not in (1 + n + 7, 1 + n + 9):
        return (
            f"FLASER: expected {n} ranges, 6 pose numbers and 'ts' or 'ts host logger_ts', "
            f"got {len(tokens) - 1} fields after the count"
        )
    values = parse_floats(tokens[1 : 1 + n + 6])
    t = _stamp_fields(tokens[1 + n + 6 :])
    if values is None or t is None:
        return "FLASER: a field is not a number"
    return _Scan(t, values[:n], None, values[n : n + 3], values[n + 3 : n + 6])


def _parse_laser_block(tokens: list[str], kind: str, n_after: int) -> tuple[Any, ...] | str:
    """The common head of ROBOTLASER1/RAWLASER: geometry, ranges, remissions; then
    ``n_after`` numbers and the stamp fields."""
    head = parse_floats(tokens[:8]) if len(tokens) >= 8 else None
    if head is None or not float(head[7]).is_integer() or head[7] < 1:
        return f"{kind}: expected 7 laser settings and a beam count"
    n = int(head[7])
    if len(tokens) < 8 + n + 1:
        return f"{kind}: expected {n} ranges and a remission count"
    m_val = parse_floats(tokens[8 + n : 9 + n])
    if m_val is None or not m_val[0].is_integer() or m_val[0] < 0:
        return f"{kind}: expected a remission count after the {n} ranges"
    m = int(m_val[0])
    rest = 9 + n + m
    if len(tokens) not in (rest + n_after + 1, rest + n_after + 3):
        return (
            f"{kind}: expected {n} ranges, {m} remissions, {n_after} numbers and 'ts' or "
            f"'ts host logger_ts', got {len(tokens)} fields"
        )
    ranges = parse_floats(tokens[8 : 8 + n])
    after = parse_floats(tokens[rest : rest + n_after])
    t = _stamp_fields(tokens[rest + n_after :])
    if ranges is None or after is None or t is None or parse_floats(tokens[9 + n : rest]) is None:
        return f"{kind}: a field is not a number"
    start, fov, res, max_range = head[1], head[2], head[3], head[4]
    if not all(math.isfinite(v) for v in (start, fov, res)) or res <= 0:
        return f"{kind}: start angle, field of view and resolution must be finite, res > 0"
    # Finite is not enough: a start angle of 1e308 puts every beam on one float, and beams
    # that span more than a turn are not a 2D laser's.
    if not (abs(start) <= TWO_PI + ANGLE_SLACK and 0.0 < fov <= TWO_PI + ANGLE_SLACK):
        return f"{kind}: start angle {start!r} and field of view {fov!r} rad: not angles of a scan"
    if (n - 1) * res > TWO_PI + ANGLE_SLACK or start + res == start:  # > a turn, or one angle
        return f"{kind}: {n} beams at {res!r} rad: not the beams of one scan"
    if min(abs(n * res - fov), abs((n - 1) * res - fov)) > res / 2:
        return f"{kind}: {n} beams at {res!r} rad do not span the field of view {fov!r} rad"
    if not (math.isfinite(max_range) and max_range > 0):
        return f"{kind}: max range must be a number > 0, got {max_range!r}"
    return t, ranges, (start, res, max_range), after


def _parse_robotlaser(tokens: list[str]) -> _Scan | str:
    out = _parse_laser_block(tokens, "ROBOTLASER1", 11)
    if isinstance(out, str):
        return out
    t, ranges, geometry, after = out
    return _Scan(t, ranges, geometry, after[0:3], after[3:6])


def _parse_rawlaser(tokens: list[str], kind: str) -> _Scan | str:
    out = _parse_laser_block(tokens, kind, 0)
    if isinstance(out, str):
        return out
    t, ranges, geometry, _ = out
    return _Scan(t, ranges, geometry, None, None)


def _parse_odom(tokens: list[str]) -> list[float] | str:
    values = parse_floats(tokens[:6]) if len(tokens) in (7, 9) else None
    t = _stamp_fields(tokens[6:]) if len(tokens) in (7, 9) else None
    if values is None or t is None or not all(math.isfinite(v) for v in values[:3]):
        return "ODOM: expected x y theta tv rv accel ts [host logger_ts]"
    return [t, *values[:3]]


def _param_float(
    params: dict[str, str], lines: dict[str, int], path: Path, key: str
) -> float | None:
    if key not in params:
        return None
    v = parse_floats([params[key]])
    if v is None or not (math.isfinite(v[0]) and v[0] > 0):
        raise DatasetFormatError(f"PARAM {key}: expected a number > 0", path, lines[key])
    return v[0]


def parse_carmen_raw(path: str | Path, options: CarmenRawOptions | None = None) -> CarmenRawLog:
    """Read the laser, ODOM and PARAM lines of a raw CARMEN log (see the module docstring)."""
    opts = options or CarmenRawOptions()
    p = Path(path)
    lines = read_lines(p)
    problems = LineProblems(p, opts.lenient)
    counts, params, param_lines = _count_and_params(lines, problems)
    laser = opts.laser or next((k for k in LASER_MESSAGES if k in counts), None)
    if laser is None or laser not in counts:
        raise DatasetFormatError(
            f"no {laser or ' or '.join(LASER_MESSAGES)} lines in the log; it has: "
            f"{', '.join(sorted(counts)) or 'nothing'}",
            p,
        )
    scans, numbers, odom_rows = _laser_and_odom_lines(lines, laser, problems)
    angles, scans, numbers, note = _geometry(
        scans, numbers, laser, opts, params, param_lines, p, problems
    )
    times, stamps = repair_stamps(np.asarray([s.t for s in scans], dtype=np.float64))
    odom, repeats, unordered = _odom_table(odom_rows)
    with_poses = laser in ("FLASER", "ROBOTLASER1")
    return CarmenRawLog(
        path=p,
        laser=laser,
        times=times,
        ranges=np.asarray([s.ranges for s in scans], dtype=np.float64).reshape(len(scans), -1),
        beam_angles=angles,
        line_max_range=np.asarray(
            [math.nan if s.geometry is None else s.geometry[2] for s in scans], dtype=np.float64
        ),
        laser_poses=_pose_rows([s.laser_pose for s in scans]) if with_poses else None,
        odom_poses=_pose_rows([s.odom_pose for s in scans]) if with_poses else None,
        odom_times=odom[:, 0].copy(),
        odom_lines=odom[:, 1:].copy(),
        line_numbers=np.asarray(numbers, dtype=np.int64),
        param_max_range=_param_float(params, param_lines, p, "robot_front_laser_max"),
        counts=counts,
        skipped=problems.metadata(),
        odom_repeats=repeats,
        odom_unordered=unordered,
        stamps=stamps,
        geometry_note=note,
    )


def _pose_rows(rows: list[list[float] | None]) -> FloatArray:
    return np.asarray(rows, dtype=np.float64).reshape(-1, 3)


def _count_and_params(
    lines: list[str], problems: LineProblems
) -> tuple[dict[str, int], dict[str, str], dict[str, int]]:
    """The first pass: lines per message type, and the ``PARAM`` values with their lines."""
    counts: dict[str, int] = {}
    params: dict[str, str] = {}
    param_lines: dict[str, int] = {}
    for number, line in enumerate(lines, start=1):
        head = line.split(None, 1)
        if not head or head[0].startswith("#"):
            continue
        counts[head[0]] = counts.get(head[0], 0) + 1
        if head[0] == "PARAM":
            fields_ = head[1].split() if len(head) > 1 else []
            if len(fields_) < 2:
                problems.report(number, "PARAM: expected a name and a value")
                continue
            params[fields_[0]] = fields_[1]
            param_lines[fields_[0]] = number
    return counts, params, param_lines


def _laser_and_odom_lines(
    lines: list[str], laser: str, problems: LineProblems
) -> tuple[list[_Scan], list[int], list[list[float]]]:
    """The second pass: the scans of ``laser`` (with their lines) whose ranges and poses
    are finite, and the ODOM rows ``(t, x, y, theta)``; malformed lines reported."""
    scans: list[_Scan] = []
    numbers: list[int] = []
    odom_rows: list[list[float]] = []
    for number, line in enumerate(lines, start=1):
        tokens = line.split()
        if not tokens or (tokens[0] != laser and tokens[0] != "ODOM"):
            continue
        if tokens[0] == "ODOM":
            row = _parse_odom(tokens[1:])
            if isinstance(row, str):
                problems.report(number, row)
            else:
                odom_rows.append(row)
            continue
        scan = _parse_scan(tokens, laser)
        if isinstance(scan, str):
            problems.report(number, scan)
            continue
        scans.append(scan)
        numbers.append(number)
    return scans, numbers, odom_rows


def _parse_scan(tokens: list[str], laser: str) -> _Scan | str:
    """A laser line of the log's laser, or what is wrong with it (its form, a range that
    is not finite and >= 0, a pose that is not finite)."""
    if laser == "FLASER":
        scan = _parse_flaser(tokens[1:])
    elif laser == "ROBOTLASER1":
        scan = _parse_robotlaser(tokens[1:])
    else:
        scan = _parse_rawlaser(tokens[1:], laser)
    if isinstance(scan, str):
        return scan
    bad = [v for v in scan.ranges if not (math.isfinite(v) and v >= 0.0)]
    poses = (scan.laser_pose or []) + (scan.odom_pose or [])
    if bad:
        return f"{laser}: ranges must be finite and >= 0, got {bad[0]!r}"
    if not all(math.isfinite(v) for v in poses):
        return f"{laser}: the poses must be finite numbers"
    return scan


def _odom_table(rows: list[list[float]]) -> tuple[FloatArray, int, int]:
    """The ODOM rows ``(M, 4)`` in time order, headings wrapped: repeats left out, and
    rows stamped 0 or out of order, which cannot be placed in time (they matter only to a
    laser without poses, which interpolates them); with the two counts."""
    odom = np.asarray(rows, dtype=np.float64).reshape(-1, 4)
    odom[:, 3] = wrap_angle(odom[:, 3])
    repeats = repeat_mask(odom[:, 0], odom[:, 1:])
    odom = odom[~repeats]
    in_order = increasing_mask(odom[:, 0]) & (odom[:, 0] > 0.0)
    return odom[in_order], int(np.count_nonzero(repeats)), int(np.count_nonzero(~in_order))


def _geometry(
    scans: list[_Scan],
    numbers: list[int],
    laser: str,
    opts: CarmenRawOptions,
    params: dict[str, str],
    param_lines: dict[str, int],
    path: Path,
    problems: LineProblems,
) -> tuple[FloatArray, list[_Scan], list[int], str | None]:
    """The beam angles of the log, the scans that have them (others reported), and a note
    on how an unusual FLASER geometry was read."""
    if not scans:
        raise DatasetFormatError(f"no valid {laser} scans", path)
    kept: list[int] = []
    first = scans[0]
    n0 = len(first.ranges)
    note = None
    if first.geometry is None:  # FLASER: declared or known from the count
        geometry = log_geometry(
            n0, params, param_lines, path, opts.fov_deg, opts.angular_resolution_deg
        )
        if geometry is None:
            raise DatasetFormatError(
                f"FLASER: {n0} beams do not match the declared field of view and resolution "
                "(in degrees or in radians); give fov_deg and angular_resolution_deg",
                path,
                numbers[0],
            )
        note = geometry.note
        angles = beam_angles_from_geometry(n0, geometry.fov_deg, geometry.resolution_deg)
        for i, s in enumerate(scans):
            if len(s.ranges) != n0:
                problems.report(numbers[i], f"FLASER: {len(s.ranges)} beams, the log has {n0}")
            else:
                kept.append(i)
    else:
        start0, res0, _ = first.geometry
        angles = start0 + res0 * np.arange(n0, dtype=np.float64)
        for i, s in enumerate(scans):
            assert s.geometry is not None
            start, res, _ = s.geometry
            same = len(s.ranges) == n0 and abs(start - start0) <= GEOMETRY_TOLERANCE
            if not (same and abs(res - res0) * n0 <= GEOMETRY_TOLERANCE):
                problems.report(
                    numbers[i],
                    f"{laser}: geometry ({len(s.ranges)} beams from {start!r} by {res!r} rad) "
                    f"differs from the first scan's ({n0} from {start0!r} by {res0!r})",
                )
            else:
                kept.append(i)
    return angles, [scans[i] for i in kept], [numbers[i] for i in kept], note


def _mounting(log: CarmenRawLog) -> tuple[tuple[float, float, float], float]:
    """The laser's pose on the robot (median of ``odom ⊖ laser`` over the scans) and the
    largest distance [m] of a scan's offset from it."""
    if log.laser_poses is None or log.odom_poses is None or log.n_scans == 0:
        return (0.0, 0.0, 0.0), 0.0
    offsets = between(log.odom_poses, log.laser_poses)
    x, y = np.median(offsets[:, 0]), np.median(offsets[:, 1])
    yaw = float(wrap_angle(np.median(wrap_angle(offsets[:, 2]))))
    spread = float(np.max(np.hypot(offsets[:, 0] - x, offsets[:, 1] - y)))
    return (float(x), float(y), yaw), spread


def read_carmen_raw_log(
    path: str | Path,
    options: CarmenRawOptions | Mapping[str, Any] | None = None,
    *,
    name: str | None = None,
) -> Dataset:
    """Read a raw CARMEN log into a :class:`Dataset` with its raw odometry (see the module
    docstring)."""
    opts = (
        options
        if isinstance(options, CarmenRawOptions)
        else config_from_mapping(CarmenRawOptions, options, "carmen raw options")
    )
    log = parse_carmen_raw(path, opts)
    if log.n_scans == 0:
        raise DatasetFormatError(f"no valid {log.laser} scans", log.path)
    max_range, max_from = _max_range(log, opts)
    threshold = np.where(np.isfinite(log.line_max_range), log.line_max_range, max_range)
    threshold = np.minimum(threshold, max_range)
    no_return = log.ranges >= threshold[:, None]
    ranges = np.where(no_return, max_range, log.ranges)
    keep, odometry, dropped, odometry_from = _scan_odometry(log, opts)
    mounting, spread = _mounting(log)
    laser = LaserSpec(log.beam_angles, max_range, opts.range_sigma, mounting=mounting)
    n = int(keep.sum())
    p = log.path
    reading = _reading_summary(log, n, dropped)
    metadata: dict[str, Any] = {
        "kind": "real",
        "format": "carmen-raw",
        "file": p.name,
        "laser_message": log.laser,
        "scans": n,
        "scan_lines": log.n_scans,
        "beams": int(log.beam_angles.size),
        "max_range": max_range,
        "max_range_from": max_from,
        "max_range_readings": int(np.count_nonzero(no_return)),
        "odometry_from": odometry_from,
        "odom_lines": int(log.odom_times.size),
        "odometry_repeats_dropped": log.odom_repeats,
        "odometry_unordered_dropped": log.odom_unordered,
        "mounting": list(laser.mounting),
        "mounting_spread": spread,
        "dropped": dropped,
        "message_counts": dict(log.counts),
        "skipped_lines": log.skipped,
    }
    return raw_laser_dataset(
        name=name or p.name,
        times=log.times[keep],
        odometry=odometry,
        ranges=ranges[keep],
        laser=laser,
        motion_cov=raw_odometry_cov(opts.odometry_sigma_trans, opts.odometry_sigma_rot_deg),
        description=f"raw CARMEN log {p.name}: {n} {log.laser} scans × "
        f"{log.beam_angles.size} beams, raw odometry ({odometry_from})",
        metadata=metadata,
        reading=reading,
        provenance=Provenance(options=config_to_dict(opts)),
    )


def _max_range(log: CarmenRawLog, opts: CarmenRawOptions) -> tuple[float, str]:
    """The max range and where it came from: the option, the laser lines' field, PARAM
    ``robot_front_laser_max``, else the SICK LMS's 80 m."""
    if opts.max_range is not None:
        return opts.max_range, "option max_range"
    if np.isfinite(log.line_max_range[0]):
        return float(log.line_max_range[0]), f"{log.laser} max range field"
    if log.param_max_range is not None:
        return log.param_max_range, "PARAM robot_front_laser_max"
    return DEFAULT_MAX_RANGE, "SICK LMS default (80 m)"


def _scan_odometry(
    log: CarmenRawLog, opts: CarmenRawOptions
) -> tuple[NDArray[np.bool_], FloatArray, dict[str, int], str]:
    """The robot's odometry at the scans: the laser lines' own poses, else the ODOM lines
    interpolated (:func:`_odom_lines`); which scans have it, the drops by reason, and
    where it came from."""
    if log.odom_poses is None:
        keep, odometry, dropped = _odom_lines(log, opts)
        return keep, odometry, dropped, "ODOM lines interpolated to the scan stamps"
    odometry = log.odom_poses.copy()
    odometry[:, 2] = wrap_angle(odometry[:, 2])
    dropped = {"before_odometry": 0, "after_odometry": 0, "odometry_gap": 0}
    return np.ones(log.n_scans, dtype=bool), odometry, dropped, f"{log.laser} odometry pose"


def _reading_summary(log: CarmenRawLog, used: int, dropped: Mapping[str, int]) -> ReadingSummary:
    """What reading the log did: scans kept of the laser's lines, dropped by reason (a
    lenient read's malformed lines, scans without odometry), stamps repaired by reason."""
    lines = int(log.counts.get(log.laser, log.n_scans))
    by_reason = {k.replace("_", " ") + " (scans)": v for k, v in dropped.items() if v}
    malformed = lines - log.n_scans
    if malformed:
        by_reason["malformed lines"] = malformed
    check_dropped_share(log.path, lines, lines - used)
    notes = [] if log.geometry_note is None else [log.geometry_note]
    if log.stamps.restamped:
        notes.append(
            f"{log.n_scans} stamps carry no timing: re-made from the line order, "
            f"{log.stamps.period:g} s apart"
        )
    repaired = {} if log.stamps.restamped else dict(log.stamps.counts)
    if log.odom_unordered and log.odom_poses is None:  # the ODOM lines were used
        notes.append(f"{log.odom_unordered} ODOM lines stamped 0 or out of order left out")
    return ReadingSummary(
        file=log.path.name,
        records=lines,
        used=used,
        dropped=by_reason,
        repaired=repaired,
        notes=tuple(notes),
        ignored=ignored_lines(log.counts),
    )


def _odom_lines(
    log: CarmenRawLog, opts: CarmenRawOptions
) -> tuple[NDArray[np.bool_], FloatArray, dict[str, int]]:
    """The ODOM lines interpolated to the scans: which scans have odometry, their poses and
    the drop counts."""
    if log.odom_times.size == 0:
        raise DatasetFormatError(
            f"{log.laser} lines carry no pose and the log has no ODOM lines", log.path
        )
    at = odometry_at_scans(log.times, log.odom_times, log.odom_lines, opts.max_odom_gap)
    if at.in_gap.any() and not opts.lenient:
        i = int(np.argmax(at.in_gap))
        raise DatasetFormatError(
            f"{log.laser}: scan at t={float(log.times[i])!r} lies in a {at.gap[i]:.3f} s gap of "
            f"the ODOM lines (max_odom_gap {opts.max_odom_gap} s; raise it or set lenient)",
            log.path,
            int(log.line_numbers[i]),
        )
    if not at.keep.any():
        raise DatasetFormatError(f"no {log.laser} scan lies within the ODOM lines", log.path)
    return at.keep, at.poses, at.dropped
