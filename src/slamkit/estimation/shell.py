"""The shell every estimator shares: turning the stream's motion events into controls, the
runner's step numbering for errors raised inside an estimator, and the recorders of what an
estimator did with each reading (innovations, the landmark each reading was given).

An estimator built on :class:`EstimatorShell` implements the hooks it needs
(:meth:`~EstimatorShell.on_control`, :meth:`~EstimatorShell.on_landmarks`,
:meth:`~EstimatorShell.on_scan`) and inherits :meth:`~EstimatorShell.handle`, which

* counts the event on the :class:`~slamkit.estimation.contract.StepClock` — one step per
  distinct time stamp, the numbering of :func:`slamkit.pipeline.run`;
* turns :class:`~slamkit.datasets.Control` events into ``(u, dt)`` and consecutive
  :class:`~slamkit.datasets.Odometry` poses into the odometry model's
  ``(rot1, trans, rot2)`` with ``dt = 0`` (:class:`MotionInput`);
* calls :meth:`~EstimatorShell.after_event` (periodic checks of the state);
* re-raises a :class:`~slamkit.errors.ConvergenceError` from a hook with that step.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from slamkit._validation import FloatArray
from slamkit.datasets.stream import (
    Control,
    Event,
    GpsFix,
    KnownPose,
    LandmarkReadings,
    LaserScan,
    Odometry,
)
from slamkit.errors import ConvergenceError
from slamkit.estimation.contract import InnovationLog, StepClock
from slamkit.models import odometry_control

__all__ = ["AssociationRecorder", "EstimatorShell", "InnovationRecorder", "MotionInput"]


class MotionInput:
    """The controls ``(u, dt)`` a motion model is driven with, from the stream's events.

    :class:`Control` events give their ``(u, dt)``. :class:`Odometry` events give the
    odometry model's control between the previous odometry pose and this one, ``dt = 0``
    (the first pose only starts the chain). Other events give ``None``.
    """

    def __init__(self) -> None:
        self._last: FloatArray | None = None

    def control(self, event: Event) -> tuple[FloatArray, float] | None:
        if isinstance(event, Control):
            return event.u, event.dt
        if isinstance(event, Odometry):
            last, self._last = self._last, event.pose
            if last is not None:
                return odometry_control(last, event.pose), 0.0
        return None


class InnovationRecorder:
    """Collects an :class:`InnovationLog`, one measurement update at a time (``enabled =
    False``: records nothing and :meth:`log` is ``None``)."""

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        self._t: list[float] = []
        self._nis: list[float] = []
        self._dof: list[int] = []
        self._ids: list[int] = []

    def add(self, t: float, nis: float, dof: int, landmark_id: int) -> None:
        """One update at time ``t``: its NIS ``νᵀ S⁻¹ ν`` with ``dof`` components, of the
        landmark ``landmark_id``."""
        if self.enabled:
            self._t.append(float(t))
            self._nis.append(float(nis))
            self._dof.append(int(dof))
            self._ids.append(int(landmark_id))

    @property
    def nis(self) -> FloatArray:
        """The NIS values recorded so far ``(K,)``."""
        return np.asarray(self._nis, dtype=float)

    def log(self) -> InnovationLog | None:
        if not self.enabled:
            return None
        return InnovationLog(
            times=np.asarray(self._t, dtype=float),
            nis=self.nis,
            dof=np.asarray(self._dof, dtype=np.int64),
            landmark_ids=np.asarray(self._ids, dtype=np.int64),
        )


class AssociationRecorder:
    """The landmark every reading was given (``-1``: not used), one readings event at a
    time, in stream order: :attr:`EstimatorOutput.reading_landmarks`."""

    def __init__(self) -> None:
        self._chosen: list[NDArray[np.int64]] = []

    def add(self, landmark_ids: NDArray[np.integer] | list[int]) -> None:
        """The landmarks of the readings of one event, in the event's order."""
        self._chosen.append(np.asarray(landmark_ids, dtype=np.int64).reshape(-1))

    def result(self) -> NDArray[np.int64]:
        return np.concatenate([np.zeros(0, np.int64), *self._chosen])


class EstimatorShell:
    """The event handling an estimator shares (see the module docstring). ``name`` prefixes
    the errors the hooks raise ("EKF-SLAM at t = 12.3 s: ...")."""

    name: ClassVar[str] = "estimator"

    def __init__(self) -> None:
        self.clock = StepClock()
        self.motion_input = MotionInput()

    def handle(self, event: Event) -> None:
        step = self.clock.tick(event.t)
        try:
            control = self.motion_input.control(event)
            if control is not None:
                self.on_control(*control)
            elif isinstance(event, KnownPose):
                self.on_known_pose(event)
            elif isinstance(event, LandmarkReadings):
                self.on_landmarks(event)
            elif isinstance(event, LaserScan):
                self.on_scan(event)
            elif isinstance(event, GpsFix):
                self.on_gps(event)
            self.after_event(step)
        except ConvergenceError as exc:
            stamped = self.clock.stamped(exc, self.name, event.t)
            if stamped is exc:
                raise
            raise stamped from exc

    def on_control(self, u: FloatArray, dt: float) -> None:
        """A motion step with control ``u`` over ``dt`` seconds. Default: ignored."""

    def on_known_pose(self, event: KnownPose) -> None:
        """The robot's pose, given (mapping with known poses). Default: ignored."""

    def on_landmarks(self, event: LandmarkReadings) -> None:
        """A set of landmark readings. Default: ignored."""

    def on_scan(self, event: LaserScan) -> None:
        """A laser scan. Default: ignored."""

    def on_gps(self, event: GpsFix) -> None:
        """A GPS fix (only in a stream whose loader was asked to fuse GPS). Default:
        ignored."""

    def after_event(self, step: int) -> None:
        """After every event (``step``: the runner's step it belongs to), inside the step
        numbering: periodic checks of the state. Default: nothing."""
