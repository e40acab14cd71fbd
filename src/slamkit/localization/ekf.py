"""EKF localization against a known landmark map.

The extended Kalman filter linearises the motion and measurement models at the current mean:

* **prediction** (:func:`ekf_predict`, which is :func:`slamkit.estimation.belief.predict`):
  ``μ ← g(μ, u, dt)``, ``P ← G P Gᵀ + V Q Vᵀ`` with ``G = ∂g/∂x`` and ``V = ∂g/∂u``;
* **update** with one reading ``z`` of the landmark ``l`` (:func:`ekf_update`):
  ``ν = z ⊖ h(μ, l)`` (angular components wrapped by the model's residual),
  ``H = ∂h/∂x``, ``S = H P Hᵀ + R``, ``K = P Hᵀ S⁻¹``, ``μ ← μ + K ν`` (heading wrapped) and the
  Joseph form ``P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ``, symmetrised (see
  :mod:`slamkit.estimation.kalman` for why).

Several readings of one time step are applied one at a time, each linearised at the mean the
previous one left (*Probabilistic Robotics*, table 7.2).

:class:`EkfLocalization` is the estimator around these functions (see
:mod:`slamkit.estimation.contract`); it shares its event handling with
:class:`~slamkit.localization.ukf.UkfLocalization`. It runs the steps :func:`choose_ekf_steps`
picks once from its models: the same equations on floats
(:mod:`slamkit.localization.closed_form`) for a range-bearing sensor, else
:class:`GeneralEkfSteps`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_array, as_covariance
from slamkit.datasets.stream import Dataset, LandmarkReadings
from slamkit.errors import ConfigError, GeometryError, InputError, SlamkitError
from slamkit.estimation.belief import GaussianBelief, predict
from slamkit.estimation.contract import EstimatorOutput, LandmarkIds, PoseEstimate
from slamkit.estimation.gaussian import (
    angular_indices,
    check_covariance,
    gain_update,
    innovation_unchecked,
    measure_unchecked,
    wrap_components,
)
from slamkit.estimation.kalman import UpdateInfo
from slamkit.estimation.shell import AssociationRecorder, EstimatorShell, InnovationRecorder
from slamkit.localization.association import associate_arrays_unchecked
from slamkit.localization.closed_form import EkfClosedForm, FilterSteps, closed_form_supports
from slamkit.models import LandmarkModel, MotionModel
from slamkit.models.motion import motion_kernels
from slamkit.prob import chi2_gate

__all__ = [
    "EkfConfig",
    "EkfLocalization",
    "GaussianFilterConfig",
    "GaussianLocalization",
    "GeneralEkfSteps",
    "check_reading",
    "choose_ekf_steps",
    "ekf_predict",
    "ekf_predict_unchecked",
    "ekf_update",
]


# --------------------------------------------------------------------------------------------
# functional core
# --------------------------------------------------------------------------------------------


def ekf_predict(
    belief: GaussianBelief,
    u: ArrayLike,
    dt: float,
    model: MotionModel,
    control_cov: ArrayLike,
) -> GaussianBelief:
    """The EKF prediction: :func:`slamkit.estimation.belief.predict` (shared with dead
    reckoning), ``μ ← g(μ, u, dt)``, ``P ← G P Gᵀ + V Q Vᵀ`` with ``Q = control_cov``."""
    return predict(belief, u, dt, model, control_cov)


def ekf_predict_unchecked(
    mean: FloatArray,
    cov: FloatArray,
    u: FloatArray,
    dt: float,
    model: MotionModel,
    Q: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """:func:`ekf_predict` on validated arrays (the estimators' fast path; same equations as
    :func:`slamkit.estimation.belief.predict`, checked against it in the tests)."""
    x = mean[:3]
    moved, G, V = motion_kernels(model).step_single(x, u, dt)  # the fused one-pose kernel
    if mean.size == 3:
        new_mean = moved
        new_cov = G @ cov @ G.T + V @ Q @ V.T
    else:  # landmarks do not move: only the pose block and the pose-map cross terms change
        new_mean = mean.copy()
        new_mean[:3] = moved
        new_cov = cov.copy()
        new_cov[:3, :3] = G @ cov[:3, :3] @ G.T + V @ Q @ V.T
        new_cov[:3, 3:] = G @ cov[:3, 3:]
        new_cov[3:, :3] = new_cov[:3, 3:].T
    new_cov = 0.5 * (new_cov + new_cov.T)
    check_covariance(new_cov, "ekf_predict")
    return new_mean, new_cov


def _ekf_update_arrays(
    mean: FloatArray,
    cov: FloatArray,
    z: FloatArray,
    landmark: FloatArray,
    model: LandmarkModel,
    R: FloatArray,
    angular: tuple[int, ...],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float]:
    """:func:`ekf_update` on validated arrays: ``(mean, cov, ν, S, nis)``. ``angular`` are the
    indices of the model's angular components."""
    z_hat, Hp = measure_unchecked(model, mean[:3], landmark)
    nu = innovation_unchecked(model, z, z_hat, angular)  # z ⊖ h(μ): bearings wrapped
    n = mean.size
    if n == 3:
        H = Hp
    else:  # the reading depends on the pose only
        H = np.zeros((Hp.shape[0], n))
        H[:, :3] = Hp
    new_mean, new_cov, S, nis = gain_update(mean, cov, nu, H, R, "ekf_update")
    wrap_components(new_mean, (2,))
    return new_mean, new_cov, nu, S, nis


