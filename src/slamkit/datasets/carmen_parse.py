"""Line parsing for the laser-log readers of :mod:`slamkit.datasets.carmen`: reading a (gzip
or plain) text file, checking and parsing blocks of numbers, the beam geometry of a scan,
and the CARMEN log itself (:func:`parse_carmen_log`, :class:`CarmenLog`). The formats and
the rules for malformed lines are described in :mod:`slamkit.datasets.carmen`.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.text import ascii_fields, read_text, text_lines
from slamkit.errors import DatasetFormatError

__all__ = [
    "FOV_PARAMS",
    "IGNORED_MESSAGES",
    "RESOLUTION_PARAMS",
    "SKIPPED_SHOWN",
    "CarmenLog",
    "LineProblems",
    "LogGeometry",
    "beam_angles_from_geometry",
    "count_geometry",
    "ignored_lines",
    "log_geometry",
    "parse_carmen_log",
    "parse_floats",
    "read_lines",
    "resolve_geometry",
]

SKIPPED_SHOWN = 20
"""Malformed lines listed (line number and reason) in the metadata of a lenient read."""

FOV_PARAMS = ("laser_front_laser_fov", "laser_frontlaser_fov")
"""``PARAM`` names of the front laser's field of view, in the spellings logs use."""
RESOLUTION_PARAMS = ("laser_front_laser_resolution", "laser_frontlaser_resolution")
"""``PARAM`` names of the front laser's angle between beams."""
RADIAN_RESOLUTION_BELOW = 0.05
"""A ``PARAM`` resolution below this is radians (0.05 rad is 2.9°; no laser's beams are
under 0.05° apart)."""
ASSUMED_FOV_DEG = 180.0
"""The field of view of a log that states none: the SICK LMS and PLS of the CARMEN era."""


IGNORED_MESSAGES = {
    "SYNC": "clock sync between the logging hosts; the stamps are read as logged",
    "TRUEPOS": "a simulator's true pose; not read as ground truth",
}
"""CARMEN messages the readers read past on purpose, and why: counted in the reading
summary (:func:`ignored_lines`), never refused."""


def ignored_lines(counts: Mapping[str, int]) -> dict[str, int]:
    """The lines of :data:`IGNORED_MESSAGES` among a log's ``counts`` (lines per message
    type), by kind and reason, for :attr:`ReadingSummary.ignored
    <slamkit.datasets.reading.ReadingSummary.ignored>`."""
    return {
        f"{kind} lines ({why})": int(counts[kind])
        for kind, why in IGNORED_MESSAGES.items()
        if counts.get(kind)
    }


def read_lines(path: Path) -> list[str]:
    """The lines of a gzip or plain text file (gzip recognised by its magic bytes), split at
    ``\n`` only (:func:`slamkit.datasets.text.read_text`, :func:`~slamkit.datasets.text.
    text_lines`)."""
    return text_lines(read_text(path))


class LineProblems:
    """Malformed lines: raise at the first one, or (lenient) collect and count them."""

    def __init__(self, path: Path, lenient: bool) -> None:
        self.path = path
        self.lenient = lenient
        self.lines: list[tuple[int, str]] = []

    def report(self, line: int, message: str) -> None:
        """A malformed ``line``: raise :class:`DatasetFormatError`, or (lenient) keep it."""
        if not self.lenient:
            raise DatasetFormatError(message, self.path, line)
        self.lines.append((line, message))

    def metadata(self) -> dict[str, Any]:
        """How many lines were skipped, and the first :data:`SKIPPED_SHOWN` of them."""
        return {
            "count": len(self.lines),
            "first": [{"line": n, "reason": m} for n, m in self.lines[:SKIPPED_SHOWN]],
        }


def parse_floats(tokens: list[str]) -> list[float] | None:
    """The tokens as numbers, or None when one of them is not a number."""
    if not ascii_fields(tokens):
        return None
    try:
        return [float(t) for t in tokens]
    except ValueError:
        return None


