"""One definiteness check for every Gaussian filter (slamkit.estimation.gaussian.check_covariance):
its tolerance, its fast path, and the same ConvergenceError from EKF, KF and UKF localization
and EKF-SLAM when a covariance is made indefinite in the middle of a run."""

from __future__ import annotations

import re

import numpy as np
import pytest

from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset
from slamkit.errors import ConvergenceError
from slamkit.estimation.gaussian import (
    DEFINITENESS_TOLERANCE,
    check_covariance,
    check_covariance_entries,
    check_state_covariance,
)
from slamkit.estimation.kalman import Gaussian, KalmanFilter
from slamkit.localization import GaussianBelief
from slamkit.localization.ekf import EkfConfig, EkfLocalization
from slamkit.localization.ukf import SigmaPointParams, UkfConfig, UkfLocalization, ukf_update
from slamkit.models import RangeOnly
from slamkit.slam.ekf_slam import EkfSlam, EkfSlamConfig

LOST = (
    r"the covariance lost positive definiteness \(smallest eigenvalue -[0-9.e+-]+, "
    r"largest \|eigenvalue\| [0-9.e+-]+\)"
)
"""The one message form (after the ``where:`` prefix)."""

CORRUPT_AT = 30
"""The prediction (counting from 1) after which a test filter's covariance is corrupted."""


def indefinite(P: np.ndarray) -> np.ndarray:
    """``P`` with its largest eigenvalue λ replaced by −9λ: far beyond any rounding."""
    w, V = np.linalg.eigh(P)
    v = V[:, -1]
    return P - 10.0 * w[-1] * np.outer(v, v)


def test_the_tolerance_separates_rounding_from_lost_definiteness() -> None:
    rng = np.random.default_rng(0)
    Q, _ = np.linalg.qr(rng.normal(size=(5, 5)))
    for smallest, lost in ((-1e-17, False), (-1e-12, False), (-1e-8, True), (-0.5, True)):
        P = Q @ np.diag([smallest, 0.1, 0.3, 0.7, 1.0]) @ Q.T
        P = 0.5 * (P + P.T)
        if lost:
            with pytest.raises(ConvergenceError, match="^here: " + LOST):
                check_covariance(P, "here")
        else:
            check_covariance(P, "here")  # rounding: a PSD matrix to 1e-9 of its largest
    assert DEFINITENESS_TOLERANCE == 1e-9
    check_covariance(np.zeros((3, 3)), "known pose")  # singular PSD: fine
    with pytest.raises(ConvergenceError, match="became non-finite"):
        check_covariance(np.full((3, 3), np.nan), "nan")
    with pytest.raises(ConvergenceError, match="the information matrix lost"):
        check_covariance(-np.eye(3), "seif", "information matrix")


def test_the_3x3_fast_path_agrees_with_the_eigenvalues() -> None:
    rng = np.random.default_rng(1)
    for _ in range(2000):
        A = rng.normal(size=(3, 3))
        P = A @ A.T + np.diag(rng.uniform(-1.0, 0.5, 3))
        P = 0.5 * (P + P.T)
        eig = np.linalg.eigvalsh(P)
        lost = eig[0] < -DEFINITENESS_TOLERANCE * np.abs(eig).max()
        if lost:
            with pytest.raises(ConvergenceError):
                check_covariance(P, "p")
        else:
            check_covariance(P, "p")


def test_stacks_and_state_blocks() -> None:
    blocks = np.stack([np.eye(2), np.diag([1.0, 2.0]), np.array([[1.0, 2.0], [2.0, 1.0]])])
    with pytest.raises(ConvergenceError, match="smallest eigenvalue -1, "):
        check_covariance(blocks, "ekf-mapping update")
    check_covariance(blocks[:2], "ekf-mapping update")
    # a pose-map state: the pose block every step, the whole matrix every `full_every`
    P = np.eye(7)
    P[3, 5] = P[5, 3] = 3.0  # an indefinite landmark part, healthy pose block
    check_state_covariance(P, "ekf-slam", step=7, full_every=5)
    check_state_covariance(P, "ekf-slam", step=7, full_every=None)
    with pytest.raises(ConvergenceError, match="^ekf-slam: " + LOST):
        check_state_covariance(P, "ekf-slam", step=10, full_every=5)


class CorruptedEkf(EkfLocalization):
    """EKF localization whose covariance turns indefinite before its CORRUPT_AT-th
    prediction."""

    predictions = 0

    def _predict(self, u: np.ndarray, dt: float) -> None:
        self.predictions += 1
        if self.predictions == CORRUPT_AT:
            assert self._cov is not None
            self._cov = indefinite(self._cov)
        super()._predict(u, dt)


