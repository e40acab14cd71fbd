"""UKF-SLAM: the kernels against dense unscented references, the estimator on the seeded
five-feature world (known ids, unknown association), consistency over seeds, and EKF-SLAM's
answer recovered as the noise shrinks."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from slamkit.datasets import Dataset, LandmarkReadings, load_dataset
from slamkit.errors import ConfigError
from slamkit.estimation.belief import GaussianBelief
from slamkit.estimation.gaussian import motion_jacobians_unchecked
from slamkit.eval import chi2_bounds, landmark_map_error, nees, pose_errors
from slamkit.geometry import circular_mean
from slamkit.localization.ukf import (
    SigmaPointParams,
    circular_mean_about,
    sigma_point_weights,
    ukf_predict,
    unscented_motion_unchecked,
)
from slamkit.models import RangeBearing, UnicycleEuler
from slamkit.slam import EkfSlam, EkfSlamConfig, UkfSlam, UkfSlamConfig
from slamkit.slam.ukf_slam import UnscentedKernels, regress

R_RB = np.diag([0.1**2, np.deg2rad(2.0) ** 2])
Q_U = np.diag([0.1**2, np.deg2rad(5.0) ** 2])


def kernels() -> UnscentedKernels:
    model = RangeBearing()
    return UnscentedKernels(UnicycleEuler(), Q_U, model, model, R_RB, (1,))


def random_state(rng: np.random.Generator, L: int) -> tuple[np.ndarray, np.ndarray]:
    n = 3 + 2 * L
    mean = np.concatenate([[0.5, -0.3, 0.4], rng.uniform(-8.0, 8.0, 2 * L)])
    A = rng.normal(size=(n, n)) * 0.1
    return mean, A @ A.T + np.diag(rng.uniform(0.01, 0.05, n))


def run(cls: type[EkfSlam], dataset: Dataset, config: EkfSlamConfig) -> EkfSlam:
    est = cls(dataset, config, np.random.default_rng(0))
    for ev in dataset.events:
        est.handle(ev)
    return est


# --------------------------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------------------------


def test_regress_is_the_conditional_gaussian_and_handles_a_singular_block() -> None:
    """For a linear output ``y = A s`` the covariance with the rest is exactly ``A Σ_sr``;
    with a singular ``Σ_ss`` (a pose known exactly) the pseudo-inverse gives the same."""
    rng = np.random.default_rng(0)
    _, P = random_state(rng, 3)
    A = rng.normal(size=(2, 5))
    rows = P[:5]
    np.testing.assert_allclose(regress(P[:5, :5], A @ P[:5, :5], rows), A @ rows, atol=1e-12)
    B = rng.normal(size=(9, 2))
    Ps = B @ B.T  # rank 2
    np.testing.assert_allclose(regress(Ps[:5, :5], A @ Ps[:5, :5], Ps[:5]), A @ Ps[:5], atol=1e-9)


def test_prediction_without_a_map_is_the_ukf_localisation_prediction() -> None:
    rng = np.random.default_rng(1)
    mean, cov = random_state(rng, 0)
    u = np.array([1.0, 0.3])
    ref = ukf_predict(GaussianBelief(mean, cov), u, 0.1, UnicycleEuler(), Q_U)
    m, c = mean.copy(), cov.copy()
    kernels().predict(m, c, u, 0.1)
    np.testing.assert_allclose(m, ref.mean, atol=1e-12)
    np.testing.assert_allclose(c, ref.cov, atol=1e-12)


def test_motion_cross_covariance_tends_to_the_jacobian_times_the_covariance() -> None:
    """``unscented_motion_unchecked``'s ``C = Cov(x', x)``: as the pose covariance shrinks,
    ``C P⁻¹`` tends to the motion Jacobian ``G`` (the statistical linearisation becomes the
    analytic one). Measured: largest entry error 1.8e-3 and 1.8e-5 at ``P``
    scaled by 1e-2 and 1e-4."""
    rng = np.random.default_rng(5)
    A = rng.normal(size=(3, 3))
    P0 = A @ A.T + np.eye(3)
    x, u, dt = np.array([1.0, -2.0, 0.7]), np.array([1.5, 0.4]), 0.1
    model = UnicycleEuler()
    G = motion_jacobians_unchecked(model, x, u, dt)[0]
    errs = []
    for scale in (1e-2, 1e-4):
        P = scale * P0
        _, _, C = unscented_motion_unchecked(x, P, u, dt, model, Q_U, SigmaPointParams())
        errs.append(float(np.max(np.abs(np.linalg.solve(P, C.T).T - G))))
    assert errs[0] < 5e-3 and errs[1] < errs[0] / 50, errs  # first order in the scale


def test_circular_mean_about_agrees_with_the_circular_mean_across_the_seam() -> None:
    """Headings straddling ±π average to π's side, wrapped into ``[-π, π)``; with positive
    weights the same as :func:`~slamkit.geometry.circular_mean`."""
    a = np.array([math.pi - 0.1, -math.pi + 0.05, math.pi - 0.02])
    w = np.array([0.2, 0.5, 0.3])
    got = circular_mean_about(a, w, float(a[0]))
    assert -math.pi <= got < math.pi
    assert got == pytest.approx(float(circular_mean(a, w)), abs=1e-12)
    assert abs(got) > math.pi - 0.05


def test_update_of_a_one_landmark_state_is_the_textbook_ukf_update() -> None:
    """With the pose and one landmark the sigma set covers the whole state, so the update
    must be the plain UKF's: 11 points, ``K = P_xz S⁻¹``, ``Σ − K S Kᵀ``."""
    rng = np.random.default_rng(2)
    mean, cov = random_state(rng, 1)
    mean[3:] = [5.0, 3.0]  # bearing ≈ 0.23 rad: every sigma point's bearing far from ±π
    model, z = RangeBearing(), np.array([5.8, 0.3])
    Wm, Wc, c = sigma_point_weights(SigmaPointParams(), 5)
    L = math.sqrt(c) * np.linalg.cholesky(cov)
    X = np.vstack([mean, mean + L.T, mean - L.T])
    Z = model.predict(X[:, :3], X[:, 3:])
    zb = Wm @ Z
    zb[1] = circular_mean(Z[:, 1], Wm)  # the bearings' weighted circular mean (far from ±π)
    dZ, dX = Z - zb, X - mean
    S = (dZ.T * Wc) @ dZ + R_RB
    K = ((dX.T * Wc) @ dZ) @ np.linalg.inv(S)
    nu = z - zb
    m, cv = mean.copy(), cov.copy()
    nis = kernels().update(m, cv, 3, z, np.empty(64), False)
    np.testing.assert_allclose(m, mean + K @ nu, atol=1e-10)
    np.testing.assert_allclose(cv, cov - K @ S @ K.T, atol=1e-10)
    assert nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-10)


