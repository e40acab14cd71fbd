"""Innovation (NIS) statistics of a filter run: consistency on data without ground truth.

Each measurement update of a Gaussian filter yields ``NIS = νᵀ S⁻¹ ν``, χ²-distributed with
``dof`` = the measurement dimension when the filter is consistent. A sum of NIS values over a
window of updates is χ² with the summed degrees of freedom, which gives a two-sided band per
window; the fraction of the run's time covered by windows inside their band says "how much of
the run the filter stays consistent".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError, ShapeError

__all__ = ["NisSummary", "nis_summary"]


@dataclass(frozen=True, eq=False)
class NisSummary:
    """NIS statistics of one run (see :func:`nis_summary`)."""

    count: int
    mean_per_dof: float
    """Σ NIS / Σ dof: 1 for a consistent filter, > 1 over-confident, < 1 too cautious."""
    fraction_in_band: float
    """Share of single updates inside their own two-sided band (expect ≈ probability)."""
    window: int
    window_sums: FloatArray
    window_lower: FloatArray
    window_upper: FloatArray
    window_start: FloatArray
    window_end: FloatArray
    fraction_windows_consistent: float
    consistent_time_fraction: float
    """Share of the run's duration covered by windows whose NIS sum is inside its band."""
    probability: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "count": self.count,
            "mean_nis_per_dof": self.mean_per_dof,
            "fraction_updates_in_band": self.fraction_in_band,
            "window_updates": self.window,
            "windows": int(self.window_sums.size),
            "fraction_windows_consistent": self.fraction_windows_consistent,
            "consistent_time_fraction": self.consistent_time_fraction,
            "probability": self.probability,
        }


def nis_summary(
    times: ArrayLike,
    nis: ArrayLike,
    dof: ArrayLike,
    *,
    window: int = 50,
    probability: float = 0.95,
) -> NisSummary:
    """Summarise NIS values ``(K,)`` with their degrees of freedom ``(K,)`` at ``times (K,)``
    (non-decreasing). Windows are consecutive, non-overlapping runs of ``window`` updates
    (the last, shorter one included)."""
    t = as_array(times, "times", (None,))
    v = as_array(nis, "nis", (t.size,))
    d = np.asarray(dof)
    if d.shape != t.shape or not np.issubdtype(d.dtype, np.integer) or np.any(d < 1):
        raise ShapeError(f"dof: expected {t.size} positive integers")
    if t.size == 0:
        raise InputError("nis_summary: no updates to summarise")
    if np.any(v < 0):
        raise InputError("nis: expected non-negative values")
    if not 0 < probability < 1:
        raise InputError(f"probability: expected a value in (0, 1), got {probability}")
    if window < 1:
        raise InputError(f"window: expected >= 1 updates, got {window}")
    lo_p, hi_p = (1 - probability) / 2, (1 + probability) / 2
    single_lo, single_hi = stats.chi2.ppf(lo_p, d), stats.chi2.ppf(hi_p, d)
    starts = np.arange(0, t.size, window)
    sums = np.add.reduceat(v, starts)
    dofs = np.add.reduceat(d, starts)
    w_lo, w_hi = stats.chi2.ppf(lo_p, dofs), stats.chi2.ppf(hi_p, dofs)
    inside = (sums >= w_lo) & (sums <= w_hi)
    ends = np.minimum(starts + window, t.size) - 1
    t0, t1 = t[starts], t[ends]
    # A window covers the time from its first update to the next window's first update.
    cover_end = np.append(t[starts[1:]], t[-1])
    spans = cover_end - t0
    total = float(t[-1] - t[0])
    time_frac = float(spans[inside].sum() / total) if total > 0 else float(np.mean(inside))
    return NisSummary(
        count=int(t.size),
        mean_per_dof=float(v.sum() / d.sum()),
        fraction_in_band=float(np.mean((v >= single_lo) & (v <= single_hi))),
        window=window,
        window_sums=sums,
        window_lower=np.asarray(w_lo, dtype=float),
        window_upper=np.asarray(w_hi, dtype=float),
        window_start=t0,
        window_end=t1,
        fraction_windows_consistent=float(np.mean(inside)),
        consistent_time_fraction=time_frac,
        probability=probability,
    )