class CorruptedUkf(UkfLocalization):
    predictions = 0

    def _predict(self, u: np.ndarray, dt: float) -> None:
        self.predictions += 1
        if self.predictions == CORRUPT_AT:
            assert self._cov is not None
            self._cov = indefinite(self._cov)
        super()._predict(u, dt)


class CorruptedSlam(EkfSlam):
    predictions = 0

    def _predict(self, u: np.ndarray, dt: float) -> None:
        super()._predict(u, dt)
        self.predictions += 1
        if self.predictions == CORRUPT_AT:
            cov = self._state.views()[1]
            cov[:3, :3] = indefinite(cov[:3, :3])


def drive(estimator: EkfLocalization | UkfLocalization | EkfSlam, data: Dataset) -> str:
    """Feed the events until the estimator raises; the message."""
    with pytest.raises(ConvergenceError) as info:
        for event in data.events:
            estimator.handle(event)
    return str(info.value)


@pytest.mark.parametrize(
    ("make", "where"),
    [
        (lambda d: CorruptedEkf(d, EkfConfig(), np.random.default_rng(0)), "ekf_predict"),
        (lambda d: CorruptedUkf(d, UkfConfig(), np.random.default_rng(0)), "ukf_predict"),
        (lambda d: CorruptedSlam(d, EkfSlamConfig(), np.random.default_rng(0)), "ekf-slam"),
    ],
    ids=["ekf-localization", "ukf-localization", "ekf-slam"],
)
def test_every_filter_raises_the_same_error_for_an_indefinite_covariance(make, where) -> None:
    data = load_dataset("five-features", seed=0)
    estimator = make(data)
    message = drive(estimator, data)
    assert estimator.predictions == CORRUPT_AT  # caught at the step it happened
    assert re.search(rf"^step \d+: [^:]+ at t = [0-9.]+ s: {where}: {LOST}$", message), message


def test_the_kalman_filter_raises_the_same_error() -> None:
    class Corrupted(KalmanFilter):
        def predict(self, u: np.ndarray | None = None) -> None:
            self._cov = indefinite(self._cov)
            super().predict(u)

    A = np.array([[1.0, 0.1], [0.0, 1.0]])
    kf = Corrupted(Gaussian([0.0, 1.0], np.eye(2)), A, 0.01 * np.eye(2), [[1.0, 0.0]], [[0.1]])
    with pytest.raises(ConvergenceError, match="^predict: " + LOST):
        kf.predict()


def test_the_ukf_update_message_is_the_shared_one() -> None:
    # κ = −2.5 makes the central weight −5: the UKF's P − K S Kᵀ turns indefinite.
    params = SigmaPointParams(alpha=1.0, beta=0.0, kappa=-2.5)
    b = GaussianBelief([0.0, 0.0, 0.2], np.diag([0.09, 0.09, 0.5]))
    landmark = np.array([1.0, 0.3])
    z = RangeOnly().predict([0.1, 0.0, 0.2], landmark)
    with pytest.raises(ConvergenceError, match="^ukf_update: " + LOST):
        ukf_update(b, z, landmark, RangeOnly(), [[1e-4]], params)


def test_the_entry_form_agrees_with_the_matrix_form() -> None:
    # FastSLAM's landmarks are struct-of-arrays entries (c00, c01, c11)
    rng = np.random.default_rng(3)
    for _ in range(500):
        A = rng.normal(size=(2, 2))
        P = A @ A.T + np.diag(rng.uniform(-1.0, 0.3, 2))
        P = 0.5 * (P + P.T)
        c00, c01, c11 = (np.full((4, 5), P[i, j]) for i, j in ((0, 0), (0, 1), (1, 1)))
        try:
            check_covariance(P, "matrix")
        except ConvergenceError as exc:
            with pytest.raises(ConvergenceError, match="^entries: " + LOST) as info:
                check_covariance_entries(c00, c01, c11, "entries")
            # the same smallest eigenvalue in both messages
            assert str(info.value).split("(")[1] == str(exc).split("(")[1]
        else:
            check_covariance_entries(c00, c01, c11, "entries")
    # rounding-sized negative eigenvalues pass, like the matrix form
    check_covariance_entries(np.array([1.0]), np.array([1.0 + 1e-15]), np.array([1.0]), "r")
    with pytest.raises(ConvergenceError, match="became non-finite"):
        check_covariance_entries(np.array([np.nan]), np.zeros(1), np.ones(1), "nan")
