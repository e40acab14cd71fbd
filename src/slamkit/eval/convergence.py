"""Convergence of a localizer that starts without knowing where it is.

A global localizer (MCL from a uniform start) is wrong at first, then — if it works — finds
the robot and follows it, and may now and then lose it again. :func:`convergence` turns a
position-error track into the numbers that describe this:

* **time to converge**: the first time ``t_c`` after which the position error stays below
  ``threshold`` for at least ``hold`` seconds (every sample in ``[t_c, t_c + hold]`` below
  it, and the record reaching ``t_c + hold``), and its sample index (the *step*);
* the **error after convergence** (every sample from ``t_c`` on): median, mean, RMS, 90th
  and 95th percentile, maximum, and the same of the heading error when it is given;
* the **fraction of time tracking is lost** after ``t_c``: the time the error spends above
  ``lost_threshold`` (default ``threshold``), as a fraction of the time after ``t_c``, and
  the number of separate stretches ("episodes") that make it up.

Time, not sample count: an estimate is taken to hold from its sample to the next (the
runner records one after every group of events), so irregular sampling (a laser log that
writes a scan only when the robot moved) weighs each sample by how long it was in force.
:func:`convergence_against_truth` pairs an estimated trajectory with the true one first.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError, ShapeError
from slamkit.eval.trajectory import associate, pose_errors

__all__ = ["ConvergenceReport", "ErrorStats", "convergence", "convergence_against_truth"]


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of a set of non-negative errors (metres or radians)."""

    median: float
    mean: float
    rmse: float
    p90: float
    p95: float
    max: float
    count: int

    @classmethod
    def of(cls, values: FloatArray) -> ErrorStats:
        v = np.abs(np.asarray(values, dtype=np.float64))
        p50, p90, p95 = np.percentile(v, [50.0, 90.0, 95.0])
        return cls(
            median=float(p50),
            mean=float(v.mean()),
            rmse=float(np.sqrt(np.mean(v * v))),
            p90=float(p90),
            p95=float(p95),
            max=float(v.max()),
            count=int(v.size),
        )

    def as_dict(self) -> dict[str, float | int]:
        return {
            "median": self.median,
            "mean": self.mean,
            "rmse": self.rmse,
            "p90": self.p90,
            "p95": self.p95,
            "max": self.max,
            "count": self.count,
        }


@dataclass(frozen=True)
class ConvergenceReport:
    """What :func:`convergence` found. Times in seconds, errors in metres (headings: rad).

    When the error never stays below ``threshold`` for ``hold`` seconds, ``converged`` is
    False and every field about the time after convergence is ``None``.
    """

    converged: bool
    threshold: float
    """Position error [m] below which the estimate counts as converged."""
    hold: float
    """How long [s] the error had to stay below ``threshold``."""
    lost_threshold: float
    """Position error [m] above which tracking counts as lost (after convergence)."""
    step: int | None
    """Index of the sample at which the converged stretch begins."""
    time: float | None
    """``times[step] - times[0]``: the time to converge [s]."""
    position_error: ErrorStats | None
    """Position error of every sample from ``step`` on."""
    heading_error: ErrorStats | None
    """Absolute heading error from ``step`` on (``None`` without heading errors)."""
    lost_fraction: float | None
    """Fraction of the time after ``times[step]`` with the error above ``lost_threshold``."""
    lost_episodes: int | None
    """How many separate stretches of lost tracking that time is made of."""
    duration: float
    """``times[-1] - times[0]``: how long the record is [s]."""

    def as_dict(self) -> dict[str, Any]:
        """JSON-able form (for ``metrics.json``)."""
        return {
            "converged": self.converged,
            "threshold_m": self.threshold,
            "hold_s": self.hold,
            "lost_threshold_m": self.lost_threshold,
            "step": self.step,
            "time_s": self.time,
            "position_error_after": None
            if self.position_error is None
            else self.position_error.as_dict(),
            "heading_error_after": None
            if self.heading_error is None
            else self.heading_error.as_dict(),
            "lost_fraction": self.lost_fraction,
            "lost_episodes": self.lost_episodes,
            "duration_s": self.duration,
        }


def _first_held(times: FloatArray, ok: np.ndarray, hold: float) -> int | None:
    """The first index ``i`` with ``ok[j]`` for every ``j`` with ``times[j] <= times[i] +
    hold``, ``j >= i``, and ``times[-1] >= times[i] + hold``."""
    n = times.size
    # For each i: the index of the first failure at or after i (n if none).
    bad = np.flatnonzero(~ok)
    next_bad = np.full(n, n, dtype=np.int64)
    if bad.size:
        pos = np.searchsorted(bad, np.arange(n), side="left")
        has = pos < bad.size
        next_bad[has] = bad[pos[has]]
    # The stretch from i must last past times[i] + hold: the last sample inside the window
    # is at searchsorted(times, times[i] + hold, "right") - 1, and none of them may fail.
    end = np.searchsorted(times, times + hold, side="right")  # first index beyond the window
    long_enough = times[-1] >= times + hold
    candidates = np.flatnonzero(ok & long_enough & (next_bad >= end))
    return int(candidates[0]) if candidates.size else None


