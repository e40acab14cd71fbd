"""The consistency monitor of a run: NEES and NIS over sliding windows against their χ² bands,
reported as warnings when a window falls far outside.

A consistent Gaussian filter has a NEES ``eᵀ P⁻¹ e ~ χ²(dof)`` at every step and a NIS
``νᵀ S⁻¹ ν ~ χ²(m)`` at every update. Over a window of ``W`` consecutive values the mean is
compared with the two-sided band of :func:`slamkit.eval.chi2_bounds`; a filter whose window
mean leaves it is over-confident (above: its covariance is too small for its errors — e.g.
EKF localization on five-features with σ = 1e-6 readings, NEES window means ~1e7) or too
cautious (below). The first window *far* outside (beyond :data:`MONITOR_MARGIN` times the
band) is reported with its step range, value and band.

The band is for a whole run, not for one window: a run of ``K`` values holds ``m = ⌈K / W⌉``
disjoint windows, and each window is held to the probability ``1 − (1 − p) / m``
(Bonferroni over the disjoint windows, which the overlapping ones between them barely add to),
so a consistent run is flagged with probability about ``1 − p`` per statistic.

* **NIS** values of a consistent filter are independent (its innovations are white), so the
  sum over a window of updates with ``D`` scalar components is χ²(``D``): the band is
  ``chi2_bounds(1, D, ·)`` on the mean NIS per degree of freedom.
* **NEES** values are not: the estimation error of one step carries into the next, and 50
  steps of EKF localization on ``landmark-loop`` hold far fewer than 50 independent values
  (their window means range over [0.95, 6.2] for a consistent filter, against a band of
  [1.99, 4.27] for 50 independent χ²(3) values at 0.999). The window then counts as
  ``⌊W / τ⌋`` independent values, ``τ`` the integrated autocorrelation time of the run's
  NEES sequence (:func:`autocorrelation_time`, at most ``W``).

Numbers only: the records say what was found; :mod:`slamkit.cli` prints them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError, ShapeError
from slamkit.eval.consistency import chi2_bounds

__all__ = [
    "MONITOR_MARGIN",
    "MONITOR_PROBABILITY",
    "MONITOR_WINDOW",
    "ConsistencyWarning",
    "autocorrelation_time",
    "nees_warning",
    "nis_warning",
]

MONITOR_WINDOW = 50
"""Values per sliding window: steps for the NEES, measurement updates for the NIS."""
MONITOR_PROBABILITY = 0.9999
"""Probability that a consistent run stays inside the band of one statistic (see the module
docstring for how it is shared among the windows)."""
MONITOR_MARGIN = 1.5
"""How far outside its band a window must be to warn: above ``upper · margin`` or below
``lower / margin``. Measured: on 40 runs of consistent filters (EKF localization on
five-features and landmark-loop, UKF localization and EKF-SLAM on five-features, seeds
0–9) the only windows outside their 0.9999 band were within 2 % of it (NIS per dof 0.477
against 0.483, EKF localization on five-features, seed 0: linearisation near a landmark;
NEES 0.590 against 0.590 at the start of EKF-SLAM, seed 0), while σ = 1e-6 readings put the
NEES of EKF localization 10⁶ times above it."""


@dataclass(frozen=True)
class ConsistencyWarning:
    """The first window whose NEES or NIS mean lies outside its χ² band, and how many did."""

    statistic: Literal["nees", "nis"]
    first: int
    """Index of the window's first value (a matched step for the NEES, an update for the
    NIS), counting from 0."""
    last: int
    """Index of its last value (inclusive)."""
    start_time: float
    end_time: float
    value: float
    """The window's mean NEES, or mean NIS per degree of freedom."""
    band: tuple[float, float]
    """The χ² band of the window; it warns beyond ``(lower / margin, upper · margin)``."""
    margin: float
    direction: Literal["over-confident", "too cautious"]
    windows_outside: int
    """Windows (sliding, one per start) outside their band."""
    windows: int
    probability: float
    """Probability of the band for a consistent run (:data:`MONITOR_PROBABILITY`)."""
    independent_values: int
    """Values the window counts as independent (``W`` for the NIS, ``⌊W / τ⌋`` for the
    NEES; per degree of freedom for the NIS)."""

    @property
    def message(self) -> str:
        """One line for a person: what, where, how far."""
        name = "NEES" if self.statistic == "nees" else "NIS per dof"
        what = "steps" if self.statistic == "nees" else "updates"
        lo, hi = self.band
        return (
            f"{name} inconsistent ({self.direction}): mean {self.value:.4g} over {what} "
            f"{self.first}-{self.last} (t = {self.start_time:.2f}-{self.end_time:.2f} s), "
            f"more than {self.margin:g}x outside its {100 * self.probability:g} % chi-square "
            f"band [{lo:.3g}, {hi:.3g}]; {self.windows_outside} of {self.windows} windows "
            "that far out"
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "statistic": self.statistic,
            "first": self.first,
            "last": self.last,
            "start_time": self.start_time,
            "end_time": self.end_time,
            "value": self.value,
            "band": list(self.band),
            "margin": self.margin,
            "direction": self.direction,
            "windows_outside": self.windows_outside,
            "windows": self.windows,
            "probability": self.probability,
            "independent_values": self.independent_values,
            "message": self.message,
        }


