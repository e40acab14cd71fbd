"""Whether a laser tracker's result is suspect, said in a line each: the warnings shared by
every estimator that tracks scans against a map with the wheels as the prior (graph SLAM's
front end, laser odometry), listed under ``warnings`` in ``metrics.json``.

A wrong path looks like a right one unless the run says what it saw. Each rule reads what
the tracker counted anyway:

* **odometry glitches** — the laser overrode the wheels (:mod:`slamkit.scanmatch.relocate`):
  the run went on from the laser, but the user's odometry has faults;
* **track lost** — scans that fit the map neither where the wheels put them nor anywhere a
  wide search looked, more than :data:`LOST_SHARE` of them: their poses are the wheels';
* **unmatched stretch** — the longest run of consecutive scans without a match, when the
  wheels carried the robot :data:`UNMATCHED_TRAVEL` or more through it.

An estimator adds its own rules after these (graph SLAM's closures and final graph:
:mod:`slamkit.slam.laser_graph.health`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from slamkit._validation import FloatArray
from slamkit.datasets.stream import Control, Dataset, MotionSpec, Odometry
from slamkit.estimation.contract import RunWarning
from slamkit.geometry.angles import wrap_angle

__all__ = [
    "LOST_SHARE",
    "OVERRIDES_SHOWN",
    "STILL_ODOMETRY",
    "UNMATCHED_TRAVEL",
    "UnmatchedStretch",
    "override_rows",
    "still_odometry_warning",
    "tracking_warnings",
    "usable_motion",
]

LOST_SHARE = 0.01
"""Lost scans above this share of the scans make a warning."""
UNMATCHED_TRAVEL = 2.0
"""[m] the wheels carry the robot through an unmatched stretch before it is a warning."""
STILL_ODOMETRY = (1e-3, 1e-3)
"""Odometry that moves the robot no farther than this [m] and turns it no more [rad] over
the whole log says nothing of the motion."""
OVERRIDES_SHOWN = 20
"""The diagnostics list this many overridden glitches (the first ones); all are counted."""


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


def override_rows(overrides: Sequence[tuple[float, FloatArray]]) -> list[dict[str, float]]:
    """The first :data:`OVERRIDES_SHOWN` overridden glitches ``(stamp, T_wheels_laser)`` as
    diagnostics rows: the stamp [s] and the laser's correction of the wheels (x, y [m] in
    the wheels' frame, deg)."""
    return [
        {"t": t, "x": float(d[0]), "y": float(d[1]), "deg": math.degrees(float(d[2]))}
        for t, d in overrides[:OVERRIDES_SHOWN]
    ]


def tracking_warnings(
    scans: int,
    lost: int,
    overrides: Sequence[tuple[float, FloatArray]],
    stretch: UnmatchedStretch,
) -> list[RunWarning]:
    """The tracker's warnings (module docstring) from the number of scans and of lost
    ones, the overridden glitches ``(stamp, T_wheels_laser)`` and the longest unmatched
    stretch."""
    found: list[RunWarning] = []
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
    return found


def usable_motion(dataset: Dataset) -> tuple[MotionSpec | None, str | None]:
    """The data set's motion, or None and why, when it says nothing: the odometry poses
    never move (or there are none), or every control is zero, over the whole log
    (:data:`STILL_ODOMETRY`). A laser tracker then runs on the laser alone instead of
    holding the robot still against what the scans show, and says so."""
    motion = dataset.motion
    if motion is None:
        return None, None
    if motion.source == "odometry":
        poses = np.array([e.pose for e in dataset.events if isinstance(e, Odometry)])
        if poses.shape[0] == 0:
            return None, "the data set has no odometry readings"
        travel = float(np.hypot(*(poses[:, :2] - poses[0, :2]).T).max())
        turn = float(np.abs(wrap_angle(poses[:, 2] - poses[0, 2])).max())
        what = f"the odometry never moves ({len(poses)} readings)"
    else:
        controls = [e.u for e in dataset.events if isinstance(e, Control)]
        if not controls:
            return None, "the data set has no controls"
        travel = turn = float(np.abs(np.asarray(controls)).max())
        what = f"every control is zero ({len(controls)} controls)"
    if travel <= STILL_ODOMETRY[0] and turn <= STILL_ODOMETRY[1]:
        return None, what
    return motion, None


def still_odometry_warning(reason: str) -> RunWarning:
    """The warning of a run whose data set's motion said nothing (:func:`usable_motion`)."""
    return RunWarning("no_odometry", f"{reason}: the scans were tracked by the laser alone")
