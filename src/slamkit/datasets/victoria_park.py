"""Victoria Park: a utility truck driving through a Sydney park, laser-detected trees, GPS.

Guivant and Nebot, "Optimization of the simultaneous localization and map-building algorithm
for real-time implementation", IEEE Trans. Robotics and Automation 17(3), 2001 (Australian
Centre for Field Robotics). The truck logs the speed of its rear left wheel and the steering
angle at 40 Hz; a SICK laser (180°, in front of the truck) sees tree trunks, extracted as
point landmarks; a GPS receiver, failing under the trees, gives a sparse reference track.

Files under ``landmarks/victoria_park/`` (white space separated, ``#`` header lines):

===========================================  ================================================
``original_acfr/aa3_dr.csv.gz``              ``time_ms speed steering`` [ms, m/s, rad]:
                                             61,945 samples every 25 ms
``original_acfr/aa3_gpsx.csv``               ``time_ms x y`` [ms, m, m] (east, north): 4,466
                                             fixes with dropouts and jumps
``slsjf/data_sensor_clean_clean.csv.gz``     ``time_ms range bearing x_est y_est
                                             feature_index`` [ms, m, rad, m, m, -]: 46,860
                                             tree detections of 299 trees (SLSJF clean-up)
===========================================  ================================================

Conversion (:func:`load_victoria_park`):

* **Times** in seconds, on the files' clock (``time_ms / 1000``; the run spans 21.94 s to
  1570.54 s). ``max_duration_s`` keeps the first that many seconds after the first odometry
  sample (readings, controls and GPS fixes up to then).
* **Controls.** Odometry sample ``k`` is held until sample ``k + 1``:
  ``Control(t_{k+1}, u = (speed_k, steering_k), dt = 25 ms)`` for
  :class:`~slamkit.models.Ackermann` with wheelbase ``L = 2.83`` m and encoder offset
  ``H = 0.76`` m (the speed is that of the rear left wheel, ``H`` left of the centre line; the
  speed of the rear-axle centre is ``speed / (1 - tan(steering) H / L)``), steering at the
  front axle, positive to the left. The state is the pose of the **rear-axle centre**. With
  ``split_at_readings`` (default) a control whose interval contains detection times is cut
  there into pieces with the same control, so every detection sees the pose of its own
  time stamp (the truck covers up to 17 cm in 25 ms). The last sample has no successor.
* **Readings.** The laser reports ``range`` and ``bearing`` in its own frame, ``bearing`` in
  ``[0, pi]`` from the truck's right (the scan direction of the original ``info.txt``: column
  ``k`` at ``(k - 1) / 2`` degrees). Each detection becomes the point
  ``p = (a, b) + range (cos(bearing - pi/2), sin(bearing - pi/2))`` in the vehicle frame
  (rear-axle centre, x forward, y left; laser at ``(a, b) = (3.78, 0.50)`` m) and is given to
  estimators as the range-bearing reading of ``p`` *from the rear-axle centre*,
  ``(|p|, atan2(p_y, p_x))``: the standard :class:`~slamkit.models.RangeBearing` model of the
  robot pose then applies, with no sensor offset. Detections with the same time stamp form
  one :class:`LandmarkReadings` event (7,122 events), placed after the control that ends at
  that time. Ids are ``-1`` (unknown) unless ``identities`` is set: the ``feature_index`` of
  the file is a data association made by the SLSJF authors, kept as ground truth
  (``truth.reading_ids``, one array per readings event) for scoring association. Rows with
  ``feature_index = -1`` (poor features, none in this file) are dropped and counted.
  The ``x_est y_est`` columns are the SLSJF estimate of the tree in the world frame; they are
  not read.
* **Where the laser sees.** The readings are moved to the rear axle, but the laser still
  sees from where it sits: its 180° field of view is the half-plane ahead of ``(a, b)``,
  its ranges are measured from there. The sensor specification's ``offset = (a, b)``
  records it for estimators that predict which trees should be seen (FastSLAM's existence
  counters): from the axle, trees beside the cab, between axle and laser, would count as
  missed at every scan. (The sensor specification's ``max_range`` is the laser's 80 m plus
  ``|(a, b)|``, a bound from the axle; ``fov`` is the laser's.)
* **GPS** is ``truth.position_times``/``truth.positions``: positions only (no heading), in
  the GPS frame, every fix as recorded, outliers included. :func:`slamkit.eval.gps.gps_error`
  rejects fixes that disagree with their neighbours and scores an estimate after an SE(2)
  alignment at the GPS times. There is no true trajectory and no landmark map. With
  ``gps_fuse`` the fixes are also put in the stream as ``GpsFix`` events (every
  ``gps_holdout_every``-th left out, to score on) with noise ``gps_sigma`` per axis, for
  estimators that fuse them (EKF-SLAM, ``docs/estimators/gps.md``).
* **Prior**: the start defines the frame: pose ``(0, 0, 0)`` with zero covariance.

**Conventions checked on the data.** Dead reckoning below integrates the odometry with the
published vehicle; "spread" is the RMS distance of detections, placed through the
dead-reckoned poses, from the centroid of their tree (``feature_index``) over 5-s chunks of
the whole run, which keeps the dead-reckoning drift out of it.

* *Handedness and steering sign.* The GPS frame is right-handed (x east, y north). Dead
  reckoning with steering positive to the left matches the GPS track under a proper rotation
  (median residual 2.5 m over the first 100 s) and not under a reflection (10.8 m); with the
  steering sign flipped it is the reverse. So steering > 0 turns left, as in the model.
* *Bearing reference.* With that steering sign, detections placed through the dead-reckoned
  poses cluster into trees only with ``bearing - pi/2`` (counter-clockwise from the truck's
  forward axis): spread 0.36 m, against 6.9 m with the mirrored ``pi/2 - bearing`` and 5.1 m
  with ``bearing`` unchanged. Over the first 60 s (2557 detections, 66 trees seen 3+ times)
  the median per-tree spread is 0.59 m, and 12.3 m mirrored.
* *Laser offset.* ``info.txt`` gives ``a = 0.95`` m, ``../shared/DATA.md`` ``a = 3.78`` m;
  ``3.78 - 0.95 = 2.83 = L``, so ``info.txt`` measures from the front axle. The data agree
  with 3.78 m from the rear axle: fitting ``(a, b)`` (with a steering offset, an effective
  wheelbase and a detection time lag, all free) to minimise the spread over 2-s and 5-s
  chunks gives ``a = 3.66`` m, ``b = 0.57–0.59`` m (left); at ``a = 3.78, b = 0.50`` the
  spread is 0.196 m (5-s chunks), at ``a = 0.95`` 0.327 m. With the published vehicle and
  nothing fitted: 0.36 m against 0.62 m; over the first 60 s, 0.59 m against 0.88 m. The
  file agrees: at the first time stamp (truck at the origin, not yet moved) its SLSJF
  estimate of each tree equals ``(3.78, 0.5) + range (cos, sin)(bearing - pi/2)`` to 1e-7 m,
  so the SLSJF authors used ``a = 3.78, b = 0.5`` too.

**Dead reckoning is biased.** Both the tree clusters and the GPS prefer a small steering
offset (+0.0035 to +0.0059 rad) and a wheelbase of 2.69–2.84 m; option ``steering_offset``
adds a constant to every steering reading (default 0: the data as recorded, the published
vehicle). Over the whole run, dead reckoning misses the GPS by an RMSE of 92.8 m as
recorded and 32.7 m with ``steering_offset = 0.0045`` (after SE(2) alignment,
:func:`slamkit.eval.gps.gps_error`); over the first 60 s by 2.05 m. The detection time
stamps lag the odometry by 0.06–0.09 s (fitted); the loader does not shift them.

**Nominal noise** (measured; tune per estimator):

* readings: against each tree's centroid over 2-s chunks, the range residual has a MAD-based
  sigma of 0.05 m (standard deviation 0.07 m) and the bearing residual 0.0034 rad (0.005 rad)
  in the laser frame. Viewpoint-dependent errors (the trunk's centre seen from different
  sides) do not show in 2 s, so the defaults are about twice that: ``sigma_range = 0.1`` m,
  ``sigma_bearing = 0.01`` rad. The vehicle-frame reading has nearly the laser's noise (the
  offset is small beside the ranges, median 23 m); the exact covariance differs by the
  Jacobian of the change of frame, which the nominal values ignore.
* controls, per 25-ms sample: ``sigma_speed = 0.5`` m/s and ``sigma_steering = 0.3`` rad.
  With ``sigma_steering = 0.1`` rad the white noise gives a heading spread of about 0.04
  rad after 5 s and 0.09 rad after 30 s at the mean speed (2.8 m/s); the tree spread over
  5-s chunks (0.36 m at ranges around 20 m) suggests 0.02–0.03 rad at 5 s, but the GPS
  track, aligned over 10 s at both ends of a 30-s window, shows 0.2 rad (MAD) with a bias
  of 0.17 rad. The long-term drift is mostly systematic; white noise cannot describe both
  ends, and a filter needs the long one: 0.3 rad gives 0.27 rad after 30 s. Measured with
  EKF-SLAM on the whole run, no ids, nearest neighbour: at 0.1 rad the filter misses
  re-observed trees at its gates and maps 569 landmarks (GPS RMSE 11.1 m); at 0.3 rad 331
  landmarks, 95.6 % of the readings associated as the file's feature index does, GPS RMSE
  4.81 m — what EKF-SLAM given the feature index reaches at 0.1 rad (4.81 m).

**FastSLAM** needs other settings than the nominal noise on this data set; they are the
preset ``victoria-park-fastslam`` (:mod:`slamkit.app.presets`; how they were measured:
``docs/presets.md``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets.assemble import (
    assemble_events,
    control_events,
    reading_events,
    time_groups,
)
from slamkit.datasets.gps_split import holdout_mask
from slamkit.datasets.paths import data_root as resolve_data_root
from slamkit.datasets.plaza import cut_intervals
from slamkit.datasets.provenance import Provenance
from slamkit.datasets.stream import (
    Dataset,
    GpsFix,
    GpsSpec,
    GroundTruth,
    LandmarkSensorSpec,
    MotionSpec,
    measured_detection_range,
)
from slamkit.datasets.text import (
    NumericTable,
    check_times,
    integer_values,
    raise_at_first,
    read_table,
)
from slamkit.errors import ConfigError, DataNotFoundError, DatasetFormatError
from slamkit.geometry import wrap_angle
from slamkit.models import Ackermann

__all__ = [
    "DETECTIONS_FILE",
    "ENCODER_OFFSET",
    "FOLDER",
    "GPS_FILE",
    "LASER_MAX_RANGE",
    "LASER_OFFSET",
    "ODOMETRY_FILE",
    "SIGMA_SPEED",
    "SIGMA_STEERING",
    "VICTORIA_PARK_FILES",
    "WHEELBASE",
    "VictoriaParkOptions",
    "ackermann_motion",
    "laser_to_vehicle",
    "load_victoria_park",
    "odometry_controls",
    "read_odometry",
]

FOLDER = "landmarks/victoria_park"
ODOMETRY_FILE = f"{FOLDER}/original_acfr/aa3_dr.csv.gz"
GPS_FILE = f"{FOLDER}/original_acfr/aa3_gpsx.csv"
DETECTIONS_FILE = f"{FOLDER}/slsjf/data_sensor_clean_clean.csv.gz"
VICTORIA_PARK_FILES = (ODOMETRY_FILE, GPS_FILE, DETECTIONS_FILE)
"""The files :func:`load_victoria_park` reads, relative to the data root."""

WHEELBASE = 2.83
"""``L``: rear axle to front axle [m]."""
ENCODER_OFFSET = 0.76
"""``H``: the speed encoder's wheel (rear left) from the centre line [m]."""
LASER_OFFSET = (3.78, 0.50)
"""``(a, b)``: the laser ahead of and left of the rear-axle centre [m] (see the module
docstring for why not ``info.txt``'s 0.95 m)."""
LASER_MAX_RANGE = 80.0
"""The SICK laser's maximum range [m] (``info.txt``: 8000 cm and beyond = no return)."""
SIGMA_SPEED = 0.5
"""Nominal speed noise per 25-ms odometry sample [m/s] (module docstring, "Nominal noise")."""
SIGMA_STEERING = 0.3
"""Nominal steering noise per 25-ms odometry sample [rad] (why 0.3 and not 0.1: module
docstring, "Nominal noise")."""