def _parse_block(
    bodies: list[str], width: int, numbers: list[int], problems: LineProblems, what: str
) -> tuple[FloatArray, list[int]]:
    """Parse ``bodies`` (whitespace-separated numbers, ``width`` per line) into a
    ``(n, width)`` array. Fast path: one C-level parse of all lines; only if that fails are
    the lines parsed one by one to find (or, lenient, drop) the malformed ones."""
    # Count the fields of every line first: a line short of one number and another with one
    # too many would otherwise parse into a block of the right total size, misaligned.
    if bodies and all(len(b.split()) == width for b in bodies):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a partial parse warns: treat it as a failure
            try:
                flat = np.fromstring("\n".join(bodies), dtype=np.float64, sep=" ")
            except (ValueError, DeprecationWarning):
                flat = np.empty(0)
        if flat.size == width * len(bodies):
            return flat.reshape(len(bodies), width), list(numbers)
    rows: list[list[float]] = []
    kept: list[int] = []
    for body, lineno in zip(bodies, numbers, strict=True):
        tokens = body.split()
        if len(tokens) != width:
            problems.report(lineno, f"{what}: expected {width} numbers, got {len(tokens)}")
            continue
        values = parse_floats(tokens)
        if values is None:
            problems.report(lineno, f"{what}: a field is not a number")
            continue
        rows.append(values)
        kept.append(lineno)
    return np.asarray(rows, dtype=np.float64).reshape(len(rows), width), kept


def _check_ranges(
    ranges: FloatArray, numbers: list[int], problems: LineProblems, what: str
) -> NDArray[np.bool_]:
    """Rows whose ranges are all finite and >= 0 (others reported as malformed)."""
    ok = np.all(np.isfinite(ranges) & (ranges >= 0.0), axis=1)
    for i in np.flatnonzero(~ok):
        row = ranges[i]
        bad = row[~(np.isfinite(row) & (row >= 0.0))]
        problems.report(
            numbers[i], f"{what}: ranges must be finite and >= 0, got {float(bad[0])!r}"
        )
    return ok


# --------------------------------------------------------------------------------------------
# beam geometry
# --------------------------------------------------------------------------------------------


def beam_angles_from_geometry(n_beams: int, fov_deg: float, resolution_deg: float) -> FloatArray:
    """Beam angles ``(n,)`` [rad]: ``-fov/2 + i * resolution``, i = 0 .. n-1 (counter-
    clockwise from the right-most beam)."""
    return np.deg2rad(-fov_deg / 2.0 + resolution_deg * np.arange(n_beams, dtype=np.float64))


def _geometry_counts(fov_deg: float, resolution_deg: float) -> tuple[int, int]:
    """Beam counts consistent with a field of view and a resolution: ``fov/res`` beams (the
    last end excluded) or ``fov/res + 1`` (both ends included)."""
    n = round(fov_deg / resolution_deg)
    return n, n + 1


def count_geometry(n_beams: int) -> tuple[float, float]:
    """``(fov, resolution)`` [deg] of ``n_beams`` over :data:`ASSUMED_FOV_DEG`: both ends
    included for an odd count (181 at 1°, 361 at 0.5°), the last end excluded for an even
    one (180 at 1°, 360 at 0.5°)."""
    gaps = n_beams - 1 if n_beams % 2 else n_beams
    return ASSUMED_FOV_DEG, ASSUMED_FOV_DEG / max(gaps, 1)


def resolve_geometry(
    n_beams: int, fov: float | None, res: float | None, source: str
) -> tuple[float, float, str] | None:
    """``(fov, resolution, how)`` [deg] for ``n_beams`` given what is declared (either may
    be None; nothing declared: :func:`count_geometry`); None if the declared geometry
    contradicts the beam count or is impossible (a field of view outside (0°, 360°], a
    resolution outside (0, fov])."""
    if fov is None and res is None:
        if n_beams < 2:
            return None
        f, r = count_geometry(n_beams)
        return f, r, "beam count"
    if fov is None:
        assert res is not None
        fov = n_beams * res if n_beams * res <= 180.0 + 1e-9 else (n_beams - 1) * res
    if res is None:  # both ends included for an odd count, as count_geometry
        res = fov / (n_beams - 1 if n_beams % 2 and n_beams > 1 else n_beams)
    if not (0.0 < fov <= 360.0 + 1e-9 and 0.0 < res <= fov):  # e.g. 90° steps, 1000° views
        return None
    if n_beams not in _geometry_counts(fov, res):
        return None
    return fov, res, source


