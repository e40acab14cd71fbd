"""Data association: which known landmark produced each reading, when readings carry no id.

Maximum likelihood with a validation gate. For a reading ``z_k`` and a landmark ``l_j`` seen
from the belief ``N(μ, P)`` the innovation is ``ν_kj = z_k − h(μ, l_j)`` (angles wrapped) with
covariance ``S_j = H_j P H_jᵀ + R`` (``H_j`` the pose Jacobian at ``μ``). Its squared
Mahalanobis distance ``d²_kj = ν_kjᵀ S_j⁻¹ ν_kj`` is χ²(m) distributed when ``l_j`` is the right
landmark, so only landmarks with ``d²_kj`` inside the gate ``χ²_m⁻¹(gate_probability)`` are
candidates, and the reading goes to the candidate with the smallest ``d²``. A reading with no
candidate is reported as unassociated (``-1``), never forced onto the nearest landmark.

Each reading is associated on its own (nearest neighbour in the Mahalanobis sense): two readings
of one scan may pick the same landmark. The ``log det S_j`` term of the full Gaussian likelihood
is left out, as usual; it only matters when the candidates' innovation covariances differ a lot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import InputError
from slamkit.estimation.belief import GaussianBelief
from slamkit.estimation.gaussian import angular_indices, measure_unchecked, wrap_array
from slamkit.maps import LandmarkMap
from slamkit.models import MIN_RANGE, LandmarkModel
from slamkit.prob import chi2_gate, mahalanobis_squared

__all__ = ["Association", "associate_ml"]


@dataclass(frozen=True)
class Association:
    """The landmark chosen for each of ``K`` readings and how far its innovation was.

    ``landmark_ids (K,)`` are ids of the map (``-1``: outside every gate, unassociated).
    ``d2 (K,)`` is the smallest squared Mahalanobis distance of each reading over all
    landmarks — the chosen one's, or for an unassociated reading the nearest one outside the
    gate (``inf`` when the map is empty).
    """

    landmark_ids: NDArray[np.int64]
    d2: FloatArray

    @property
    def associated(self) -> NDArray[np.bool_]:
        """Mask ``(K,)`` of the readings that were associated."""
        return np.asarray(self.landmark_ids >= 0)


def _distances(
    pose: FloatArray,
    pose_cov: FloatArray,
    z: FloatArray,
    positions: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
) -> FloatArray:
    """``d² (K, M)`` of every reading against every landmark (``inf`` for landmarks at the
    sensor, whose bearing and Jacobian are undefined). Vectorised over readings × landmarks."""
    K, M = z.shape[0], positions.shape[0]
    d2 = np.full((K, M), np.inf)
    seen = np.hypot(positions[:, 0] - pose[0], positions[:, 1] - pose[1]) >= MIN_RANGE
    if K == 0 or not seen.any():
        return d2
    pos = positions[seen]
    z_hat, Hp = measure_unchecked(model, np.broadcast_to(pose, (pos.shape[0], 3)), pos)  # (M', m)
    S = Hp @ pose_cov @ np.swapaxes(Hp, -1, -2) + R  # (M', m, m): H_j P H_jᵀ + R
    nu = z[:, None, :] - z_hat[None, :, :]  # (K, M', m)
    for i in angular_indices(model):
        nu[..., i] = wrap_array(nu[..., i])
    d2[:, seen] = mahalanobis_squared(nu, S)
    return d2


def associate_arrays_unchecked(
    pose: FloatArray,
    pose_cov: FloatArray,
    z: FloatArray,
    landmarks: LandmarkMap,
    model: LandmarkModel,
    R: FloatArray,
    gate: float,
) -> Association:
    """:func:`associate_ml` on validated arrays; ``gate`` is the χ² threshold (may be inf)."""
    d2 = _distances(pose, pose_cov, z, landmarks.positions, model, R)
    K = z.shape[0]
    if d2.shape[1] == 0:
        return Association(np.full(K, -1, dtype=np.int64), np.full(K, np.inf))
    best = np.argmin(d2, axis=1)
    best_d2 = d2[np.arange(K), best]
    ids = np.where(best_d2 <= gate, landmarks.ids[best], -1).astype(np.int64)
    return Association(ids, best_d2)


def associate_ml(
    belief: GaussianBelief,
    z: ArrayLike,
    landmarks: LandmarkMap,
    model: LandmarkModel,
    R: ArrayLike,
    gate_probability: float = 0.99,
) -> Association:
    """Associate readings ``z (K, m)`` with the ``landmarks`` by maximum likelihood inside a
    χ² gate (see the module docstring).

    ``belief`` is the pose belief the readings are compared against (its first three entries
    are the pose); ``model`` the sensor's measurement model (``m = model.dim``); ``R (m, m)``
    the noise of one reading; ``gate_probability`` in ``(0, 1)`` the probability mass of the
    gate (0.99: a correct association is rejected 1 % of the time). Raises
    :class:`~slamkit.errors.NonFiniteError` for NaN readings and
    :class:`~slamkit.errors.CovarianceError` if ``R`` is not positive definite.
    """
    m = model.dim
    za = as_array(z, "z", (None, m))
    Ra = as_covariance(R, "R", m)
    if not isinstance(landmarks, LandmarkMap):
        raise InputError(f"landmarks: expected a LandmarkMap, got {type(landmarks).__name__}")
    gate = chi2_gate(m, gate_probability)
    return associate_arrays_unchecked(belief.pose, belief.pose_cov, za, landmarks, model, Ra, gate)
