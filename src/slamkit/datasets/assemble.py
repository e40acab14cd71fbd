"""The loader kit: the steps every reader takes, and the one function that ends them.

Every reader of real data goes through the same four steps, each its own small function:

1. **parse** — the file's text or records into arrays, with the line (or message) each
   row came from; a line that cannot be read is a
   :class:`~slamkit.errors.DatasetFormatError` naming the file and line (or, lenient,
   counted).
2. **check** — what parsed but is not physically plausible (a range beyond the sensor, a
   stamp that is not a time), by the same typed error; quirks are repaired and counted in
   the :class:`~slamkit.datasets.reading.ReadingSummary`.
3. **convert** — units and conventions into slamkit's (seconds, metres, radians, wrapped
   angles, the robot's frame), as arrays: :func:`control_events`,
   :func:`odometry_events`, :func:`scan_events` and :func:`reading_events` turn them into
   one stream of events per kind.
4. **assemble** — :func:`assemble_events` merges the streams into the data set's one
   time-ordered tuple. No reader interleaves streams by hand.

:func:`assemble_events` puts events in the order every estimator expects: by time, and at
one time stamp the known pose first, then the motion (:class:`Control` over ``(t − dt,
t]``, or the :class:`Odometry` pose at ``t``), then the readings and scans taken at ``t``
(:data:`EVENT_RANK`) — so a reading at the stamp of a control is processed after the robot
has moved. Events of the same rank at the same time keep the order of the streams as given,
and within a stream their order in it: the merge is stable.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit.datasets.stream import (
    Control,
    Event,
    GpsFix,
    KnownPose,
    LandmarkReadings,
    LaserScan,
    Odometry,
)
from slamkit.errors import InputError, ShapeError

__all__ = [
    "EVENT_RANK",
    "assemble_events",
    "control_events",
    "odometry_events",
    "reading_events",
    "scan_events",
    "time_groups",
]

EVENT_RANK: dict[type, int] = {
    KnownPose: 0,
    Control: 1,
    Odometry: 1,
    LandmarkReadings: 2,
    LaserScan: 2,
    GpsFix: 2,
}
"""The order of event kinds at one time stamp (lower first)."""


def assemble_events(*streams: Iterable[Event]) -> tuple[Event, ...]:
    """The streams merged into one: by time, at equal times by :data:`EVENT_RANK`, then by
    the order of the streams, then by the order within a stream (see the module docstring).
    The stamps are kept as they are. An event of an unknown type, or a stamp that is not a
    finite number, raises :class:`~slamkit.errors.InputError` naming the stream and the
    event's place in it."""
    items: list[Event] = []
    source: list[int] = []
    for s, stream in enumerate(streams):
        part = list(stream)
        items.extend(part)
        source.extend([s] * len(part))
    try:
        rank = np.fromiter((EVENT_RANK[type(ev)] for ev in items), np.int64, len(items))
    except KeyError as exc:
        raise InputError(f"assemble_events: unknown event type {exc.args[0].__name__}") from None
    times = np.fromiter((ev.t for ev in items), np.float64, len(items))
    bad = np.flatnonzero(~np.isfinite(times))
    if bad.size:
        i = int(bad[0])
        where = i - source.index(source[i])
        raise InputError(
            f"assemble_events: stream {source[i]}, event {where} ({type(items[i]).__name__}): "
            f"time stamp {times[i]!r} is not a finite number"
        )
    order = np.lexsort((np.asarray(source, np.int64), rank, times))  # last key sorts first
    return tuple(items[i] for i in order)


def control_events(times: ArrayLike, u: ArrayLike, dt: ArrayLike) -> list[Control]:
    """One :class:`Control` per row: ``u[k]`` over ``(times[k] − dt[k], times[k]]``."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    uu = _rows(u, t.size, "controls")
    d = np.asarray(dt, dtype=np.float64).reshape(-1)
    if d.size != t.size:
        raise ShapeError(f"control dt: expected {t.size} durations, got {d.size}")
    return [Control(float(t[k]), uu[k].copy(), float(d[k])) for k in range(t.size)]


def odometry_events(times: ArrayLike, poses: ArrayLike) -> list[Odometry]:
    """One :class:`Odometry` per row: the pose ``poses[k] (3,)`` at ``times[k]``."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    p = _rows(poses, t.size, "odometry poses")
    return [Odometry(float(t[k]), p[k].copy()) for k in range(t.size)]


def scan_events(times: ArrayLike, ranges: ArrayLike) -> list[LaserScan]:
    """One :class:`LaserScan` per row: ``ranges[k] (B,)`` at ``times[k]``."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    r = _rows(ranges, t.size, "scan ranges")
    return [LaserScan(float(t[k]), r[k].copy()) for k in range(t.size)]


def reading_events(times: ArrayLike, z: ArrayLike, ids: ArrayLike) -> list[LandmarkReadings]:
    """Readings ``z (K, m)`` with ids ``(K,)`` at ``times (K,)`` (non-decreasing), the rows
    of one stamp together as one :class:`LandmarkReadings` event, in the order given."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    zz = _rows(z, t.size, "readings")
    idv: NDArray[np.int64] = np.asarray(ids, dtype=np.int64).reshape(-1)
    if idv.size != t.size:
        raise ShapeError(f"reading ids: expected {t.size} ids, got {idv.size}")
    if np.any(np.diff(t) < 0):
        raise InputError("reading_events: expected non-decreasing reading times")
    starts, ends = time_groups(t)
    return [
        LandmarkReadings(float(t[a]), zz[a:b].copy(), idv[a:b].copy())
        for a, b in zip(starts, ends, strict=True)
    ]


def time_groups(times: Sequence[float] | NDArray[np.float64]) -> tuple[list[int], list[int]]:
    """The ``[start, end)`` rows of each run of equal stamps in sorted ``times``."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if t.size == 0:
        return [], []
    starts = np.flatnonzero(np.r_[True, np.diff(t) != 0])
    ends = np.r_[starts[1:], t.size]
    return [int(a) for a in starts], [int(b) for b in ends]


def _rows(values: ArrayLike, n: int, what: str) -> NDArray[np.float64]:
    a = np.asarray(values, dtype=np.float64)
    if n == 0 and a.size == 0:
        return np.zeros((0, 0))
    if a.ndim == 1 and n > 0 and a.size == n:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] != n:
        raise ShapeError(f"{what}: expected {n} rows, got shape {a.shape}")
    return a
