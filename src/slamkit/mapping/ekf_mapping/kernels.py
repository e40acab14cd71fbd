"""EKF landmark mapping with KNOWN robot poses.

This is *mapping with known poses*: the robot's pose ``x_t`` is given at every reading (the
estimator :class:`EkfMapping` takes it from the data set's true trajectory, by time stamp) and
only the landmark positions are estimated. Compare the robot-pose-and-map problem of EKF-SLAM,
where the pose is uncertain and correlates every landmark with every other.

The filter
----------
The state is the map ``m = (m_1, …, m_n) ∈ R^{2n}`` with belief ``N(μ, Σ)``.

* **Prediction**: landmarks do not move and there is no process noise, so ``μ`` and ``Σ`` are
  unchanged; nothing is computed between readings.
* **Update** with a reading ``z`` (noise ``R``) of landmark ``i``: ``h(x_t, m)`` depends on
  ``m_i`` only, so the ``m × 2n`` Jacobian ``G`` is zero outside the two columns of ``m_i``,
  where it is ``H_i = ∂h/∂m_i``. Writing ``Σ_{:i}`` for the two columns of ``i``::

      ν = z ⊟ h(x_t, μ_i)                  (angular components wrapped)
      S = H_i Σ_ii H_iᵀ + R                (m × m)
      K = Σ_{:i} H_iᵀ S⁻¹                  (2n × m; only block column i of Σ is read)
      μ ← μ + K ν
      Σ ← (I − K G) Σ (I − K G)ᵀ + K R Kᵀ  (Joseph form)
        = Σ − B − Bᵀ + K S Kᵀ,   B = K (H_i Σ_{i:})

  The last line is the Joseph form multiplied out with ``G Σ = H_i Σ_{i:}``: two rank-``m``
  corrections, ``O(n²)`` per reading, without ever forming ``G``, ``K G`` or ``I − K G``.
  Joseph rather than ``Σ − K S Kᵀ``: it is a sum of a congruence and a PSD term, so the
  covariance stays symmetric positive semi-definite even when round-off makes the gain
  slightly sub-optimal; it costs two extra rank-``m`` products. The result is symmetrised
  to remove the remaining round-off asymmetry.
* **First sighting**: the state grows by ``μ_new = g(x_t, z)`` (the inverse measurement
  model) with covariance ``L_z R L_zᵀ``, ``L_z = ∂g/∂z``. The ``L_x P_x L_xᵀ`` term of
  :func:`~slamkit.models.landmark_initial_covariance` vanishes because the pose is known,
  and the new landmark's cross-covariances with the old ones are zero: with a known pose a
  reading of one landmark says nothing about any other.

Consequence: the covariance stays block-diagonal
------------------------------------------------
If ``Σ_ji = 0`` for ``j ≠ i`` then the rows of ``K`` outside block ``i`` are zero, so ``B``
and ``K S Kᵀ`` are zero outside block ``(i, i)``: an update never creates a cross-covariance,
and initialisation never does either. (In floating point the zeros stay exactly ``0.0``.)
The map filter is therefore ``n`` independent 2-D Kalman filters, one per landmark. This
module exploits that: :class:`LandmarkBelief` stores per-landmark means ``(n, 2)`` and 2×2
covariance blocks ``(n, 2, 2)``, an update costs ``O(1)`` instead of ``O(n²)``, memory is
``O(n)``, and all readings of one scan (of distinct landmarks) are updated in one vectorised
call. The textbook full-matrix filter is kept as :class:`DenseLandmarkBelief` with
:func:`dense_initialise_landmark` / :func:`dense_update_landmark`: the reference a test
compares with (they agree to 1e-10), and the form EKF-SLAM needs once the pose is uncertain.

Data association (readings with id ``-1``)
------------------------------------------
Each unlabelled reading ``k`` is compared with every mapped landmark ``j`` by the squared
Mahalanobis distance of its innovation, ``d²_kj = ν_kjᵀ S_kj⁻¹ ν_kj``
(:func:`association_distances`). :func:`associate_nearest` then assigns pairs greedily by
increasing ``d²`` — a greedy global nearest neighbour of the scan, under the rule that one
scan sees a landmark at most once — and accepts a pair only inside the gate
``d² ≤ χ²_m(gate_probability)``. A reading
left unmatched starts a new landmark only if it is far from EVERY landmark:
``min_j d²_kj > χ²_m(new_landmark_probability)``, a stricter threshold than the gate. A
reading between the two thresholds is ambiguous — most likely a noisy reading of a known
landmark that just missed the gate — and is rejected rather than allowed to start a
duplicate of that landmark.

Near the sensor a range-bearing EKF is not valid: see :attr:`EkfMappingConfig.min_range`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_factor, cho_solve

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.datasets.stream import Dataset, Event, LandmarkReadings
from slamkit.errors import ConfigError, InputError, ShapeError
from slamkit.estimation.contract import (
    EstimatorOutput,
    InnovationLog,
    LandmarkEstimate,
    PoseEstimate,
)
from slamkit.estimation.readings import AssociationCode, ReadingStatus
from slamkit.maps import LandmarkMap
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.prob import chi2_gate, mahalanobis_squared, symmetrize

__all__ = [
    "DISCARDED",
    "INITIALISED",
    "NEW",
    "REJECTED",
    "TOO_CLOSE",
    "UPDATED",
    "DenseLandmarkBelief",
    "EkfMapping",
    "EkfMappingConfig",
    "InvertibleLandmarkModel",
    "LandmarkBelief",
    "ReadingsOutcome",
    "associate_nearest",
    "associate_nearest_unchecked",
    "association_distances",
    "association_probabilities",
    "dense_initialise_landmark",
    "dense_update_landmark",
    "initialise_landmarks",
    "process_readings",
    "update_landmarks",
]

# The codes as module constants (the values of the enums in slamkit.estimation.readings).
NEW = AssociationCode.NEW
REJECTED = AssociationCode.REJECTED
UPDATED = ReadingStatus.UPDATED
INITIALISED = ReadingStatus.INITIALISED
DISCARDED = ReadingStatus.DISCARDED
TOO_CLOSE = ReadingStatus.TOO_CLOSE


def _require_invertible(model: object) -> InvertibleLandmarkModel:
    if not isinstance(model, InvertibleLandmarkModel):
        raise InputError(
            f"EKF mapping needs a measurement model with an inverse (one reading fixes the "
            f"landmark), got {type(model).__name__}: range-only and bearing-only readings "
            "cannot initialise a landmark from a single reading"
        )
    return model


def _ids_array(ids: ArrayLike, name: str, n: int | None = None) -> NDArray[np.int64]:
    arr = np.asarray(ids)
    if arr.ndim != 1 or (n is not None and arr.size != n):
        want = "(n,)" if n is None else f"({n},)"
        raise ShapeError(f"{name}: expected shape {want}, got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f"{name}: expected integers, got {arr.dtype}")
    return arr.astype(np.int64)


# --------------------------------------------------------------------------------------------
# beliefs
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LandmarkBelief:
    """The map belief in block-diagonal form: landmark ``k`` with id ``ids[k]`` is
    ``N(means[k], covs[k])``, independent of every other (see the module docstring for why
    this is exact when the poses are known).

    ``ids (n,)`` unique integers, ``means (n, 2)`` world metres, ``covs (n, 2, 2)``. Values
    are treated as immutable: the functions below return new beliefs.
    """

    ids: NDArray[np.int64]
    means: FloatArray
    covs: FloatArray

    def __post_init__(self) -> None:
        means = as_array(self.means, "landmark means", (None, 2))
        n = means.shape[0]
        ids = _ids_array(self.ids, "landmark ids", n)
        if np.unique(ids).size != n:
            raise InputError("landmark ids: expected unique ids, got duplicates")
        covs = as_array(self.covs, "landmark covariances", (n, 2, 2))
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "means", means)
        object.__setattr__(self, "covs", covs)

    @classmethod
    def empty(cls) -> LandmarkBelief:
        return cls(np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros((0, 2, 2)))

    def __len__(self) -> int:
        return int(self.ids.size)

    def index_of(self, ids: ArrayLike) -> NDArray[np.int64]:
        """Row of each id in this belief, ``-1`` for ids not (yet) mapped."""
        want = np.asarray(ids, dtype=np.int64)
        if self.ids.size == 0:
            return np.full(want.shape, -1, dtype=np.int64)
        order = np.argsort(self.ids)
        pos = np.clip(np.searchsorted(self.ids, want, sorter=order), 0, self.ids.size - 1)
        rows = order[pos]
        return np.where(self.ids[rows] == want, rows, -1).astype(np.int64)

    def to_landmark_estimate(self) -> LandmarkEstimate:
        """The map and per-landmark covariances in the estimator-output form."""
        return LandmarkEstimate(LandmarkMap(self.means.copy(), self.ids.copy()), self.covs.copy())

    def to_dense(self) -> DenseLandmarkBelief:
        """The same belief as one ``2n`` vector and a block-diagonal ``2n × 2n`` matrix."""
        n = len(self)
        cov = np.zeros((2 * n, 2 * n))
        for k in range(n):
            cov[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = self.covs[k]
        return DenseLandmarkBelief(self.ids.copy(), self.means.reshape(-1).copy(), cov)


@dataclass(frozen=True)
class DenseLandmarkBelief:
    """The map belief as the textbook EKF holds it: ``mean (2n,)`` = ``(x_1, y_1, …)`` and
    the full covariance ``cov (2n, 2n)``, landmark ``k`` with id ``ids[k]`` in rows
    ``2k, 2k+1``. The reference implementation; :class:`LandmarkBelief` is the fast one."""

    ids: NDArray[np.int64]
    mean: FloatArray
    cov: FloatArray

    def __post_init__(self) -> None:
        mean = as_array(self.mean, "map mean", (None,))
        if mean.size % 2:
            raise ShapeError(f"map mean: expected an even length (x, y pairs), got {mean.size}")
        ids = _ids_array(self.ids, "landmark ids", mean.size // 2)
        if np.unique(ids).size != ids.size:
            raise InputError("landmark ids: expected unique ids, got duplicates")
        cov = as_array(self.cov, "map covariance", (mean.size, mean.size))
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

    @classmethod
    def empty(cls) -> DenseLandmarkBelief:
        return cls(np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros((0, 0)))

    def __len__(self) -> int:
        return int(self.ids.size)

    def to_blocks(self) -> LandmarkBelief:
        """The diagonal 2×2 blocks (exact when the belief is block-diagonal, see
        :attr:`max_cross_covariance`)."""
        n = len(self)
        idx = np.arange(n)
        c = self.cov.reshape(n, 2, n, 2)
        covs = c[idx, :, idx, :]  # (n, 2, 2): block (k, k)
        return LandmarkBelief(self.ids.copy(), self.mean.reshape(n, 2).copy(), covs.copy())

    @property
    def max_cross_covariance(self) -> float:
        """Largest ``|Σ_ij|`` outside the 2×2 diagonal blocks (0 for independent landmarks)."""
        n = len(self)
        if n < 2:
            return 0.0
        c = np.abs(self.cov.reshape(n, 2, n, 2)).max(axis=(1, 3))
        np.fill_diagonal(c, 0.0)
        return float(c.max())


# --------------------------------------------------------------------------------------------
# functional core: block-diagonal form
# --------------------------------------------------------------------------------------------


def _check_inputs(
    pose: ArrayLike, z: ArrayLike, noise_cov: ArrayLike, model: InvertibleLandmarkModel
) -> tuple[FloatArray, FloatArray, FloatArray]:
    x = as_array(pose, "pose", (3,))
    m = model.dim
    za = as_array(z, "readings z", (None, m))
    R = as_covariance(noise_cov, "measurement noise_cov", m)
    return x, za, R


def _trusted(ids: NDArray[np.int64], means: FloatArray, covs: FloatArray) -> LandmarkBelief:
    """A belief from arrays the kernels built themselves (no re-validation on the hot path)."""
    belief = object.__new__(LandmarkBelief)
    object.__setattr__(belief, "ids", ids)
    object.__setattr__(belief, "means", means)
    object.__setattr__(belief, "covs", covs)
    return belief


# The public functions validate their arguments and call these kernels, which trust them.


def _initialise(
    belief: LandmarkBelief,
    x: FloatArray,
    z: FloatArray,
    new_ids: NDArray[np.int64],
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> LandmarkBelief:
    mu = model.inverse(x, z)  # μ = g(x, z), (K, 2)
    _, Lz = model.inverse_jacobians(x, z)  # (K, 2, m)
    cov = symmetrize(Lz @ R @ np.swapaxes(Lz, -1, -2))  # L_z R L_zᵀ; pose known: no L_x term
    return _trusted(
        np.concatenate([belief.ids, new_ids]),
        np.concatenate([belief.means, mu.reshape(-1, 2)]),
        np.concatenate([belief.covs, cov.reshape(-1, 2, 2)]),
    )


def _update(
    belief: LandmarkBelief,
    rows: NDArray[np.int64],
    x: FloatArray,
    z: FloatArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> tuple[LandmarkBelief, FloatArray]:
    mu, P = belief.means[rows], belief.covs[rows]  # (K, 2), (K, 2, 2)
    nu = model.residual(z, model.predict(x, mu))  # ν = z ⊟ h(x, μ), (K, m)
    _, H = model.jacobians(x, mu)  # (K, m, 2)
    HP = H @ P  # (K, m, 2)
    S = HP @ np.swapaxes(H, -1, -2) + R  # S = H P Hᵀ + R
    gain = np.swapaxes(np.linalg.solve(S, HP), -1, -2)  # K = P Hᵀ S⁻¹ = (S⁻¹ H P)ᵀ
    nis = np.einsum("ki,ki->k", nu, np.linalg.solve(S, nu[..., None])[..., 0])  # νᵀ S⁻¹ ν
    A = np.eye(2) - gain @ H  # I − K H, (K, 2, 2)
    # Joseph form: (I − K H) P (I − K H)ᵀ + K R Kᵀ stays PSD under round-off.
    P_new = symmetrize(A @ P @ np.swapaxes(A, -1, -2) + gain @ R @ np.swapaxes(gain, -1, -2))
    means, covs = belief.means.copy(), belief.covs.copy()
    means[rows] = mu + np.einsum("kij,kj->ki", gain, nu)  # μ + K ν
    covs[rows] = P_new
    return _trusted(belief.ids, means, covs), nis


def _distances(
    belief: LandmarkBelief,
    x: FloatArray,
    z: FloatArray,
    R: FloatArray,
    model: InvertibleLandmarkModel,
) -> FloatArray:
    if len(belief) == 0 or z.shape[0] == 0:
        return np.zeros((z.shape[0], len(belief)))
    z_hat = model.predict(x, belief.means)  # (n, m)
    _, H = model.jacobians(x, belief.means)  # (n, m, 2)
    S = symmetrize(H @ belief.covs @ np.swapaxes(H, -1, -2) + R)  # (n, m, m)
    nu = model.residual(z[:, None, :], z_hat[None, :, :])  # (K, n, m)
    return mahalanobis_squared(nu, S)


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


def _process(
    belief: LandmarkBelief,
    x: FloatArray,
    z: FloatArray,
    rid: NDArray[np.int64],
    R: FloatArray,
    model: InvertibleLandmarkModel,
    gate: float,
    new_gate: float,
    min_range: float,
) -> tuple[LandmarkBelief, ReadingsOutcome]:
    k = z.shape[0]
    out_ids = np.full(k, -1, dtype=np.int64)
    status = np.full(k, DISCARDED, dtype=np.int64)
    nis = np.full(k, np.nan)
    usable = np.ones(k, dtype=bool)
    if min_range > 0 and k:
        # Distance of the landmark each reading places, |g(x, z) − t|, for any model.
        d = np.hypot(*(model.inverse(x, z) - x[:2]).T)
        usable = d >= min_range
        status[~usable] = TOO_CLOSE

    known = np.flatnonzero((rid >= 0) & usable)
    # Rounds of distinct ids: round r takes the r-th reading of each id in this scan.
    while known.size:
        _, first = np.unique(rid[known], return_index=True)
        if first.size == known.size:  # the usual case: every id once
            now, known = known, known[:0]
        else:
            take = np.zeros(known.size, dtype=bool)
            take[first] = True
            now, known = known[take], known[~take]
        rows = belief.index_of(rid[now])
        fresh = now[rows < 0]
        if fresh.size:
            belief = _initialise(belief, x, z[fresh], rid[fresh], R, model)
            out_ids[fresh], status[fresh] = rid[fresh], INITIALISED
        old = now[rows >= 0]
        if old.size:
            belief, nis[old] = _update(belief, rows[rows >= 0], x, z[old], R, model)
            out_ids[old], status[old] = rid[old], UPDATED

    unknown = np.flatnonzero((rid < 0) & usable)
    if unknown.size:
        d = _distances(belief, x, z[unknown], R, model)
        match = associate_nearest_unchecked(d, gate, new_gate)
        hit = unknown[match >= 0]
        if hit.size:
            rows = match[match >= 0]
            belief, nis[hit] = _update(belief, rows, x, z[hit], R, model)
            out_ids[hit], status[hit] = belief.ids[rows], UPDATED
        new = unknown[match == NEW]
        if new.size:
            start = int(belief.ids.max()) + 1 if len(belief) else 0
            new_ids = np.arange(start, start + new.size, dtype=np.int64)
            belief = _initialise(belief, x, z[new], new_ids, R, model)
            out_ids[new], status[new] = new_ids, INITIALISED
    return belief, ReadingsOutcome(out_ids, status, nis)


def initialise_landmarks(
    belief: LandmarkBelief,
    pose: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> LandmarkBelief:
    """Add the landmarks first seen in readings ``z (K, m)`` with new ``ids (K,)`` from the
    known ``pose (3,)``: ``μ = g(pose, z)``, ``Σ = L_z R L_zᵀ`` (no pose term: the pose is
    known), no cross-covariances. Raises :class:`InputError` if an id is already mapped."""
    model = _require_invertible(model)
    x, za, R = _check_inputs(pose, z, noise_cov, model)
    new_ids = _ids_array(ids, "ids", za.shape[0])
    if np.any(belief.index_of(new_ids) >= 0) or np.unique(new_ids).size != new_ids.size:
        raise InputError("initialise_landmarks: an id is already in the map or repeated")
    return _initialise(belief, x, za, new_ids, R, model)


def update_landmarks(
    belief: LandmarkBelief,
    index: ArrayLike,
    pose: ArrayLike,
    z: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> tuple[LandmarkBelief, FloatArray]:
    """EKF update of the landmarks in rows ``index (K,)`` (distinct) with their readings
    ``z (K, m)`` from the known ``pose (3,)``.

    Each landmark is its own 2-D Kalman filter (the block-diagonal form): ``S = H P Hᵀ + R``,
    ``K = P Hᵀ S⁻¹``, ``μ ← μ + K ν``, ``P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ`` (Joseph),
    vectorised over the ``K`` readings. Returns the new belief and the normalised innovation
    squared ``νᵀ S⁻¹ ν`` of each reading ``(K,)``.
    """
    model = _require_invertible(model)
    x, za, R = _check_inputs(pose, z, noise_cov, model)
    rows = _ids_array(index, "index", za.shape[0])
    if np.any((rows < 0) | (rows >= len(belief))):
        raise InputError(f"index: expected rows in [0, {len(belief)}), got {rows.tolist()}")
    if np.unique(rows).size != rows.size:
        raise InputError("index: expected distinct landmarks (update repeats one at a time)")
    return _update(belief, rows, x, za, R, model)


def association_distances(
    belief: LandmarkBelief,
    pose: ArrayLike,
    z: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> FloatArray:
    """Squared Mahalanobis distances ``(K, n)`` of readings ``z (K, m)`` to every mapped
    landmark: ``νᵀ S⁻¹ ν`` with ``ν = z ⊟ h(pose, μ_j)`` and ``S = H_j P_j H_jᵀ + R``."""
    model = _require_invertible(model)
    x, za, R = _check_inputs(pose, z, noise_cov, model)
    return _distances(belief, x, za, R, model)


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


@dataclass(frozen=True)
class ReadingsOutcome:
    """What happened to each reading of a scan ``(K,)``: the id of the landmark it updated or
    started (``-1`` if not used), a status code (:data:`UPDATED` = 0, :data:`INITIALISED` = 1,
    :data:`DISCARDED` = 2, :data:`TOO_CLOSE` = 3) and its NIS (NaN unless it updated a
    landmark)."""

    landmark_ids: NDArray[np.int64]
    status: NDArray[np.int64]
    nis: FloatArray

    @property
    def updated(self) -> NDArray[np.bool_]:
        return np.asarray(self.status == UPDATED)


def process_readings(
    belief: LandmarkBelief,
    pose: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
    *,
    gate: float,
    new_gate: float,
    min_range: float = 0.0,
) -> tuple[LandmarkBelief, ReadingsOutcome]:
    """One scan: readings ``z (K, m)`` with ``ids (K,)`` (``-1`` = unknown) from ``pose``.

    Readings that place their landmark closer than ``min_range`` (m) to the sensor are
    skipped (status :data:`TOO_CLOSE`; see :attr:`EkfMappingConfig.min_range`). Readings with
    an id update that landmark, or start it when it is not mapped yet (a
    landmark read twice in one scan is updated once per reading, in turn). Readings without
    an id are then associated with :func:`associate_nearest` (gates on ``νᵀ S⁻¹ ν``) and
    update, start a new landmark (ids continue after the largest mapped id) or are rejected.
    """
    model = _require_invertible(model)
    x, za, R = _check_inputs(pose, z, noise_cov, model)
    rid = _ids_array(ids, "ids", za.shape[0])
    if not (0 < gate <= new_gate):
        raise InputError(f"gates: expected 0 < gate <= new_gate, got {gate}, {new_gate}")
    if not (np.isfinite(min_range) and min_range >= 0):
        raise InputError(f"min_range: expected a number >= 0, got {min_range}")
    return _process(belief, x, za, rid, R, model, gate, new_gate, float(min_range))


# --------------------------------------------------------------------------------------------
# functional core: full-matrix reference
# --------------------------------------------------------------------------------------------


def dense_initialise_landmark(
    belief: DenseLandmarkBelief,
    pose: ArrayLike,
    z: ArrayLike,
    landmark_id: int,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> DenseLandmarkBelief:
    """Grow the full state by one landmark seen at ``z (m,)``: mean ``g(pose, z)``,
    covariance ``[[Σ, 0], [0, L_z R L_zᵀ]]`` (zero cross-covariances: the pose is known)."""
    model = _require_invertible(model)
    x, za, R = _check_inputs(pose, np.atleast_2d(z), noise_cov, model)
    if za.shape[0] != 1:
        raise ShapeError(f"z: expected one reading, got {za.shape[0]}")
    if landmark_id in belief.ids.tolist():
        raise InputError(f"dense_initialise_landmark: id {landmark_id} is already mapped")
    mu = model.inverse(x, za[0])
    _, Lz = model.inverse_jacobians(x, za[0])
    n2 = belief.mean.size
    cov = np.zeros((n2 + 2, n2 + 2))
    cov[:n2, :n2] = belief.cov
    cov[n2:, n2:] = symmetrize(Lz @ R @ Lz.T)  # L_z R L_zᵀ
    return DenseLandmarkBelief(
        np.append(belief.ids, np.int64(landmark_id)), np.concatenate([belief.mean, mu]), cov
    )


def dense_update_landmark(
    belief: DenseLandmarkBelief,
    index: int,
    pose: ArrayLike,
    z: ArrayLike,
    noise_cov: ArrayLike,
    model: InvertibleLandmarkModel,
) -> tuple[DenseLandmarkBelief, float]:
    """The full-state EKF update with one reading ``z (m,)`` of the landmark in row
    ``index``, touching only that landmark's two columns of ``Σ`` for the gain and applying
    the Joseph form through its rank-``m`` expansion ``Σ − B − Bᵀ + K S Kᵀ``,
    ``B = K H Σ_{i:}`` (see the module docstring). ``O(n²)``; no ``m × 2n`` Jacobian is
    formed. Returns the new belief and the NIS."""
    model = _require_invertible(model)
    x, za, R = _check_inputs(pose, np.atleast_2d(z), noise_cov, model)
    if za.shape[0] != 1:
        raise ShapeError(f"z: expected one reading, got {za.shape[0]}")
    if not 0 <= index < len(belief):
        raise InputError(f"index: expected a row in [0, {len(belief)}), got {index}")
    cols = slice(2 * index, 2 * index + 2)
    mu_i = belief.mean[cols]
    nu = model.residual(za[0], model.predict(x, mu_i))  # (m,)
    _, H = model.jacobians(x, mu_i)  # (m, 2)
    P = belief.cov
    P_ci = P[:, cols]  # Σ_{:i}, (2n, 2)
    HPi = H @ P_ci.T  # H Σ_{i:} = G Σ, (m, 2n)
    S = symmetrize(H @ P[cols, cols] @ H.T + R)  # S = H Σ_ii Hᵀ + R
    factor = cho_factor(S)
    gain = cho_solve(factor, HPi).T  # K = Σ_{:i} Hᵀ S⁻¹, (2n, m)
    nis = float(nu @ cho_solve(factor, nu))
    B = gain @ HPi  # K G Σ, rank m
    # Joseph form multiplied out: (I − K G) Σ (I − K G)ᵀ + K R Kᵀ = Σ − B − Bᵀ + K S Kᵀ.
    cov = symmetrize(P - B - B.T + gain @ S @ gain.T)
    return DenseLandmarkBelief(belief.ids, belief.mean + gain @ nu, cov), nis


# --------------------------------------------------------------------------------------------
# the estimator
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EkfMappingConfig:
    """Settings of :class:`EkfMapping` (EKF landmark mapping with known poses)."""

    noise_scale: float = 1.0
    """Multiplies the sensor's measurement-noise covariance ``R`` (1 = trust the data set)."""
    use_ids: bool = True
    """Use the landmark ids the readings carry. False ignores them and associates every
    reading by nearest neighbour (to test data association on labelled data)."""
    gate_probability: float = 0.999
    """Association gate: an unlabelled reading may update a landmark only if
    ``νᵀ S⁻¹ ν ≤ χ²_m(gate_probability)`` (``m`` = reading dimension; 13.8 for ``m = 2``)."""
    new_landmark_probability: float = 0.99999
    """A reading matching no landmark starts a new one only if ``νᵀ S⁻¹ ν`` to EVERY landmark
    exceeds ``χ²_m(new_landmark_probability)`` (23.0 for ``m = 2``); between the two
    thresholds it is rejected, to avoid duplicating a landmark. Must be ≥ gate_probability."""
    min_range: float = 0.0
    """Readings that place their landmark closer than this to the sensor (m) are skipped.
    0 uses every reading. Near the sensor the EKF's linearisation of a range-bearing model
    fails: a reading at range ``r ≲ 3 σ_range`` initialises a landmark whose lateral
    variance ``(r σ_bearing)²`` is far too small (measured on ``landmark-loop`` seed 11: a
    landmark first read at 2.6 mm ends with NEES 2500; dropping readings below 0.3 m brings
    the 30-run mean NEES from 4.6 to 2.0). The relative-position model is linear and needs
    no such limit."""
    pose_time_tolerance: float = 1e-6
    """A reading at time ``t`` uses the true pose whose time stamp is within this many
    seconds of ``t``; none there is an error (no interpolation)."""

    def __post_init__(self) -> None:
        if not (self.noise_scale > 0 and np.isfinite(self.noise_scale)):
            raise ConfigError(f"noise_scale: expected a number > 0, got {self.noise_scale}")
        association_probabilities(self.gate_probability, self.new_landmark_probability)
        if not (self.min_range >= 0 and np.isfinite(self.min_range)):
            raise ConfigError(f"min_range: expected a number >= 0, got {self.min_range}")
        if not self.pose_time_tolerance >= 0:
            raise ConfigError(
                f"pose_time_tolerance: expected a number >= 0, got {self.pose_time_tolerance}"
            )


