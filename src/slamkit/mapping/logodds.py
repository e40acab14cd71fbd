"""Log-odds ↔ probability, the one place slamkit converts between them.

An occupancy grid stores for each cell ``m`` the log odds ``l = log(p / (1 - p))`` of
``p = p(m occupied | z_1:t, x_1:t)``. The recursive Bayes update of a static binary cell with
an inverse sensor model ``p(m | z_t, x_t)`` and prior ``p0`` is (Thrun et al., *Probabilistic
Robotics*, eq. 9.7)::

    l_t = logit(p(m | z_t, x_t)) + l_{t-1} - l_0,        l_0 = logit(p0)

so every measurement adds a constant per region of the inverse model. The log odds are clamped
to ``[logit(p_min), logit(p_max)]`` after every update: without a bound, a cell seen free a
thousand times needs a thousand "occupied" readings to change its mind (a door that opens, a
person who walks away), and ``expit`` of a huge value saturates to exactly 0 or 1.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array
from slamkit.errors import InputError

__all__ = ["clamp_log_odds", "expit", "log_odds_update", "logit"]


def logit(p: ArrayLike) -> FloatArray:
    """``log(p / (1 - p))`` for probabilities strictly between 0 and 1."""
    arr = as_array(p, "probability")
    if np.any((arr <= 0.0) | (arr >= 1.0)):
        raise InputError("probability: expected values strictly between 0 and 1 for log odds")
    return np.log(arr) - np.log1p(-arr)


def expit(log_odds: ArrayLike) -> FloatArray:
    """``1 / (1 + exp(-l))``, the inverse of :func:`logit`, without overflow for large ``|l|``
    (``exp`` is only ever taken of ``-|l|``)."""
    # Written with in-place operations: on a large grid every fresh temporary array costs
    # more (first-touch page faults) than the arithmetic itself.
    out = np.array(log_odds, dtype=np.float64)  # a copy: becomes the result
    negative = out < 0.0
    np.abs(out, out=out)
    np.negative(out, out=out)
    np.exp(out, out=out)  # e = exp(-|l|) in (0, 1]
    denominator = out + 1.0
    out[~negative] = 1.0  # numerator: 1 for l >= 0, e for l < 0
    np.divide(out, denominator, out=out)
    return out


def clamp_log_odds(log_odds: ArrayLike, l_min: float, l_max: float) -> FloatArray:
    """Log odds clipped to ``[l_min, l_max]`` (requires ``l_min < l_max``)."""
    if not l_min < l_max:
        raise InputError(f"log-odds bounds: expected l_min < l_max, got {l_min}, {l_max}")
    return np.clip(np.asarray(log_odds, dtype=np.float64), l_min, l_max)


def log_odds_update(
    previous: ArrayLike,
    p_inverse: ArrayLike,
    p_prior: float,
    l_min: float = -np.inf,
    l_max: float = np.inf,
) -> FloatArray:
    """One Bayes update in log-odds form: ``clamp(logit(p_inverse) + previous - logit(p_prior))``.

    ``previous`` are the cells' log odds, ``p_inverse`` the inverse sensor model's
    probabilities for them (broadcast), ``p_prior`` the prior occupancy probability.
    """
    prev = np.asarray(previous, dtype=np.float64)
    l0 = float(logit(p_prior))
    return clamp_log_odds(logit(p_inverse) + prev - l0, l_min, l_max)
