"""Monte Carlo localization: particle-filter steps and the ``mcl`` estimator.

The filter (Probabilistic Robotics, chapter 8) as pure functions over a
:class:`~slamkit.estimation.particles.ParticleSet`:

* :func:`mcl_predict` moves every particle through the motion model with its own control
  noise draw;
* :func:`mcl_update_landmarks` and :func:`mcl_update_laser` add ``log p(z | x_i)`` to each
  log-weight (point landmarks with known identities; a laser scan through the
  likelihood field) and renormalise;
* :func:`mcl_resample` draws a new, equally weighted set by low-variance resampling;
* **augmented MCL** (table 8.3): :class:`Augmentation` keeps a slow and a fast average of the
  measurement likelihood; when the fast one drops below the slow one — by more than its
  natural spread (``AugmentedConfig.injection_sigmas``) — the robot has probably been moved, and
  :func:`mcl_resample` replaces a fraction ``max(0, 1 - w_fast/w_slow)`` (against the
  lowered slow average) of the particles by random poses;
* **KLD-sampling** (Fox 2003): :func:`kld_resample_predict` draws particles until their
  number suffices, with probability ``1 - δ``, to keep the KL divergence between the sample
  and the true posterior below ``ε``, judged by how many histogram bins the sample occupies.
  The estimator resamples this way whenever it resamples, which the ESS trigger decides;
* **tempering** of laser scans (``LaserConfig.independent_beams``) and the
  **innovation log** of landmark readings against the particle mean and covariance
  (:func:`landmark_innovations`), which gives MCL the NIS statistics of the EKF.

:class:`MonteCarloLocalization` is the thin stateful shell the runner drives.

The package's modules: :mod:`.core` (prediction, reweighting, the laser update,
resampling), :mod:`.landmarks` (landmark likelihoods and innovations), :mod:`.augmented`,
:mod:`.kld`, :mod:`.sampling` (random poses for a global start and for injections),
:mod:`.config` (:class:`MclConfig`) and :mod:`.estimator`.
"""

from slamkit.localization.mcl.augmented import Augmentation
from slamkit.localization.mcl.config import (
    AugmentedConfig,
    KldConfig,
    LaserConfig,
    MclConfig,
    SnapshotConfig,
    StartConfig,
)
from slamkit.localization.mcl.core import (
    MeasurementUpdate,
    mcl_predict,
    mcl_resample,
    mcl_update_laser,
    reweight,
)
from slamkit.localization.mcl.estimator import MonteCarloLocalization
from slamkit.localization.mcl.kld import kld_resample_predict, kld_sample_size
from slamkit.localization.mcl.landmarks import (
    LandmarkInnovations,
    landmark_innovations,
    landmark_log_likelihood,
    mcl_update_landmarks,
)
from slamkit.localization.mcl.sampling import PoseSampler

__all__ = [
    "Augmentation",
    "AugmentedConfig",
    "KldConfig",
    "LandmarkInnovations",
    "LaserConfig",
    "MclConfig",
    "MeasurementUpdate",
    "MonteCarloLocalization",
    "PoseSampler",
    "SnapshotConfig",
    "StartConfig",
    "kld_resample_predict",
    "kld_sample_size",
    "landmark_innovations",
    "landmark_log_likelihood",
    "mcl_predict",
    "mcl_resample",
    "mcl_update_landmarks",
    "mcl_update_laser",
    "reweight",
]
