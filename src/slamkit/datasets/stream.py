"""The data model every loader and every simulated scenario produces.

A :class:`Dataset` is a time-ordered stream of typed events plus the metadata an estimator
needs (motion model and its noise, sensor descriptions, the prior it may use) and optional
ground truth for evaluation:

======================  ==========================================================
event                    meaning
======================  ==========================================================
:class:`Control`         control ``u`` applied over ``(t - dt, t]`` (e.g. v, ω)
:class:`Odometry`        the robot's pose in the odometry frame at ``t``
:class:`LandmarkReadings`  readings ``z (K, m)`` of point landmarks at ``t``, with
                         identities ``ids (K,)`` or ``-1`` where unknown
:class:`LaserScan`       ranges ``(B,)`` at ``t``; ``max_range`` means no return
:class:`GpsFix`          a GPS fix: the antenna's position ``(2,)`` in the GPS frame
======================  ==========================================================

Conventions (also in ``docs/architecture.md``): times in seconds, lengths in metres, angles in
radians wrapped to ``[-pi, pi)``; poses ``(x, y, theta)``; landmark readings ordered
``(range, bearing)`` (a single column for range-only or bearing-only sensors), or ``(x, y)``
in the robot frame for the ``"position"`` kind. Loaders convert
units and conventions at load time so estimators never see a data set's own quirks.

Events are plain frozen values; the :class:`Dataset` validates the whole stream once (order,
shapes, finiteness) so estimators can trust it.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal, NoReturn, TypeAlias

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray, as_array, as_covariance, as_positive
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.reading import ReadingSummary
from slamkit.datasets.relations import Relations
from slamkit.errors import InputError, NonFiniteError, ShapeError
from slamkit.geometry.angles import wrap_angle
from slamkit.geometry.pose2 import interpolate_poses
from slamkit.maps import LandmarkMap, OccupancyGrid, SegmentMap
from slamkit.models import (
    BearingOnly,
    LandmarkModel,
    MotionModel,
    OdometryModel,
    RangeBearing,
    RangeOnly,
    RelativePosition,
    motion_kernels,
)
from slamkit.models.measurement import InvertibleLandmarkModel

__all__ = [
    "Control",
    "Dataset",
    "Event",
    "GpsFix",
    "GpsSpec",
    "GroundTruth",
    "KnownPose",
    "LandmarkReadings",
    "LandmarkSensorSpec",
    "LaserScan",
    "LaserSpec",
    "MotionSpec",
    "Odometry",
    "group_by_time",
    "measured_detection_range",
    "with_known_poses",
]

UNKNOWN_ID = -1


@dataclass(frozen=True, slots=True)
class Control:
    """Control ``u (k,)`` applied over the interval ``(t - dt, t]``."""

    t: float
    u: FloatArray
    dt: float


@dataclass(frozen=True, slots=True)
class Odometry:
    """An odometry reading: the robot pose ``(3,)`` in the odometry frame at ``t``."""

    t: float
    pose: FloatArray


@dataclass(frozen=True, slots=True)
class KnownPose:
    """The robot's pose ``(3,)`` at ``t``, given: the input of mapping *with known poses*
    (:func:`with_known_poses` puts one at the head of every time stamp of a data set with a
    true trajectory). Estimators that localize ignore it."""

    t: float
    pose: FloatArray


@dataclass(frozen=True, slots=True)
class LandmarkReadings:
    """Readings ``z (K, m)`` of point landmarks at ``t``; ``ids (K,)``, ``-1`` = unknown."""

    t: float
    z: FloatArray
    ids: NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class LaserScan:
    """One scan: ``ranges (B,)`` at the beam angles of the dataset's :class:`LaserSpec`."""

    t: float
    ranges: FloatArray


@dataclass(frozen=True, slots=True)
class GpsFix:
    """A GPS fix: the antenna's position ``(2,)`` [m] in the GPS frame at ``t``. A loader
    emits fixes as events only when asked to (the data set's :class:`GpsSpec` says how
    noisy they are); otherwise a data set's GPS is reference (``truth.positions``), which
    estimators never read. Where the antenna sits on the robot is the estimator's setting."""

    t: float
    position: FloatArray


Event: TypeAlias = Control | Odometry | KnownPose | LandmarkReadings | LaserScan | GpsFix