class EkfMapping:
    """EKF landmark mapping with KNOWN poses, as an estimator of the pipeline.

    The robot pose at each event is read from ``dataset.truth`` by time stamp — the one
    estimator allowed to do so, because mapping with known poses assumes exactly that. The
    landmark map is estimated from the :class:`~slamkit.datasets.LandmarkReadings` events with
    the block-diagonal EKF of this module; every other event only moves the current time.
    :meth:`estimate` returns the known pose with a zero covariance.

    Works with any landmark sensor whose model has an inverse (``"range-bearing"``,
    ``"position"``); range-only and bearing-only sensors raise :class:`InputError` (a single
    reading does not locate a landmark).
    """

    def __init__(
        self, dataset: Dataset, config: EkfMappingConfig, rng: np.random.Generator
    ) -> None:
        sensor = dataset.landmark_sensor
        if sensor is None:
            raise InputError(f"EKF mapping needs a landmark sensor; {dataset.name} has none")
        if not isinstance(sensor.model(), InvertibleLandmarkModel):
            raise InputError(
                f"EKF mapping cannot use the {sensor.kind!r} sensor of {dataset.name}: one "
                "reading does not locate a landmark, so a first sighting cannot be "
                "initialised (use range-bearing or position readings)"
            )
        truth = dataset.truth
        if truth.times is None or truth.poses is None or truth.times.size == 0:
            raise InputError(
                f"EKF mapping with known poses needs the true trajectory; {dataset.name} has none"
            )
        self._config = config
        self._model = _require_invertible(sensor.model())
        self._R = config.noise_scale * sensor.noise_cov
        m = self._model.dim
        self._gate = chi2_gate(m, config.gate_probability)
        self._new_gate = chi2_gate(m, config.new_landmark_probability)
        self._times = truth.times
        self._poses = truth.poses
        self._pose = truth.poses[0].copy()
        self._belief = LandmarkBelief.empty()
        self._log_t: list[FloatArray] = []
        self._log_ids: list[NDArray[np.int64]] = []
        self._log_status: list[NDArray[np.int64]] = []
        self._log_nis: list[FloatArray] = []

    def _pose_at(self, t: float) -> FloatArray | None:
        i = int(np.searchsorted(self._times, t))
        best: int | None = None
        for j in (i - 1, i):
            if 0 <= j < self._times.size and (
                best is None or abs(self._times[j] - t) < abs(self._times[best] - t)
            ):
                best = j
        if best is None or abs(self._times[best] - t) > self._config.pose_time_tolerance:
            return None
        return self._poses[best]

    def handle(self, event: Event) -> None:
        pose = self._pose_at(event.t)
        if pose is not None:
            self._pose = pose.copy()
        if not isinstance(event, LandmarkReadings):
            return
        if pose is None:
            raise InputError(
                f"EKF mapping with known poses: no true pose within "
                f"{self._config.pose_time_tolerance:g} s of the readings at t={event.t}"
            )
        z = np.asarray(event.z, dtype=np.float64)
        ids = np.asarray(event.ids, dtype=np.int64)
        if not self._config.use_ids:
            ids = np.full(ids.shape, -1, dtype=np.int64)
        # The Dataset validated z and the constructor R and the model: call the kernel.
        self._belief, outcome = _process(
            self._belief,
            pose,
            z,
            ids,
            self._R,
            self._model,
            self._gate,
            self._new_gate,
            self._config.min_range,
        )
        self._log_t.append(np.full(ids.size, float(event.t)))
        self._log_ids.append(outcome.landmark_ids)
        self._log_status.append(outcome.status)
        self._log_nis.append(outcome.nis)

    def estimate(self) -> PoseEstimate:
        """The known (true) pose at the current time, with a zero covariance."""
        return PoseEstimate(self._pose.copy(), np.zeros((3, 3)))

    @property
    def belief(self) -> LandmarkBelief:
        """The current map belief (block-diagonal form)."""
        return self._belief

    def reading_log(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading handled so far, in stream order: ``(times, landmark ids, status)``;
        the id is the landmark the reading updated or started, ``-1`` if it was rejected;
        status codes as in :class:`ReadingsOutcome`."""
        return (
            _cat(self._log_t, np.float64),
            _cat(self._log_ids, np.int64),
            _cat(self._log_status, np.int64),
        )

    def finish(self) -> EstimatorOutput:
        times, ids, status = self.reading_log()
        nis = _cat(self._log_nis, np.float64)
        upd = status == UPDATED
        log = InnovationLog(
            times=times[upd],
            nis=nis[upd],
            dof=np.full(int(upd.sum()), self._model.dim, dtype=np.int64),
            landmark_ids=ids[upd],
        )
        diagnostics: dict[str, Any] = {
            "known_poses": True,
            "n_landmarks": len(self._belief),
            "n_readings": int(status.size),
            "n_updates": int(upd.sum()),
            "n_new_landmarks": int(np.count_nonzero(status == INITIALISED)),
            "n_rejected": int(np.count_nonzero(status == DISCARDED)),
            "n_too_close": int(np.count_nonzero(status == TOO_CLOSE)),
            "mean_nis": float(nis[upd].mean()) if upd.any() else None,
        }
        return EstimatorOutput(
            landmarks=self._belief.to_landmark_estimate(),
            innovations=log,
            diagnostics=diagnostics,
        )


def _cat(parts: Sequence[NDArray[Any]], dtype: type) -> NDArray[Any]:
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype=dtype)