def check_reading(
    z: ArrayLike, landmark: ArrayLike, model: LandmarkModel, R: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    if not isinstance(model, LandmarkModel):
        raise InputError(f"model: expected a LandmarkModel, got {type(model).__name__}")
    m = model.dim
    za = as_array(z, "z", (m,))
    la = as_array(landmark, "landmark", (2,))
    Ra = as_covariance(R, "R", m)
    return za, la, Ra


def ekf_update(
    belief: GaussianBelief,
    z: ArrayLike,
    landmark: ArrayLike,
    model: LandmarkModel,
    R: ArrayLike,
) -> tuple[GaussianBelief, UpdateInfo]:
    """One EKF update with the reading ``z (m,)`` of the landmark at ``landmark (2,)``.

    ``model`` is the sensor's measurement model (``m = model.dim``) and ``R (m, m)`` its
    noise. Returns the updated belief and the innovation statistics (``ν`` wrapped, ``S``,
    ``νᵀ S⁻¹ ν``). The belief may be longer than the pose (its first three entries); the
    reading then updates the rest through the cross-covariances.

    Raises :class:`~slamkit.errors.NonFiniteError` for a NaN reading,
    :class:`~slamkit.errors.CovarianceError` if ``R`` is not positive definite,
    :class:`~slamkit.errors.GeometryError` if the landmark sits on the sensor and
    :class:`~slamkit.errors.ConvergenceError` if the covariance stops being one.
    """
    za, la, Ra = check_reading(z, landmark, model, R)
    idx = angular_indices(model)
    mean, cov, nu, S, nis = _ekf_update_arrays(belief.mean, belief.cov, za, la, model, Ra, idx)
    return GaussianBelief(mean, cov), UpdateInfo(nu, S, nis)


class GeneralEkfSteps:
    """The EKF's steps for any models (:func:`ekf_predict_unchecked` and the update of
    :func:`ekf_update` on validated arrays): a :class:`FilterSteps`."""

    def __init__(
        self, motion: MotionModel, measurement: LandmarkModel, Q: FloatArray, R: FloatArray
    ) -> None:
        self._motion, self._meas, self._Q, self._R = motion, measurement, Q, R
        self._angular = angular_indices(measurement)

    def predict(
        self, mean: FloatArray, cov: FloatArray, u: FloatArray, dt: float
    ) -> tuple[FloatArray, FloatArray]:
        return ekf_predict_unchecked(mean, cov, u, dt, self._motion, self._Q)

    def update(
        self, mean: FloatArray, cov: FloatArray, z: FloatArray, landmark: FloatArray
    ) -> tuple[FloatArray, FloatArray, float]:
        new_mean, new_cov, _, _, nis = _ekf_update_arrays(
            mean, cov, z, landmark, self._meas, self._R, self._angular
        )
        return new_mean, new_cov, nis


def choose_ekf_steps(
    motion: MotionModel, measurement: LandmarkModel, Q: FloatArray, R: FloatArray
) -> FilterSteps:
    """The EKF steps for a pose-only filter with these models, chosen once: the closed form
    of :class:`~slamkit.localization.closed_form.EkfClosedForm` when it covers them (a
    slamkit motion model and a range-bearing sensor), else :class:`GeneralEkfSteps`. Both
    give the same numbers to rounding."""
    if closed_form_supports(motion, measurement)[0]:
        return EkfClosedForm(motion_kernels(motion), Q, R)
    return GeneralEkfSteps(motion, measurement, Q, R)


# --------------------------------------------------------------------------------------------
# estimators
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GaussianFilterConfig:
    """Settings shared by :class:`EkfConfig` and the UKF's config."""

    motion_cov_scale: float = 1.0
    """Multiplies the data set's nominal control-noise covariance ``Q`` (1 = trust it as
    given; > 1 inflates it, e.g. to cover unmodelled slip). Must be >= 0."""
    measurement_cov_scale: float = 1.0
    """Multiplies the landmark sensor's nominal noise covariance ``R``. Must be > 0."""
    gate_probability: float | None = 0.999
    """Probability mass of the χ² validation gate, in (0, 1). With ``association="known"``
    a reading whose NIS exceeds ``χ²_m⁻¹(gate_probability)`` is rejected as an outlier; with
    ``"ml"`` it is the association gate. ``None``: no gate (known ids are always used; ML
    takes the nearest landmark however far). A gate also rejects ``1 − gate_probability``
    of the valid readings — those with the largest innovations, i.e. the ones that would
    correct the largest errors — which makes the filter slightly over-confident: on
    ``five-features`` the mean pose NEES is 3.10 without a gate, 3.13 with 0.999 and 3.23
    with 0.99 (χ²₃ mean: 3).

    The same probability tests every static fix the filter starts (or re-starts) from: a fix
    whose residual χ² exceeds ``χ²_d⁻¹(gate_probability)``, ``d`` the number of its scalar
    readings beyond the unknowns, is refused (see :class:`GaussianLocalization`). ``None``
    accepts every fix."""
    relocalize_after: int | None = 10
    """Lock-out guard: after this many *consecutive* readings rejected by the gate (no update
    accepted in between) the filter declares a lock-out and re-initialises from the next
    static fix that passes its residual test, as at the start (it keeps predicting and
    updating meanwhile). Reported in the diagnostics (``lockouts``, ``lockout_times``,
    ``relocalization_times``), never silent. A consistent filter rejects ``10`` valid
    readings in a row with probability ``(1 − gate_probability)¹⁰``; a filter whose error
    has outgrown its covariance (a bad start, a long blind stretch) rejects every reading
    that would correct it, and without the guard never recovers (MRCLAM 1 with half the
    nominal control noise locks out for good after its longest gap without readings; see
    ``docs/estimators/localization.md``). Needs known ids (``association="known"``) and a
    gate; ``None`` disables it."""
    association: Literal["known", "ml"] = "known"
    """``"known"``: use the readings' landmark ids (``-1`` readings are skipped).
    ``"ml"``: ignore the ids and associate each reading by maximum likelihood inside the gate
    (:func:`slamkit.localization.association.associate_ml`)."""
    record_innovations: bool = True
    """Keep every update's NIS in the output's :class:`InnovationLog`."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.motion_cov_scale) and self.motion_cov_scale >= 0):
            raise ConfigError(
                f"motion_cov_scale: expected a number >= 0, got {self.motion_cov_scale}"
            )
        if not (math.isfinite(self.measurement_cov_scale) and self.measurement_cov_scale > 0):
            raise ConfigError(
                f"measurement_cov_scale: expected a number > 0, got {self.measurement_cov_scale}"
            )
        p = self.gate_probability
        if p is not None and not 0.0 < p < 1.0:
            raise ConfigError(f"gate_probability: expected a number in (0, 1), got {p}")
        if self.association not in ("known", "ml"):
            raise ConfigError(f"association: expected 'known' or 'ml', got {self.association!r}")
        n = self.relocalize_after
        if n is not None and not (isinstance(n, int) and n >= 1):
            raise ConfigError(f"relocalize_after: expected an integer >= 1 or None, got {n!r}")


@dataclass(frozen=True)
class EkfConfig(GaussianFilterConfig):
    """Settings of :class:`EkfLocalization` (all shared with the UKF's config)."""


_UNINITIALISED_COV = np.diag([1e6, 1e6, np.pi**2 / 3.0])
"""Reported before a filter without a prior has fixed its start: 1000 m standard deviation in
position and the variance of a heading uniform on [-π, π)."""

_FIX_UNKNOWNS = {"range": 2}
"""Unknowns a static fix estimates, by sensor kind (3, the pose, unless listed): ranges leave
the heading out."""


def _fix_residual_chi2(residuals: FloatArray, R: FloatArray, kind: str) -> tuple[float, int]:
    """``(Σₖ eₖᵀ R⁻¹ eₖ, dof)`` of a static fix's residuals ``(K, m)``: χ² distributed with
    ``dof = K m − unknowns`` degrees of freedom when every reading is valid (``dof = 0``: no
    redundancy, nothing to test)."""
    e = residuals.reshape(-1, R.shape[0])
    chi2 = float(np.sum(e * np.linalg.solve(R, e.T).T))  # eᵀ R⁻¹ e per reading, summed
    return chi2, e.size - _FIX_UNKNOWNS.get(kind, 3)


class GaussianLocalization(EstimatorShell):
    """Event handling shared by the EKF and UKF localization estimators.

    Controls (or consecutive odometry poses) drive the prediction; every landmark reading
    drives one update against ``dataset.known_landmarks``. Without a prior in the data set the
    filter starts from a static fix (:func:`slamkit.localization.static.localize_from_readings`)
    of the first readings that determine one (those readings are not used again), and ignores
    the motion before; until then :meth:`estimate` reports the origin with a huge covariance.
    The fix needs landmark ids, so with ``association="ml"`` (ids ignored) a data set without
    a prior never starts (``failed_static_starts`` counts the attempts).

    With a gate, a fix is refused when its readings contradict each other — residual
    ``χ² = Σ eᵀ R⁻¹ e`` above ``χ²_d⁻¹(gate_probability)`` with ``d`` = scalar readings minus
    unknowns — since one outlier among two or three readings moves the fix by metres (MRCLAM
    1 with two landmarks' labels swapped: ``docs/estimators/localization.md``); the filter
    then waits for
    the next readings (``rejected_static_fixes``). Not every outlier shows: with a single
    redundant reading a range error is largely absorbed by the pose, and it is the lock-out
    guard that catches the consequences.

    **Lock-out guard** (``relocalize_after``): after that many consecutive readings rejected
    by the gate, the filter re-initialises from the next static fix that passes the test
    above, keeping its belief (and predicting and updating) until then. A filter whose error
    has outgrown its covariance otherwise rejects precisely the readings that would correct
    it, for ever.

    Diagnostics: ``predictions``, ``readings`` (after the start), ``updates``,
    ``unassociated`` (id −1 or no landmark inside the gate), ``rejected_by_gate`` (known ids
    whose NIS exceeded the gate), ``unknown_ids`` (ids not in the map), ``degenerate`` (a
    landmark on the sensor), ``motion_before_start``, ``mean_nis`` and ``mean_nis_per_dof``
    of the applied updates, ``start_time``, ``failed_static_starts``,
    ``rejected_static_fixes``, ``lockouts`` (declared), ``lockout_times``,
    ``relocalization_times`` and ``relocalization_readings`` (readings used by those fixes,
    not as updates).

    Subclasses implement :meth:`_predict` and :meth:`_update` on ``self._mean``/``self._cov``.
    """

    name = "gaussian"

    def __init__(
        self, dataset: Dataset, config: GaussianFilterConfig, rng: np.random.Generator
    ) -> None:
        missing = [
            what
            for what, value in (
                ("a motion model", dataset.motion),
                ("a landmark sensor", dataset.landmark_sensor),
                ("a known landmark map", dataset.known_landmarks),
            )
            if value is None
        ]
        if missing or dataset.motion is None or dataset.landmark_sensor is None:
            raise InputError(f"{self.name} needs {', '.join(missing)}; {dataset.name} has none")
        if dataset.known_landmarks is None:
            raise InputError(f"{self.name} needs a known landmark map; {dataset.name} has none")
        self._config = config
        self._motion = dataset.motion.model
        self._Q = config.motion_cov_scale * dataset.motion.noise_cov
        self._sensor = dataset.landmark_sensor
        self._meas = dataset.landmark_sensor.model()
        self._R = as_covariance(
            config.measurement_cov_scale * dataset.landmark_sensor.noise_cov, "R", None
        )
        self._angular = angular_indices(self._meas)
        self._landmarks = dataset.known_landmarks
        self._row_of = {int(i): r for r, i in enumerate(self._landmarks.ids.tolist())}
        p = config.gate_probability
        self._gate = math.inf if p is None else chi2_gate(self._meas.dim, p)

        self._mean: FloatArray | None = None
        self._cov: FloatArray | None = None
        if dataset.initial_pose is not None:
            start = GaussianBelief.from_pose(dataset.initial_pose, dataset.initial_cov)
            self._mean, self._cov = start.mean.copy(), start.cov.copy()
        super().__init__()

        self._counts = {
            "predictions": 0,
            "readings": 0,
            "updates": 0,
            "unassociated": 0,
            "rejected_by_gate": 0,
            "unknown_ids": 0,
            "degenerate": 0,
            "motion_before_start": 0,
            "relocalization_readings": 0,
        }
        self._start_time: float | None = None if self._mean is None else dataset.start_time
        self._failed_starts = 0
        self._rejected_fixes = 0
        # Lock-out guard: the gate rejections since the last accepted update, and whether a
        # relocalisation is pending.
        self._relocalize_after = (
            config.relocalize_after if config.association == "known" and p is not None else None
        )
        self._rejections_in_a_row = 0
        self._relocalizing = False
        self._lockout_times: list[float] = []
        self._relocalization_times: list[float] = []
        self._innovations = InnovationRecorder(config.record_innovations)
        self._chosen = AssociationRecorder()  # per reading: its landmark or -1

    # -- the two steps a filter provides ------------------------------------------------

    def _predict(self, u: FloatArray, dt: float) -> None:
        raise NotImplementedError

    def _update(self, z: FloatArray, landmark: FloatArray, gate: float) -> tuple[float, bool]:
        """Update with one reading unless its NIS exceeds ``gate``; ``(nis, applied)``."""
        raise NotImplementedError

    # -- Estimator protocol -------------------------------------------------------------

    def on_control(self, u: FloatArray, dt: float) -> None:
        self._motion_step(u, dt)

    def on_landmarks(self, event: LandmarkReadings) -> None:
        chosen = np.full(event.ids.size, -1, dtype=np.int64)
        if self._mean is None:
            self._start_from_fix(event)
        else:
            self._readings(event, chosen)
        self._chosen.add(chosen)

    def estimate(self) -> PoseEstimate:
        if self._mean is None or self._cov is None:
            return PoseEstimate(np.zeros(3), _UNINITIALISED_COV.copy())
        return PoseEstimate(self._mean[:3].copy(), self._cov[:3, :3].copy())

    def finish(self) -> EstimatorOutput:
        nis = self._innovations.nis
        diagnostics: dict[str, Any] = dict(self._counts)
        diagnostics["mean_nis"] = float(nis.mean()) if nis.size else None
        diagnostics["mean_nis_per_dof"] = float(nis.mean()) / self._meas.dim if nis.size else None
        diagnostics["association"] = self._config.association
        diagnostics["start_time"] = self._start_time
        diagnostics["failed_static_starts"] = self._failed_starts
        diagnostics["rejected_static_fixes"] = self._rejected_fixes
        diagnostics["lockouts"] = len(self._lockout_times)
        diagnostics["lockout_times"] = list(self._lockout_times)
        diagnostics["relocalization_times"] = list(self._relocalization_times)
        return EstimatorOutput(
            diagnostics=diagnostics,
            innovations=self._innovations.log(),
            reading_landmarks=self._chosen.result(),
            landmark_numbering=LandmarkIds.DATASET,  # the known map's ids
        )

    # -- internals ------------------------------------------------------------------------

    def _motion_step(self, u: FloatArray, dt: float) -> None:
        if self._mean is None:
            self._counts["motion_before_start"] += 1
            return
        self._predict(u, dt)
        self._counts["predictions"] += 1

    def _static_fix(self, event: LandmarkReadings) -> GaussianBelief | None:
        """A belief from a static pose fix of these readings, or ``None`` when they do not
        determine one or contradict each other (residual χ² beyond the gate)."""
        # Imported here: static localization is a sibling module that imports models only.
        from slamkit.localization.static import localize_from_readings

        ids = event.ids if self._config.association == "known" else np.full_like(event.ids, -1)
        try:
            fix = localize_from_readings(event.z, ids, self._sensor, self._landmarks)
            belief = GaussianBelief(fix.pose, fix.cov)
        except SlamkitError:  # too few readings, degenerate geometry: wait for the next ones
            return None
        p = self._config.gate_probability
        if p is not None:
            chi2, dof = _fix_residual_chi2(fix.residuals, self._R, self._sensor.kind)
            if dof > 0 and chi2 > chi2_gate(dof, p):  # an outlier among the readings
                self._rejected_fixes += 1
                return None
        return belief

    def _start_from_fix(self, event: LandmarkReadings) -> None:
        """Initialise from a static pose fix of these readings (when they give a sound one)."""
        start = self._static_fix(event)
        if start is None:
            self._failed_starts += 1
            return
        # The fix used these readings; updating with them again would count them twice.
        self._mean, self._cov = start.mean.copy(), start.cov.copy()
        self._start_time = float(event.t)

    def _relocalize(self, event: LandmarkReadings) -> bool:
        """After a lock-out: re-initialise from a sound static fix of these readings."""
        fix = self._static_fix(event)
        if fix is None:
            return False
        self._mean, self._cov = fix.mean.copy(), fix.cov.copy()
        self._relocalizing = False
        self._rejections_in_a_row = 0
        self._relocalization_times.append(float(event.t))
        self._counts["readings"] += event.ids.size
        self._counts["relocalization_readings"] += event.ids.size
        return True

    def _readings(self, event: LandmarkReadings, chosen: NDArray[np.int64]) -> None:
        """Update with the readings of ``event``; ``chosen[j]`` becomes the landmark reading
        ``j`` updated with (left ``-1`` when unassociated, rejected or used by a fix)."""
        if self._relocalizing and self._relocalize(event):
            return  # the fix used these readings
        z = event.z
        k = z.shape[0]
        self._counts["readings"] += k
        if self._config.association == "ml":
            assert self._mean is not None and self._cov is not None
            assoc = associate_arrays_unchecked(
                self._mean[:3], self._cov[:3, :3], z, self._landmarks, self._meas, self._R,
                self._gate,
            )  # fmt: skip
            ids = assoc.landmark_ids
            gate = math.inf  # the association gate has already been applied
        else:
            ids = event.ids
            gate = self._gate
        for j in range(k):
            lid = int(ids[j])
            if lid < 0:
                self._counts["unassociated"] += 1
                continue
            row = self._row_of.get(lid)
            if row is None:
                self._counts["unknown_ids"] += 1
                continue
            try:
                nis, applied = self._update(z[j], self._landmarks.positions[row], gate)
            except GeometryError:  # the landmark sits on the sensor: no bearing, no Jacobian
                self._counts["degenerate"] += 1
                continue
            if not applied:
                self._counts["rejected_by_gate"] += 1
                self._rejections_in_a_row += 1
                n = self._relocalize_after
                if n is not None and self._rejections_in_a_row >= n and not self._relocalizing:
                    self._relocalizing = True  # locked out: re-initialise at the next fix
                    self._lockout_times.append(float(event.t))
                continue
            self._counts["updates"] += 1
            chosen[j] = lid
            self._rejections_in_a_row = 0
            self._innovations.add(event.t, nis, self._meas.dim, lid)


class EkfLocalization(GaussianLocalization):
    """EKF localization with point landmarks of a known map (range-bearing, range-only or
    bearing-only readings, known or unknown correspondences). Configured by
    :class:`EkfConfig`; see :class:`GaussianLocalization` for the event handling."""

    name = "EKF localization"

    def __init__(self, dataset: Dataset, config: EkfConfig, rng: np.random.Generator) -> None:
        super().__init__(dataset, config, rng)
        # The closed form or the general steps, decided here once (the state is the pose).
        self._steps = choose_ekf_steps(self._motion, self._meas, self._Q, self._R)

    def _predict(self, u: FloatArray, dt: float) -> None:
        assert self._mean is not None and self._cov is not None
        self._mean, self._cov = self._steps.predict(self._mean, self._cov, u, dt)

    def _update(self, z: FloatArray, landmark: FloatArray, gate: float) -> tuple[float, bool]:
        assert self._mean is not None and self._cov is not None
        mean, cov, nis = self._steps.update(self._mean, self._cov, z, landmark)
        if nis > gate:
            return nis, False
        self._mean, self._cov = mean, cov
        return nis, True