def test_new_landmark_from_an_exactly_known_pose_has_no_cross_covariance() -> None:
    """Pose known exactly: the landmark's covariance is the unscented transform of the
    reading alone (compared with its dense form) and its cross-covariances are zero."""
    mean_buf, cov_buf = np.zeros(5), np.zeros((5, 5))
    mean_buf[:3] = [1.0, 2.0, 0.5]
    z = np.array([4.0, -0.4])
    kernels().add(mean_buf, cov_buf, 3, z)
    Wm, Wc, c = sigma_point_weights(SigmaPointParams(), 5)
    Lz = math.sqrt(c) * np.linalg.cholesky(R_RB)
    # rows: centre, pose +, reading +, pose −, reading − (pose offsets zero here)
    zs = np.vstack([np.tile(z, (4, 1)), z + Lz.T, np.tile(z, (3, 1)), z - Lz.T])
    pts = RangeBearing().inverse(mean_buf[:3], zs)
    mu = Wm @ pts
    np.testing.assert_allclose(mean_buf[3:], mu, atol=1e-12)
    np.testing.assert_allclose(cov_buf[3:, 3:], ((pts - mu).T * Wc) @ (pts - mu), atol=1e-12)
    np.testing.assert_array_equal(cov_buf[3:, :3], 0.0)
    # the curved arc: the unscented mean sits inside the arc, nearer than the range read
    assert math.hypot(*(mu - mean_buf[:2])) < 4.0