@dataclass(frozen=True)
class LogGeometry:
    """A log's beam geometry [deg], where it came from, and a note when a ``PARAM`` value
    had to be read in radians or no geometry was stated for an unusual beam count."""

    fov_deg: float
    resolution_deg: float
    source: str
    note: str | None = None


def _first_param(
    params: Mapping[str, str], lines: Mapping[str, int], path: Path, names: tuple[str, ...]
) -> tuple[str, float] | None:
    for name in names:
        value = _param_number(params, lines, path, name)
        if value is not None:
            return name, value
    return None


def log_geometry(
    n_beams: int,
    params: Mapping[str, str],
    param_lines: Mapping[str, int],
    path: Path,
    fov_deg: float | None = None,
    resolution_deg: float | None = None,
) -> LogGeometry | None:
    """The geometry of a log's ``n_beams`` scans: the options (degrees) if given, else the
    ``PARAM`` lines, else the beam count over 180°. A ``PARAM`` field of view up to 2π, or a
    resolution under :data:`RADIAN_RESOLUTION_BELOW`, is radians (a log of the Radish
    collection writes its field of view as 3.14…; read as degrees it would fit 181 beams as
    a 3° fan), other values degrees; if the geometry in that unit does not fit the beam
    count, the other unit is tried. Radians are said in the note. None when nothing
    declared fits the beam count."""
    if fov_deg is not None or resolution_deg is not None:
        found = resolve_geometry(n_beams, fov_deg, resolution_deg, "options")
        return None if found is None else LogGeometry(found[0], found[1], found[2])
    fov = _first_param(params, param_lines, path, FOV_PARAMS)
    res = _first_param(params, param_lines, path, RESOLUTION_PARAMS)
    f, r = (None if fov is None else fov[1]), (None if res is None else res[1])
    if fov is None and res is None:
        found = resolve_geometry(n_beams, None, None, "beam count")
        if found is None:
            return None
        usual = n_beams in (180, 181, 360, 361)
        note = None if usual else f"no field of view stated: {n_beams} beams taken over 180°"
        return LogGeometry(found[0], found[1], found[2], note)
    # The unit by the value (no laser of the field has a view under 2π degrees or beams
    # under 0.05° apart), then by the fit to the beam count.
    radians_first = (f is not None and f <= 2.0 * math.pi + 1e-6) or (
        r is not None and r < RADIAN_RESOLUTION_BELOW
    )
    f_deg = None if f is None else math.degrees(f)
    r_deg = None if r is None else math.degrees(r)
    tries = [(f, r, "PARAM"), (f_deg, r_deg, "PARAM (radians)")]
    found = None
    for fov_try, res_try, how in tries[::-1] if radians_first else tries:
        found = resolve_geometry(n_beams, fov_try, res_try, how)
        if found is not None:
            break
    if found is None:
        return None
    if found[2] == "PARAM":
        return LogGeometry(found[0], found[1], found[2])
    said = [f"PARAM {p[0]} {p[1]:g}" for p in (fov, res) if p is not None]
    note = f"{' and '.join(said)} read as radians ({found[0]:g}° at {found[1]:g}°)"
    return LogGeometry(found[0], found[1], found[2], note)


