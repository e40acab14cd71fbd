"""Data association of EKF mapping: the gates (:func:`association_probabilities`) and the
greedy global nearest neighbour of a scan (:func:`associate_nearest`), shared with EKF-SLAM,
SEIF and FastSLAM."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array
from slamkit.errors import ConfigError, InputError
from slamkit.estimation.readings import AssociationCode

__all__ = [
    "NEW",
    "REJECTED",
    "associate_nearest",
    "associate_nearest_unchecked",
    "association_probabilities",
]

# The codes as module constants (the values of the enum in slamkit.estimation.readings).
NEW = AssociationCode.NEW
REJECTED = AssociationCode.REJECTED


def associate_nearest_unchecked(d: FloatArray, gate: float, new_gate: float) -> NDArray[np.int64]:
    """:func:`associate_nearest` without its input checks (``d`` finite or ``inf``, ``>= 0``):
    the estimators' hot path."""
    k, n = d.shape
    out = np.full(k, REJECTED, dtype=np.int64)
    if n == 0:
        out[:] = NEW
        return out
    flat = np.argsort(d, axis=None, kind="stable")  # all pairs, nearest first
    flat = flat[d.reshape(-1)[flat] <= gate]
    used_reading = np.zeros(k, dtype=bool)
    used_landmark = np.zeros(n, dtype=bool)
    for f in flat.tolist():
        r, c = divmod(f, n)
        if used_reading[r] or used_landmark[c]:
            continue
        out[r] = c
        used_reading[r] = used_landmark[c] = True
    out[~used_reading & (d.min(axis=1) > new_gate)] = NEW
    return out


def association_probabilities(gate: float, new_landmark: float) -> tuple[float, float]:
    """Check a config's ``gate_probability`` and ``new_landmark_probability`` (each in
    ``(0, 1)``, the new-landmark threshold the stricter one) and return them; a
    :class:`~slamkit.errors.ConfigError` names the one that is wrong."""
    for name, p in (("gate_probability", gate), ("new_landmark_probability", new_landmark)):
        if not 0 < p < 1:
            raise ConfigError(f"{name}: expected a probability in (0, 1), got {p}")
    if new_landmark < gate:
        raise ConfigError(
            "new_landmark_probability: expected >= gate_probability (the new-landmark "
            f"threshold is the stricter one), got {new_landmark} < {gate}"
        )
    return float(gate), float(new_landmark)


def associate_nearest(d2: ArrayLike, gate: float, new_gate: float) -> NDArray[np.int64]:
    """Greedy global nearest-neighbour association of one scan.

    ``d2 (K, n)``: squared Mahalanobis distances of ``K`` readings to ``n`` landmarks.
    Pairs are taken by increasing ``d2``; a pair is accepted when ``d2 ≤ gate`` and neither
    its reading nor its landmark is taken yet (a scan sees each landmark at most once).
    Returns, per reading, the landmark column, or :data:`NEW` when the reading's smallest
    ``d2`` exceeds ``new_gate`` (far from every landmark), else :data:`REJECTED`.
    ``new_gate ≥ gate`` is the stricter "new landmark" threshold.
    """
    d = as_array(d2, "d2", (None, None), finite=False)
    if np.any(np.isnan(d)) or np.any(d < 0):
        raise InputError("d2: expected squared distances >= 0 (no NaN)")
    if not (0 < gate <= new_gate):
        raise InputError(f"gates: expected 0 < gate <= new_gate, got {gate}, {new_gate}")
    return associate_nearest_unchecked(d, gate, new_gate)