def test_bad_sigma_points_are_refused() -> None:
    with pytest.raises(ConfigError):
        UkfSlamConfig(sigma_points=SigmaPointParams(alpha=0.0))


# --------------------------------------------------------------------------------------------
# the estimator on the five-feature world
# --------------------------------------------------------------------------------------------


def test_known_ids_converge_in_the_five_feature_world() -> None:
    """One lap of the five-feature world with known ids. Measured over 30 seeds: final
    position error ≤ 0.158 m (mean 0.068), largest landmark error after a rigid alignment
    0.033 m (without alignment up to 0.66 m: the start-pose prior, which SLAM cannot
    observe) — the same as EKF-SLAM's 0.157 / 0.031 / 0.65 m."""
    dataset = load_dataset("five-features", seed=0)
    assert dataset.truth.poses is not None and dataset.truth.landmarks is not None
    est = run(UkfSlam, dataset, UkfSlamConfig())
    out = est.finish()
    assert out.landmarks is not None and out.landmarks.covariances is not None
    assert out.diagnostics["n_landmarks"] == 5 and out.diagnostics["n_provisional"] == 0
    err = pose_errors(est.estimate().pose, dataset.truth.poses[-1])
    assert math.hypot(err[0], err[1]) < 0.05  # measured 0.012 m
    assert abs(err[2]) < np.deg2rad(1.0)  # measured 0.07°
    lm = landmark_map_error(out.landmarks.landmarks, dataset.truth.landmarks, align=False)
    assert lm.n_matched == 5 and lm.max < 0.2  # measured 0.098 m
    assert landmark_map_error(out.landmarks.landmarks, dataset.truth.landmarks).max < 0.05
    d = out.diagnostics
    assert d["updates"] + d["provisional_updates"] + d["new_features"] == d["readings"]
    assert 1.8 < d["mean_nis"] < 2.2  # measured 1.97 (30 seeds: 1.88–2.10)


def test_pose_nees_over_30_seeds_is_inside_the_chi2_band() -> None:
    """Pose NEES (χ²₃) at every scan over 30 seeded laps (readings every 0.2 s): the
    30-run average at each scan inside its 95 % band (χ²₉₀ / 30) at most steps. Measured:
    outside at 3.6 % of the steps (EKF-SLAM the same), mean 3.19 over runs and scans
    (EKF-SLAM 3.22; per-run means 1.0–8.5, so 20 seeds give 3.56 and 9 % outside); over two
    laps both turn optimistic (3.40 vs 3.43, ``docs/estimators/ukf_slam.md``)."""
    runs = []
    for seed in range(30):
        data = load_dataset("five-features", seed=seed, options={"observe_every": 2})
        assert data.truth.poses is not None
        row = {t: i for i, t in enumerate(data.truth.times.tolist())}
        est = UkfSlam(data, UkfSlamConfig(), np.random.default_rng(0))
        rows, poses, covs = [], [], []
        for ev in data.events:
            est.handle(ev)
            if isinstance(ev, LandmarkReadings):
                p = est.estimate()
                rows.append(row[ev.t])
                poses.append(p.pose)
                covs.append(p.cov)
        runs.append(nees(pose_errors(np.array(poses), data.truth.poses[rows]), np.array(covs)))
    T = min(v.size for v in runs)
    P = np.array([v[:T] for v in runs])
    lo, hi = chi2_bounds(3, 30)
    avg = P.mean(axis=0)
    outside = float(np.mean((avg < lo) | (avg > hi)))
    assert outside < 0.08, outside  # a consistent filter: 5 %
    assert 2.8 < P.mean() < 3.5, P.mean()


