"""EKF-SLAM: the robot pose and a map of point landmarks in one Gaussian.

The state is ``x = (x_r, m_1, …, m_L)`` with the pose ``x_r = (x, y, θ)`` followed by the
landmark positions ``m_j = (x_j, y_j)``, ``n = 3 + 2L`` numbers, with the full covariance
``Σ (n × n)``; landmark ``j`` sits in rows ``s_j = 3 + 2j`` and ``s_j + 1``. Every formula
below is derived here (the course notes have typos, see ``notes/README.md``).

Prediction (:func:`slam_predict`)
---------------------------------
Landmarks do not move, so ``g`` changes the pose only: with ``G = ∂g/∂x_r`` (3 × 3),
``V = ∂g/∂u`` and the control noise ``Q``::

    x_r ← g(x_r, u, dt)
    Σ_rr ← G Σ_rr Gᵀ + V Q Vᵀ            (3 × 3)
    Σ_rm ← G Σ_rm,  Σ_mr = Σ_rmᵀ          (3 × 2L)

i.e. ``F Σ Fᵀ + F_x V Q Vᵀ F_xᵀ`` with ``F = diag(G, I)``, in ``O(L)`` instead of ``O(n³)``
(:func:`dense_slam_predict` is the full-matrix form; a test checks they agree to 1e-12).

Update with one reading ``z`` of landmark ``j`` (:func:`slam_update`)
--------------------------------------------------------------------
``h(x_r, m_j)`` depends on five state entries, so its ``m × n`` Jacobian ``H`` is zero
outside the columns ``0, 1, 2, s_j, s_j + 1``, where it holds ``H_r = ∂h/∂x_r`` and
``H_j = ∂h/∂m_j``. Because ``Σ`` is symmetric, ``H Σ`` (``m × n``) needs five ROWS of ``Σ``
(contiguous in memory)::

    H Σ = H_r Σ[0:3, :] + H_j Σ[s_j:s_j+2, :]          (= (Σ Hᵀ)ᵀ)
    S   = (H Σ)[:, 0:3] H_rᵀ + (H Σ)[:, s_j:s_j+2] H_jᵀ + R
    Kᵀ  = S⁻¹ (H Σ)                                      (K = Σ Hᵀ S⁻¹, n × m)
    x   ← x + K ν,   ν = z ⊖ h(x_r, m_j)                 (bearing wrapped, heading wrapped)

and the Joseph form ``Σ ← (I − K H) Σ (I − K H)ᵀ + K R Kᵀ``, multiplied out:
``Σ − K (H Σ) − (H Σ)ᵀ Kᵀ + K S Kᵀ``. With ``D = K S / 2 − (H Σ)ᵀ`` this is exactly

    Σ ← Σ + D Kᵀ + K Dᵀ                                  (one rank-2m product)

— the Joseph form, not the short ``Σ − K S Kᵀ``: it is the covariance of the estimator that
used THIS gain, rounding and all, hence symmetric positive semi-definite for any ``K``; the
short form is only right for the exactly optimal gain and loses definiteness when very
precise readings make ``K H`` nearly the identity in some direction. In exact arithmetic
``D = −(H Σ)ᵀ / 2`` and both agree (:func:`dense_slam_update` is the textbook
``(I − K H) Σ (I − K H)ᵀ + K R Kᵀ`` with the dense ``H``; a test checks they agree to
1e-10). The product is applied block-row by block-row through a small scratch buffer, so one
update reads and writes the ``n × n`` matrix once and allocates nothing of size ``n²``.

A new landmark (:func:`slam_add_landmark`)
------------------------------------------
From its first reading by the inverse model ``m = g⁻¹(x_r, z)`` with ``L_x = ∂m/∂x_r``
and ``L_z = ∂m/∂z``, to first order ``δm = L_x δx_r + L_z δz``, so::

    Σ_mm = L_x Σ_rr L_xᵀ + L_z R L_zᵀ,   Σ_m,: = L_x Σ_r,:    (cross with the WHOLE state)

The state lives in preallocated buffers whose capacity doubles when full; adding a landmark
writes two rows and two columns, ``O(n)``.

Data association, provisional features, removal: see :class:`EkfSlam` and :func:`jcbb`.

The package, by concern:

* :mod:`~slamkit.slam.ekf_slam.belief` — :class:`SlamBelief` and the validated functional
  core (``slam_predict``, ``slam_update``, ``slam_add_landmark``, the dense references);
* :mod:`~slamkit.slam.ekf_slam.state` — the state buffers (:class:`~slamkit.slam.ekf_slam.
  state.SlamState`) and the in-place prediction and landmark initialisation;
* :mod:`~slamkit.slam.ekf_slam.update` — the in-place 5-column Joseph update;
* :mod:`~slamkit.slam.ekf_slam.association` — distances, nearest neighbour, JCBB;
* :mod:`~slamkit.slam.ekf_slam.window` — each reading's candidates (windowed
  correspondence);
* :mod:`~slamkit.slam.ekf_slam.selection` — which unmatched readings may start a feature;
* :mod:`~slamkit.slam.ekf_slam.provisional` — the provisional feature list: the in-view
  test, the miss limit from the detection rate, removal;
* :mod:`~slamkit.slam.ekf_slam.kernels` — the prediction, update and new landmark as one
  object the estimator holds (:class:`~slamkit.slam.ekf_slam.kernels.EkfKernels`; UKF-SLAM
  passes its unscented ones);
* :mod:`~slamkit.slam.ekf_slam.gps` — GPS fixes (stream events ``GpsFix``): the antenna's
  position with a lever arm as a measurement of the pose, the χ² gate, the move into the
  GPS frame;
* :mod:`~slamkit.slam.ekf_slam.config` and :mod:`~slamkit.slam.ekf_slam.estimator` — the
  settings and the estimator shell :class:`EkfSlam`.
"""

from slamkit.mapping.ekf_mapping import DISCARDED, INITIALISED, TOO_CLOSE, UPDATED
from slamkit.slam.common import OWN_ID_BASE
from slamkit.slam.common import reading_jacobians as reading_jacobians
from slamkit.slam.common import scan_readings as scan_readings
from slamkit.slam.ekf_slam.association import JcbbResult, jcbb
from slamkit.slam.ekf_slam.belief import (
    SlamBelief,
    dense_slam_predict,
    dense_slam_update,
    slam_add_landmark,
    slam_predict,
    slam_update,
)
from slamkit.slam.ekf_slam.config import EkfSlamConfig
from slamkit.slam.ekf_slam.estimator import EkfSlam
from slamkit.slam.ekf_slam.provisional import TRACKED

__all__ = [
    "DISCARDED",
    "INITIALISED",
    "OWN_ID_BASE",
    "TOO_CLOSE",
    "TRACKED",
    "UPDATED",
    "EkfSlam",
    "EkfSlamConfig",
    "JcbbResult",
    "SlamBelief",
    "dense_slam_predict",
    "dense_slam_update",
    "jcbb",
    "slam_add_landmark",
    "slam_predict",
    "slam_update",
]