_MS = 1e-3


@dataclass(frozen=True)
class VictoriaParkOptions:
    """Options of :func:`load_victoria_park` (units: metres, radians, seconds)."""

    max_duration_s: float | None = None
    """Keep only the first this many seconds after the first odometry sample (all: None)."""
    identities: bool = False
    """Give estimators the file's ``feature_index`` as reading ids. Default: ids ``-1`` (the
    association is the estimator's job; the ids stay in ``truth.reading_ids``)."""
    laser_offset: tuple[float, float] = LASER_OFFSET
    """``(a, b)``: the laser ahead of and left of the rear-axle centre [m]."""
    wheelbase: float = WHEELBASE
    """``L`` [m]."""
    encoder_offset: float = ENCODER_OFFSET
    """``H`` [m], left of the centre line."""
    steering_offset: float = 0.0
    """Added to every steering reading [rad] (the data suggest +0.0035 to +0.0059)."""
    sigma_speed: float = SIGMA_SPEED
    """Nominal speed noise per 25-ms sample [m/s]."""
    sigma_steering: float = SIGMA_STEERING
    """Nominal steering noise per 25-ms sample [rad]."""
    sigma_range: float = 0.1
    """Nominal range noise [m]."""
    sigma_bearing: float = 0.01
    """Nominal bearing noise [rad]."""
    split_at_readings: bool = True
    """Cut controls at the detection times so each detection sees the pose of its time."""
    gps_fuse: bool = False
    """Put the GPS fixes into the stream as ``GpsFix`` events, for estimators that fuse
    them (EKF-SLAM). Default: the GPS is reference only (``truth.positions``)."""
    gps_holdout_every: int = 10
    """With ``gps_fuse``: every this-many-th fix (the 10th, 20th, …) stays out of the stream,
    to score on (``eval.gps_holdout``); 0: every fix in the stream. The truth keeps all."""
    gps_sigma: float = 1.0
    """With ``gps_fuse``: the fixes' nominal standard deviation per axis [m] (the graph's,
    measured in ``docs/estimators/gps.md``)."""

    def __post_init__(self) -> None:
        if self.max_duration_s is not None and not self.max_duration_s > 0:
            raise ConfigError(f"max_duration_s: expected a number > 0, got {self.max_duration_s}")
        for name in ("sigma_speed", "sigma_steering"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name}: expected a number >= 0, got {getattr(self, name)}")
        if not (isinstance(self.gps_holdout_every, int) and self.gps_holdout_every >= 0) or (
            self.gps_holdout_every == 1
        ):
            raise ConfigError(
                f"gps_holdout_every: expected 0 or an integer >= 2, got {self.gps_holdout_every}"
            )
        for name in ("sigma_range", "sigma_bearing", "wheelbase", "gps_sigma"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a number > 0, got {getattr(self, name)}")
        values = (*self.laser_offset, self.encoder_offset, self.steering_offset)
        if not all(np.isfinite(v) for v in values):
            raise ConfigError("laser_offset, encoder_offset, steering_offset: expected finite")


def laser_to_vehicle(
    ranges: FloatArray, bearings: FloatArray, laser_offset: tuple[float, float] = LASER_OFFSET
) -> FloatArray:
    """Laser detections -> range-bearing readings ``(K, 2)`` from the rear-axle centre.

    ``bearings`` are the laser's, in ``[0, pi]`` from the truck's right; the detection is
    ``p = (a, b) + r (cos(bearing - pi/2), sin(bearing - pi/2))`` in the vehicle frame
    (x forward, y left) and the result is ``(|p|, atan2(p_y, p_x))``, bearing wrapped.
    """
    a, b = laser_offset
    beta = np.asarray(bearings, dtype=np.float64) - np.pi / 2.0
    r = np.asarray(ranges, dtype=np.float64)
    px = a + r * np.cos(beta)
    py = b + r * np.sin(beta)
    return np.column_stack([np.hypot(px, py), wrap_angle(np.arctan2(py, px))])


def _require(root: Path, relative: str) -> Path:
    path = root / relative
    if not path.exists():
        raise DataNotFoundError(f"{path}: not found (needed under the data folder, SLAMKIT_DATA)")
    return path


def read_odometry(
    path: Path,
    *,
    steering_offset: float = 0.0,
    wheelbase: float = WHEELBASE,
    encoder_offset: float = ENCODER_OFFSET,
    unit: str = "ms",
) -> NumericTable:
    """Read the truck's ``time speed steering`` samples (time in ``unit``) and check them:
    at least two, strictly increasing times, and every steering angle (plus
    ``steering_offset``) one the :class:`~slamkit.models.Ackermann` model can take
    (``|alpha| < pi/2``, the encoder wheel inside the turn circle). Shared by every reader
    of this truck's odometry (the ACFR ``.csv`` in ms, the raw laser release's ``drs`` in
    s), so both refuse the same rows with the same :class:`DatasetFormatError`."""
    odo = read_table(path, 3)
    if len(odo) < 2:
        raise DatasetFormatError(f"expected at least 2 odometry samples, got {len(odo)}", path)
    check_times(odo, path, strict=True, unit=unit)
    alpha = odo.values[:, 2] + steering_offset
    # The Ackermann model needs |alpha| < pi/2 and the encoder wheel inside the turn circle.
    with np.errstate(invalid="ignore"):
        inside = 1.0 - np.tan(alpha) * encoder_offset / wheelbase
    wild = (np.abs(alpha) >= np.pi / 2) | ~(inside > 1e-9)
    raise_at_first(odo, wild, path, "steering {2:g} rad: not a steering angle of this vehicle")
    return odo


def odometry_controls(
    times: FloatArray,
    samples: FloatArray,
    cuts: FloatArray,
    *,
    steering_offset: float = 0.0,
    split: bool = True,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The Ackermann controls of odometry samples ``samples (N, 2)`` = ``(speed, steering)``
    at ``times (N,)`` [s, increasing]: sample ``k`` is held over ``(t_k, t_{k+1}]`` with
    ``steering_offset`` added to its steering; the last sample has no successor and gives
    none. With ``split``, an interval that holds one of the times ``cuts`` strictly inside
    is cut there into pieces with the same control, so an event at that time sees the pose
    of its own time stamp. Returns the end time ``(C,)``, duration ``(C,)`` and control
    ``(C, 2)`` of every piece, in time order (``Control(end, u, dt)``)."""
    u = np.array(samples[:-1, :2], dtype=np.float64)
    u[:, 1] += steering_offset
    t_begin, t_end = times[:-1], times[1:]
    if split:
        ends, dts, owner = cut_intervals(t_begin, t_end, cuts)
    else:
        ends, dts, owner = t_end, t_end - t_begin, np.arange(t_end.size)
    return ends, dts, u[owner]


def ackermann_motion(
    *,
    wheelbase: float = WHEELBASE,
    encoder_offset: float = ENCODER_OFFSET,
    sigma_speed: float = SIGMA_SPEED,
    sigma_steering: float = SIGMA_STEERING,
) -> MotionSpec:
    """The truck's motion: :class:`~slamkit.models.Ackermann` of the rear-axle centre (the
    state), speed from the encoder ``encoder_offset`` left of the centre line, with the
    nominal noise ``diag(sigma_speed², sigma_steering²)`` per control."""
    model = Ackermann(wheelbase, (0.0, 0.0), encoder_offset)
    return MotionSpec(model, np.diag([sigma_speed**2, sigma_steering**2]))


def _read_detections(path: Path) -> NumericTable:
    det = read_table(path, 6)
    check_times(det, path, strict=False, unit="ms")
    v = det.values
    raise_at_first(det, ~(v[:, 1] > 0), path, "expected a positive range, got {1:g}")
    # Finite is not enough: a range beyond what the laser reaches is damage, not a tree.
    far = v[:, 1] > LASER_MAX_RANGE
    raise_at_first(det, far, path, f"range {{1:g}} m: beyond the laser's {LASER_MAX_RANGE:g} m")
    out = ~((v[:, 2] >= 0) & (v[:, 2] <= np.pi))
    raise_at_first(det, out, path, "expected a laser bearing in [0, pi], got {2:g}")
    feat = v[:, 5]
    raise_at_first(
        det,
        (feat != np.round(feat)) | (feat < -1),
        path,
        "expected a feature index >= -1 (an integer), got {5:g}",
    )
    return det


_DESCRIPTION = (
    "Victoria Park: truck odometry at 40 Hz (Ackermann, rear-axle centre), laser "
    "range-bearing readings of 299 trees moved to the rear axle, ids unknown; GPS "
    "positions as reference"
)


@dataclass(frozen=True)
class _Detections:
    """The detections kept (stamps, ``(range, bearing)`` from the rear axle, true tree
    ids) and the counts of those dropped."""

    t: FloatArray
    z: FloatArray
    tree: NDArray[np.int64]
    poor: int
    outside: int


def load_victoria_park(
    options: Mapping[str, Any] | None = None,
    *,
    seed: int = 0,
    data_root: Path | None = None,
) -> Dataset:
    """Load Victoria Park as a :class:`Dataset`: Ackermann controls of the rear-axle centre,
    range-bearing readings of trees from the rear-axle centre (ids ``-1`` unless
    ``identities``), GPS as a position-only reference, start at the origin.

    ``options`` are the fields of :class:`VictoriaParkOptions`; ``seed`` is unused (real
    data); ``data_root`` defaults to :func:`slamkit.datasets.paths.data_root`. Raises
    :class:`DatasetFormatError` (file and line) on malformed rows and
    :class:`DataNotFoundError` when a file is missing. See the module docstring.
    """
    opts = config_from_mapping(VictoriaParkOptions, options, "victoria-park")
    root = resolve_data_root(data_root)
    p_odo, p_gps, p_det = (_require(root, f) for f in VICTORIA_PARK_FILES)
    odo = read_odometry(
        p_odo,
        steering_offset=opts.steering_offset,
        wheelbase=opts.wheelbase,
        encoder_offset=opts.encoder_offset,
    )
    gps = read_table(p_gps, 3)
    check_times(gps, p_gps, strict=True, unit="ms")
    det = _read_detections(p_det)
    # Odometry sample k holds over (t_k, t_{k+1}]; the run ends with the last one (or cut).
    t_odo = odo.values[:, 0] * _MS
    t0, t_last = float(t_odo[0]), float(t_odo[-1])
    cut = t_last if opts.max_duration_s is None else min(t_last, t0 + opts.max_duration_s)
    kept = _detections(det, p_det, opts.laser_offset, (t0, t_last), cut)
    starts, _ = time_groups(kept.t)
    group_t = kept.t[starts] if kept.t.size else kept.t
    ends, dts, u = odometry_controls(
        t_odo, odo.values[:, 1:3], group_t,
        steering_offset=opts.steering_offset, split=opts.split_at_readings,
    )  # fmt: skip
    n_ctrl = int(np.searchsorted(ends, cut, side="right"))
    ids = kept.tree if opts.identities else np.full(kept.tree.size, -1, dtype=np.int64)
    readings = reading_events(kept.t, kept.z, ids)
    truth_ids = tuple(ev.ids.copy() for ev in reading_events(kept.t, kept.z, kept.tree))
    t_gps = gps.values[:, 0] * _MS
    n_gps, sensor = int(np.searchsorted(t_gps, cut, side="right")), _tree_sensor(opts)
    fixes, gps_spec = _gps_stream(opts, t_gps[:n_gps], gps.values[:n_gps, 1:3])
    controls = control_events(ends[:n_ctrl], u[:n_ctrl], dts[:n_ctrl])
    events = assemble_events(controls, readings, fixes)
    return Dataset(
        name="victoria-park",
        events=events,
        motion=_motion(opts),
        landmark_sensor=replace(sensor, detection_range=measured_detection_range(events, sensor)),
        initial_pose=np.zeros(3),
        initial_cov=np.zeros((3, 3)),
        gps=gps_spec,
        truth=GroundTruth(
            position_times=t_gps[:n_gps],
            positions=gps.values[:n_gps, 1:3].copy(),
            reading_ids=truth_ids,
        ),
        description=_DESCRIPTION,
        provenance=Provenance(options=config_to_dict(opts)),
        metadata=_metadata(
            opts, len(odo), t_odo, n_ctrl, len(det), kept, len(readings), n_gps, cut
        ),
    )


def _motion(opts: VictoriaParkOptions) -> MotionSpec:
    return ackermann_motion(
        wheelbase=opts.wheelbase,
        encoder_offset=opts.encoder_offset,
        sigma_speed=opts.sigma_speed,
        sigma_steering=opts.sigma_steering,
    )


def _gps_stream(
    opts: VictoriaParkOptions, t: FloatArray, xy: FloatArray
) -> tuple[list[GpsFix], GpsSpec | None]:
    """The fixes as stream events when ``gps_fuse`` (without every ``gps_holdout_every``-th,
    the held-out ones), and their noise. Why the loader and not the estimator reads them:
    an estimator sees only the stream, in time order, as a robot would; ``truth`` is for
    scoring, and the held-out fixes never reach the estimator."""
    if not opts.gps_fuse:
        return [], None
    fused = ~holdout_mask(t.shape[0], opts.gps_holdout_every)
    fixes = [GpsFix(float(ti), p.copy()) for ti, p in zip(t[fused], xy[fused], strict=True)]
    return fixes, GpsSpec(np.eye(2) * opts.gps_sigma**2)


def _detections(
    det: NumericTable,
    path: Path,
    laser_offset: tuple[float, float],
    span: tuple[float, float],
    cut: float,
) -> _Detections:
    """Detections of poor features (index ``-1``) and outside the odometry's ``span`` are
    dropped and counted, those after ``cut`` left out; the rest moved to the rear axle."""
    d = det.values
    poor = d[:, 5] < 0
    t_det = d[:, 0] * _MS
    outside = ~poor & ((t_det < span[0]) | (t_det > span[1]))
    keep = ~poor & ~outside & (t_det <= cut)
    return _Detections(
        t=t_det[keep],
        z=laser_to_vehicle(d[keep, 1], d[keep, 2], laser_offset),
        tree=integer_values(d[keep, 5], det.line_numbers[keep], "feature index", path),
        poor=int(poor.sum()),
        outside=int(outside.sum()),
    )


def _tree_sensor(opts: VictoriaParkOptions) -> LandmarkSensorSpec:
    """The laser's tree detector seen from the rear axle (its detection range is measured
    from the readings by the caller: the laser reaches 80 m but seldom detects a trunk
    beyond ~40 m — 38 m from the laser on the whole run)."""
    a_off, b_off = opts.laser_offset
    return LandmarkSensorSpec(
        kind="range-bearing",
        noise_cov=np.diag([opts.sigma_range**2, opts.sigma_bearing**2]),
        max_range=LASER_MAX_RANGE + float(np.hypot(a_off, b_off)),
        fov=np.pi,
        identities=opts.identities,
        offset=(a_off, b_off),
    )


def _metadata(
    opts: VictoriaParkOptions,
    n_odo: int,
    t_odo: FloatArray,
    n_ctrl: int,
    n_det: int,
    kept: _Detections,
    n_events: int,
    n_gps: int,
    cut: float,
) -> dict[str, Any]:
    rows_used = int(np.searchsorted(t_odo[1:], cut, side="right"))
    a_off, b_off = opts.laser_offset
    return {
        "kind": "real",
        "source": "Victoria Park, ACFR (Guivant & Nebot 2001); detections cleaned by SLSJF",
        "files": list(VICTORIA_PARK_FILES),
        "time_origin": "the files' clock: t = time_ms / 1000",
        "odometry_samples": n_odo,
        "odometry_samples_used": rows_used,
        "controls": n_ctrl,
        "controls_added_by_splitting": n_ctrl - rows_used,
        "detections_in_file": n_det,
        "detections_kept": int(kept.t.size),
        "reading_events": n_events,
        "trees": int(np.unique(kept.tree).size),
        "dropped": {"poor_feature": kept.poor, "outside_odometry": kept.outside},
        "gps_fixes": n_gps,
        "vehicle": {
            "wheelbase": opts.wheelbase,
            "encoder_offset": opts.encoder_offset,
            "laser_offset": [a_off, b_off],
            "state": "rear-axle centre",
        },
        "cut_at_s": None if opts.max_duration_s is None else cut,
        "options": config_to_dict(opts),
    }
