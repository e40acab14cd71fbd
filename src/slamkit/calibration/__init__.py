"""Calibration from a run's own data: the odometry's systematic errors (wheel-radius and
wheel-base scales), the laser's mounting and the odometry's noise, learned from the laser's
relative motions between keyframe scans (``docs/estimators/calibration.md``)."""

from slamkit.calibration.calibrate import (
    CalibrationResult,
    CalibrationSettings,
    apply_calibration,
    calibrate,
    calibrate_pairs,
)
from slamkit.calibration.noise import NOISE_MODELS, NoiseFit, fit_noise, odometry_cov_bases
from slamkit.calibration.pairs import ScanPairs, odometry_at_scans, scan_pairs
from slamkit.calibration.systematic import (
    SystematicFit,
    corrected_steps,
    fit_systematic,
    pair_residuals,
)

__all__ = [
    "NOISE_MODELS",
    "CalibrationResult",
    "CalibrationSettings",
    "NoiseFit",
    "ScanPairs",
    "SystematicFit",
    "apply_calibration",
    "calibrate",
    "calibrate_pairs",
    "corrected_steps",
    "fit_noise",
    "fit_systematic",
    "odometry_at_scans",
    "odometry_cov_bases",
    "pair_residuals",
    "scan_pairs",
]
