"""Localization: beliefs, dead reckoning, static least squares, KF/EKF/UKF and MCL.

Functional cores (``predict``, ``kf_update``, ``ekf_update``, ``ukf_update``, ...) work on
frozen beliefs; the estimator classes are thin stateful shells registered in
:mod:`slamkit.pipeline.registry`.
"""

from slamkit.estimation.belief import GaussianBelief, predict, predict_unchecked
from slamkit.estimation.kalman import Gaussian, KalmanFilter, UpdateInfo, kf_predict, kf_update
from slamkit.estimation.particles import (
    ParticleSet,
    effective_sample_size,
    low_variance_resample,
    normalize_log_weights,
    particle_estimate,
)
from slamkit.localization.association import Association, associate_ml
from slamkit.localization.dead_reckoning import DeadReckoning, DeadReckoningConfig
from slamkit.localization.ekf import EkfConfig, EkfLocalization, ekf_predict, ekf_update
from slamkit.localization.least_squares import LeastSquaresConfig, LeastSquaresLocalization
from slamkit.localization.mcl import MclConfig, MonteCarloLocalization
from slamkit.localization.static import (
    LeastSquaresResult,
    PoseFix,
    PositionFix,
    localize_from_readings,
    localize_range_bearing,
    rls_from_first,
    rls_init,
    rls_update,
    triangulate,
    trilaterate,
    weighted_least_squares,
)
from slamkit.localization.ukf import (
    SigmaPointParams,
    UkfConfig,
    UkfLocalization,
    ukf_predict,
    ukf_update,
)
from slamkit.maps.likelihood_field import LikelihoodField

__all__ = [
    "Association",
    "DeadReckoning",
    "DeadReckoningConfig",
    "EkfConfig",
    "EkfLocalization",
    "Gaussian",
    "GaussianBelief",
    "KalmanFilter",
    "LeastSquaresConfig",
    "LeastSquaresLocalization",
    "LeastSquaresResult",
    "LikelihoodField",
    "MclConfig",
    "MonteCarloLocalization",
    "ParticleSet",
    "PoseFix",
    "PositionFix",
    "SigmaPointParams",
    "UkfConfig",
    "UkfLocalization",
    "UpdateInfo",
    "associate_ml",
    "effective_sample_size",
    "ekf_predict",
    "ekf_update",
    "kf_predict",
    "kf_update",
    "localize_from_readings",
    "localize_range_bearing",
    "low_variance_resample",
    "normalize_log_weights",
    "particle_estimate",
    "predict",
    "predict_unchecked",
    "rls_from_first",
    "rls_init",
    "rls_update",
    "triangulate",
    "trilaterate",
    "ukf_predict",
    "ukf_update",
    "weighted_least_squares",
]
