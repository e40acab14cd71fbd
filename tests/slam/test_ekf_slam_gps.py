"""GPS fixes fused into EKF-SLAM (:mod:`slamkit.slam.ekf_slam.gps`): the antenna measurement's
Jacobian, the update against a dense textbook EKF, the move into the GPS frame, a simulated
drive with a known lever arm and multipath outliers, and Victoria Park (real data)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import Dataset, GpsFix, load_dataset
from slamkit.errors import ConfigError, InputError
from slamkit.eval.gps_holdout import holdout_gps_error
from slamkit.geometry.alignment import align_points_2d
from slamkit.pipeline import run
from slamkit.sim.gps import landmark_loop_with_gps
from slamkit.sim.scenarios import build_landmark_loop
from slamkit.slam.ekf_slam import EkfSlamConfig
from slamkit.slam.ekf_slam.gps import (
    antenna_measurement,
    gps_update_inplace,
    gps_warnings,
    move_state_inplace,
)

LEVER = np.array([1.5, -0.4])  # the true antenna position in the robot frame [m]
SIGMA = 0.5  # GPS noise per axis [m]
N_OUT = 8  # multipath: fixes moved 15-30 m
GPS_ANGLE, GPS_SHIFT = 0.7, np.array([120.0, -45.0])  # the GPS frame from the world's


def _antenna(poses: np.ndarray, lever: np.ndarray) -> np.ndarray:
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return poses[:, :2] + np.stack([c * lever[0] - s * lever[1], s * lever[0] + c * lever[1]], 1)


def _to_gps(xy: np.ndarray) -> np.ndarray:
    c, s = np.cos(GPS_ANGLE), np.sin(GPS_ANGLE)
    return xy @ np.array([[c, -s], [s, c]]).T + GPS_SHIFT


def test_antenna_jacobian_matches_finite_differences(rng: np.random.Generator) -> None:
    """∂(t + R(θ) o)/∂(x, y, θ) against central differences at random poses and arms."""
    for _ in range(20):
        pose = np.array([*rng.normal(0, 10, 2), rng.uniform(-np.pi, np.pi)])
        lever = rng.normal(0.0, 3.0, 2)
        h, H = antenna_measurement(pose, lever)
        np.testing.assert_allclose(h, _antenna(pose[None], lever)[0], atol=1e-12)
        eps = 1e-6
        num = np.empty((2, 3))
        for k in range(3):
            d = np.zeros(3)
            d[k] = eps
            num[:, k] = (antenna_measurement(pose + d, lever)[0]
                         - antenna_measurement(pose - d, lever)[0]) / (2 * eps)  # fmt: skip
        np.testing.assert_allclose(H, num, atol=1e-8)


def test_update_matches_a_dense_joseph_update(
    slam_gaussian: Callable[[int], tuple[np.ndarray, np.ndarray]],
) -> None:
    """The in-place update (three rows of Σ) equals the textbook EKF with the full ``H`` —
    the pose block, zeros for the map — in the Joseph form, to 1e-10."""
    mean, cov = slam_gaussian(4)
    lever, R = np.array([2.0, 0.3]), np.diag([0.5, 0.8])
    z = _antenna(mean[None, :3], lever)[0] + np.array([0.4, -0.3])
    h, Hr = antenna_measurement(mean[:3], lever)
    H = np.zeros((2, mean.size))
    H[:, :3] = Hr
    S = H @ cov @ H.T + R
    K = cov @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(mean.size) - K @ H
    want_cov = I_KH @ cov @ I_KH.T + K @ R @ K.T
    want_mean = mean + K @ (z - h)
    m, c = mean.copy(), cov.copy()
    d2, used = gps_update_inplace(m, c, z, lever, R, 9.21, np.empty(mean.size))
    assert used
    assert d2 == pytest.approx(float((z - h) @ np.linalg.solve(S, z - h)), rel=1e-12)
    np.testing.assert_allclose(m, want_mean, atol=1e-10)
    np.testing.assert_allclose(c, want_cov, atol=1e-10)
    # A fix beyond the gate leaves the state as it was.
    m2, c2 = mean.copy(), cov.copy()
    d2, used = gps_update_inplace(m2, c2, z + 100.0, lever, R, 9.21, np.empty(mean.size))
    assert not used and d2 > 9.21
    np.testing.assert_array_equal(m2, mean)
    np.testing.assert_array_equal(c2, cov)


def test_move_state_keeps_the_geometry(
    slam_gaussian: Callable[[int], tuple[np.ndarray, np.ndarray]],
) -> None:
    """Moving the state into another frame keeps every robot-to-landmark vector in the robot
    frame and the covariance's eigenvalues; moving back restores it (1e-10)."""
    mean, cov = slam_gaussian(3)
    m, c = mean.copy(), cov.copy()
    move_state_inplace(m, c, 0.9, np.array([10.0, -3.0]))

    def local(x: np.ndarray) -> np.ndarray:
        d = x[3:].reshape(-1, 2) - x[:2]
        cth, sth = np.cos(x[2]), np.sin(x[2])
        return d @ np.array([[cth, -sth], [sth, cth]])

    np.testing.assert_allclose(local(m), local(mean), atol=1e-10)
    np.testing.assert_allclose(np.linalg.eigvalsh(c), np.linalg.eigvalsh(cov), atol=1e-10)
    c9, s9 = np.cos(-0.9), np.sin(-0.9)
    back = -np.array([[c9, -s9], [s9, c9]]) @ np.array([10.0, -3.0])
    move_state_inplace(m, c, -0.9, back)
    np.testing.assert_allclose(m, mean, atol=1e-10)
    np.testing.assert_allclose(c, cov, atol=1e-10)


