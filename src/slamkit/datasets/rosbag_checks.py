"""The checks of :mod:`slamkit.datasets.rosbag` over the scans of a bag, all vectorised: bad
messages named by topic, index and reason, strict (raise at the first) or lenient (count by
kind) in one small object, :class:`Problems`.

A ``LaserScan``'s ``angle_max`` is redundant (``angle_min + (n − 1)·angle_increment``) and
drivers and converters often write it a beam off (an off-by-one field of view, a rounding
of the increment to float32): like gmapping, slam_toolbox and Cartographer, slamkit takes
``angle_min``, the increment and the number of ranges as the truth, accepts an ``angle_max``
up to :data:`ANGLE_MAX_TOLERANCE` increments off, and notes it once for the whole bag.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.rosbag_read import BagContents
from slamkit.errors import DatasetFormatError

__all__ = [
    "ANGLE_MAX_TOLERANCE",
    "LENIENT_SHOWN",
    "Problems",
    "check_geometry",
    "clean_ranges",
    "header_stamps",
]

LENIENT_SHOWN = 20
"""Problems listed (topic, index, reason) in the metadata of a lenient read."""

ANGLE_MAX_TOLERANCE = 1.5
"""How far a scan's ``angle_max`` may be from its last beam's angle
``angle_min + (n − 1)·angle_increment``, in increments, and still be read (the beam angles
then follow the increment). Up to half an increment is rounding; from half to this many
increments it is the common off-by-one of drivers and bag converters (a quirk, noted once);
further it says the ranges and the geometry disagree, an error (lenient: dropped)."""


class Problems:
    """Bad messages: raise at the first, or (lenient) count them by kind."""

    def __init__(self, path: Path, lenient: bool) -> None:
        self.path = path
        self.lenient = lenient
        self.counts: dict[str, int] = {}
        self.first: list[dict[str, Any]] = []

    def report(self, kind: str, topic: str, indices: NDArray[np.int64], why: str) -> None:
        """Messages ``indices`` of ``topic`` are bad (``why`` of the first); raise unless
        lenient."""
        if indices.size == 0:
            return
        where = f"{topic} message {int(indices[0])}"
        if not self.lenient:
            raise DatasetFormatError(f"{where}: {why}", self.path)
        self.counts[kind] = self.counts.get(kind, 0) + int(indices.size)
        if len(self.first) < LENIENT_SHOWN:
            self.first.append({"topic": topic, "message": int(indices[0]), "reason": why})


def header_stamps(sec: NDArray[np.int64], nsec: NDArray[np.int64]) -> FloatArray:
    """Stamps [s] as float64 ``sec + nanosec·1e-9`` (the relations files' values exactly)."""
    return sec.astype(np.float64) + nsec.astype(np.float64) * 1e-9


def check_geometry(
    bag: BagContents, topic: str, problems: Problems
) -> tuple[NDArray[np.bool_], str | None]:
    """Scans with the first scan's geometry and an ``angle_max`` within
    :data:`ANGLE_MAX_TOLERANCE` increments of the last beam; and the note, once for the bag,
    when some ``angle_max`` was more than half an increment off (None otherwise)."""
    s = bag.scans
    n = s.beam_counts
    ok = np.ones(n.size, dtype=bool)
    n0, amin0, inc0 = int(n[0]), float(s.angle_min[0]), float(s.angle_increment[0])
    finite = np.isfinite(s.angle_min) & np.isfinite(s.angle_increment) & np.isfinite(s.angle_max)
    bad = np.flatnonzero(~finite | (n < 1) | ((n > 1) & (s.angle_increment == 0)))
    problems.report("geometry", topic, bad, "angle_min/angle_increment not usable")
    ok[bad] = False
    with np.errstate(over="ignore", invalid="ignore"):  # a huge increment: inf, refused
        last = s.angle_min + (n - 1) * s.angle_increment
        off = np.abs(last - s.angle_max)
    inc = np.abs(s.angle_increment)
    bad = np.flatnonzero(ok & (off > np.maximum(ANGLE_MAX_TOLERANCE * inc, 1e-9)))
    if bad.size:
        i = int(bad[0])
        why = (
            f"{int(n[i])} beams from angle_min {s.angle_min[i]:.9g} by {s.angle_increment[i]:.9g}"
            f" end at {last[i]:.9g} rad, but angle_max is {s.angle_max[i]:.9g} (more than "
            f"{ANGLE_MAX_TOLERANCE:g} increments off)"
        )
        problems.report("geometry", topic, bad, why)
    ok[bad] = False
    with np.errstate(divide="ignore", invalid="ignore"):
        quirk = ok & (off > np.maximum(inc / 2.0, 1e-9))
        worst = float(np.max(off[quirk] / inc[quirk])) if quirk.any() else 0.0
    note = None
    if quirk.any():
        note = (
            f"angle_max up to {worst:.2f} increments off the last beam on "
            f"{int(quirk.sum())} of {n.size} scans: the beams are angle_min + i·angle_increment"
        )
    changed = (n != n0) | (np.abs(s.angle_min - amin0) > 1e-6)
    with np.errstate(over="ignore", invalid="ignore"):
        changed |= np.abs(s.angle_increment - inc0) * np.maximum(n - 1, 0) > 1e-6
    bad = np.flatnonzero(ok & changed)
    problems.report(
        "geometry",
        topic,
        bad,
        f"beam geometry differs from the first scan's ({n0} beams from {amin0:.9g} rad by "
        f"{inc0:.9g})",
    )
    ok[bad] = False
    limits = np.isfinite(s.range_max) & (s.range_max > 0) & np.isfinite(s.range_min)
    limits &= (s.range_min >= 0) & (s.range_min < s.range_max)
    bad = np.flatnonzero(ok & ~limits)
    problems.report("geometry", topic, bad, "range_min/range_max: expected 0 <= min < max")
    ok[bad] = False
    return ok, note


def clean_ranges(
    raw: FloatArray,
    range_min: FloatArray,
    range_max: FloatArray,
    max_range: float,
    index: NDArray[np.int64],
    topic: str,
    problems: Problems,
) -> tuple[FloatArray, dict[str, int]]:
    """Ranges ``(N, B)`` with every no return (at/over range_max or +inf, under range_min or
    -inf) and (lenient) every bad reading (NaN, negative) set to ``max_range``; the counts of
    readings by kind."""
    with np.errstate(invalid="ignore"):
        invalid = np.isnan(raw) | (np.isfinite(raw) & (raw < 0.0))
        far = raw >= np.minimum(range_max, max_range)[:, None]
        near = ~invalid & (raw < range_min[:, None])
    rows = np.flatnonzero(invalid.any(axis=1))
    if rows.size:
        r = int(rows[0])
        b = int(np.argmax(invalid[r]))
        problems.report(
            "invalid_readings",
            topic,
            index[rows],
            f"beam {b}: range {float(raw[r, b])!r} is not a reading (expected >= 0, +inf or -inf)",
        )
    out = np.where(invalid | far | near, max_range, raw)
    counts = {
        "no_return_far": int(np.count_nonzero(far & ~invalid)),
        "no_return_near": int(np.count_nonzero(near)),
        "invalid_readings": int(np.count_nonzero(invalid)),
    }
    return out, counts
