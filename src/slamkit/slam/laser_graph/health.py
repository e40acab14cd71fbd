"""Whether a graph-SLAM run's result is suspect, said in a line each: the warnings a run
prints and lists under ``warnings`` in ``metrics.json``.

A wrong map looks like a right one unless the run says what it saw. The front end's rules
(odometry glitches, track lost, unmatched stretch) are every laser tracker's
(:mod:`slamkit.estimation.health`); graph SLAM adds three of its own:

* **closures refused** — verified closures the consistency checks refused, when they are
  at least :data:`REFUSED_AT_LEAST` and outnumber those kept: places the map joins in two
  incompatible ways;
* **a map that contradicts itself** — revisits of the final map
  (:func:`~slamkit.slam.laser_graph.freespace.revisit_contradictions`) whose two visits lay
  walls in each other's open space, when they are at least
  :data:`CONTRADICTING_AT_LEAST` and more than :data:`CONTRADICTING_SHARE` of the revisits
  checked;
* **strained graph** — loop edges of the final graph whose residual exceeds
  :data:`STRAINED_CHI2` (ten standard deviations in their own metric), the map disagreeing
  with its own evidence, when they are more than :data:`STRAINED_SHARE` of the closures
  and at least :data:`STRAINED_AT_LEAST` (Intel's good run, 0.017 m, keeps one such edge
  of 1,750).

A run whose laser gave nothing to match — no scan with enough points to start a map, or
none matched after the first — is not a result but a dead-reckoning path under a SLAM
name: it ends with one line saying why (:func:`laser_unusable`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence

import numpy as np

from slamkit._validation import FloatArray
from slamkit.estimation.contract import RunWarning
from slamkit.estimation.health import UnmatchedStretch, tracking_warnings

__all__ = [
    "CONTRADICTING_AT_LEAST",
    "CONTRADICTING_SHARE",
    "REFUSED_AT_LEAST",
    "STRAINED_AT_LEAST",
    "STRAINED_CHI2",
    "STRAINED_SHARE",
    "laser_unusable",
    "run_warnings",
]

CONTRADICTING_SHARE = 0.12
"""Revisits of the final map that contradict it above this share of those checked ..."""
CONTRADICTING_AT_LEAST = 5
"""... and at least this many make a warning."""
REFUSED_AT_LEAST = 10
"""Refused closures fewer than this are never a warning."""
STRAINED_CHI2 = 100.0
"""A final loop edge whose ``eᵀ Ω e`` exceeds this is strained (10 σ)."""
STRAINED_SHARE = 0.01
"""Strained loop edges above this share of the closures make a warning ..."""
STRAINED_AT_LEAST = 3
"""... when they are at least this many."""


def run_warnings(
    diagnostics: Mapping[str, object],
    overrides: Sequence[tuple[float, FloatArray]],
    stretch: UnmatchedStretch,
    loop_chi2: FloatArray,
    revisits: tuple[int, int] = (0, 0),
) -> tuple[RunWarning, ...]:
    """The warnings of a run (module docstring) from its diagnostics, the overridden
    glitches ``(stamp, T_wheels_laser)``, the longest unmatched stretch, the final loop
    edges' ``eᵀ Ω e`` and the final map's revisits ``(checked, contradicting)``."""
    scans = int(diagnostics.get("scans", 0) or 0)  # type: ignore[call-overload]
    lost = int(diagnostics.get("lost", 0) or 0)  # type: ignore[call-overload]
    found = tracking_warnings(scans, lost, overrides, stretch)
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
    checked, contradicting = revisits
    if contradicting >= CONTRADICTING_AT_LEAST and contradicting > CONTRADICTING_SHARE * checked:
        found.append(
            RunWarning(
                "map_contradicts_itself",
                f"{contradicting} of {checked} places the robot came back to are mapped "
                "twice or bent: the two visits put walls in each other's open space",
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


def laser_unusable(counts: Counter[str], tracker_counts: Counter[str]) -> str:
    """The one line that ends a run whose laser gave nothing to match, from the
    estimator's and the front end's counts (keyframes refused and matches failed, by
    reason)."""
    scans = counts["scans"]
    refused = {k.split(":", 1)[1]: v for k, v in counts.items() if k.startswith("keyframe_")}
    failed = {k.split(":", 1)[1]: v for k, v in tracker_counts.items() if k.startswith("failed:")}
    why = ", ".join(
        f"{n} {reason.replace('_', ' ')}" for reason, n in {**refused, **failed}.items()
    )
    return (
        f"graph SLAM: the laser gave nothing to match in {scans} scans"
        + (f" ({why})" if why else "")
        + ": check the laser's range limits (min_range, max_range) and its beam angles"
    )
