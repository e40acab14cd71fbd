"""The shared estimator shell: motion events to controls, the step numbering of errors,
and the recorders."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets.stream import Control, LandmarkReadings, LaserScan, Odometry
from slamkit.errors import ConvergenceError
from slamkit.estimation.contract import ParticleSnapshot, SpreadSnapshots
from slamkit.estimation.shell import (
    AssociationRecorder,
    EstimatorShell,
    InnovationRecorder,
    MotionInput,
)
from slamkit.models import OdometryModel, odometry_control


def test_motion_input_turns_odometry_into_the_odometry_models_control() -> None:
    src = MotionInput()
    a, b, c = np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.5, 0.3]), np.array([2.0, 0.2, -0.4])
    assert src.control(Odometry(0.0, a)) is None  # the first pose only starts the chain
    u, dt = src.control(Odometry(1.0, b))  # type: ignore[misc]
    assert dt == 0.0
    np.testing.assert_array_equal(u, odometry_control(a, b))
    # the control moves the previous pose onto the new one
    np.testing.assert_allclose(OdometryModel().apply(a, u, 0.0), b, atol=1e-12)
    u2, _ = src.control(Odometry(2.0, c))  # type: ignore[misc]
    np.testing.assert_allclose(OdometryModel().apply(b, u2, 0.0), c, atol=1e-12)
    v, dt = src.control(Control(3.0, np.array([0.4, 0.1]), 0.25))  # type: ignore[misc]
    np.testing.assert_array_equal(v, [0.4, 0.1])
    assert dt == 0.25
    assert src.control(LaserScan(4.0, np.ones(3))) is None


def test_recorders_collect_in_order() -> None:
    rec = InnovationRecorder()
    rec.add(1.0, 2.5, 2, 7)
    rec.add(1.5, 0.5, 1, 3)
    log = rec.log()
    assert log is not None and len(log) == 2
    np.testing.assert_array_equal(log.nis, [2.5, 0.5])
    np.testing.assert_array_equal(log.dof, [2, 1])
    np.testing.assert_array_equal(log.landmark_ids, [7, 3])
    off = InnovationRecorder(enabled=False)
    off.add(1.0, 2.0, 2, 1)
    assert off.log() is None and off.nis.size == 0
    chosen = AssociationRecorder()
    assert chosen.result().shape == (0,)
    chosen.add([1, -1])
    chosen.add(np.array([4]))
    np.testing.assert_array_equal(chosen.result(), [1, -1, 4])


class _Diverges(EstimatorShell):
    name = "test filter"

    def __init__(self, at: float) -> None:
        super().__init__()
        self.at = at
        self.controls = 0

    def on_control(self, u: np.ndarray, dt: float) -> None:
        self.controls += 1

    def on_landmarks(self, event: LandmarkReadings) -> None:
        if event.t >= self.at:
            raise ConvergenceError("the covariance became non-finite")


def test_errors_inside_a_hook_carry_the_runners_step() -> None:
    est = _Diverges(at=2.0)
    readings = LandmarkReadings(2.0, np.ones((1, 2)), np.array([0]))
    est.handle(Control(1.0, np.zeros(2), 0.1))  # step 1
    est.handle(Control(1.0, np.zeros(2), 0.1))  # same stamp: still step 1
    est.handle(Control(2.0, np.zeros(2), 0.1))  # step 2
    with pytest.raises(ConvergenceError, match=r"test filter at t = 2 s") as info:
        est.handle(readings)  # same stamp: step 2
    assert info.value.step == 2
    assert est.controls == 3


@pytest.mark.parametrize("updates", [3, 6, 50, 1000, 4097])
def test_spread_snapshots_are_even_and_bounded_without_knowing_the_length(updates: int) -> None:
    spread = SpreadSnapshots(6)
    held = 0
    for k in range(updates + 1):  # update 0: the start
        spread.offer(k, lambda k=k: ParticleSnapshot(float(k), np.zeros((1, 3)), np.ones(1)))
        held = max(held, spread.held)
    assert held <= 49
    final = ParticleSnapshot(updates + 0.5, np.zeros((1, 3)), np.ones(1))
    times = [s.t for s in spread.pick(final)]
    assert times[0] == 0.0 and times[-1] == updates + 0.5
    assert len(times) == min(6, updates + 2)
    if updates >= 50:  # evenly spread: every gap within a factor 1.5 of the even one
        gaps, even = np.diff(times), (updates + 0.5) / 5
        assert np.all((gaps > even / 1.5) & (gaps < even * 1.5)), gaps
