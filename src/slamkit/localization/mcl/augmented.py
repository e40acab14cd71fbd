"""Augmented MCL (Probabilistic Robotics, table 8.3): a slow and a fast average of the
measurement likelihood; when the fast one drops below the slow one — by more than its
natural spread — the robot has probably been moved, and a fraction of the particles is
replaced by random poses at the next resampling.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamkit._validation import as_positive

__all__ = ["Augmentation", "advance_augmentation"]


_SPREAD_WARMUP = 20
"""Updates after which deviations of the log evidence are clipped (see Augmentation)."""
_SPREAD_CLIP = 3.0
"""... to this many of its standard deviations."""


@dataclass(frozen=True)
class Augmentation:
    """The slow and fast averages of the measurement likelihood (Thrun table 8.3), in log
    space: ``w ← w + α (w_avg - w)`` becomes a ``logaddexp``; and how much the likelihood
    naturally varies from update to update.

    The likelihood that is averaged is the filter's evidence ``Σ_i w_i p(z | x_i)``
    (which equals Thrun's ``w_avg`` right after resampling, when all ``w_i = 1/P``) taken
    **per reading**: its ``n``-th root for ``n`` readings. A 90-beam scan's likelihood spans
    hundreds of orders of magnitude and grows with the number of beams that returned; per
    reading, ``w_fast / w_slow`` measures how well the particles explain the scans and not
    how many beams they had.

    Per reading is not enough, though: how much the evidence varies between updates while
    the filter tracks well depends on the sensor. The mean of many beams' log-likelihoods
    varies little from scan to scan; a single range reading's ``log N(ν; 0, S)`` by ±1
    (its ``ν²/S`` is χ²₁). Thrun's rule injects ``1 - w_fast/w_slow`` whenever the fast
    average is below the slow one — for a well-localized robot half the time, and on
    range-only beacons a large share of the particles (measurements in
    docs/estimators/mcl.md). So the update also keeps a
    slow (rate ``alpha_slow``) mean and variance ``s²`` of the per-reading log evidence, and
    :meth:`tolerance` gives the natural spread of ``log w_fast``,
    ``s · sqrt(α_fast / (2 - α_fast))`` (an exponential average of rate ``α`` of values with
    variance ``s²`` has variance ``s² α / (2 - α)``).
    """

    log_w_slow: float
    log_w_fast: float
    mean_log_w: float = 0.0
    """Slow average of the per-reading log evidence."""
    var_log_w: float = 0.0
    """Slow average of its squared deviation (not yet bias-corrected)."""
    count: int = 1
    """Updates averaged so far (the start included)."""

    @classmethod
    def start(cls, log_w: float) -> Augmentation:
        """Both averages at ``log_w`` (e.g. the first measured per-reading evidence)."""
        return cls(float(log_w), float(log_w), float(log_w), 0.0, 1)

    def update(self, log_w_avg: float, alpha_slow: float, alpha_fast: float) -> Augmentation:
        """``w_slow += α_slow (w_avg - w_slow)`` and ``w_fast += α_fast (w_avg - w_fast)``;
        the mean and variance of ``log w_avg`` with rate ``α_slow``."""

        def step(log_w: float, alpha: float) -> float:
            return float(np.logaddexp(np.log1p(-alpha) + log_w, np.log(alpha) + log_w_avg))

        # Exponentially weighted mean and variance (West 1979): d = x - m, m += α d,
        # v = (1 - α)(v + α d²), with d clipped to ±3 standard deviations once there are
        # some: the spread is that of the evidence while tracking, and a kidnapping's
        # collapse of the evidence must not widen the tolerance that is to detect it.
        d = float(log_w_avg) - self.mean_log_w
        if self.count > _SPREAD_WARMUP:
            s = np.sqrt(self._variance(alpha_slow))
            d = float(np.clip(d, -_SPREAD_CLIP * s, _SPREAD_CLIP * s))
        return Augmentation(
            step(self.log_w_slow, alpha_slow),
            step(self.log_w_fast, alpha_fast),
            self.mean_log_w + alpha_slow * d,
            (1.0 - alpha_slow) * (self.var_log_w + alpha_slow * d * d),
            self.count + 1,
        )

    def _variance(self, alpha_slow: float) -> float:
        """The variance of the per-reading log evidence so far, corrected for the bias of an
        exponential average started at zero; 0 before the second update."""
        n = self.count - 1  # deviations averaged
        if n < 1:
            return 0.0
        return max(float(self.var_log_w / -np.expm1(n * np.log1p(-alpha_slow))), 0.0)

    def tolerance(self, alpha_slow: float, alpha_fast: float) -> float:
        """The natural spread of ``log w_fast`` about ``log w_slow`` (see the class
        docstring): ``s · sqrt(α_fast / (2 - α_fast))``."""
        return float(np.sqrt(self._variance(alpha_slow) * alpha_fast / (2.0 - alpha_fast)))

    @property
    def injection_probability(self) -> float:
        """``max(0, 1 - w_fast / w_slow)``: Thrun's fraction of particles to replace by random
        poses at the next resampling."""
        return self.injection_probability_below(1.0)

    def injection_probability_below(self, ratio: float) -> float:
        """``max(0, 1 - w_fast / (ratio · w_slow))``: no injection until the fast average has
        dropped below ``ratio`` times the slow one (``ratio = 1``: Thrun's rule)."""
        r = as_positive(ratio, "ratio")
        return float(max(0.0, -np.expm1(self.log_w_fast - self.log_w_slow - np.log(r))))


def advance_augmentation(
    aug: Augmentation | None,
    log_w_avg: float,
    alpha_slow: float,
    alpha_fast: float,
    injection_sigmas: float,
) -> tuple[Augmentation, float]:
    """One measurement update of the averages (started at the first one), and the
    probability with which a particle is then replaced by a random pose: Thrun's
    ``1 - w_fast / w_slow`` against the slow average lowered by ``injection_sigmas`` times
    the fast average's natural spread (``AugmentedConfig.injection_sigmas``)."""
    if aug is None:
        aug = Augmentation.start(log_w_avg)
    else:
        aug = aug.update(log_w_avg, alpha_slow, alpha_fast)
    spread = aug.tolerance(alpha_slow, alpha_fast)
    ratio = float(np.exp(-injection_sigmas * spread))
    return aug, aug.injection_probability_below(ratio)