@dataclass(frozen=True)
class GpsSpec:
    """The GPS fixes in a data set's stream: their nominal noise ``noise_cov (2, 2)`` [m²]
    (east, north). A fix's frame is the GPS's own, not the estimator's map frame."""

    noise_cov: FloatArray

    def __post_init__(self) -> None:
        object.__setattr__(self, "noise_cov", as_covariance(self.noise_cov, "gps noise_cov", 2))


@dataclass(frozen=True)
class MotionSpec:
    """How the robot moves and how the dataset reports it.

    ``source`` is ``"control"`` when the stream carries :class:`Control` events for ``model``
    and ``"odometry"`` when it carries :class:`Odometry` poses (then ``model`` is the
    :class:`~slamkit.models.OdometryModel` and ``noise_cov`` the covariance of
    ``(rot1, trans, rot2)``). ``noise_cov (k, k)`` is the nominal control noise.
    """

    model: MotionModel
    noise_cov: FloatArray
    source: Literal["control", "odometry"] = "control"

    def __post_init__(self) -> None:
        k = motion_kernels(self.model).control_dim  # InputError naming what a model lacks
        cov = as_covariance(self.noise_cov, "motion noise_cov", k, semidefinite=True)
        object.__setattr__(self, "noise_cov", cov)
        if self.source == "odometry" and not isinstance(self.model, OdometryModel):
            raise InputError("MotionSpec: source 'odometry' needs model OdometryModel()")


LandmarkKind = Literal["range-bearing", "range", "bearing", "position"]


@dataclass(frozen=True)
class LandmarkSensorSpec:
    """A point-landmark sensor: what it measures, its noise and its limits."""

    kind: LandmarkKind
    noise_cov: FloatArray
    max_range: float = float("inf")
    fov: float = 2.0 * np.pi
    identities: bool = True
    min_range: float = 0.0
    """Landmarks closer than this are not reported (real sensors have a minimum range; a
    bearing read at millimetres is meaningless and wrecks a linearised filter)."""
    offset: tuple[float, float] = (0.0, 0.0)
    """Where the sensor sits in the robot frame [m] (ahead, left). The readings are of the
    landmark from the robot's pose all the same; the field of view (``fov``, centred ahead)
    is the sensor's, from here: estimators that predict which landmarks should have been
    seen (FastSLAM's existence counters) judge from this point."""
    detection_range: float | None = None
    """The range [m, from the sensor] within which it reads the landmarks it could see —
    shorter than ``max_range`` for a laser that seldom detects a tree trunk far away.
    Estimators that count missed landmarks count only within it. ``None``: ``max_range``.
    A loader may measure it from its log (:func:`measured_detection_range`)."""

    def __post_init__(self) -> None:
        try:
            a, b = (float(v) for v in self.offset)
        except (TypeError, ValueError) as exc:
            raise InputError(
                f"landmark sensor offset: expected two numbers [m], got {self.offset!r}"
            ) from exc
        if not (np.isfinite(a) and np.isfinite(b)):
            raise InputError(f"landmark sensor offset: expected finite numbers, got {(a, b)}")
        object.__setattr__(self, "offset", (a, b))
        if self.kind not in ("range-bearing", "range", "bearing", "position"):
            raise InputError(
                f"landmark sensor kind: expected 'range-bearing', 'range', 'bearing' or "
                f"'position', got {self.kind!r}"
            )
        cov = as_covariance(self.noise_cov, "landmark noise_cov", self.dim)
        object.__setattr__(self, "noise_cov", cov)
        if not float(self.max_range) > 0:  # +inf (no range limit) is allowed
            raise InputError(f"max_range: expected a number > 0, got {self.max_range!r}")
        object.__setattr__(self, "max_range", float(self.max_range))
        if not 0.0 <= float(self.min_range) < self.max_range:
            raise InputError(
                f"min_range: expected 0 <= min_range < max_range, got {self.min_range!r}"
            )
        object.__setattr__(self, "fov", as_positive(self.fov, "fov"))
        if self.detection_range is not None:
            d = float(self.detection_range)
            if not 0.0 < d <= self.max_range:
                raise InputError(
                    f"detection_range: expected 0 < detection_range <= max_range "
                    f"({self.max_range:g}), got {self.detection_range!r}"
                )
            object.__setattr__(self, "detection_range", d)

    @property
    def reach(self) -> float:
        """:attr:`detection_range`, or ``max_range`` when it is not given."""
        return self.max_range if self.detection_range is None else self.detection_range

    @property
    def dim(self) -> int:
        return 2 if self.kind in ("range-bearing", "position") else 1

    def model(self) -> LandmarkModel:
        """The measurement model h(pose, landmark) of this sensor."""
        if self.kind == "range-bearing":
            return RangeBearing()
        if self.kind == "position":
            return RelativePosition()
        return RangeOnly() if self.kind == "range" else BearingOnly()


