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

The package
-----------
* :mod:`~slamkit.mapping.ekf_mapping.beliefs` — :class:`LandmarkBelief` (block-diagonal) and
  :class:`DenseLandmarkBelief` (full matrix);
* :mod:`~slamkit.mapping.ekf_mapping.kernels` — the per-landmark Gaussian kernels:
  initialise, update, association distances;
* :mod:`~slamkit.mapping.ekf_mapping.association` — the gates and the greedy nearest
  neighbour, with the codes :data:`NEW` and :data:`REJECTED`;
* :mod:`~slamkit.mapping.ekf_mapping.readings` — one scan through the filter
  (:func:`process_readings`), the status codes and :class:`ReadingsOutcome`;
* :mod:`~slamkit.mapping.ekf_mapping.dense` — the full-matrix reference update;
* :mod:`~slamkit.mapping.ekf_mapping.inputs` — the argument checks the public functions share;
* :mod:`~slamkit.mapping.ekf_mapping.config` — :class:`EkfMappingConfig`;
* :mod:`~slamkit.mapping.ekf_mapping.estimator` — the pipeline estimator :class:`EkfMapping`.
"""

from slamkit.mapping.ekf_mapping.association import (
    NEW,
    REJECTED,
    associate_nearest,
    associate_nearest_unchecked,
    association_probabilities,
)
from slamkit.mapping.ekf_mapping.beliefs import DenseLandmarkBelief, LandmarkBelief
from slamkit.mapping.ekf_mapping.config import EkfMappingConfig
from slamkit.mapping.ekf_mapping.dense import dense_initialise_landmark, dense_update_landmark
from slamkit.mapping.ekf_mapping.estimator import EkfMapping
from slamkit.mapping.ekf_mapping.kernels import (
    association_distances,
    initialise_landmarks,
    update_landmarks,
)
from slamkit.mapping.ekf_mapping.readings import (
    DISCARDED,
    INITIALISED,
    TOO_CLOSE,
    UPDATED,
    ReadingsOutcome,
    process_readings,
)
from slamkit.models.measurement import InvertibleLandmarkModel

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
