"""Feature selection of EKF-SLAM: which unmatched readings may start a feature.

A reading that no landmark's gate takes and that is beyond every landmark's new-landmark
threshold (:func:`~slamkit.slam.ekf_slam.association.associate_scan`) is a candidate
feature. Two tests, each a setting of :class:`~slamkit.slam.ekf_slam.EkfSlamConfig`, can
refuse it (the reading is then counted as ``not_selected`` and used for nothing):

* **spatial spread** (``min_feature_spacing``): the landmark it would place,
  ``p = g⁻¹(x_r, z)``, must lie at least this far from every landmark of the state
  (provisional ones included) and from the features already started by the same scan. The
  Mahalanobis test alone lets a reading start a second feature beside a landmark whose
  covariance has become too small for the readings it gets; a Euclidean spacing does not
  depend on that covariance.
* **expected information** (``max_new_feature_trace``): the covariance the reading alone
  gives the landmark, ``L_z R L_zᵀ`` (``L_z = ∂g⁻¹/∂z``; for range and bearing its trace is
  ``σ_r² + r² σ_b²``), must have a trace below this [m²]. A far reading locates its landmark
  poorly, so the feature it starts is wide, takes readings of its neighbours and is often
  deleted and started again; the same landmark is started from a nearer reading later.

Signatures (a distinctness test between a reading's signature and the landmarks') are not
implemented: no reading in slamkit's event stream carries one (Victoria Park's trunk
diameters are not readings, :mod:`slamkit.datasets.victoria_park_trees`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.models.measurement import InvertibleLandmarkModel

__all__ = ["NOT_SELECTED", "select_features"]

NOT_SELECTED = -3
"""What the estimator writes in place of a landmark index for a reading that association
would have let start a feature but selection refused (beside
:class:`~slamkit.estimation.readings.AssociationCode`'s ``NEW = -1``, ``REJECTED = -2``)."""


def select_features(
    mean: FloatArray,
    z: FloatArray,
    model: InvertibleLandmarkModel,
    R: FloatArray,
    min_spacing: float,
    max_trace: float | None,
) -> NDArray[np.bool_]:
    """``(K,)``: which of the candidate readings ``z (K, m)`` (in scan order) may start a
    feature at the state ``mean (3 + 2L,)``, by the spatial spread (``min_spacing`` [m],
    ``0`` for no test) and the expected information (``max_trace`` [m²], ``None`` for no
    test) of the module docstring. A candidate refused keeps no place: a later candidate
    is compared with the earlier ones that were selected only."""
    K = z.shape[0]
    ok = np.ones(K, dtype=bool)
    if K == 0:
        return ok
    x = np.broadcast_to(mean[:3], (K, 3))
    if max_trace is not None:
        _, Lz = model.inverse_jacobians(x, z)
        C = Lz @ R @ np.swapaxes(Lz, -1, -2)  # the reading's own covariance of the landmark
        ok &= np.trace(C, axis1=-2, axis2=-1) <= max_trace
    if min_spacing > 0.0:
        p = model.inverse(x, z)  # (K, 2)
        lm = mean[3:].reshape(-1, 2)
        if lm.shape[0]:
            d2 = np.einsum("kli,kli->kl", p[:, None] - lm[None], p[:, None] - lm[None])
            ok &= d2.min(axis=1) >= min_spacing**2
        for k in range(1, K):  # the features this scan starts, in order
            if ok[k]:
                earlier = np.flatnonzero(ok[:k])
                if earlier.size and np.min(np.sum((p[earlier] - p[k]) ** 2, axis=1)) < (
                    min_spacing**2
                ):
                    ok[k] = False
    return ok
