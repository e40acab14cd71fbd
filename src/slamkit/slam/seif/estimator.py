"""The SEIF estimator of the pipeline (:class:`Seif`): a thin stateful shell over the
information-form kernels (:mod:`~slamkit.slam.seif.kernels`), the association
(:mod:`~slamkit.slam.seif.association`) and the mean recovery
(:mod:`~slamkit.slam.seif.recovery`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slamkit._validation import FloatArray, as_covariance
from slamkit.datasets.stream import (
    Dataset,
    GpsFix,
    LandmarkReadings,
    LandmarkSensorSpec,
    MotionSpec,
)
from slamkit.errors import ConvergenceError, GeometryError, InputError
from slamkit.estimation.contract import (
    EstimatorOutput,
    LandmarkEstimate,
    LandmarkIds,
    PoseEstimate,
)
from slamkit.estimation.gaussian import angular_indices
from slamkit.estimation.gps import GpsFrontEnd, gps_warnings
from slamkit.estimation.shell import EstimatorShell
from slamkit.mapping.ekf_mapping import DISCARDED, INITIALISED, NEW, REJECTED, UPDATED
from slamkit.maps import LandmarkMap
from slamkit.models import MIN_RANGE, LandmarkModel
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.prob import chi2_gate
from slamkit.slam.common import OWN_ID_BASE, NisRecord, ReadingLog, scan_readings
from slamkit.slam.seif.association import (
    associate,
    blanket_covariance,
    conditional_nis,
    wrapped_pose,
)
from slamkit.slam.seif.config import SeifConfig
from slamkit.slam.seif.gps import fix_distance, gps_information_update, move_information
from slamkit.slam.seif.kernels import (
    PendingMotion,
    apply_motion,
    landmark_indices,
    measurement_block,
    motion_step,
    pose_indices,
    sparsify_state,
)
from slamkit.slam.seif.recovery import check_pose_block, exact_estimate, exact_mean, relax_step
from slamkit.slam.seif.state import SeifState

__all__ = ["COUNTS", "Seif"]

COUNTS = ("predictions", "readings", "updates", "new_landmarks", "unlabelled", "rejected",
          "degenerate", "sparsifications", "association_scans")  # fmt: skip
"""The counts in the diagnostics of :meth:`Seif.finish`."""


def _check_dataset(
    dataset: Dataset,
) -> tuple[MotionSpec, LandmarkSensorSpec, InvertibleLandmarkModel]:
    """The data set's motion, landmark sensor and the sensor's (invertible) model; a named
    error if SEIF cannot run on the data set."""
    if dataset.motion is None or dataset.landmark_sensor is None:
        raise InputError(f"seif needs a motion model and a landmark sensor; {dataset.name}")
    sensor = dataset.landmark_sensor
    model = sensor.model()
    if not isinstance(model, InvertibleLandmarkModel):
        raise InputError(
            f"seif cannot use the {sensor.kind!r} sensor: one reading does not locate a landmark"
        )
    return dataset.motion, sensor, model


class Seif(EstimatorShell):
    """SEIF SLAM as an estimator of the pipeline.

    Per time step: the motion update of the mean, its information composed with the
    other steps since the last scan (:class:`~slamkit.slam.seif.kernels.PendingMotion`)
    and applied to the pose and active landmarks once, before the scan; per scan, data
    association at the state before the scan (readings with ids and ``use_ids`` go to
    their landmark, the others by maximum likelihood over the candidates near the robot
    with the blanket covariance, :mod:`slamkit.slam.seif`), one information update per reading
    (new landmarks start at the inverse-model point with no information of their own,
    which the reading then supplies), sparsification down to ``max_active`` active
    landmarks, and the amortised relaxation of the mean. Without ids the filter numbers
    its landmarks from :data:`~slamkit.slam.common.OWN_ID_BASE`.

    :class:`~slamkit.datasets.GpsFix` events (a stream whose loader was asked to fuse GPS)
    measure the antenna at ``gps_lever_arm``: the first move ``(Ω, ξ, μ)`` into the GPS
    frame, the others are information updates on the pose block through a χ² gate
    (:mod:`slamkit.slam.seif.gps`); :meth:`finish` then returns the path in the GPS frame
    and the GPS counts.

    :meth:`estimate` reports the pose with no covariance (SEIF has none at hand);
    :meth:`finish` solves for the exact mean once and returns the landmarks with their
    marginal covariances, and diagnostics: the counts, ``n_landmarks``, ``association``,
    ``max_block`` (the largest block of state a motion update or sparsification touched:
    the robot and at most ``max_active`` plus one scan's new landmarks — it does not grow
    with the map), ``max_blanket`` (most state entries of one association solve),
    ``max_links`` (most landmarks any landmark is linked to, which bounds a relaxation
    step), ``mean_links``, ``mean_nis`` and ``relaxed_vs_exact_max`` (how far the running
    mean is from ``Ω⁻¹ ξ`` at the end).

    Divergence — a non-finite mean, a singular block in the relaxation, an information
    block that is not positive definite (the pose block after every scan, the blanket of
    every association) — raises :class:`~slamkit.errors.ConvergenceError` with the step
    (the runner's numbering: one step per distinct time stamp).
    """

    name = "SEIF"

    def __init__(self, dataset: Dataset, config: SeifConfig, rng: np.random.Generator) -> None:
        motion, sensor, model = _check_dataset(dataset)
        self._config = config
        self._motion = motion.model
        self._Q = config.motion_cov_scale * motion.noise_cov
        self._meas: InvertibleLandmarkModel = model
        self._model: LandmarkModel = sensor.model()
        self._R = as_covariance(config.measurement_cov_scale * sensor.noise_cov, "R")
        self._R_inv = np.asarray(np.linalg.inv(self._R), dtype=np.float64)
        self._m = int(self._R.shape[0])
        self._angular = angular_indices(self._model)
        self._use_ids = config.use_ids and sensor.identities
        self._gates = (
            chi2_gate(self._m, config.gate_probability),
            chi2_gate(self._m, config.new_landmark_probability),
        )
        pose = np.zeros(3) if dataset.initial_pose is None else dataset.initial_pose.copy()
        cov = np.zeros((3, 3)) if dataset.initial_cov is None else dataset.initial_cov
        self._st = SeifState(config.initial_capacity, pose, cov, config.prior_information)
        self._pending = PendingMotion(self._st.mu[:3])
        self._next_id = OWN_ID_BASE
        self._cursor = 0
        self._max_block = 0  # the largest index block a motion update or sparsification used
        self._max_blanket = 0  # the largest association solve (state entries)
        super().__init__()
        self._counts = dict.fromkeys(COUNTS, 0)
        self._nis = NisRecord()
        self._log = ReadingLog()
        self._gps = None if dataset.gps is None else GpsFrontEnd(
            dataset.gps.noise_cov, config.gps_lever_arm, config.gps_gate_probability,
            dataset.start_time, wrapped_pose(self._st.mu),
        )  # fmt: skip

    def on_control(self, u: FloatArray, dt: float) -> None:
        self._predict(u, dt)

    def on_landmarks(self, event: LandmarkReadings) -> None:
        self.apply_motion()
        self._readings(event)
        touched = sparsify_state(self._st, self._config.max_active)
        if touched:
            self._max_block = max(self._max_block, touched)
            self._counts["sparsifications"] += 1
        cfg = self._config
        self._cursor = relax_step(self._st, cfg.relax_sweeps, cfg.relax_per_step, self._cursor)
        check_pose_block(self._st.Om)

    def on_gps(self, event: GpsFix) -> None:
        if self._gps is not None:  # the Dataset refuses fixes without a GpsSpec
            self._fix(float(event.t), np.asarray(event.position, dtype=float))

    def after_event(self, step: int) -> None:
        if not math.isfinite(float(self._st.mu[0] + self._st.mu[1] + self._st.mu[2])):
            raise ConvergenceError("the mean became non-finite")
        if self._gps is not None:
            self._gps.record(float(self.clock.time or 0.0), wrapped_pose(self._st.mu))

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(wrapped_pose(self._st.mu), None)

    @property
    def mean(self) -> FloatArray:
        """The running (relaxed) mean ``(3 + 2L,)``, heading unwrapped."""
        return self._st.mu[: self._st.n].copy()

    @property
    def information(self) -> tuple[FloatArray, FloatArray]:
        """Copies of ``(Ω, ξ)`` over the current state (after :meth:`apply_motion`)."""
        self.apply_motion()
        n = self._st.n
        return self._st.Om[:n, :n].copy(), self._st.xi[:n].copy()

    @property
    def active(self) -> list[int]:
        """Map rows of the landmarks linked to the robot."""
        return list(self._st.active)

    @property
    def landmark_ids(self) -> NDArray[np.int64]:
        return np.asarray(self._st.ids, dtype=np.int64)

    def reading_log(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading handled so far: ``(times, landmark ids, status)``; the id of the
        landmark the reading updated or started (``-1`` if none), status
        :data:`~slamkit.slam.ekf_slam.UPDATED`, :data:`~slamkit.slam.ekf_slam.INITIALISED`
        or :data:`~slamkit.slam.ekf_slam.DISCARDED` (rejected by the association, or a
        reading too close to the robot to linearise)."""
        return self._log.arrays()

    def links(self, row: int) -> set[int]:
        """Map rows of the landmarks that landmark ``row`` is linked to (``Ω`` entries
        between them that may be nonzero); the robot's links are :attr:`active`."""
        return set(self._st.links[row])

    def blanket_covariance(
        self, rows: ArrayLike, hops: int | None = None, max_blanket: int | None = None
    ) -> FloatArray:
        """The joint covariance ``(3 + 2k, 3 + 2k)`` of the robot and the landmarks ``rows``
        (map rows, ``k`` of them) from the information over their blanket
        (:mod:`slamkit.slam.seif`, *Data association*), ``hops`` and ``max_blanket``
        defaulting to the configuration's."""
        cfg = self._config
        self.apply_motion()
        return blanket_covariance(
            self._st.Om, rows, self._st.active, self._st.links,
            cfg.blanket_hops if hops is None else hops,
            cfg.max_blanket if max_blanket is None else max_blanket,
        )  # fmt: skip

    def recover_mean(self) -> FloatArray:
        """The exact mean ``Ω⁻¹ ξ`` (a dense solve, ``O(n³)``)."""
        return exact_mean(*self.information)

    def landmark_estimate(self) -> LandmarkEstimate:
        """The landmarks now at the amortised (relaxed) mean, without covariances: recovering
        those needs the whole information matrix, which only :meth:`finish` does."""
        mean = self._st.mu[3 : self._st.n].reshape(-1, 2).copy()
        return LandmarkEstimate(LandmarkMap(mean, np.asarray(self._st.ids, dtype=np.int64)))

    def finish(self) -> EstimatorOutput:
        self.apply_motion()
        L = self._st.n_landmarks
        lm, mu = exact_estimate(self._st)
        links = [len(s) for s in self._st.links]
        nis = np.asarray(self._nis.nis)
        diagnostics: dict[str, Any] = dict(self._counts)
        diagnostics.update(
            association="known ids" if self._use_ids else "nn",
            n_landmarks=L,
            max_block=self._max_block,
            max_blanket=self._max_blanket,
            max_links=max(links) if links else 0,
            mean_links=float(np.mean(links)) if links else 0.0,
            mean_nis=float(nis.mean()) if nis.size else None,
            relaxed_vs_exact_max=float(np.abs(self._st.mu[: self._st.n] - mu).max()),
        )
        if self._gps is not None:
            diagnostics.update(self._gps.counts)
        return EstimatorOutput(
            trajectory=None if self._gps is None else self._gps.trajectory(),
            warnings=() if self._gps is None else gps_warnings(self._gps.counts),
            landmarks=lm,
            diagnostics=diagnostics,
            innovations=self._nis.log(self._m),
            reading_landmarks=self._log.arrays()[1],
            landmark_numbering=LandmarkIds.DATASET if self._use_ids else LandmarkIds.OWN,
        )

    def apply_motion(self) -> None:
        """Apply the information of the motion steps since the last scan to ``Ω``, ``ξ``
        (the mean moves at every step; :class:`~slamkit.slam.seif.kernels.PendingMotion`):
        done before each scan and whenever ``Ω`` is read, so at most once per scan."""
        if not self._pending.steps:
            return
        idx = np.concatenate([pose_indices(), landmark_indices(self._st.active)])
        try:
            apply_motion(self._st.Om, self._st.xi, self._st.mu, idx, self._pending)
        except np.linalg.LinAlgError:
            raise ConvergenceError("the motion update met a singular matrix") from None
        self._max_block = max(self._max_block, idx.size)

    def _fix(self, t: float, z: FloatArray) -> None:
        """A GPS fix (:mod:`~slamkit.slam.seif.gps`): collected for the move into the GPS
        frame, then an information update on the pose block through the gate."""
        gps, st = self._gps, self._st
        assert gps is not None
        self.apply_motion()
        if not gps.aligned:
            fit = gps.collect(t, z, wrapped_pose(st.mu))
            if fit is not None:
                move_information(st.Om, st.xi, st.mu, st.n, fit.angle, fit.shift)
                self._pending.restart(st.mu[:3])
            return
        pose_cov = self.blanket_covariance([])
        used = fix_distance(st.mu[:3], pose_cov, z, gps.lever, gps.noise_cov) <= gps.gate
        gps.judged(used)
        if not used:
            return
        R_inv = np.asarray(np.linalg.inv(gps.noise_cov), dtype=np.float64)
        gps_information_update(st.Om, st.xi, st.mu, z, gps.lever, R_inv)
        cfg = self._config
        self._cursor = relax_step(st, cfg.relax_sweeps, cfg.relax_per_step, self._cursor)
        check_pose_block(st.Om)

    def _predict(self, u: FloatArray, dt: float) -> None:
        if not self._pending.steps:  # the relaxation may have moved the mean since
            self._pending.restart(self._st.mu[:3])
        self._pending.add(*motion_step(self._st.mu, u, dt, self._motion, self._Q))
        self._counts["predictions"] += 1

    def _readings(self, event: LandmarkReadings) -> None:
        z, ids = scan_readings(event, self._m, self._use_ids)
        t = float(event.t)
        K = z.shape[0]
        self._counts["readings"] += K
        labelled = ids >= 0
        # association at the state before the scan
        target = np.full(K, REJECTED, dtype=np.int64)  # map row, NEW or REJECTED
        d2 = np.full(K, np.nan)
        for k in np.flatnonzero(labelled).tolist():
            target[k] = self._st.slot_of.get(int(ids[k]), NEW)
        free = np.flatnonzero(~labelled)
        if free.size:
            self._counts["unlabelled"] += free.size
            match, d2[free], solved = associate(
                self._st, z[free], self._meas, self._model, self._R, self._angular, self._config,
                self._gates,
            )  # fmt: skip
            if solved:
                self._counts["association_scans"] += 1
                self._max_blanket = max(self._max_blanket, solved)
            if self._use_ids:  # unlabelled readings never start a landmark there
                match = np.where(match == NEW, REJECTED, match)
            target[free] = match
        for k in range(K):
            j = int(target[k])
            if j == REJECTED:
                self._counts["rejected"] += 1
                self._log.add(t, -1, DISCARDED)
                continue
            status = UPDATED
            if j == NEW:
                lid = int(ids[k]) if labelled[k] else self._next_id
                j = self._st.slot_of.get(lid, -1)
                if j < 0:  # a new landmark: the inverse-model point, no information yet
                    point = self._meas.inverse(wrapped_pose(self._st.mu), z[k])
                    if math.hypot(*(point - self._st.mu[:2])) < MIN_RANGE:
                        self._counts["degenerate"] += 1  # it would get no information
                        self._log.add(t, -1, DISCARDED)
                        continue
                    j = self._st.add(point, lid)
                    self._next_id = max(self._next_id, lid + 1)
                    self._counts["new_landmarks"] += 1
                    status = INITIALISED
            s = 3 + 2 * j
            try:
                nu, H = measurement_block(
                    self._st.Om,
                    self._st.xi,
                    self._st.mu,
                    s,
                    z[k],
                    self._model,
                    self._R_inv,
                    self._angular,
                )
            except GeometryError:
                self._counts["degenerate"] += 1
                self._log.add(t, -1, DISCARDED)
                continue
            self._counts["updates"] += 1
            lid = self._st.ids[j]
            self._log.add(t, lid, status)
            if j in self._st.active:
                self._st.active.remove(j)
            self._st.active.append(j)  # most recently observed last
            if status == UPDATED:
                nis = (
                    d2[k]
                    if math.isfinite(d2[k])
                    else conditional_nis(self._st.Om, nu, H, s, self._R)
                )
                self._nis.add(t, float(nis), lid)
