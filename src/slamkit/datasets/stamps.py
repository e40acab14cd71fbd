"""Time stamps as real logs write them, made strictly increasing in the file's order.

The logs of the field carry stamps of 0.0, negative stamps, stamps that repeat, stamps
that go back by a second, and stamps printed with six significant digits (``1.01893e+09``:
one value for a whole 20-minute log). The order of the lines is the order of the log, so
the line order is the truth and a stamp is evidence about *when*, to be used where it is
consistent.

:func:`repair_stamps` keeps as anchors the longest strictly increasing run of plausible
stamps (not necessarily contiguous: a longest increasing subsequence, so that one stamp
that jumps ahead or back costs only itself; of equally long ones, the one that keeps the
earliest lines), and places every other line between the anchors around it by linear
interpolation in the line index (beyond the first or last anchor: the anchors' median
period). Stamps that never go back but repeat (low precision) are one rounded time per
run: the middle line of each run keeps the value and the others spread around it. When
stamps also go back and fewer than half of them are anchors, or fewer than two are, the
stamps carry no usable timing and every line is re-stamped at ``nominal_period`` from the
line order. Each repaired stamp is counted by what was wrong with it, for the
:class:`~slamkit.datasets.reading.ReadingSummary`.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray

__all__ = ["MAX_PLAUSIBLE_STAMP", "RESTAMP_REASON", "StampRepair", "repair_stamps"]

MAX_PLAUSIBLE_STAMP = 1e10
"""Stamps above this [s] (the year 2286 in Unix time) are not stamps but damage."""

ZERO = "zero or negative stamps"
REPEATED = "repeated stamps"
BACKWARD = "stamps out of order"
IMPLAUSIBLE = "stamps not a plausible time"
RESTAMP_REASON = "stamps unusable, re-made from the line order"
"""The reason :class:`StampRepair` gives when the whole file was re-stamped."""


@dataclass(frozen=True)
class StampRepair:
    """What :func:`repair_stamps` did: ``counts`` of repaired stamps by reason (empty when
    the stamps were strictly increasing already), and whether the whole file was re-stamped
    from the line order (``restamped``, at ``period`` seconds a line)."""

    counts: dict[str, int] = field(default_factory=dict)
    restamped: bool = False
    period: float = 0.0

    @property
    def repaired(self) -> int:
        return sum(self.counts.values())


def _run_lengths(values: FloatArray, usable: NDArray[np.bool_]) -> NDArray[np.int64]:
    """For each usable line, the length of the longest strictly increasing run of usable
    values that *ends* there (patience sorting, O(n log n)); 0 for unusable lines."""
    tails: list[float] = []  # the smallest last value of an increasing run of each length
    out = np.zeros(values.size, dtype=np.int64)
    for i in np.flatnonzero(usable):
        v = float(values[i])
        k = bisect.bisect_left(tails, v)
        if k == len(tails):
            tails.append(v)
        else:
            tails[k] = v
        out[i] = k + 1
    return out


def _longest_increasing(values: FloatArray, usable: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Indices of the longest strictly increasing subsequence of the usable values that
    keeps the earliest lines: where several are equally long (``1, 2, 1.5, 3``), the stamp
    that goes back is the later one, so ``1, 2, 3`` and not ``1, 1.5, 3``."""
    # The longest run *starting* at each line: runs ending there, on the reversed negation.
    starting = _run_lengths(-values[::-1], usable[::-1])[::-1]
    need = int(starting.max()) if starting.size else 0
    picked: list[int] = []
    last = -np.inf
    for i in np.flatnonzero(usable):
        if need == 0:
            break
        if starting[i] == need and values[i] > last:
            picked.append(int(i))
            last = float(values[i])
            need -= 1
    return np.asarray(picked, dtype=np.int64)


def _reasons(times: FloatArray, anchors: NDArray[np.int64]) -> dict[str, int]:
    """Count the non-anchor stamps by what was wrong with them."""
    counts: dict[str, int] = {}
    is_anchor = np.zeros(times.size, dtype=bool)
    is_anchor[anchors] = True
    for i in np.flatnonzero(~is_anchor):
        t = float(times[i])
        if not (np.isfinite(t) and t <= MAX_PLAUSIBLE_STAMP):
            reason = IMPLAUSIBLE
        elif t <= 0.0:
            reason = ZERO
        elif i > 0 and t == times[i - 1]:
            reason = REPEATED
        else:
            reason = BACKWARD
        counts[reason] = counts.get(reason, 0) + 1
    return counts


def repair_stamps(times: FloatArray, nominal_period: float = 1.0) -> tuple[FloatArray, StampRepair]:
    """Strictly increasing stamps for lines in the file order (see the module docstring).

    ``times (N,)`` as read (any values, NaN included); returns the repaired ``(N,)`` stamps
    and what was done. Anchors keep their stamps exactly (for runs of a repeated stamp, the
    run's middle keeps it).
    """
    t = np.asarray(times, dtype=np.float64)
    n = t.size
    if n == 0:
        return t.copy(), StampRepair()
    if n > 1 and np.all(np.diff(t) > 0) and t[0] > 0 and t[-1] <= MAX_PLAUSIBLE_STAMP:
        return t.copy(), StampRepair()
    usable = np.isfinite(t) & (t > 0.0) & (t <= MAX_PLAUSIBLE_STAMP)
    anchors = _longest_increasing(t, usable)
    # Stamps that only repeat (low precision) are consistent however few distinct values
    # they have; stamps that also go back must agree on at least half the lines.
    consistent = bool(usable.all() and np.all(np.diff(t) >= 0))
    if anchors.size < 2 or not (consistent or anchors.size >= 0.5 * n):
        if n == 1 and anchors.size == 1:
            return t.copy(), StampRepair()
        return _restamp(t, anchors, nominal_period)
    if consistent:
        # A run of equal stamps is one rounded time: its middle line is where the printed
        # value is best, and the lines of the run spread around it.
        values, first_line, size = np.unique(t, return_index=True, return_counts=True)
        index, anchor_t = first_line + (size - 1) / 2.0, values
        counts = {REPEATED: int(np.sum(size[size > 1]))} if np.any(size > 1) else {}
    else:
        index, anchor_t = anchors.astype(np.float64), t[anchors]
        counts = _reasons(t, anchors)
    period = float(np.median(np.diff(anchor_t) / np.diff(index)))
    line = np.arange(n, dtype=np.float64)
    out = np.interp(line, index, anchor_t)
    before, after = line < index[0], line > index[-1]
    out[before] = anchor_t[0] - period * (index[0] - line[before])
    out[after] = anchor_t[-1] + period * (line[after] - index[-1])
    if not np.all(np.diff(out) > 0):
        # Anchors closer than the float spacing at their size (56 lines within 6 µs of a
        # Unix time): the interpolated stamps would repeat, so the stamps carry no timing.
        return _restamp(t, anchors, nominal_period)
    return out, StampRepair(counts, period=period)


def _restamp(
    t: FloatArray, anchors: NDArray[np.int64], nominal_period: float
) -> tuple[FloatArray, StampRepair]:
    """Every line re-stamped at ``nominal_period`` from the line order, placed so that the
    first anchor (if any) keeps its time (never before 0)."""
    n = t.size
    start = float(t[anchors[0]]) if anchors.size else 0.0
    first = start - nominal_period * float(anchors[0]) if anchors.size else 0.0
    out = max(first, 0.0) + nominal_period * np.arange(n, dtype=np.float64)
    return out, StampRepair({RESTAMP_REASON: n}, restamped=True, period=nominal_period)