def _drive_with_gps(seed: int) -> Dataset:
    """The landmark loop (two laps, short range, noisy turn rate: EKF-SLAM alone drifts)
    with a fix every fifth step of the antenna at ``LEVER``, in a GPS frame turned and
    shifted from the world's, σ = ``SIGMA``, and ``N_OUT`` fixes moved 15-30 m
    (:func:`~slamkit.sim.gps.landmark_loop_with_gps`)."""
    return landmark_loop_with_gps(seed).dataset


@pytest.mark.parametrize("seed", [1, 2])
def test_fusion_ends_closer_to_the_truth_and_gates_the_outliers(seed: int) -> None:
    """With the fixes fused, the path's RMS error in the GPS frame (against the truth moved
    there, no alignment; measured 0.30 and 0.33 m) is below 0.5 m, and the unfused path's
    after its best SE(2) alignment to the truth above 1.5 m (2.19, 3.82 m); the final
    position's error is smaller too (0.33 against 1.54 m, 0.10 against 4.27 m). At least
    ``N_OUT`` fixes are refused (the outliers, 30-60 σ off) and at most 3 % of the rest
    (gate: the 99 % quantile; measured 15 and 13 refused of ~420)."""
    ds = _drive_with_gps(seed)
    assert ds.truth.times is not None and ds.truth.poses is not None
    cfg = EkfSlamConfig(gps_lever_arm=(float(LEVER[0]), float(LEVER[1])))
    fused = run("ekf-slam", ds, config=cfg, seed=seed)
    plain = run("ekf-slam", replace(ds, events=tuple(e for e in ds.events
                                                     if not isinstance(e, GpsFix)),
                                    gps=None), seed=seed)  # fmt: skip
    d = fused.output.diagnostics
    assert d["gps_fixes"] == d["gps_aligning"] + d["gps_fused"] + d["gps_refused"]
    assert d["gps_refused"] >= N_OUT
    assert d["gps_refused"] - N_OUT <= 0.03 * d["gps_fused"]
    assert "gps_fused" not in plain.output.diagnostics
    assert fused.output.warnings == ()

    def truth_at(times: np.ndarray) -> np.ndarray:
        k = np.searchsorted(ds.truth.times, times).clip(0, ds.truth.times.size - 1)  # type: ignore[arg-type]
        return ds.truth.poses[k, :2]  # type: ignore[index]

    true_gps = _to_gps(truth_at(fused.times))
    err_fused = np.linalg.norm(fused.poses[:, :2] - true_gps, axis=1)
    true_w = truth_at(plain.times)
    sim = align_points_2d(plain.poses[:, :2], true_w)
    err_plain = np.linalg.norm(sim.apply_to_points(plain.poses[:, :2]) - true_w, axis=1)
    rmse_fused = float(np.sqrt(np.mean(err_fused**2)))
    rmse_plain = float(np.sqrt(np.mean(err_plain**2)))
    assert rmse_fused < 0.5 < 1.5 < rmse_plain
    assert err_fused[-1] < err_plain[-1]