def convergence(
    times: ArrayLike,
    position_errors: ArrayLike,
    threshold: float,
    hold: float,
    *,
    lost_threshold: float | None = None,
    heading_errors: ArrayLike | None = None,
) -> ConvergenceReport:
    """Time to converge and the error after it, from ``position_errors (N,)`` [m] at
    non-decreasing ``times (N,)`` [s] (see the module docstring).

    ``threshold`` [m] > 0 and ``hold`` [s] >= 0 define convergence; ``lost_threshold`` [m]
    (default ``threshold``) defines lost tracking; ``heading_errors (N,)`` [rad] are
    summarised too when given. ``hold = 0`` means the first sample below the threshold.
    """
    t = as_array(times, "times", (None,))
    e = as_array(position_errors, "position_errors", (t.size,))
    if t.size == 0:
        raise InputError("times: expected at least one sample, got none")
    if np.any(np.diff(t) < 0):
        raise InputError("times: expected non-decreasing times")
    if np.any(e < 0):
        raise InputError("position_errors: expected distances >= 0")
    thr = float(threshold)
    if not (np.isfinite(thr) and thr > 0):
        raise InputError(f"threshold: expected a finite number > 0, got {threshold!r}")
    hold_s = float(hold)
    if not (np.isfinite(hold_s) and hold_s >= 0):
        raise InputError(f"hold: expected a finite number >= 0, got {hold!r}")
    lost = thr if lost_threshold is None else float(lost_threshold)
    if not (np.isfinite(lost) and lost > 0):
        raise InputError(f"lost_threshold: expected a finite number > 0, got {lost_threshold!r}")
    h = None
    if heading_errors is not None:
        h = as_array(heading_errors, "heading_errors", (t.size,))
        if h.shape != t.shape:
            raise ShapeError(f"heading_errors: expected shape {t.shape}, got {h.shape}")
    duration = float(t[-1] - t[0])
    step = _first_held(t, e < thr, hold_s)
    if step is None:
        return ConvergenceReport(
            False, thr, hold_s, lost, None, None, None, None, None, None, duration
        )
    ta, ea = t[step:], e[step:]
    # Each sample holds until the next one; the last one for no time.
    held = np.append(np.diff(ta), 0.0)
    above = ea > lost
    total = float(held.sum())
    lost_fraction = float(held[above].sum() / total) if total > 0 else float(above.mean())
    starts = above & ~np.concatenate([[False], above[:-1]])
    return ConvergenceReport(
        converged=True,
        threshold=thr,
        hold=hold_s,
        lost_threshold=lost,
        step=step,
        time=float(t[step] - t[0]),
        position_error=ErrorStats.of(ea),
        heading_error=None if h is None else ErrorStats.of(h[step:]),
        lost_fraction=lost_fraction,
        lost_episodes=int(np.count_nonzero(starts)),
        duration=duration,
    )


def convergence_against_truth(
    times: ArrayLike,
    poses: ArrayLike,
    truth_times: ArrayLike,
    truth_poses: ArrayLike,
    threshold: float,
    hold: float,
    *,
    max_dt: float = 0.02,
    lost_threshold: float | None = None,
) -> ConvergenceReport:
    """:func:`convergence` of an estimated trajectory ``(times (N,), poses (N, 3))`` against
    the truth ``(truth_times (M,), truth_poses (M, 3))``: each estimate is paired with the
    nearest true pose within ``max_dt`` seconds (estimates without one are left out) and
    its position and heading errors are those of
    :func:`~slamkit.eval.trajectory.pose_errors`."""
    t = as_array(times, "times", (None,))
    p = as_array(poses, "poses", (t.size, 3))
    tt = as_array(truth_times, "truth_times", (None,))
    tp = as_array(truth_poses, "truth_poses", (tt.size, 3))
    ia, ib = associate(t, tt, max_dt)
    if ia.size == 0:
        raise InputError(f"no estimate has a true pose within max_dt = {max_dt} s")
    err = pose_errors(p[ia], tp[ib])
    return convergence(
        t[ia],
        np.hypot(err[:, 0], err[:, 1]),
        threshold,
        hold,
        lost_threshold=lost_threshold,
        heading_errors=np.abs(err[:, 2]),
    )
