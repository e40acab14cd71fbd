"""Whether a graph-SLAM run's result is suspect, said in a line each: the warnings a run
prints and lists under ``warnings`` in ``metrics.json``.

A wrong map looks like a right one unless the run says what it saw. Each rule reads what
the estimator counted anyway:

* **odometry glitches** — the laser overrode the wheels (:mod:`slamkit.scanmatch.relocate`):
  the run went on from the laser, but the user's odometry has faults;
* **track lost** — scans that fit the map neither where the wheels put them nor anywhere a
  wide search looked, more than :data:`LOST_SHARE` of them: their poses are the wheels';
* **unmatched stretch** — the longest run of consecutive scans without a match, when the
  wheels carried the robot :data:`UNMATCHED_TRAVEL` or more through it;
* **closures refused** — verified closures the consistency checks refused, when they are
  at least :data:`REFUSED_AT_LEAST` and outnumber those kept: places the map joins in two
  incompatible ways;
* **strained graph** — loop edges of the final graph whose residual exceeds
  :data:`STRAINED_CHI2` (ten standard deviations in their own metric), the map disagreeing
  with its own evidence, when they are more than :data:`STRAINED_SHARE` of the closures
  and at least :data:`STRAINED_AT_LEAST` (Intel's good run, 0.017 m, keeps one such edge
  of 1,750).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.estimation.contract import RunWarning

__all__ = [
    "LOST_SHARE",
    "REFUSED_AT_LEAST",
    "STRAINED_AT_LEAST",
    "STRAINED_CHI2",
    "STRAINED_SHARE",
    "UNMATCHED_TRAVEL",
    "UnmatchedStretch",
    "run_warnings",
]

LOST_SHARE = 0.01
"""Lost scans above this share of the scans make a warning."""
UNMATCHED_TRAVEL = 2.0
"""[m] the wheels carry the robot through an unmatched stretch before it is a warning."""
REFUSED_AT_LEAST = 10
"""Refused closures fewer than this are never a warning."""
STRAINED_CHI2 = 100.0
"""A final loop edge whose ``eᵀ Ω e`` exceeds this is strained (10 σ)."""
STRAINED_SHARE = 0.01
"""Strained loop edges above this share of the closures make a warning ..."""
STRAINED_AT_LEAST = 3
"""... when they are at least this many."""


@dataclass
class UnmatchedStretch:
    """The longest run of consecutive unmatched scans: where it began and ended [s], how
    many scans, and how far the wheels moved the robot through it [m]."""

    start: float = math.nan
    end: float = math.nan
    scans: int = 0
    travel: float = 0.0
    _current: tuple[float, int, float] | None = None  # start, scans, travel of the open run

    def add(self, t: float, matched: bool, moved: float) -> None:
        """One scan at ``t``: whether it matched, and how far the wheels moved since the
        scan before [m]."""
        if matched:
            self._current = None
            return
        start, scans, travel = self._current or (t, 0, 0.0)
        self._current = (start, scans + 1, travel + moved)
        if self._current[2] > self.travel or (
            self._current[2] == self.travel and scans >= self.scans
        ):
            self.start, self.end = start, t
            self.scans, self.travel = self._current[1], self._current[2]


def run_warnings(
    diagnostics: Mapping[str, object],
    overrides: Sequence[tuple[float, FloatArray]],
    stretch: UnmatchedStretch,
    loop_chi2: FloatArray,
) -> tuple[RunWarning, ...]:
    """The warnings of a run (module docstring) from its diagnostics, the overridden
    glitches ``(stamp, T_wheels_laser)``, the longest unmatched stretch and the final loop
    edges' ``eᵀ Ω e``."""
    found: list[RunWarning] = []
    scans = int(diagnostics.get("scans", 0) or 0)  # type: ignore[call-overload]
    if overrides:
        t, d = overrides[0]
        found.append(
            RunWarning(
                "odometry_glitches",
                f"the wheels glitched {len(overrides)} time(s) (first at t = {t:.2f} s, "
                f"{math.degrees(float(d[2])):+.0f}° and {math.hypot(d[0], d[1]):.2f} m off "
                "what the laser saw): the laser's pose was kept; check the odometry",
            )
        )
    lost = int(diagnostics.get("lost", 0) or 0)  # type: ignore[call-overload]
    if scans and lost > LOST_SHARE * scans:
        found.append(
            RunWarning(
                "track_lost",
                f"{lost} of {scans} scans ({100 * lost / scans:.1f} %) fit the map nowhere "
                "the wheels or a wide search put them: the wheels' poses were kept there",
            )
        )
    if stretch.travel >= UNMATCHED_TRAVEL:
        found.append(
            RunWarning(
                "unmatched_stretch",
                f"the laser matched nothing for {stretch.travel:.1f} m ({stretch.scans} scans, "
                f"t = {stretch.start:.1f}-{stretch.end:.1f} s): the wheels alone there",
            )
        )
    refused = int(diagnostics.get("loops_refused", 0) or 0)  # type: ignore[call-overload]
    kept = int(diagnostics.get("loops_kept", 0) or 0)  # type: ignore[call-overload]
    if refused >= REFUSED_AT_LEAST and refused > kept:
        found.append(
            RunWarning(
                "closures_refused",
                f"{refused} verified loop closures were refused as inconsistent with the "
                f"graph ({kept} kept): some places may be joined wrongly or not at all",
            )
        )
    strained = int(np.count_nonzero(loop_chi2 > STRAINED_CHI2))
    if strained >= STRAINED_AT_LEAST and strained > STRAINED_SHARE * loop_chi2.size:
        found.append(
            RunWarning(
                "strained_graph",
                f"{strained} of {loop_chi2.size} loop closures of the final graph disagree "
                "with it by more than "
                f"10 σ (largest χ² {float(loop_chi2.max()):.0f}): the map contradicts its "
                "own evidence there",
            )
        )
    return tuple(found)