# --------------------------------------------------------------------------------------------
# CARMEN
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CarmenLog:
    """The scans of a CARMEN log as arrays (what :func:`parse_carmen_log` found).

    ``ranges (N, B)`` are the raw readings in metres (max-range codes not yet replaced);
    ``laser_poses``/``odom_poses (N, 3)`` the two pose triples of each ``FLASER`` line;
    ``times (N,)`` the ``ts`` field; ``line_numbers (N,)`` 1-based lines of the scans;
    ``params`` the ``PARAM`` values as text (``param_lines`` their line numbers);
    ``counts`` the number of lines per message type; ``skipped`` the malformed lines a
    lenient read dropped, as (line, reason); ``geometry`` the beams' (None: resolve it
    from ``params`` with :func:`log_geometry`).
    """

    path: Path
    times: FloatArray
    ranges: FloatArray
    laser_poses: FloatArray
    odom_poses: FloatArray
    line_numbers: NDArray[np.int64]
    params: dict[str, str] = field(default_factory=dict)
    param_lines: dict[str, int] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    skipped: tuple[tuple[int, str], ...] = ()
    geometry: LogGeometry | None = None

    def param_float(self, name: str) -> float | None:
        """The ``PARAM`` value ``name`` as a number > 0, or None when the log does not set
        it; raises :class:`DatasetFormatError` (with its line) when it is not such a number."""
        return _param_number(self.params, self.param_lines, self.path, name)

    @property
    def n_scans(self) -> int:
        return int(self.times.size)

    @property
    def n_beams(self) -> int:
        return int(self.ranges.shape[1])


def _param_number(
    params: Mapping[str, str], lines: Mapping[str, int], path: Path, name: str
) -> float | None:
    """The ``PARAM`` value ``name`` as a number > 0, or None when the log does not set it;
    raises :class:`DatasetFormatError` (with its line) when it is not such a number."""
    if name not in params:
        return None
    try:
        value = float(params[name])
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise DatasetFormatError(
            f"PARAM {name}: expected a number > 0, got {params[name]!r}", path, lines.get(name)
        )
    return value


@dataclass
class _LogLines:
    """What one pass over a CARMEN log's lines found: the ``FLASER`` lines split cheaply
    (the numbers, the stamp, the beam count, the line), the ``PARAM`` values and the count
    of every message type."""

    bodies: list[str] = field(default_factory=list)
    body_lines: list[int] = field(default_factory=list)
    stamps: list[str] = field(default_factory=list)
    beams_of: list[int] = field(default_factory=list)
    params: dict[str, str] = field(default_factory=dict)
    param_lines: dict[str, int] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)


def parse_carmen_log(
    path: str | Path,
    *,
    lenient: bool = False,
    fov_deg: float | None = None,
    angular_resolution_deg: float | None = None,
) -> CarmenLog:
    """Read the ``FLASER``, ``PARAM``, ``ODOM`` and ``NEFF`` lines of a CARMEN log.

    Checks every line's form (see the module docstring); the beam count of every scan must
    match the declared geometry (``fov_deg``/``angular_resolution_deg`` if given, else the
    ``PARAM`` lines, else the first scan's count). Other message types (``RLASER``, ``SYNC``,
    ``TRUEPOS``, …) are counted and ignored.
    """
    p = Path(path)
    problems = LineProblems(p, lenient)
    found = _log_lines(read_lines(p), problems)
    n_beams, geometry, keep = _scan_geometry(found, p, fov_deg, angular_resolution_deg, problems)
    values, numbers = _parse_block(
        [found.bodies[i] for i in keep],
        n_beams + 6,
        [found.body_lines[i] for i in keep],
        problems,
        "FLASER",
    )
    stamp_of = {found.body_lines[i]: found.stamps[i] for i in keep}
    times, ok_time = _flaser_stamps(numbers, stamp_of, problems)
    ranges = values[:, :n_beams]
    ok = ok_time & _check_ranges(ranges, numbers, problems, "FLASER")
    ok &= np.all(np.isfinite(values[:, n_beams:]), axis=1)
    for row in np.flatnonzero(~np.all(np.isfinite(values[:, n_beams:]), axis=1) & ok_time):
        problems.report(numbers[int(row)], "FLASER: the poses must be finite numbers")
    return CarmenLog(
        path=p,
        times=times[ok],
        ranges=np.ascontiguousarray(ranges[ok]),
        laser_poses=np.ascontiguousarray(values[ok, n_beams : n_beams + 3]),
        odom_poses=np.ascontiguousarray(values[ok, n_beams + 3 : n_beams + 6]),
        line_numbers=np.asarray(numbers, dtype=np.int64)[ok],
        params=found.params,
        param_lines=found.param_lines,
        counts=found.counts,
        skipped=tuple(sorted(problems.lines)),
        geometry=geometry,
    )


