"""EKF landmark mapping with known robot poses (being split into a package)."""

from slamkit.mapping.ekf_mapping.kernels import *  # noqa: F403
from slamkit.mapping.ekf_mapping.kernels import __all__  # noqa: F401
