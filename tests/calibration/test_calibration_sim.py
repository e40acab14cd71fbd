"""Calibration on simulated runs with injected errors: the rooms tour (six laps, a laser of
1 cm range noise mounted 5 cm ahead of the robot's centre but stated at the centre) with
odometry rebuilt under the stated error model (the corpus's typical random noise but a
third of its turn noise, chosen systematic errors). The issue's bar: a 2 % wheel-radius and
a 3 % wheel-base error each recovered to within 0.3 %, the 5 cm mounting to within 1 cm.

The turn noise is lowered because the wheel-base error is read from the turns: its standard
deviation is at least ``k_rot / √(Σ|turn|)`` (0.20 % for the typical 0.03 rad/√rad over this
tour's 221 rad, 0.07 % at 0.01; the fit states 0.22 % and 0.10 %;
``docs/estimators/calibration.md``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from slamkit.calibration import (
    CalibrationSettings,
    apply_calibration,
    calibrate,
    calibrate_pairs,
    scan_pairs,
)
from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset, Odometry
from slamkit.errors import InputError
from slamkit.sim import OdometryErrorModel, corrupt_odometry, remount_laser

MOUNTING = (0.05, 0.0, 0.0)
ERRORS = OdometryErrorModel(k_rot=0.01).without_glitches()


@pytest.fixture(scope="module")
def remounted() -> Dataset:
    data = load_dataset("rooms-laser", seed=1, options={"laps": 6, "sigma_range": 0.01})
    return remount_laser(data, MOUNTING, np.random.default_rng(11))


def _corrupted(data: Dataset, radius: float, base: float, seed: int) -> Dataset:
    model = replace(ERRORS, wheel_radius_error=radius, wheel_base_error=base)
    out, record = corrupt_odometry(data, model, np.random.default_rng(seed))
    assert (record.wheel_radius_error, record.wheel_base_error) == (radius, base)
    return out


@pytest.mark.parametrize(("radius", "base"), [(0.02, 0.0), (0.0, 0.03), (0.02, 0.03)])
def test_injected_wheel_errors_and_mounting_are_recovered(
    remounted: Dataset, radius: float, base: float
) -> None:
    result = calibrate(_corrupted(remounted, radius, base, seed=21))
    er, ser, eb, seb = result.systematic.wheel_errors()
    assert abs(er - radius) < 0.003
    assert abs(eb - base) < 0.003
    # The stated uncertainty is honest: the error within 3σ, σ below the 0.3 % bar.
    assert abs(er - radius) < 3 * ser and ser < 0.003
    assert abs(eb - base) < 3 * seb and seb < 0.003
    mx, my, myaw = result.systematic.mounting
    assert np.hypot(mx - MOUNTING[0], my - MOUNTING[1]) < 0.01
    assert abs(myaw) < np.radians(0.5)
    assert result.nominal_mounting == (0.0, 0.0, 0.0)


def test_learned_noise_matches_the_injected_model(remounted: Dataset) -> None:
    # Equal radius and base errors leave the turns unscaled (s = 1): any other pair meets
    # corrupt_odometry's fault at steps back (tests/sim/test_odometry_errors_backward.py),
    # whose heading jumps lift k_rot.
    truth = ERRORS
    result = calibrate(_corrupted(remounted, 0.02, 0.02, seed=22))
    fit = result.noise["per_distance"]
    k_trans, k_rot, _ = fit.values
    assert k_trans == pytest.approx(truth.k_trans, rel=0.1)
    assert k_rot == pytest.approx(truth.k_rot, rel=0.1)
    assert fit.chi2_per_dof == pytest.approx(1.0, abs=0.3)
    # The per-step model is what a MotionSpec holds: fed back by apply_calibration.
    sr, st = result.noise["per_step"].values
    fed = apply_calibration(_corrupted(remounted, 0.02, 0.02, seed=22), result)
    assert fed.motion is not None
    np.testing.assert_allclose(np.diag(fed.motion.noise_cov), [sr**2, st**2, sr**2])
    assert fed.laser is not None and fed.laser.mounting == pytest.approx(result.systematic.mounting)


def test_applied_scales_give_the_true_path_length(remounted: Dataset) -> None:
    data = _corrupted(remounted, 0.02, 0.03, seed=23)
    result = calibrate(data)
    fixed = apply_calibration(data, result)

    def length(d: Dataset) -> float:
        poses = np.array([ev.pose for ev in d.events if isinstance(ev, Odometry)])
        return float(np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T)))

    assert data.truth.poses is not None
    true_length = float(np.sum(np.hypot(*np.diff(data.truth.poses[:, :2], axis=0).T)))
    assert length(data) / true_length == pytest.approx(1.02, abs=0.003)
    assert length(fixed) / true_length == pytest.approx(1.0, abs=0.003)


def test_mounting_held_when_asked(remounted: Dataset) -> None:
    data = _corrupted(remounted, 0.02, 0.0, seed=24)
    pairs = scan_pairs(data)
    assert data.motion is not None
    held = calibrate_pairs(pairs, data.motion.noise_cov, CalibrationSettings(fit_mounting=False))
    assert held.systematic.mounting == (0.0, 0.0, 0.0)
    assert np.all(held.systematic.cov[2:] == 0.0)
    assert held.systematic.fit_mounting is False


def test_a_run_without_wheel_odometry_is_refused() -> None:
    with pytest.raises(InputError, match="no wheel odometry"):
        calibrate(load_dataset("rooms-laser", seed=0))  # controls, not odometry
    with pytest.raises(InputError, match="no laser scans"):
        calibrate(load_dataset("five-features", seed=0))
