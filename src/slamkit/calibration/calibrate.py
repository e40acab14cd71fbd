"""Calibrate a run from its own data: systematic odometry errors, the laser's mounting and
the odometry noise, and feed them back.

:func:`calibrate` matches keyframe scans (:func:`~slamkit.calibration.pairs.scan_pairs`)
and alternates two fits, as an EM alternates its steps: the systematic scales and the
mounting by weighted least squares (:func:`~slamkit.calibration.systematic.fit_systematic`),
weights from the current noise; then the noise by maximum likelihood given the corrected
odometry (:func:`~slamkit.calibration.noise.fit_noise`). The noise starts at the data set's
own nominal covariance. :func:`apply_calibration` feeds a result back into a data set: the
odometry re-integrated from corrected steps, the laser's mounting and the learned per-step
noise. :meth:`CalibrationResult.dataset_options` gives the learned noise as the raw
loaders' options (``odometry_sigma_trans``, ``odometry_sigma_rot_deg``) for a
``[dataset]`` table.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from slamkit._validation import FloatArray
from slamkit.calibration.noise import (
    NOISE_MODELS,
    NoiseFit,
    NoiseModelName,
    fit_noise,
    negative_log_likelihood,
    odometry_cov_bases,
)
from slamkit.calibration.pairs import ScanPairs, scan_pairs
from slamkit.calibration.systematic import (
    SystematicFit,
    corrected_steps,
    fit_systematic,
    pair_residuals,
)
from slamkit.config import Section, config_to_dict, finite_above, fraction, int_at_least, setting
from slamkit.datasets.stream import Dataset, LaserSpec, MotionSpec, Odometry
from slamkit.errors import InputError
from slamkit.geometry.pose2 import inverse
from slamkit.models import OdometryModel, integrate_odometry, odometry_control

__all__ = [
    "CalibrationResult",
    "CalibrationSettings",
    "apply_calibration",
    "calibrate",
    "calibrate_pairs",
]


@dataclass(frozen=True)
class CalibrationSettings(Section):
    """How :func:`calibrate` chooses and fits its pairs."""

    SECTION: ClassVar[str] = "calibration"

    min_distance: float = setting(0.5, finite_above(0.0), "a number > 0 [m]")
    """A new keyframe once the wheels report this much travel since the last [m]."""
    min_turn_deg: float = setting(20.0, finite_above(0.0), "a number > 0 [deg]")
    """... or this much turning [deg]."""
    min_inlier_fraction: float = setting(0.5, fraction(), "a fraction in [0, 1]")
    """A match keeping fewer of its points is left out (too little overlap)."""
    fit_mounting: bool = True
    """Estimate the laser's mounting; False holds it at the data set's."""
    rounds: int = setting(2, int_at_least(1), "an integer >= 1")
    """Systematic-then-noise rounds (each re-weights the least squares by the likelier of
    the two noise models just fitted)."""


def _adjoint_inverse(M: FloatArray) -> FloatArray:
    """``Ad(M⁻¹) (3, 3)``: a right perturbation of the robot's end pose seen at the laser,
    ``T exp(δ) M = T M exp(Ad(M⁻¹) δ)``; for ``N = (t, φ)``, ``Ad(N) = [[R(φ), (t_y, -t_x)ᵀ],
    [0, 1]]``."""
    n = inverse(M)
    c, s = math.cos(n[2]), math.sin(n[2])
    return np.array([[c, -s, n[1]], [s, c, -n[0]], [0.0, 0.0, 1.0]])


def _laser_bases(pairs: ScanPairs, fit: SystematicFit, model: NoiseModelName) -> FloatArray:
    """The noise bases of ``model`` in the residuals' (laser) frame."""
    u = corrected_steps(pairs.steps, fit.translation_scale, fit.rotation_scale)
    B = odometry_cov_bases(u, pairs.first, pairs.last, model)
    A = _adjoint_inverse(np.asarray(fit.mounting))
    return np.einsum("ij,kpjl,ml->kpim", A, B, A)