def test_warnings_name_a_filter_that_refuses_most_fixes() -> None:
    def counts(fixes: int, aligning: int, fused: int, refused: int) -> dict[str, int]:
        return dict(gps_fixes=fixes, gps_aligning=aligning, gps_fused=fused,
                    gps_refused=refused)  # fmt: skip

    assert gps_warnings(counts(0, 0, 0, 0)) == ()
    assert gps_warnings(counts(100, 20, 60, 20)) == ()
    assert [w.kind for w in gps_warnings(counts(100, 20, 30, 50))] == ["gps_refused"]
    assert "50 of 80" in gps_warnings(counts(100, 20, 30, 50))[0].message
    assert [w.kind for w in gps_warnings(counts(5, 5, 0, 0))] == ["gps_not_used"]


def test_settings_are_checked() -> None:
    with pytest.raises(ConfigError, match="gps_lever_arm"):
        EkfSlamConfig(gps_lever_arm=(1.0,))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="gps_gate_probability"):
        EkfSlamConfig(gps_gate_probability=1.0)
    ds = build_landmark_loop({}, seed=1)
    with pytest.raises(InputError, match="GpsSpec"):
        replace(ds, events=(*ds.events[:3], GpsFix(ds.events[2].t, np.zeros(2))))


def test_victoria_park_fused_scores_on_held_out_fixes(data_root: Path) -> None:
    """The first 200 s of Victoria Park with ``gps_fuse``: 9 of 10 fixes in the stream; EKF-
    SLAM with the graph's lever arm (3.98, 0.41) m scores on the held-out tenth, without
    alignment, below 1.6 m RMSE (measured 1.30 m), and refuses few fixes (measured 1). With
    the arm left at 0 the gate refuses most (measured 328 of 418) and the run says so."""
    opts = {"gps_fuse": True, "identities": True, "max_duration_s": 200.0}
    ds = load_dataset("victoria-park", options=opts, data_root=data_root)
    t, xy = ds.truth.position_times, ds.truth.positions
    assert t is not None and xy is not None
    held = np.arange(t.size) % 10 == 9
    assert ds.counts()["GpsFix"] == int((~held).sum())
    res = run("ekf-slam", ds, config=EkfSlamConfig(gps_lever_arm=(3.98, 0.41)))
    d = res.output.diagnostics
    assert d["gps_refused"] <= 5
    s = holdout_gps_error(res.times, res.poses, t, xy, held, (3.98, 0.41))
    assert s.direct_rmse < 1.6
    assert res.output.warnings == ()
    wrong = run("ekf-slam", ds).output
    assert wrong.diagnostics["gps_refused"] > 0.5 * (
        wrong.diagnostics["gps_refused"] + wrong.diagnostics["gps_fused"]
    )
    assert [w.kind for w in wrong.warnings] == ["gps_refused"]
    assert (
        "GpsFix"
        not in load_dataset(
            "victoria-park", options={"max_duration_s": 20.0}, data_root=data_root
        ).counts()
    )
