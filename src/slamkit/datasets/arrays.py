"""A :class:`~slamkit.datasets.stream.Dataset` from your own arrays.

:func:`landmark_dataset_from_arrays` builds a landmark data set from plain arrays: one row per
control (or odometry pose), one row per landmark reading (rows with the same time become one
:class:`LandmarkReadings` event), optional truth. Units: seconds, metres, radians.
The events are merged by the loader kit's :func:`~slamkit.datasets.assemble.assemble_events`
(by time; at one stamp the motion before the readings).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import as_array
from slamkit.datasets.assemble import (
    assemble_events,
    control_events,
    odometry_events,
    reading_events,
)
from slamkit.datasets.stream import (
    Control,
    Dataset,
    GroundTruth,
    LandmarkReadings,
    LandmarkSensorSpec,
    MotionSpec,
    Odometry,
)
from slamkit.errors import InputError, ShapeError
from slamkit.maps import LandmarkMap
from slamkit.models import OdometryModel, UnicycleEuler

__all__ = ["landmark_dataset_from_arrays"]


def _readings(
    times: ArrayLike, z: ArrayLike, ids: ArrayLike | None, dim: int
) -> list[LandmarkReadings]:
    t = as_array(times, "reading times", (None,))
    zz = np.asarray(z, dtype=float)
    if zz.ndim == 1 and dim == 1:
        zz = zz[:, None]
    zz = as_array(zz, "readings", (t.size, dim))
    if ids is None:
        idv = np.full(t.size, -1, dtype=np.int64)
    else:
        raw = np.asarray(ids)
        if raw.shape != (t.size,) or not np.issubdtype(raw.dtype, np.integer):
            raise ShapeError(
                f"reading ids: expected {t.size} integers, got {raw.shape} {raw.dtype}"
            )
        idv = raw.astype(np.int64)
    order = np.argsort(t, kind="stable")
    return reading_events(t[order], zz[order], idv[order])


def landmark_dataset_from_arrays(
    *,
    sensor: LandmarkSensorSpec,
    reading_times: ArrayLike,
    readings: ArrayLike,
    reading_ids: ArrayLike | None = None,
    control_times: ArrayLike | None = None,
    controls: ArrayLike | None = None,
    control_dt: ArrayLike | None = None,
    odometry_times: ArrayLike | None = None,
    odometry_poses: ArrayLike | None = None,
    motion_noise_cov: ArrayLike,
    initial_pose: ArrayLike | None = None,
    initial_cov: ArrayLike | None = None,
    truth_times: ArrayLike | None = None,
    truth_poses: ArrayLike | None = None,
    true_landmarks: LandmarkMap | None = None,
    known_landmarks: LandmarkMap | None = None,
    name: str = "my-data",
    description: str = "",
    metadata: dict[str, Any] | None = None,
) -> Dataset:
    """A landmark data set from arrays (see the module docstring).

    Motion is either ``controls (N, 2)`` = ``(v [m/s], ω [rad/s])`` of the unicycle model at
    ``control_times (N,)``, each applied over ``(t − dt, t]`` (``control_dt (N,)``; default:
    the gap to the previous control, the first one's equal to the second's), with
    ``motion_noise_cov (2, 2)``; or ``odometry_poses (N, 3)`` at ``odometry_times``, with
    ``motion_noise_cov (3, 3)`` of the odometry model's ``(rot1, trans, rot2)``.
    ``readings (K, m)`` at ``reading_times (K,)`` (``m`` = ``sensor.dim``), ``reading_ids
    (K,)`` or ``None`` for unknown (``-1``). The truth (``truth_times``/``truth_poses``,
    ``true_landmarks``) is for evaluation only; ``known_landmarks`` is the map a
    localization estimator may use."""
    has_controls = controls is not None or control_times is not None
    has_odometry = odometry_poses is not None or odometry_times is not None
    if has_controls == has_odometry:
        raise InputError("give the motion as controls or as odometry poses (one of the two)")
    readings_ = _readings(reading_times, readings, reading_ids, sensor.dim)
    moves: list[Control] | list[Odometry]
    if has_controls:
        motion, moves = _control_stream(control_times, controls, control_dt, motion_noise_cov)
    else:
        motion, moves = _odometry_stream(odometry_times, odometry_poses, motion_noise_cov)
    truth = GroundTruth(
        times=None if truth_times is None else as_array(truth_times, "truth times", (None,)),
        poses=None if truth_poses is None else as_array(truth_poses, "truth poses", (None, 3)),
        landmarks=true_landmarks,
    )
    return Dataset(
        name=name,
        events=assemble_events(moves, readings_),
        motion=motion,
        landmark_sensor=sensor,
        initial_pose=None if initial_pose is None else as_array(initial_pose, "initial pose", (3,)),
        initial_cov=None if initial_cov is None else np.asarray(initial_cov, dtype=float),
        known_landmarks=known_landmarks,
        truth=truth,
        description=description,
        metadata=dict(metadata or {}),
    )


def _control_stream(
    times: ArrayLike | None, u: ArrayLike | None, dt: ArrayLike | None, cov: ArrayLike
) -> tuple[MotionSpec, list[Control]]:
    if times is None or u is None:
        raise InputError("controls: give control_times and controls together")
    t = as_array(times, "control times", (None,))
    uu = as_array(u, "controls", (t.size, 2))
    if dt is None:
        if t.size < 2:
            raise InputError("control_dt: needed when there is only one control")
        gaps = np.diff(t)
        dts = np.r_[gaps[0], gaps]
    else:
        dts = as_array(dt, "control dt", (t.size,))
    if np.any(dts <= 0):
        raise InputError("control dt: expected durations > 0 s")
    motion = MotionSpec(UnicycleEuler(), as_array(cov, "motion noise", (2, 2)))
    return motion, control_events(t, uu, dts)


def _odometry_stream(
    times: ArrayLike | None, poses: ArrayLike | None, cov: ArrayLike
) -> tuple[MotionSpec, list[Odometry]]:
    if times is None or poses is None:
        raise InputError("odometry: give odometry_times and odometry_poses together")
    t = as_array(times, "odometry times", (None,))
    p = as_array(poses, "odometry poses", (t.size, 3))
    motion = MotionSpec(OdometryModel(), as_array(cov, "motion noise", (3, 3)), source="odometry")
    return motion, odometry_events(t, p)