def measured_detection_range(events: Sequence[Event], sensor: LandmarkSensorSpec) -> float:
    """A sensor's detection range measured from the readings of a log: ``min(max_range,
    q₉₀ / √0.9)``, ``q₉₀`` the 90th percentile of the readings' ranges from the sensor (at
    ``sensor.offset``) — the range of an ideal sensor (it reads every landmark within it,
    none beyond) whose readings of landmarks spread evenly in the plane (range CDF
    ``(r/R)²``) have that percentile. ``max_range`` when there are no readings; range-only
    and bearing-only readings, which do not place a landmark, give ``max_range`` too."""
    model = sensor.model()
    if not isinstance(model, InvertibleLandmarkModel):
        return sensor.max_range
    z = [ev.z for ev in events if isinstance(ev, LandmarkReadings) and ev.z.size]
    if not z:
        return sensor.max_range
    lm = model.inverse(np.zeros(3), np.concatenate(z))  # in the robot frame
    a, b = sensor.offset
    q90 = float(np.quantile(np.hypot(lm[:, 0] - a, lm[:, 1] - b), 0.9))
    return min(sensor.max_range, q90 / math.sqrt(0.9))


@dataclass(frozen=True)
class LaserSpec:
    """A 2D laser scanner: beam angles ``(B,)`` [rad] in the laser's frame, max range [m],
    range noise [m], and where the laser sits on the robot (``mounting``)."""

    beam_angles: FloatArray
    max_range: float
    range_sigma: float = 0.0
    mounting: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The laser's pose ``(x, y, yaw)`` in the robot frame [m, m, rad]: a beam at angle ``a``
    reading ``r`` hits ``mounting ⊕ (r cos a, r sin a)`` in the robot frame. The default
    (the laser at the robot's origin, facing ahead) makes the laser frame the robot frame;
    readers of real logs take it from the log (a ROS bag's ``/tf_static``, a CARMEN laser
    line's two poses). The yaw is wrapped to ``[-pi, pi)``."""

    def __post_init__(self) -> None:
        angles = as_array(self.beam_angles, "beam_angles", (None,))
        if angles.size == 0:
            raise ShapeError("beam_angles: expected at least one beam, got none")
        object.__setattr__(self, "beam_angles", angles)
        try:
            mx, my, myaw = (float(v) for v in self.mounting)
        except (TypeError, ValueError) as exc:
            raise InputError(
                f"laser mounting: expected three numbers (x [m], y [m], yaw [rad]), "
                f"got {self.mounting!r}"
            ) from exc
        if not all(math.isfinite(v) for v in (mx, my, myaw)):
            raise NonFiniteError(f"laser mounting: expected finite numbers, got {(mx, my, myaw)}")
        object.__setattr__(self, "mounting", (mx, my, float(wrap_angle(myaw))))
        object.__setattr__(self, "max_range", as_positive(self.max_range, "max_range"))
        object.__setattr__(
            self, "range_sigma", as_positive(self.range_sigma, "range_sigma", allow_zero=True)
        )

    @property
    def n_beams(self) -> int:
        return int(self.beam_angles.size)


@dataclass(frozen=True)
class GroundTruth:
    """What really happened, where known: trajectory, landmarks, walls, occupancy."""

    times: FloatArray | None = None
    poses: FloatArray | None = None
    landmarks: LandmarkMap | None = None
    walls: SegmentMap | None = None
    occupancy: OccupancyGrid | None = None
    position_times: FloatArray | None = None
    positions: FloatArray | None = None
    """A position-only reference track ``(N, 2)`` at ``position_times (N,)``, e.g. GPS: no
    heading, and it may hold outliers and gaps. Scored by :mod:`slamkit.eval.gps` (outlier
    rejection, alignment at its times), not by the pose metrics."""
    reading_ids: tuple[NDArray[np.int64], ...] | None = None
    """The true landmark id of every reading, one array per :class:`LandmarkReadings` event
    in stream order (``-1`` = unknown): the data association, for scoring an estimator that
    was given no ids (matched against the events by :meth:`Dataset.check_reading_ids`)."""
    relations: Relations | None = None
    """Reference relations (the Freiburg benchmark's ground truth): the pose at ``t2`` in the
    frame at ``t1``, scored by :mod:`slamkit.eval.relations` against a trajectory that has
    the stamps."""

    def __post_init__(self) -> None:
        if (self.times is None) != (self.poses is None):
            raise InputError("ground truth: times and poses go together")
        if self.times is not None and self.poses is not None:
            times = as_array(self.times, "truth times", (None,))
            poses = as_array(self.poses, "truth poses", (times.size, 3))
            if np.any(np.diff(times) < 0):
                raise InputError("truth times: expected non-decreasing times")
            object.__setattr__(self, "times", times)
            object.__setattr__(self, "poses", poses)
        if (self.position_times is None) != (self.positions is None):
            raise InputError("ground truth: position_times and positions go together")
        if self.position_times is not None and self.positions is not None:
            pt = as_array(self.position_times, "truth position_times", (None,))
            xy = as_array(self.positions, "truth positions", (pt.size, 2))
            if np.any(np.diff(pt) < 0):
                raise InputError("truth position_times: expected non-decreasing times")
            object.__setattr__(self, "position_times", pt)
            object.__setattr__(self, "positions", xy)
        if self.reading_ids is not None:
            ids = tuple(np.asarray(a, dtype=np.int64).reshape(-1) for a in self.reading_ids)
            object.__setattr__(self, "reading_ids", ids)

    @property
    def has_trajectory(self) -> bool:
        return self.poses is not None


@dataclass(frozen=True)
class Dataset:
    """A time-ordered event stream with its metadata and optional ground truth.

    ``initial_pose``/``initial_cov`` is the prior an estimator may start from (absent for
    global localization and for data sets whose start is unknown). ``known_landmarks`` and
    ``known_grid`` are maps a *localization* estimator may use; SLAM estimators ignore them.
    ``truth`` is for evaluation only: estimators must not read it. ``reading`` says what a
    reader of a real file dropped and repaired (:class:`~slamkit.datasets.reading.
    ReadingSummary`; None for simulated data). ``provenance`` says where it came from — the
    file and reader, the resolved options (:class:`~slamkit.datasets.provenance.
    Provenance`): what a run records to re-run it. ``metadata`` holds descriptive counts
    for people; no layer reads keys of it back. (Settings measured to
    suit one estimator on a data set are not part of it: see :mod:`slamkit.app.presets`.)
    """

    name: str
    events: tuple[Event, ...]
    motion: MotionSpec | None = None
    landmark_sensor: LandmarkSensorSpec | None = None
    laser: LaserSpec | None = None
    initial_pose: FloatArray | None = None
    initial_cov: FloatArray | None = None
    known_landmarks: LandmarkMap | None = None
    known_grid: OccupancyGrid | None = None
    truth: GroundTruth = field(default_factory=GroundTruth)
    gps: GpsSpec | None = None
    """How noisy the stream's :class:`GpsFix` events are (``None``: the stream has none)."""
    description: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)
    reading: ReadingSummary | None = None
    provenance: Provenance = field(default_factory=Provenance)

    def __post_init__(self) -> None:
        if self.initial_pose is not None:
            object.__setattr__(
                self, "initial_pose", as_array(self.initial_pose, "initial_pose", (3,))
            )
        if self.initial_cov is not None:
            cov = as_covariance(self.initial_cov, "initial_cov", 3, semidefinite=True)
            object.__setattr__(self, "initial_cov", cov)
        object.__setattr__(self, "events", tuple(self.events))
        self._validate_events()

    def _validate_events(self) -> None:
        """Check the whole stream once: times finite and non-decreasing, every event's arrays
        of the shape the metadata declares and finite. Vectorised per event type (a loop over
        100k events doing a full check each would dominate load times); on failure the first
        offending event is named."""
        events = self.events
        if not events:
            return
        times = np.fromiter((ev.t for ev in events), dtype=np.float64, count=len(events))
        bad = ~np.isfinite(times)
        bad[1:] |= np.diff(times) < 0
        if np.any(bad):
            self._fail(int(np.argmax(bad)), "expected finite, non-decreasing times")
        by_type: dict[type, list[int]] = {}
        for i, ev in enumerate(events):
            by_type.setdefault(type(ev), []).append(i)
        for kind, idx in by_type.items():
            if kind is Control:
                self._check_controls(idx)
            elif kind is Odometry:
                if self.motion is None or self.motion.source != "odometry":
                    self._fail(idx[0], "an Odometry event needs an odometry MotionSpec")
                self._check_rows(idx, "pose", (3,))
            elif kind is KnownPose:
                self._check_rows(idx, "pose", (3,))
            elif kind is LandmarkReadings:
                if self.landmark_sensor is None:
                    self._fail(idx[0], "landmark readings need a LandmarkSensorSpec")
                self._check_readings(idx, self.landmark_sensor.dim)
            elif kind is LaserScan:
                if self.laser is None:
                    self._fail(idx[0], "a laser scan needs a LaserSpec")
                rows = self._check_rows(idx, "ranges", (self.laser.n_beams,))
                negative = (rows < 0).any(axis=1)
                if negative.any():
                    self._fail(
                        idx[int(np.argmax(negative))],
                        "ranges: expected ranges >= 0 m (max_range marks no return)",
                    )
            elif kind is GpsFix:
                if self.gps is None:
                    self._fail(idx[0], "a GPS fix needs a GpsSpec")
                self._check_rows(idx, "position", (2,))
            else:
                self._fail(idx[0], "unknown event type")

    def check_reading_ids(self) -> NDArray[np.int64]:
        """The true landmark of every reading, concatenated in stream order, after checking
        that ``truth.reading_ids`` holds one id per reading of every readings event (a data
        set whose events were replaced, say with clutter added, no longer matches its truth:
        :class:`~slamkit.errors.ShapeError` naming the event). Checked here, when the
        association is scored, rather than at construction, so that such a data set can
        still be run."""
        truth_ids = self.truth.reading_ids
        if truth_ids is None:
            raise InputError(f"data set {self.name!r} has no true association of its readings")
        idx = [i for i, ev in enumerate(self.events) if isinstance(ev, LandmarkReadings)]
        if len(truth_ids) != len(idx):
            raise ShapeError(
                f"truth reading_ids: expected {len(idx)} arrays (one per LandmarkReadings "
                f"event), got {len(truth_ids)}"
            )
        for i, ids in zip(idx, truth_ids, strict=True):
            n = np.size(self.events[i].ids)  # type: ignore[union-attr]
            if ids.shape != (n,):
                self._fail(i, f"truth reading_ids: expected {n} ids, got {ids.size}", ShapeError)
        return np.concatenate([np.zeros(0, np.int64), *truth_ids])

    def _fail(self, i: int, message: str, error: type[InputError] = InputError) -> NoReturn:
        ev = self.events[i]
        raise error(f"event {i} ({type(ev).__name__} at t={ev.t}): {message}")

    def _check_rows(self, idx: list[int], attr: str, shape: tuple[int, ...]) -> FloatArray:
        """Stack ``attr`` of the events ``idx`` (each of ``shape``) and check them at once."""
        try:
            rows = np.asarray([getattr(self.events[i], attr) for i in idx], dtype=np.float64)
        except (TypeError, ValueError):
            rows = np.empty(0)
        if rows.shape != (len(idx), *shape):
            for i in idx:  # find the culprit for the message
                a = np.asarray(getattr(self.events[i], attr))
                if a.shape != shape:
                    self._fail(i, f"{attr}: expected shape {shape}, got {a.shape}", ShapeError)
        finite = np.isfinite(rows).reshape(len(idx), -1).all(axis=1)
        if not finite.all():
            self._fail(idx[int(np.argmin(finite))], f"{attr}: expected finite numbers",
                       NonFiniteError)  # fmt: skip
        return rows

    def _check_controls(self, idx: list[int]) -> None:
        if self.motion is None or self.motion.source != "control":
            self._fail(idx[0], "a Control event needs a control MotionSpec")
        self._check_rows(idx, "u", (self.motion.model.control_dim,))
        dts = self._check_rows(idx, "dt", ())
        if np.any(dts < 0):
            self._fail(idx[int(np.argmax(dts < 0))], "dt: expected a time step >= 0")

    def _check_readings(self, idx: list[int], m: int) -> None:
        for i in idx:  # shapes vary per event (K readings), so check each cheaply
            ev = self.events[i]
            z, ids = np.asarray(ev.z), ev.ids  # type: ignore[union-attr]
            if z.ndim != 2 or z.shape[1] != m:
                self._fail(i, f"z: expected shape (K, {m}), got {np.shape(z)}", ShapeError)
            if np.shape(ids) != (z.shape[0],):
                self._fail(i, f"expected {z.shape[0]} ids, got shape {np.shape(ids)}", ShapeError)
        z_all = np.concatenate([np.asarray(self.events[i].z, float) for i in idx])  # type: ignore[union-attr]
        if not np.all(np.isfinite(z_all)):
            for i in idx:
                if not np.all(np.isfinite(self.events[i].z)):  # type: ignore[union-attr]
                    self._fail(i, "z: expected finite readings", NonFiniteError)

    def with_provenance(self, provenance: Provenance) -> Dataset:
        """This data set with ``provenance``: a copy sharing the events, which are not
        checked again (they did not change), with a copy of ``metadata``."""
        out = copy.copy(self)
        object.__setattr__(out, "provenance", provenance)
        object.__setattr__(out, "metadata", dict(self.metadata))
        return out

    # -- convenience views -------------------------------------------------------------

    def __len__(self) -> int:
        return len(self.events)

    @property
    def start_time(self) -> float:
        """The time of the first event (or of the first true pose, if earlier)."""
        starts = [self.events[0].t] if self.events else []
        if self.truth.times is not None and self.truth.times.size:
            starts.append(float(self.truth.times[0]))
        return float(min(starts)) if starts else 0.0

    @property
    def end_time(self) -> float:
        return float(self.events[-1].t) if self.events else self.start_time

    def counts(self) -> dict[str, int]:
        """How many events of each type the stream holds."""
        out: dict[str, int] = {}
        for ev in self.events:
            out[type(ev).__name__] = out.get(type(ev).__name__, 0) + 1
        return out

    def of_type(self, kind: type[Event]) -> Iterator[Event]:
        return (ev for ev in self.events if isinstance(ev, kind))

    def summary(self) -> dict[str, Any]:
        """A JSON-able description (for ``slamkit data list`` and result folders)."""
        return {
            "name": self.name,
            "description": self.description,
            "events": self.counts(),
            "duration_s": self.end_time - self.start_time,
            "motion": None if self.motion is None else type(self.motion.model).__name__,
            "landmark_sensor": None if self.landmark_sensor is None else self.landmark_sensor.kind,
            "laser_beams": None if self.laser is None else self.laser.n_beams,
            "ground_truth": {
                "trajectory": self.truth.has_trajectory,
                "landmarks": self.truth.landmarks is not None,
                "walls": self.truth.walls is not None,
                "occupancy": self.truth.occupancy is not None,
                "positions": self.truth.positions is not None,
            },
            **self.metadata,
        }


def group_by_time(events: tuple[Event, ...]) -> Iterator[tuple[float, tuple[Event, ...]]]:
    """Yield ``(t, events at t)`` for consecutive runs of equal time stamps."""
    n = len(events)
    i = 0
    while i < n:
        t = events[i].t
        j = i + 1
        while j < n and events[j].t == t:
            j += 1
        yield t, events[i:j]
        i = j


def with_known_poses(dataset: Dataset) -> Dataset:
    """``dataset`` with a :class:`KnownPose` event at the head of every group of events that
    share a time stamp: the true pose then, interpolated on SE(2) between the true poses
    around it (held at the ends; :func:`~slamkit.geometry.pose2.interpolate_poses`). This is
    how mapping with known poses gets its poses — through the stream, one at a time, as a
    system given them online would — rather than by reading ``truth``
    (:func:`slamkit.pipeline.run` does it for the estimators registered with
    ``known_poses``). Raises :class:`~slamkit.errors.InputError` without a true trajectory."""
    truth = dataset.truth
    if truth.times is None or truth.poses is None or truth.times.size == 0:
        raise InputError(
            f"mapping with known poses needs the true trajectory, which data set "
            f"{dataset.name!r} does not have"
        )
    events: list[Event] = []
    groups = list(group_by_time(dataset.events))
    t = np.clip([g[0] for g in groups], truth.times[0], truth.times[-1])
    poses = interpolate_poses(truth.times, truth.poses, t) if groups else np.zeros((0, 3))
    for (time, group), pose in zip(groups, poses, strict=True):
        events.append(KnownPose(time, pose))
        events.extend(group)
    return replace(dataset, events=tuple(events))