def test_equals_ekf_slam_as_the_noise_shrinks() -> None:
    """With every noise and the prior scaled by ``f`` the models are linear over the
    spread of the sigma points, and the UKF must give EKF-SLAM's answer: measured (seed 3),
    the largest mean difference in standard deviations 3.9e-3 / 4.0e-4 / 4.1e-5 and the
    relative covariance difference 7.8e-6 / 8.7e-8 / 8.6e-10 at f = 0.1 / 0.01 / 0.001 —
    first order in f for the mean, second for the covariance."""
    diffs = []
    for f in (1e-2, 1e-3):
        opts = {
            "sigma_v": 0.1 * f,
            "sigma_omega_deg": 5.0 * f,
            "sigma_range": 0.1 * f,
            "sigma_bearing_deg": 2.0 * f,
            "initial_sigma_xy": 0.05 * f,
            "initial_sigma_theta_deg": 1.0 * f,
        }
        data = load_dataset("five-features", seed=3, options=opts)
        a = run(EkfSlam, data, EkfSlamConfig())
        b = run(UkfSlam, data, UkfSlamConfig())
        np.testing.assert_array_equal(a.landmark_ids, b.landmark_ids)
        sd = np.sqrt(np.diag(a.cov))
        diffs.append(
            (
                float(np.max(np.abs(a.mean - b.mean) / sd)),
                float(np.max(np.abs(a.cov - b.cov)) / np.max(np.abs(a.cov))),
            )
        )
    (m2, c2), (m3, c3) = diffs
    assert m2 < 2e-3 and c2 < 1e-6, diffs
    assert m3 < m2 / 5 and c3 < c2 / 50, diffs  # converges: first and second order


@pytest.mark.parametrize("association", ["nn", "jcbb"])
def test_unknown_association_in_the_runner(association: str) -> None:
    from slamkit.pipeline import run as run_pipeline
    from slamkit.pipeline.evaluate import evaluate

    dataset = load_dataset("five-features", seed=1)
    config = {"association": association, "use_ids": False}
    result = run_pipeline("ukf-slam", dataset, config=config)
    assert result.config["association"] == association
    metrics = evaluate(result, dataset).metrics
    assert metrics["ate"]["rmse"] < 0.1
    assert metrics["landmarks_matched_by"] == "position"
    assert metrics["landmarks"]["n_matched"] == 5 and metrics["landmarks"]["rmse"] < 0.05
    assert metrics["association"]["accuracy"] > 0.99
    assert result.output.diagnostics["n_landmarks"] == 5


@pytest.mark.realdata
def test_victoria_park_first_300_s_matches_ekf_slam(data_root: Path) -> None:
    """The first 300 s of Victoria Park, ids withheld, nearest neighbour — the case of
    EKF-SLAM's real-data test. Measured: GPS RMSE 4.358 m (EKF-SLAM 4.352 m), 154
    landmarks (155), association accuracy 96.05 % (96.04 %), precision 96.6 %; 7.2 s
    (EKF-SLAM 5.3 s)."""
    from slamkit.pipeline import run as run_pipeline
    from slamkit.pipeline.evaluate import evaluate

    ds = load_dataset("victoria-park", options={"max_duration_s": 300.0}, data_root=data_root)
    m = evaluate(run_pipeline("ukf-slam", ds, seed=0), ds).metrics
    assert m["gps"]["used"] > 800 and m["gps"]["rmse"] < 5.2
    a = m["association"]
    assert a["readings"] > 8000 and a["accuracy"] > 0.94 and a["precision"] > 0.95
    assert 140 <= m["diagnostics"]["n_landmarks"] <= 170


def test_command_line_lists_and_runs_it(tmp_path: Path) -> None:
    """``slamkit estimators`` lists ``ukf-slam``; ``slamkit run ukf-slam`` writes the
    standard files with its settings (a sigma-point table included) and the scores."""
    import json

    from typer.testing import CliRunner

    from slamkit.cli.main import app

    runner = CliRunner()
    res = runner.invoke(app, ["estimators"], env={"COLUMNS": "200"})
    assert res.exit_code == 0 and "ukf-slam" in res.output
    out = tmp_path / "run"
    args = ["run", "ukf-slam", "--data", "five-features", "--out", str(out), "--no-plots",
            "--set", "sigma_points.alpha=0.5"]  # fmt: skip
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["landmarks"]["n_matched"] == 5 and metrics["landmarks"]["rmse"] < 0.05
    assert metrics["ate"]["rmse"] < 0.1
    config = json.loads((out / "config.json").read_text())
    assert config["estimator"]["sigma_points"]["alpha"] == 0.5
