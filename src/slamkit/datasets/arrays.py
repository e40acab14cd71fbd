"""A :class:`~slamkit.datasets.stream.Dataset` from your own arrays.

:func:`ordered_events` puts events in the order every estimator expects: by time, and at one
time stamp the known pose first, then the motion (:class:`Control` over ``(t − dt, t]``, or
the :class:`Odometry` pose at ``t``), then the readings and scans taken at ``t`` — so a
reading at the stamp of a control is processed after the robot has moved. Events given in
any order come out in that one (stable within a kind).

:func:`landmark_dataset_from_arrays` builds a landmark data set from plain arrays: one row per
control (or odometry pose), one row per landmark reading (rows with the same time become one
:class:`LandmarkReadings` event), optional truth. Units: seconds, metres, radians.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from slamkit._validation import as_array
from slamkit.datasets.stream import (
    Control,
    Dataset,
    Event,
    GroundTruth,
    KnownPose,
    LandmarkReadings,
    LandmarkSensorSpec,
    LaserScan,
    MotionSpec,
    Odometry,
)
from slamkit.errors import InputError, ShapeError
from slamkit.maps import LandmarkMap
from slamkit.models import OdometryModel, UnicycleEuler

__all__ = ["EVENT_RANK", "landmark_dataset_from_arrays", "ordered_events"]

EVENT_RANK: dict[type, int] = {
    KnownPose: 0,
    Control: 1,
    Odometry: 1,
    LandmarkReadings: 2,
    LaserScan: 2,
}
"""The order of event kinds at one time stamp (lower first)."""


def ordered_events(events: Iterable[Event]) -> tuple[Event, ...]:
    """``events`` sorted by time and, at equal times, by :data:`EVENT_RANK` (stable)."""
    items = list(events)
    for ev in items:
        if type(ev) not in EVENT_RANK:
            raise InputError(f"ordered_events: unknown event type {type(ev).__name__}")
    keys = [(float(ev.t), EVENT_RANK[type(ev)]) for ev in items]
    order = sorted(range(len(items)), key=keys.__getitem__)
    return tuple(items[i] for i in order)


def _readings(times: ArrayLike, z: ArrayLike, ids: ArrayLike | None, dim: int) -> list[Event]:
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
    t, zz, idv = t[order], zz[order], idv[order]
    starts = np.flatnonzero(np.r_[True, np.diff(t) > 0])
    ends = np.r_[starts[1:], t.size]
    return [
        LandmarkReadings(float(t[a]), zz[a:b].copy(), idv[a:b].copy())
        for a, b in zip(starts, ends, strict=True)
    ]


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
    events: list[Event] = _readings(reading_times, readings, reading_ids, sensor.dim)
    if has_controls:
        if control_times is None or controls is None:
            raise InputError("controls: give control_times and controls together")
        t = as_array(control_times, "control times", (None,))
        u = as_array(controls, "controls", (t.size, 2))
        if control_dt is None:
            if t.size < 2:
                raise InputError("control_dt: needed when there is only one control")
            gaps = np.diff(t)
            dt = np.r_[gaps[0], gaps]
        else:
            dt = as_array(control_dt, "control dt", (t.size,))
        if np.any(dt <= 0):
            raise InputError("control dt: expected durations > 0 s")
        events += [Control(float(t[k]), u[k].copy(), float(dt[k])) for k in range(t.size)]
        motion = MotionSpec(UnicycleEuler(), as_array(motion_noise_cov, "motion noise", (2, 2)))
    else:
        if odometry_times is None or odometry_poses is None:
            raise InputError("odometry: give odometry_times and odometry_poses together")
        t = as_array(odometry_times, "odometry times", (None,))
        p = as_array(odometry_poses, "odometry poses", (t.size, 3))
        events += [Odometry(float(t[k]), p[k].copy()) for k in range(t.size)]
        cov = as_array(motion_noise_cov, "motion noise", (3, 3))
        motion = MotionSpec(OdometryModel(), cov, source="odometry")
    truth = GroundTruth(
        times=None if truth_times is None else as_array(truth_times, "truth times", (None,)),
        poses=None if truth_poses is None else as_array(truth_poses, "truth poses", (None, 3)),
        landmarks=true_landmarks,
    )
    return Dataset(
        name=name,
        events=ordered_events(events),
        motion=motion,
        landmark_sensor=sensor,
        initial_pose=None if initial_pose is None else as_array(initial_pose, "initial pose", (3,)),
        initial_cov=None if initial_cov is None else np.asarray(initial_cov, dtype=float),
        known_landmarks=known_landmarks,
        truth=truth,
        description=description,
        metadata=dict(metadata or {}),
    )
