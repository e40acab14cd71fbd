"""The EKF-SLAM estimator of the pipeline (:class:`EkfSlam`): a thin stateful shell over the
state buffers (:mod:`~slamkit.slam.ekf_slam.state`), the update kernel
(:mod:`~slamkit.slam.ekf_slam.update`), data association
(:mod:`~slamkit.slam.ekf_slam.association`) and the provisional feature list
(:mod:`~slamkit.slam.ekf_slam.provisional`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray, as_covariance
from slamkit.datasets.stream import (
    Dataset,
    GpsFix,
    LandmarkReadings,
    LandmarkSensorSpec,
    MotionSpec,
)
from slamkit.errors import GeometryError, InputError
from slamkit.estimation.contract import (
    EstimatorOutput,
    LandmarkEstimate,
    LandmarkIds,
    PoseEstimate,
)
from slamkit.estimation.gaussian import angular_indices, check_state_covariance
from slamkit.estimation.shell import EstimatorShell
from slamkit.mapping.ekf_mapping import (
    DISCARDED,
    INITIALISED,
    NEW,
    REJECTED,
    TOO_CLOSE,
    UPDATED,
)
from slamkit.maps import LandmarkMap
from slamkit.models import LandmarkModel
from slamkit.models.measurement import InvertibleLandmarkModel
from slamkit.prob import chi2_gate
from slamkit.slam.common import OWN_ID_BASE, NisRecord, ReadingLog, scan_readings
from slamkit.slam.ekf_slam.association import JcbbResult, associate_scan
from slamkit.slam.ekf_slam.belief import SlamBelief
from slamkit.slam.ekf_slam.config import EkfSlamConfig
from slamkit.slam.ekf_slam.gps import GPS_COUNTS, GpsFusion, gps_warnings
from slamkit.slam.ekf_slam.kernels import EkfKernels, SlamKernels
from slamkit.slam.ekf_slam.provisional import (
    TRACKED,
    in_view,
    is_confirmed,
    miss_limit,
    reading_information,
    remove_missed,
    watched,
)
from slamkit.slam.ekf_slam.selection import NOT_SELECTED, select_features
from slamkit.slam.ekf_slam.state import SlamState, diagonal_blocks
from slamkit.slam.ekf_slam.update import check_diagonal
from slamkit.slam.ekf_slam.window import reading_window

__all__ = ["COUNTS", "GPS_COUNTS", "EkfSlam"]

COUNTS = (
    "predictions",
    "readings",
    "updates",
    "provisional_updates",
    "new_features",
    "promoted",
    "removed_provisional",
    "removed_confirmed",
    "expected_confirmed",
    "seen_confirmed",
    "rejected",
    "not_selected",
    "too_close",
    "degenerate",
    "jcbb_searches",
    "jcbb_nodes",
    "jcbb_incomplete",
)
"""The counts in the diagnostics of :meth:`EkfSlam.finish`."""


def _check_dataset(
    dataset: Dataset, key: str
) -> tuple[MotionSpec, LandmarkSensorSpec, InvertibleLandmarkModel]:
    """The data set's motion, landmark sensor and the sensor's (invertible) model; a named
    error if EKF-SLAM cannot run on the data set."""
    if dataset.motion is None or dataset.landmark_sensor is None:
        missing = [
            what
            for what, value in (
                ("a motion model", dataset.motion),
                ("a landmark sensor", dataset.landmark_sensor),
            )
            if value is None
        ]
        raise InputError(f"{key} needs {' and '.join(missing)}; {dataset.name} has none")
    sensor = dataset.landmark_sensor
    meas = sensor.model()
    if not isinstance(meas, InvertibleLandmarkModel):
        raise InputError(
            f"{key} cannot use the {sensor.kind!r} sensor of {dataset.name}: one reading "
            "does not locate a landmark (use range-bearing or position readings)"
        )
    return dataset.motion, sensor, meas


def _count_search(counts: dict[str, int], res: JcbbResult | None) -> None:
    """Add a JCBB search (if one ran) to the counts."""
    if res is not None:
        counts["jcbb_searches"] += 1
        counts["jcbb_nodes"] += res.nodes
        counts["jcbb_incomplete"] += int(not res.complete)


class EkfSlam(EstimatorShell):
    """EKF-SLAM with point landmarks, as an estimator of the pipeline.

    Controls (or consecutive odometry poses) drive :func:`slam_predict`; each
    :class:`~slamkit.datasets.LandmarkReadings` event is one scan, handled in this order:

    1. **Association** at the state before the scan. Readings with an id (and
       ``use_ids``) go to that landmark, or start it. The others are compared with every
       landmark (confirmed and provisional) by ``d² = νᵀ S⁻¹ ν`` and paired by nearest
       neighbour or JCBB (``association``); an unpaired reading starts a feature if
       ``d² > χ²_m(new_landmark_probability)`` for every landmark, else it is rejected.
       Innovations are wrapped, so a landmark read at bearing ``+π − ε`` and ``−π + ε``
       (straight behind) is one landmark, not two.
    2. **Updates**, one reading at a time, each linearised at the state the previous one
       left: a confirmed landmark's reading updates the whole state (5-column Joseph
       update), a provisional feature's only the feature (Schmidt update, see
       :attr:`EkfSlamConfig.provisional_trace`), after which the feature is promoted if its
       measurement-only covariance is small enough.
    3. **New features** from their first reading (:func:`slam_add_landmark` on the buffers),
       provisional unless ``provisional_trace`` is ``None``. Readings with an id keep it;
       without ids the filter numbers its features from :data:`OWN_ID_BASE`.
    4. **Removal**: a feature predicted well inside the field of view and detection range
       (3σ margin, at the state before the scan, judged from where the sensor sits) but not
       matched counts a miss; after as many consecutive misses as ``miss_probability``
       derives from the confirmed landmarks' detection rate (``max_misses`` without it, or
       for a sensor without a finite range) a provisional feature is removed
       (``max_misses_confirmed`` for confirmed ones). Removing marginalises the feature out
       of the Gaussian: its rows and columns are dropped.

    Between 1 and 3, **feature selection**: an unlabelled reading that association would let
    start a feature starts one only at least ``min_feature_spacing`` from every landmark
    (:mod:`~slamkit.slam.ekf_slam.selection`); and association compares each reading with
    the landmarks in its window only (:mod:`~slamkit.slam.ekf_slam.window`).

    :class:`~slamkit.datasets.GpsFix` events (a stream whose loader was asked to fuse GPS)
    measure the antenna at ``gps_lever_arm``: after the first fixes have moved the filter into
    the GPS frame, each is fused through a χ² gate (:mod:`slamkit.slam.ekf_slam.gps`), and
    :meth:`finish` returns the whole path in the GPS frame and the counts of
    :data:`GPS_COUNTS`.

    The prior is the data set's (``initial_pose``, ``initial_cov``); without one the map
    frame is the start pose, known exactly. :meth:`finish` returns the confirmed
    landmarks with their marginal covariances and the diagnostics: counts (see
    :data:`COUNTS`), ``n_landmarks``, ``n_provisional``, NIS statistics of the map updates
    Divergence — a non-finite state, an innovation covariance that is not positive
    definite, a negative variance, a pose covariance that is not positive semi-definite
    (every step) or a whole covariance that is not (every ``check_every`` steps; both
    :func:`~slamkit.estimation.gaussian.check_state_covariance`, the check every Gaussian
    filter shares) — raises :class:`~slamkit.errors.ConvergenceError` with the step (the
    runner's numbering: one step per distinct time stamp).
    """

    name = "EKF-SLAM"
    key = "ekf-slam"
    """The registry name, used in error messages."""

    def __init__(self, dataset: Dataset, config: EkfSlamConfig, rng: np.random.Generator) -> None:
        motion, sensor, meas = _check_dataset(dataset, self.key)
        self._config = config
        self._motion = motion.model
        self._Q = config.motion_cov_scale * motion.noise_cov
        self._meas: InvertibleLandmarkModel = meas
        self._model: LandmarkModel = sensor.model()
        self._R = as_covariance(config.measurement_cov_scale * sensor.noise_cov, "R", None)
        self._m = int(self._R.shape[0])
        self._R_inv = np.asarray(np.linalg.inv(self._R), dtype=np.float64)
        self._angular = angular_indices(self._model)
        self._new_gate = chi2_gate(self._m, config.new_landmark_probability)  # the window's γ
        self._kernels = self.make_kernels(
            config, EkfKernels(self._motion, self._Q, self._model, meas, self._R, self._angular)
        )
        self._sensor = sensor
        # A detection rate is the sensor's only within a stated reach (miss_probability).
        self._bounded_view = math.isfinite(sensor.reach)
        self._use_ids = config.use_ids and sensor.identities
        self._state = SlamState(config.initial_capacity, dataset.initial_pose, dataset.initial_cov)
        self._next_id = OWN_ID_BASE
        super().__init__()
        self._counts = dict.fromkeys(COUNTS, 0)
        self._log = ReadingLog()
        self._nis = NisRecord()
        self._nis_provisional: list[float] = []
        self._gps = None if dataset.gps is None else GpsFusion(
            dataset.gps.noise_cov, config.gps_lever_arm, config.gps_gate_probability,
            dataset.start_time, self._state.mean_buf[:3],
        )  # fmt: skip

    @property
    def mean(self) -> FloatArray:
        """A copy of the state mean ``(3 + 2L,)`` (pose, then landmarks in state order)."""
        return self._state.views()[0].copy()

    @property
    def cov(self) -> FloatArray:
        """A copy of the full covariance ``(n, n)``."""
        return self._state.views()[1].copy()

    @property
    def landmark_ids(self) -> NDArray[np.int64]:
        """Ids of the landmarks in state order (confirmed and provisional)."""
        return self._state.ids[: self._state.n_landmarks].copy()

    @property
    def provisional(self) -> NDArray[np.bool_]:
        """Which landmarks (state order) are still provisional."""
        return self._state.provisional[: self._state.n_landmarks].copy()

    @property
    def capacity(self) -> int:
        """Landmarks the buffers hold before the next doubling."""
        return self._state.capacity

    def belief(self) -> SlamBelief:
        """The current belief (all landmarks, provisional ones included) as a value."""
        return SlamBelief(self.mean, self.cov, self.landmark_ids)

    def make_kernels(self, config: EkfSlamConfig, ekf: EkfKernels) -> SlamKernels:
        """The Gaussian kernels this filter runs (called once, by the constructor): here
        ``ekf``, the analytic linearisation; a subclass returns its own from the same
        models and noises (the fields of ``ekf``) and its ``config``."""
        return ekf

    def on_control(self, u: FloatArray, dt: float) -> None:
        self._predict(u, dt)

    def on_landmarks(self, event: LandmarkReadings) -> None:
        self._scan(event)

    def on_gps(self, event: GpsFix) -> None:
        if self._gps is not None:  # the Dataset refuses fixes without a GpsSpec
            mean, cov = self._state.views()
            self._gps.fix(mean, cov, float(event.t), event.position, self._state.scratch)

    def after_event(self, step: int) -> None:
        check_state_covariance(self._state.views()[1], self.key, step, self._config.check_every)
        if self._gps is not None:
            self._gps.record(float(self.clock.time or 0.0), self._state.mean_buf[:3])

    def estimate(self) -> PoseEstimate:
        return PoseEstimate(self._state.mean_buf[:3].copy(), self._state.cov_buf[:3, :3].copy())

    def reading_log(self) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """Every reading handled so far: ``(times, landmark ids, status)``; the id of the
        landmark the reading updated or started (``-1`` if none), status codes
        :data:`UPDATED`, :data:`TRACKED`, :data:`INITIALISED`, :data:`DISCARDED`,
        :data:`TOO_CLOSE`."""
        return self._log.arrays()

    def landmark_estimate(self) -> LandmarkEstimate:
        """The confirmed landmarks now, with their marginal covariances ``(M, 2, 2)``."""
        st, L = self._state, self._state.n_landmarks
        mean, cov = st.views()
        keep = np.flatnonzero(~st.provisional[:L])
        covs = diagonal_blocks(cov, L)[keep]
        covs = 0.5 * (covs + np.swapaxes(covs, -1, -2))
        return LandmarkEstimate(
            LandmarkMap(mean[3:].reshape(-1, 2)[keep].copy(), st.ids[:L][keep].copy()), covs
        )

    def finish(self) -> EstimatorOutput:
        L = self._state.n_landmarks
        landmarks = self.landmark_estimate()
        keep = np.flatnonzero(~self._state.provisional[:L])
        nis = np.asarray(self._nis.nis, dtype=float)
        nis_p = np.asarray(self._nis_provisional, dtype=float)
        q95 = chi2_gate(self._m, 0.95)
        diagnostics: dict[str, Any] = dict(self._counts)
        diagnostics.update(
            association="known ids" if self._use_ids else self._config.association,
            n_landmarks=int(keep.size),
            n_provisional=int(L - keep.size),
            state_dim=self._state.n,
            capacity=self.capacity,
            mean_nis=float(nis.mean()) if nis.size else None,
            mean_nis_per_dof=float(nis.mean()) / self._m if nis.size else None,
            nis_above_95=float(np.mean(nis > q95)) if nis.size else None,
            mean_nis_provisional=float(nis_p.mean()) if nis_p.size else None,
        )
        if self._gps is not None:
            diagnostics.update(self._gps.counts)
        return EstimatorOutput(
            landmarks=landmarks,
            diagnostics=diagnostics,
            innovations=self._nis.log(self._m) if self._config.record_innovations else None,
            reading_landmarks=self._log.arrays()[1],
            landmark_numbering=LandmarkIds.DATASET if self._use_ids else LandmarkIds.OWN,
            trajectory=None if self._gps is None else self._gps.trajectory(),
            warnings=() if self._gps is None else gps_warnings(self._gps.counts),
        )

    def _predict(self, u: FloatArray, dt: float) -> None:
        mean, cov = self._state.views()
        self._kernels.predict(mean, cov, u, dt)
        self._counts["predictions"] += 1

    def _scan(self, event: LandmarkReadings) -> None:
        z, ids = scan_readings(event, self._m, self._use_ids)
        t, K, st, cfg = float(event.t), z.shape[0], self._state, self._config
        self._counts["readings"] += K
        usable = np.ones(K, dtype=bool)
        if cfg.min_range > 0 and K:
            x = st.mean_buf[:3]
            usable = np.hypot(*(self._meas.inverse(x, z) - x[:2]).T) >= cfg.min_range
        # Landmarks that misses may remove and that this scan should see.
        n_before = st.n_landmarks
        watch = watched(st.provisional[:n_before], cfg)
        expected = in_view(*st.views(), np.arange(n_before), self._sensor)
        matched = np.zeros(n_before, dtype=bool)
        # 1. association at the state before the scan
        target = np.full(K, REJECTED, dtype=np.int64)  # landmark index, NEW or REJECTED
        labelled = usable & (ids >= 0)
        for k in np.flatnonzero(labelled).tolist():
            target[k] = st.slot_of.get(int(ids[k]), NEW)
        free = np.flatnonzero(usable & (ids < 0))
        if free.size:
            window = reading_window(*st.views(), z[free], self._meas, self._R, self._new_gate)
            match, res = associate_scan(*st.views(), z[free], self._model, self._R,
                                        self._angular, cfg, window)  # fmt: skip
            _count_search(self._counts, res)
            if self._use_ids:  # unlabelled readings never start a landmark there
                match = np.where(match == NEW, REJECTED, match)
            new = np.flatnonzero(match == NEW)
            if new.size:  # feature selection (selection.py)
                chosen = select_features(st.mean_buf[: st.n], z[free[new]], self._meas,
                                         cfg.min_feature_spacing)  # fmt: skip
                match[new[~chosen]] = NOT_SELECTED
            target[free] = match
        # 2. updates in reading order; 3. new features
        for k in range(K):
            j = int(target[k])
            if not usable[k] or j in (REJECTED, NOT_SELECTED):
                what = "too_close" if not usable[k] else "rejected"
                self._counts[what if j != NOT_SELECTED else "not_selected"] += 1
                self._log.add(t, -1, TOO_CLOSE if not usable[k] else DISCARDED)
                continue
            if j == NEW:
                lid = int(ids[k]) if labelled[k] else self._next_id
                if lid not in st.slot_of:
                    self._add(z[k], lid)
                    self._log.add(t, lid, INITIALISED)
                    continue
                j = st.slot_of[lid]  # a repeated new id in one scan: update it instead
            self._update(t, j, z[k])
            if j < n_before:
                matched[j] = True
        # 4. features expected but not seen
        confirmed = expected & ~st.provisional[:n_before]
        self._counts["expected_confirmed"] += int(np.count_nonzero(confirmed))
        self._counts["seen_confirmed"] += int(np.count_nonzero(confirmed & matched))
        if watch.size:
            limit = None
            if cfg.miss_probability is not None and self._bounded_view:
                c = self._counts
                limit = miss_limit(cfg.miss_probability, c["expected_confirmed"],
                                   c["seen_confirmed"])  # fmt: skip
            n_prov, n_conf = remove_missed(st, matched | ~expected, cfg, limit)
            self._counts["removed_provisional"] += n_prov
            self._counts["removed_confirmed"] += n_conf

    def _add(self, z: FloatArray, landmark_id: int) -> None:
        provisional = self._config.provisional_trace is not None
        j = self._state.add(z, landmark_id, self._kernels.add, provisional)
        if provisional:
            self._add_information(j)
        self._next_id = max(self._next_id, landmark_id + 1)
        self._counts["new_features"] += 1

    def _add_information(self, j: int) -> None:
        info = reading_information(self._model, self._state.mean_buf, j, self._R_inv)
        if info is not None:
            self._state.info[j] += info

    def _update(self, t: float, j: int, z: FloatArray) -> None:
        st = self._state
        mean, cov = st.views()
        lid, provisional = int(st.ids[j]), bool(st.provisional[j])
        try:
            nis = self._kernels.update(mean, cov, 3 + 2 * j, z, st.scratch, provisional)
        except GeometryError:
            self._counts["degenerate"] += 1
            self._log.add(t, -1, DISCARDED)
            return
        st.misses[j] = 0
        if provisional:
            self._add_information(j)
            self._counts["provisional_updates"] += 1
            self._nis_provisional.append(nis)
            self._log.add(t, lid, TRACKED)
            threshold = self._config.provisional_trace
            assert threshold is not None
            if is_confirmed(st.info[j], threshold):
                st.provisional[j] = False
                self._counts["promoted"] += 1
            return
        check_diagonal(cov)
        self._counts["updates"] += 1
        self._log.add(t, lid, UPDATED)
        if self._config.record_innovations:
            self._nis.add(t, nis, lid)
