"""The validated functional core of FastSLAM: predict, the 1.0 and 2.0 updates and resampling
on a :class:`FastSlamParticles`."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.errors import InputError, ShapeError
from slamkit.estimation.particles import (
    low_variance_resample,
)
from slamkit.models import MotionModel
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.slam.fastslam.association import update1, usable_readings
from slamkit.slam.fastslam.particles import (
    FastSlamParticles,
    IntArray,
    int_array,
    trusted_particles,
)
from slamkit.slam.fastslam.proposal import update2
from slamkit.slam.fastslam.settings import UpdateSettings
from slamkit.slam.fastslam.store import Work

# --------------------------------------------------------------------------------------------
# Public functional core (validated)
# --------------------------------------------------------------------------------------------


def _check_particles(particles: FastSlamParticles) -> FastSlamParticles:
    if not isinstance(particles, FastSlamParticles):
        raise InputError(f"particles: expected FastSlamParticles, got {type(particles).__name__}")
    return particles


def _check_readings(
    z: ArrayLike, ids: ArrayLike | None, noise_cov: ArrayLike, model: object
) -> tuple[FloatArray, IntArray, FloatArray, InvertibleLandmarkModel]:
    if not isinstance(model, InvertibleLandmarkModel) or model.dim != 2:
        raise InputError(
            f"FastSLAM needs a 2-D measurement model with an inverse (range-bearing or relative "
            f"position: one reading must locate a landmark), got {type(model).__name__}"
        )
    za = as_array(z, "readings z", (None, 2))
    rid = (
        np.full(za.shape[0], -1, dtype=np.int64)
        if ids is None
        else int_array(ids, "ids", (za.shape[0],))
    )
    R = as_covariance(noise_cov, "measurement noise_cov", 2)
    return za, rid, R, model


def fastslam_predict(
    particles: FastSlamParticles,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    control_cov: ArrayLike,
    rng: np.random.Generator,
) -> FastSlamParticles:
    """FastSLAM's prediction: every pose moves through ``model`` with its own control noise
    ``ε ~ N(0, control_cov)`` (:meth:`MotionModel.sample`); maps and weights are copied."""
    ps = _check_particles(particles)
    poses = model.sample(ps.poses, u, dt, control_cov, rng)
    return trusted_particles(
        poses,
        ps.log_weights.copy(),
        ps.means.copy(),
        ps.covs.copy(),
        ps.counters.copy(),
        ps.ids.copy(),
        ps.counts.copy(),
        ps.next_id,
    )


def fastslam1_update(
    particles: FastSlamParticles,
    z: ArrayLike,
    ids: ArrayLike | None,
    model: InvertibleLandmarkModel,
    noise_cov: ArrayLike,
    settings: UpdateSettings,
) -> tuple[FastSlamParticles, FloatArray]:
    """The FastSLAM 1.0 measurement update with one scan ``z (K, 2)``, ``ids (K,)`` (``-1`` or
    ``None``: unknown) at the particles' current poses.

    Returns the new set (normalised log-weights, see the module docstring for association and
    existence counters) and each particle's log-likelihood of the scan ``(P,)``. Raises
    :class:`ConvergenceError` when every particle's weight is zero or NaN afterwards."""
    ps = _check_particles(particles)
    za, rid, R, m = _check_readings(z, ids, noise_cov, model)
    use = usable_readings(za, m, settings)
    w = Work.of(ps)
    lw, ll = update1(w, ps.poses, ps.log_weights, za[use], rid[use], R, m, settings)
    return w.particles(ps.poses.copy(), lw), ll


def fastslam2_update(
    particles: FastSlamParticles,
    u: ArrayLike,
    dt: float,
    motion: MotionModel,
    control_cov: ArrayLike,
    z: ArrayLike,
    ids: ArrayLike | None,
    model: InvertibleLandmarkModel,
    noise_cov: ArrayLike,
    settings: UpdateSettings,
    rng: np.random.Generator,
    pose_cov: ArrayLike | None = None,
) -> tuple[FastSlamParticles, FloatArray]:
    """One FastSLAM 2.0 step: the motion ``u`` over ``dt`` and the scan ``z``, ``ids`` taken
    after it. Poses are drawn from the Gaussian proposal that includes the readings (see the
    module docstring; the draws are ``rng.standard_normal((P, d))``, ``d = k`` or ``3 + k``
    with ``pose_cov``), weights are the marginal likelihoods. Returns the new set and each
    particle's log-weight increment.

    ``pose_cov`` ``(P, 3, 3)`` (or ``(3, 3)`` for all): the particles' poses are uncertain
    by this much before the motion (earlier motion since the last scan, linearised; their
    ``poses`` are then the means), and the proposal covers it too. None: the poses are
    exact."""
    ps = _check_particles(particles)
    za, rid, R, m = _check_readings(z, ids, noise_cov, model)
    k = motion.control_dim
    ua = as_array(u, "control u", (k,))
    Qu = as_covariance(control_cov, "control_cov", k, semidefinite=True)
    if not (dt >= 0 and math.isfinite(dt)):
        raise InputError(f"dt: expected a time step >= 0, got {dt}")
    Px = None
    if pose_cov is not None:
        Px = as_covariance(pose_cov, "pose_cov", 3, semidefinite=True)
        if Px.ndim != 2 and Px.shape != (len(ps), 3, 3):
            raise ShapeError(f"pose_cov: expected (3, 3) or ({len(ps)}, 3, 3), got {Px.shape}")
        Px = np.broadcast_to(Px, (len(ps), 3, 3))
    use = usable_readings(za, m, settings)
    w = Work.of(ps)
    poses, lw, ll = update2(w, ps.poses, ps.log_weights, motion, ua, float(dt), Qu, za[use],
                             rid[use], R, m, settings, rng, Px)  # fmt: skip
    return w.particles(poses, lw), ll


def fastslam_resample(particles: FastSlamParticles, rng: np.random.Generator) -> FastSlamParticles:
    """Low-variance resampling (:func:`low_variance_resample`); the result holds copies of
    the chosen particles' maps, with equal weights."""
    ps = _check_particles(particles)
    return ps.select(low_variance_resample(ps.weights, rng))