def _noise_cov(pairs: ScanPairs, fit: SystematicFit, noise: NoiseFit) -> FloatArray:
    """Each pair's residual covariance: the matcher's plus the odometry's under ``noise``."""
    B = _laser_bases(pairs, fit, noise.model)
    theta = np.square(np.asarray(noise.values))
    return pairs.cov + np.einsum("k,kpij->pij", theta, B)


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` learned: the systematic fit, the noise under each model of
    :data:`~slamkit.calibration.noise.NOISE_MODELS`, and the pairs' counts."""

    systematic: SystematicFit
    noise: dict[str, NoiseFit]
    nominal_mounting: tuple[float, float, float]
    weights: str
    """The noise model that weighed the final least squares (the likelier one)."""
    pairs: int
    keyframes: int
    dropped: dict[str, int]
    settings: CalibrationSettings

    def dataset_options(self) -> dict[str, float]:
        """The learned per-step noise as the raw loaders' ``[dataset]`` options."""
        sr, st = self.noise["per_step"].values
        return {"odometry_sigma_trans": st, "odometry_sigma_rot_deg": math.degrees(sr)}

    def motion_cov(self) -> FloatArray:
        """The learned per-step covariance of ``(rot1, trans, rot2)``."""
        sr, st = self.noise["per_step"].values
        return np.diag([sr**2, st**2, sr**2])

    def as_dict(self) -> dict[str, Any]:
        """JSON-able; :func:`apply_calibration` and the loaders' options read it back."""
        return {
            "systematic": self.systematic.as_dict(),
            "noise": {name: fit.as_dict() for name, fit in self.noise.items()},
            "nominal_mounting": list(self.nominal_mounting),
            "weighted_by": self.weights,
            "dataset_options": self.dataset_options(),
            "pairs": self.pairs,
            "keyframes": self.keyframes,
            "pairs_dropped": dict(self.dropped),
            "settings": config_to_dict(self.settings),
        }


def _better(
    fits: dict[str, NoiseFit], r: FloatArray, cov: FloatArray, bases: dict[str, FloatArray]
) -> NoiseFit:
    """The noise model of the smaller Akaike criterion, ``2 (NLL + k)``, on the pairs both
    fits kept: the one the least squares should weigh its pairs by."""
    masks = [f.kept for f in fits.values() if f.kept is not None]
    common = np.logical_and.reduce(masks)

    def score(name: str) -> float:
        f = fits[name]
        nll = negative_log_likelihood(f.theta(), r[common], cov[common], bases[name][:, common])
        return nll + len(f.names)

    return fits[min(fits, key=score)]


def calibrate_pairs(
    pairs: ScanPairs, start_noise: FloatArray, settings: CalibrationSettings
) -> CalibrationResult:
    """The fits of :func:`calibrate` on matched ``pairs``; ``start_noise (3, 3)`` is the
    per-step covariance of ``(rot1, trans, rot2)`` the first round weighs with."""
    if pairs.n_pairs < 5:
        raise InputError(
            f"calibration: {pairs.n_pairs} scan pairs matched (dropped: {pairs.dropped}); at "
            "least 5 are needed"
        )
    start = np.concatenate([[1.0, 1.0], pairs.nominal_mounting])
    theta = np.array([start_noise[0, 0], start_noise[1, 1]])
    weights = NoiseFit("per_step", NOISE_MODELS["per_step"], tuple(np.sqrt(theta)), (0.0, 0.0),
                       pairs.n_pairs, 0, math.nan)  # fmt: skip
    fit: SystematicFit | None = None
    fits: dict[str, NoiseFit] = {}
    for _ in range(settings.rounds):
        base = SystematicFit(start, np.zeros((5, 5)), settings.fit_mounting, 0, 0, math.nan)
        cov = _noise_cov(pairs, fit or base, weights)
        fit = fit_systematic(pairs.steps, pairs.first, pairs.last, pairs.T_laser, cov,
                             start if fit is None else fit.params,
                             fit_mounting=settings.fit_mounting)  # fmt: skip
        r = pair_residuals(pairs.steps, pairs.first, pairs.last, pairs.T_laser, fit.params)
        bases = {name: _laser_bases(pairs, fit, name) for name in NOISE_MODELS}  # type: ignore[arg-type]
        fits = {name: fit_noise(r, pairs.cov, bases[name], name) for name in NOISE_MODELS}  # type: ignore[arg-type]
        weights = _better(fits, r, pairs.cov, bases)
    assert fit is not None
    return CalibrationResult(
        systematic=fit,
        noise=fits,
        weights=weights.model,
        nominal_mounting=tuple(float(v) for v in pairs.nominal_mounting),  # type: ignore[arg-type]
        pairs=pairs.n_pairs,
        keyframes=pairs.keyframes,
        dropped=pairs.dropped,
        settings=settings,
    )


def calibrate(
    dataset: Dataset,
    settings: CalibrationSettings | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> CalibrationResult:
    """Calibrate ``dataset`` (wheel odometry and laser scans) from its own data; see the
    module docstring. ``progress(done, total)`` follows the scan matches."""
    cfg = settings or CalibrationSettings()
    pairs = scan_pairs(
        dataset,
        min_distance=cfg.min_distance,
        min_turn=math.radians(cfg.min_turn_deg),
        min_inlier_fraction=cfg.min_inlier_fraction,
        progress=progress,
    )
    assert dataset.motion is not None  # scan_pairs checked it
    return calibrate_pairs(pairs, dataset.motion.noise_cov, cfg)


def apply_calibration(
    dataset: Dataset,
    result: CalibrationResult,
    *,
    scales: bool = True,
    mounting: bool = True,
    noise: bool = True,
) -> Dataset:
    """``dataset`` with a calibration fed back: its odometry re-integrated from steps
    corrected by the learned scales (``scales``), the laser's mounting replaced by the
    learned one (``mounting``, when it was fitted), and the odometry's per-step noise
    replaced by the learned one (``noise``)."""
    if dataset.motion is None or dataset.motion.source != "odometry":
        raise InputError(f"apply_calibration: data set {dataset.name!r} has no wheel odometry")
    fit = result.systematic
    events = list(dataset.events)
    if scales:
        where = [i for i, ev in enumerate(events) if isinstance(ev, Odometry)]
        poses = np.asarray([events[i].pose for i in where])  # type: ignore[union-attr]
        u = corrected_steps(
            odometry_control(poses[:-1], poses[1:]), fit.translation_scale, fit.rotation_scale
        )
        fixed = integrate_odometry(poses[0], u)
        for k, i in enumerate(where):
            events[i] = Odometry(events[i].t, fixed[k])
    laser = dataset.laser
    if mounting and fit.fit_mounting and laser is not None:
        laser = LaserSpec(laser.beam_angles, laser.max_range, laser.range_sigma, fit.mounting)
    motion = dataset.motion
    if noise:
        motion = MotionSpec(OdometryModel(), result.motion_cov(), source="odometry")
    return replace(dataset, events=tuple(events), laser=laser, motion=motion)
