"""The estimators' fast path is a public contract: slamkit's models implement it, a model
written elsewhere that satisfies only the public protocol gets the same kernels (and the
same numbers) through :func:`slamkit.models.motion_kernels`, and an object that is not a
motion model is refused with the members it lacks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import slamkit.datasets as ds
from slamkit.datasets import MotionSpec
from slamkit.errors import InputError
from slamkit.estimation.gaussian import (
    measure_unchecked,
    motion_jacobians_unchecked,
    move_unchecked,
)
from slamkit.models import (
    LandmarkModelBase,
    MotionModelBase,
    RangeBearing,
    UnicycleArc,
    motion_kernels,
)
from slamkit.pipeline import run


class ProtocolOnlyMotion:
    """A user's motion model: the public MotionModel protocol, no slamkit base class."""

    def __init__(self, inner: MotionModelBase | None = None) -> None:
        self._inner = UnicycleArc() if inner is None else inner
        self.control_dim = self._inner.control_dim
        self.control_names = self._inner.control_names
        self.calls = 0

    def apply(self, x, u, dt):  # type: ignore[no-untyped-def]
        self.calls += 1
        return self._inner.apply(x, u, dt)

    def jacobians(self, x, u, dt):  # type: ignore[no-untyped-def]
        return self._inner.jacobians(x, u, dt)

    def sample(self, x, u, dt, control_cov, rng):  # type: ignore[no-untyped-def]
        return self._inner.sample(x, u, dt, control_cov, rng)


class ProtocolOnlyReadings:
    """A user's landmark model through the public LandmarkModel protocol only."""

    dim = 2
    angular = (False, True)

    def __init__(self) -> None:
        self._inner = RangeBearing()

    def predict(self, pose, landmark):  # type: ignore[no-untyped-def]
        return self._inner.predict(pose, landmark)

    def jacobians(self, pose, landmark):  # type: ignore[no-untyped-def]
        return self._inner.jacobians(pose, landmark)

    def residual(self, z, z_hat):  # type: ignore[no-untyped-def]
        return self._inner.residual(z, z_hat)

    def sample(self, pose, landmark, cov, rng):  # type: ignore[no-untyped-def]
        return self._inner.sample(pose, landmark, cov, rng)


def test_slamkit_models_are_their_own_kernels() -> None:
    model = UnicycleArc()
    assert motion_kernels(model) is model
    assert isinstance(model, MotionModelBase)
    assert isinstance(RangeBearing(), LandmarkModelBase)


def test_a_protocol_model_gets_the_same_kernels() -> None:
    rng = np.random.default_rng(4)
    ref, user = UnicycleArc(), motion_kernels(ProtocolOnlyMotion())
    x, u, dt = np.array([1.0, -2.0, 3.0]), np.array([0.7, 0.4]), 0.25
    for got, want in zip(user.step_single(x, u, dt), ref.step_single(x, u, dt), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    poses = rng.normal(size=(50, 3))
    controls = rng.normal(size=(50, 2))
    a, b = poses.copy(), poses.copy()
    user.move_particles(a, controls, dt)
    ref.move_particles(b, controls, dt)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        move_unchecked(ProtocolOnlyMotion(), poses, controls, dt),
        ref.apply(poses, controls, dt),
        atol=1e-12,
    )
    for got, want in zip(
        motion_jacobians_unchecked(ProtocolOnlyMotion(), x, u, dt),
        ref.jacobians(x, u, dt),
        strict=True,
    ):
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_a_protocol_landmark_model_gives_the_same_readings() -> None:
    pose, lm = np.array([0.5, 1.0, 2.9]), np.array([4.0, -3.0])
    for got, want in zip(
        measure_unchecked(ProtocolOnlyReadings(), pose, lm),
        measure_unchecked(RangeBearing(), pose, lm),
        strict=True,
    ):
        np.testing.assert_allclose(got, want, atol=1e-12)


@pytest.mark.parametrize("missing", ["apply", "jacobians", "sample"])
def test_an_incomplete_model_is_refused_by_name(missing: str) -> None:
    model = ProtocolOnlyMotion()
    cls = type("Incomplete", (), {k: v for k, v in vars(ProtocolOnlyMotion).items()})
    delattr(cls, missing)
    incomplete = cls.__new__(cls)
    incomplete.control_dim, incomplete.control_names = model.control_dim, model.control_names
    with pytest.raises(InputError, match=missing):
        motion_kernels(incomplete)
    with pytest.raises(InputError, match=missing):
        MotionSpec(incomplete, np.eye(2))  # type: ignore[arg-type]


def test_an_estimator_with_a_users_model_gives_the_same_run() -> None:
    data = ds.load_dataset("five-features", seed=2)
    assert data.motion is not None and isinstance(data.motion.model, MotionModelBase)
    user = ProtocolOnlyMotion(data.motion.model)
    mine = replace(data, motion=MotionSpec(user, data.motion.noise_cov, data.motion.source))
    for name in ("ekf-localization", "ekf-slam", "fastslam1", "mcl"):
        want = run(name, data, seed=1)
        got = run(name, mine, seed=1)
        np.testing.assert_allclose(got.poses, want.poses, rtol=0, atol=1e-9)
    assert user.calls > 0  # the user's model did the moving
