"""Probability: Gaussian densities, Mahalanobis distances, χ² gates, covariance ellipses.

NumPy/SciPy only; never imports plotting code.
"""

from slamkit.prob.gaussian import (
    Ellipse,
    chi2_gate,
    confidence_scale,
    covariance_determinant,
    covariance_ellipse,
    covariance_size,
    covariance_trace,
    ellipse_points,
    gaussian_cdf,
    gaussian_draws,
    gaussian_logpdf,
    gaussian_pdf,
    mahalanobis,
    mahalanobis_squared,
    mvn_logpdf,
    mvn_pdf,
    symmetrize,
    within_gate,
)

__all__ = [
    "Ellipse",
    "chi2_gate",
    "confidence_scale",
    "covariance_determinant",
    "covariance_ellipse",
    "covariance_size",
    "covariance_trace",
    "ellipse_points",
    "gaussian_cdf",
    "gaussian_draws",
    "gaussian_logpdf",
    "gaussian_pdf",
    "mahalanobis",
    "mahalanobis_squared",
    "mvn_logpdf",
    "mvn_pdf",
    "symmetrize",
    "within_gate",
]
