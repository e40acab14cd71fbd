"""The time a run has left, from the work it has left and the time its work has taken.

A progress bar's time left is ``work left × time per unit``. Two ways to know the time per
unit, chosen by what the estimator's cost does (:attr:`EstimatorEntry.pace`):

* ``"steady"`` — the time per unit is what it was over the last :data:`RATE_WINDOW`
  seconds (rich's bar does the same), right for an estimator whose cost per scan or reading
  does not grow with the run (filters, laser odometry, particle filters);
* ``"growing"`` — graph SLAM searches a graph that grows for its loop closures and solves
  a larger graph each time, so its time per scan rises through the run, and the last 30 s's
  rate promises far too little early on (16 s left at a quarter of Intel, truly 58 s). The
  time per unit is taken to rise linearly with the work done, ``c(x) = c_now + b (x − x_now)``:
  ``c_now`` is the rate of the last :data:`RATE_WINDOW` seconds (at the window's middle), and
  ``b`` the slope of a least-squares fit of the cumulative time against the work done
  since the start, ``T(x) = t₀ + a x + b x² / 2`` (``b`` held at 0 or more: a run that
  speeds up is given the steady estimate). The time left is the integral of ``c`` over the
  work left: ``c_now (N − x) + b ((N − m)² − (x − m)²) / 2`` with ``m`` the window's
  middle. Graph SLAM's cost does not rise for ever (on Intel it rises over the first third
  and then holds), so neither figure is right throughout; the estimate is the range from
  the steady figure to the rising one, and the truth was inside it or near it at a quarter,
  half, three quarters and 90 % of two real logs.

Measured against the truth in ``docs/architecture.md`` ("Progress").
"""

from __future__ import annotations

from collections import deque
from typing import Literal

import numpy as np

__all__ = ["MAX_SAMPLES", "RATE_WINDOW", "Pace", "TimeLeft"]

Pace = Literal["steady", "growing"]
"""How an estimator's time per unit of work behaves through a run."""

RATE_WINDOW = 30.0
"""Seconds of the latest counts the current time per unit is measured over."""

MAX_SAMPLES = 2048
"""Counts kept for the fit of a growing pace; beyond it every other one is dropped."""


class TimeLeft:
    """Collects ``(time [s], work done)`` counts with :meth:`add` and estimates the seconds
    left to ``total`` with :meth:`estimate` (module docstring). ``basis`` says in words what
    the estimate rests on, for the progress line."""

    def __init__(self, pace: Pace = "steady", window: float = RATE_WINDOW) -> None:
        self.pace: Pace = pace
        self.window = window
        self._recent: deque[tuple[float, int]] = deque()
        self._all: list[tuple[float, int]] = []

    @property
    def basis(self) -> str:
        """What :meth:`estimate` rests on, in words."""
        if self.pace == "growing":
            return (
                f"the last {self.window:.0f} s's pace holding, or rising as it has since the start"
            )
        return f"the last {self.window:.0f} s's pace"

    def add(self, t: float, done: int) -> None:
        """One count: ``done`` units of work at time ``t`` (seconds, any origin)."""
        self._recent.append((t, done))
        while len(self._recent) > 1 and self._recent[1][0] <= t - self.window:
            self._recent.popleft()  # keep one count at or before the window's start
        if self.pace == "growing":
            self._all.append((t, done))
            if len(self._all) > MAX_SAMPLES:  # thin, keeping the latest
                self._all = self._all[-1::-2][::-1]

    def _slope(self) -> float:
        """``b`` of the fit ``T(x) = t₀ + a x + b x² / 2`` over every count, at least 0."""
        if len(self._all) < 8:
            return 0.0
        data = np.asarray(self._all, dtype=float)
        t, x = data[:, 0], data[:, 1]
        if np.ptp(x) <= 0:
            return 0.0
        scale = float(x.max())  # fit in work / scale for conditioning
        u = x / scale
        design = np.column_stack([np.ones_like(u), u, 0.5 * u * u])
        coef, *_ = np.linalg.lstsq(design, t, rcond=None)
        return max(float(coef[2]) / scale**2, 0.0)

    def estimate(self, total: int, now: float | None = None) -> tuple[float, float] | None:
        """Seconds left until ``total`` units are done, as ``(low, high)``: the last
        window's pace holding, and (a growing pace) rising as it has since the start — the
        same twice for a steady pace or a run that has not sped up. None until there is a
        rate (no work done within the window yet). ``now``: the time of the estimate when
        later than the last count (a stall then makes the time left grow)."""
        if not self._recent:
            return None
        t_then, done_then = self._recent[0]
        t_now, done = self._recent[-1]
        t_now = t_now if now is None else max(now, t_now)
        if done <= done_then or t_now <= t_then:
            return None
        left = max(total - done, 0)
        per_unit = (t_now - t_then) / (done - done_then)
        steady = left * per_unit
        if self.pace != "growing":
            return steady, steady
        b = self._slope()
        middle = 0.5 * (done + done_then)
        rising = steady + 0.5 * b * ((total - middle) ** 2 - (done - middle) ** 2)
        return steady, max(rising, steady)