def _log_lines(lines: list[str], problems: LineProblems) -> _LogLines:
    """One pass over the lines: FLASER lines split into count, numbers and stamp; PARAM
    values kept; ODOM and NEFF lines checked for their form; every type counted."""
    out = _LogLines()
    for number, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        first = stripped.split(None, 1)  # any whitespace separates the fields
        kind, rest = first[0], (first[1] if len(first) > 1 else "")
        out.counts[kind] = out.counts.get(kind, 0) + 1
        if kind == "FLASER":
            split = _split_flaser(rest)
            if isinstance(split, str):
                problems.report(number, split)
                continue
            out.beams_of.append(split[0])
            out.bodies.append(split[1])
            out.stamps.append(split[2])
            out.body_lines.append(number)
        elif kind == "PARAM":
            fields_ = rest.split()
            if len(fields_) < 2:
                problems.report(number, "PARAM: expected a name and a value")
                continue
            out.params[fields_[0]] = fields_[1]
            out.param_lines[fields_[0]] = number
        else:
            wrong = _wrong_form(kind, rest)
            if wrong is not None:
                problems.report(number, wrong)
    return out


def _split_flaser(rest: str) -> tuple[int, str, str] | str:
    """``FLASER n <ranges and 6 pose numbers> ts host logger_ts`` → ``(n, numbers, ts)``,
    or what is wrong."""
    head = rest.split(None, 1)
    try:
        n = int(head[0]) if head else -1
    except ValueError:
        n = -1
    if n < 1 or len(head) < 2:
        return "FLASER: expected a beam count >= 1 and the readings"
    parts = head[1].rsplit(None, 3)
    if len(parts) != 4:
        return "FLASER: too few fields"
    return n, parts[0], parts[1]


def _wrong_form(kind: str, rest: str) -> str | None:
    """What is wrong with an ``ODOM`` or ``NEFF`` line (None: nothing; other types are
    not checked)."""
    fields_ = rest.split()
    if kind == "ODOM" and (len(fields_) != 9 or parse_floats(fields_[:7]) is None):
        return "ODOM: expected x y theta tv rv accel ts host logger_ts"
    if kind == "NEFF" and (len(fields_) != 1 or parse_floats(fields_) is None):
        return "NEFF: expected one number"
    return None


def _scan_geometry(
    found: _LogLines,
    path: Path,
    fov_deg: float | None,
    resolution_deg: float | None,
    problems: LineProblems,
) -> tuple[int, LogGeometry, list[int]]:
    """The log's beam count and geometry (from the first scan whose count fits what is
    declared), and the scans that have that count (others reported)."""
    n_beams: int | None = None
    geometry: LogGeometry | None = None
    keep: list[int] = []
    for i, n in enumerate(found.beams_of):
        line = found.body_lines[i]
        if n_beams is None:
            geometry = log_geometry(
                n, found.params, found.param_lines, path, fov_deg, resolution_deg
            )
            if geometry is None:
                problems.report(
                    line,
                    f"FLASER: {n} beams do not match the declared field of view and "
                    "resolution (in degrees or in radians); give fov_deg and "
                    "angular_resolution_deg",
                )
                continue
            n_beams = n
        elif n != n_beams:
            problems.report(
                line, f"FLASER: {n} beams disagree with the log's geometry of {n_beams} beams"
            )
            continue
        keep.append(i)
    if n_beams is None or geometry is None:
        raise DatasetFormatError("no FLASER scans found", path)
    return n_beams, geometry, keep


def _flaser_stamps(
    numbers: list[int], stamp_of: Mapping[int, str], problems: LineProblems
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The ``ts`` of each scan line (NaN where it is not a number, reported)."""
    times = np.full(len(numbers), math.nan)
    for j, number in enumerate(numbers):
        with contextlib.suppress(ValueError):  # not a number: stays NaN, reported below
            times[j] = float(stamp_of[number])
        if not math.isfinite(times[j]):
            problems.report(number, f"FLASER: time stamp {stamp_of[number]!r} is not a number")
    return times, np.isfinite(times)