def autocorrelation_time(values: ArrayLike, max_lag: int | None = None) -> float:
    """Integrated autocorrelation time ``τ = 1 + 2 Σ_{k=1}^{M} ρ_k`` of a sequence ``(K,)``:
    1 for an independent sequence, ``K / τ`` the effective number of independent values.

    The sum stops at Sokal's automatic window, the first ``M`` with ``M ≥ 5 τ(M)`` (the
    estimated ``ρ_k`` beyond a few correlation times are noise, and summing them biases
    ``τ``); lags up to ``max_lag`` (default ``K // 4``). A constant sequence gives 1."""
    x = as_array(values, "values", (None,))
    k = x.size
    if k < 2:
        return 1.0
    d = x - x.mean()
    var = float(d @ d)
    if var <= 0.0 or not math.isfinite(var):
        return 1.0
    lags = max(1, min(k - 1, k // 4 if max_lag is None else max_lag))
    # ρ_k for every lag at once: the autocovariance through the FFT (zero-padded, no wrap).
    size = 1 << (2 * k - 1).bit_length()
    f = np.fft.rfft(d, size)
    acov = np.fft.irfft(f * np.conj(f), size)[: lags + 1]
    tau = 1.0 + 2.0 * np.cumsum(acov[1:] / acov[0])  # τ(M) for M = 1 .. lags
    stop = np.flatnonzero(np.arange(1, lags + 1) >= 5.0 * tau)
    return float(max(1.0, tau[stop[0]] if stop.size else tau[-1]))


def _windows(values: FloatArray, window: int) -> FloatArray:
    """Sums over every run of ``window`` consecutive values ``(K − window + 1,)``."""
    c = np.concatenate(([0.0], np.cumsum(values)))
    return c[window:] - c[:-window]


def _check(times: FloatArray, window: int, probability: float, margin: float) -> None:
    if not (math.isfinite(margin) and margin >= 1.0):
        raise InputError(f"margin: expected a number >= 1, got {margin!r}")
    if not (isinstance(window, int) and window >= 2):
        raise InputError(f"window: expected an integer >= 2, got {window!r}")
    if not 0.0 < probability < 1.0:
        raise InputError(f"probability: expected a number in (0, 1), got {probability!r}")
    if np.any(np.diff(times) < 0):
        raise InputError("times: expected non-decreasing times")


def _first_outside(
    statistic: Literal["nees", "nis"],
    times: FloatArray,
    means: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    window: int,
    probability: float,
    margin: float,
    independent: int,
) -> ConsistencyWarning | None:
    outside = (means < lo / margin) | (means > hi * margin)
    if not outside.any():
        return None
    i = int(np.flatnonzero(outside)[0])
    return ConsistencyWarning(
        statistic=statistic,
        first=i,
        last=i + window - 1,
        start_time=float(times[i]),
        end_time=float(times[i + window - 1]),
        value=float(means[i]),
        band=(float(lo[i]), float(hi[i])),
        direction="over-confident" if means[i] > hi[i] else "too cautious",
        windows_outside=int(outside.sum()),
        windows=int(means.size),
        probability=probability,
        margin=margin,
        independent_values=independent,
    )


def _window_probability(count: int, window: int, probability: float) -> float:
    """The per-window probability: ``1 − (1 − p) / m`` over ``m`` disjoint windows."""
    return 1.0 - (1.0 - probability) / max(1, math.ceil(count / window))


def nees_warning(
    times: ArrayLike,
    nees: ArrayLike,
    dof: int,
    *,
    window: int = MONITOR_WINDOW,
    probability: float = MONITOR_PROBABILITY,
    margin: float = MONITOR_MARGIN,
) -> ConsistencyWarning | None:
    """The first sliding window of ``window`` NEES values ``(K,)`` (at ``times (K,)``, of a
    ``dof``-dimensional error) whose mean lies outside ``chi2_bounds(dof, ⌊W / τ⌋, p_w)``
    (module docstring) by more than ``margin``, or ``None``: a consistent run, or fewer than
    ``window`` values."""
    t = as_array(times, "times", (None,))
    v = as_array(nees, "nees", (t.size,))
    _check(t, window, probability, margin)
    if np.any(v < 0):
        raise InputError("nees: expected non-negative values")
    if v.size < window:
        return None
    tau = min(float(window), max(1.0, autocorrelation_time(v)))
    independent = max(1, int(window // tau))
    lo, hi = chi2_bounds(dof, independent, _window_probability(v.size, window, probability))
    means = _windows(v, window) / window
    n = means.size
    return _first_outside(
        "nees", t, means, np.full(n, lo), np.full(n, hi), window, probability, margin, independent
    )


def nis_warning(
    times: ArrayLike,
    nis: ArrayLike,
    dof: ArrayLike,
    *,
    window: int = MONITOR_WINDOW,
    probability: float = MONITOR_PROBABILITY,
    margin: float = MONITOR_MARGIN,
) -> ConsistencyWarning | None:
    """The first sliding window of ``window`` updates — NIS values ``(K,)`` with their degrees
    of freedom ``(K,)`` at ``times (K,)`` — whose mean NIS per degree of freedom
    ``Σ NIS / Σ dof`` lies outside ``chi2_bounds(1, Σ dof, p_w)`` by more than ``margin``, or
    ``None``."""
    t = as_array(times, "times", (None,))
    v = as_array(nis, "nis", (t.size,))
    d = np.asarray(dof)
    if d.shape != t.shape or not np.issubdtype(d.dtype, np.integer) or np.any(d < 1):
        raise ShapeError(f"dof: expected {t.size} positive integers")
    _check(t, window, probability, margin)
    if np.any(v < 0):
        raise InputError("nis: expected non-negative values")
    if v.size < window:
        return None
    p_w = _window_probability(v.size, window, probability)
    dofs = np.rint(_windows(d.astype(float), window)).astype(np.int64)
    means = _windows(v, window) / dofs
    lo, hi = np.empty(means.size), np.empty(means.size)
    for total in np.unique(dofs).tolist():  # one band per distinct Σ dof (usually one)
        sel = dofs == total
        lo[sel], hi[sel] = chi2_bounds(1, int(total), p_w)
    return _first_outside("nis", t, means, lo, hi, window, probability, margin, int(dofs.min()))
