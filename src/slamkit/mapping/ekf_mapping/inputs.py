"""Argument checks shared by the public functions of EKF mapping (the kernels trust them)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import InputError, ShapeError
from slamkit.models.measurement import InvertibleLandmarkModel

__all__ = ["as_landmark_ids", "check_reading_inputs", "require_invertible"]


def require_invertible(model: object) -> InvertibleLandmarkModel:
    """``model`` if it has an inverse (one reading fixes the landmark), else an
    :class:`~slamkit.errors.InputError` that says why EKF mapping needs one."""
    if not isinstance(model, InvertibleLandmarkModel):
        raise InputError(
            f"EKF mapping needs a measurement model with an inverse (one reading fixes the "
            f"landmark), got {type(model).__name__}: range-only and bearing-only readings "
            "cannot initialise a landmark from a single reading"
        )
    return model


def as_landmark_ids(ids: ArrayLike, name: str, n: int | None = None) -> NDArray[np.int64]:
    """``ids`` as an int64 vector ``(n,)`` (any length if ``n`` is None); errors name ``name``."""
    arr = np.asarray(ids)
    if arr.ndim != 1 or (n is not None and arr.size != n):
        want = "(n,)" if n is None else f"({n},)"
        raise ShapeError(f"{name}: expected shape {want}, got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f"{name}: expected integers, got {arr.dtype}")
    return arr.astype(np.int64)


def check_reading_inputs(
    pose: ArrayLike, z: ArrayLike, noise_cov: ArrayLike, model: InvertibleLandmarkModel
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``pose (3,)``, readings ``z (K, m)`` and the noise covariance ``(m, m)`` of ``model``,
    checked and as float64 arrays."""
    x = as_array(pose, "pose", (3,))
    m = model.dim
    za = as_array(z, "readings z", (None, m))
    R = as_covariance(noise_cov, "measurement noise_cov", m)
    return x, za, R
