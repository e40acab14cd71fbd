"""Static localization: least squares (batch and recursive), trilateration, triangulation,
range-bearing fixes, the dispatcher and the least-squares estimator."""

from __future__ import annotations

import numpy as np
import pytest

from slamkit.datasets import (
    Control,
    Dataset,
    GroundTruth,
    LandmarkReadings,
    LandmarkSensorSpec,
    load_dataset,
)
from slamkit.errors import GeometryError, InputError, NonFiniteError
from slamkit.eval import associate, pose_errors
from slamkit.localization import GaussianBelief, predict
from slamkit.localization.least_squares import (
    LeastSquaresConfig,
    LeastSquaresLocalization,
    snapshot_errors,
)
from slamkit.localization.static import (
    UNIFORM_HEADING_VARIANCE,
    localize_from_readings,
    localize_range_bearing,
    rls_from_first,
    rls_init,
    rls_update,
    triangulate,
    trilaterate,
    weighted_least_squares,
)
from slamkit.maps import LandmarkMap
from slamkit.models import BearingOnly, RangeBearing, RangeOnly
from slamkit.pipeline.registry import EstimatorEntry
from slamkit.pipeline.runner import run

LANDMARKS = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [5.0, -3.0]])
POSE = np.array([3.0, 4.0, 0.7])
SIGMA_R, SIGMA_B = 0.05, 0.01
RB_COV = np.diag([SIGMA_R**2, SIGMA_B**2])


def _readings(pose: np.ndarray = POSE, landmarks: np.ndarray = LANDMARKS) -> np.ndarray:
    return RangeBearing().predict(pose, landmarks)


# ------------------------------------------------------------------ weighted least squares
def test_wls_line_fit_matches_weighted_lstsq() -> None:
    # Fit y = a + b t with heteroscedastic noise: the answer of lstsq on the rows scaled by
    # 1/sigma_i, and the covariance (Hᵀ W⁻¹ H)⁻¹ written out by hand.
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    y = np.array([1.1, 2.9, 5.2, 6.8, 9.1, 11.2])
    sig = np.array([0.1, 0.2, 0.1, 0.3, 0.2, 0.5])
    H = np.stack([np.ones_like(t), t], axis=1)
    res = weighted_least_squares(H, y, np.diag(sig**2))
    ref, *_ = np.linalg.lstsq(H / sig[:, None], y / sig, rcond=None)
    np.testing.assert_allclose(res.x, ref, rtol=0, atol=1e-12)
    w = 1.0 / sig**2
    N = np.array([[w.sum(), (w * t).sum()], [(w * t).sum(), (w * t * t).sum()]])
    det = N[0, 0] * N[1, 1] - N[0, 1] ** 2
    cov_ref = np.array([[N[1, 1], -N[0, 1]], [-N[0, 1], N[0, 0]]]) / det
    np.testing.assert_allclose(res.cov, cov_ref, rtol=1e-12)
    np.testing.assert_allclose(res.residuals, y - H @ ref, atol=1e-12)


def test_wls_correlated_noise_matches_generalised_formula(rng: np.random.Generator) -> None:
    H = rng.normal(size=(7, 3))
    y = rng.normal(size=7)
    B = rng.normal(size=(7, 7))
    W = B @ B.T + 0.5 * np.eye(7)
    res = weighted_least_squares(H, y, W)
    Wi = np.linalg.inv(W)  # the test may invert; the library does not
    cov = np.linalg.inv(H.T @ Wi @ H)
    np.testing.assert_allclose(res.x, cov @ H.T @ Wi @ y, atol=1e-10)
    np.testing.assert_allclose(res.cov, cov, atol=1e-10)


def test_wls_rank_deficient_names_the_rank() -> None:
    H = np.array([[1.0, 2.0], [2.0, 4.0], [3.0, 6.0]])
    with pytest.raises(GeometryError, match="rank 1 < 2"):
        weighted_least_squares(H, np.ones(3), np.eye(3))
    with pytest.raises(GeometryError, match="rank"):
        weighted_least_squares(np.ones((1, 2)), np.ones(1), np.eye(1))


def test_wls_rejects_nan() -> None:
    with pytest.raises(NonFiniteError):
        weighted_least_squares(np.eye(2), np.array([1.0, np.nan]), np.eye(2))


# ---------------------------------------------------------------- recursive least squares
def test_recursive_equals_batch(rng: np.random.Generator) -> None:
    H = rng.normal(size=(40, 4))
    H[:3, 2:] = 0.0  # the first rows alone do not determine x: initialisation must wait
    x_true = np.array([1.0, -2.0, 0.5, 3.0])
    var = rng.uniform(0.01, 1.0, size=40)
    W = np.diag(var)
    y = H @ x_true + rng.normal(size=40) * np.sqrt(var)
    batch = weighted_least_squares(H, y, W)
    rec = rls_from_first(H, y, W)
    assert rec.count == 40
    np.testing.assert_allclose(rec.x, batch.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rec.cov, batch.cov, rtol=0, atol=1e-9)


def test_rls_blocks_and_single_rows_agree(rng: np.random.Generator) -> None:
    H = rng.normal(size=(6, 2))
    y = rng.normal(size=6)
    s0 = rls_init(np.zeros(2), 100.0 * np.eye(2))
    one = s0
    for i in range(6):
        one = rls_update(one, H[i], y[i], 0.2)
    block = rls_update(rls_update(s0, H[:3], y[:3], 0.2 * np.eye(3)), H[3:], y[3:], 0.2 * np.eye(3))
    np.testing.assert_allclose(one.x, block.x, atol=1e-12)
    np.testing.assert_allclose(one.cov, block.cov, atol=1e-12)
    # A vague prior forgets itself: close to the batch answer, not equal.
    batch = weighted_least_squares(H, y, 0.2 * np.eye(6))
    np.testing.assert_allclose(one.x, batch.x, atol=1e-2)


def test_rls_from_first_rejects_correlated_later_rows() -> None:
    H = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    W = np.eye(3)
    W[2, 0] = W[0, 2] = 0.1
    with pytest.raises(InputError, match="uncorrelated"):
        rls_from_first(H, np.ones(3), W)
    with pytest.raises(GeometryError, match="rank 1"):
        rls_from_first(np.ones((3, 2)), np.ones(3), np.eye(3))


# ------------------------------------------------------------ noise-free exact recovery
@pytest.mark.parametrize("theta", [0.7, 3.1, -3.1])
def test_noise_free_readings_recover_the_pose(theta: float) -> None:
    pose = np.array([3.0, 4.0, theta])
    z = _readings(pose)
    pos = trilaterate(LANDMARKS, z[:, 0], SIGMA_R)
    np.testing.assert_allclose(pos.position, pose[:2], atol=1e-9)
    assert pos.converged and np.max(np.abs(pos.residuals)) < 1e-9
    tri = triangulate(LANDMARKS, z[:, 1], SIGMA_B)
    np.testing.assert_allclose(tri.pose[:2], pose[:2], atol=1e-9)
    assert abs(np.angle(np.exp(1j * (tri.pose[2] - theta)))) < 1e-9
    rb = localize_range_bearing(LANDMARKS, z, RB_COV)
    np.testing.assert_allclose(rb.pose[:2], pose[:2], atol=1e-9)
    assert abs(np.angle(np.exp(1j * (rb.pose[2] - theta)))) < 1e-9
    assert rb.residuals.shape == (5, 2)


def test_minimal_sets_recover_the_pose() -> None:
    z = _readings()
    tri = triangulate(LANDMARKS[:3], z[:3, 1], SIGMA_B)
    np.testing.assert_allclose(tri.pose, POSE, atol=1e-9)
    rb = localize_range_bearing(LANDMARKS[:2], z[:2], RB_COV)
    np.testing.assert_allclose(rb.pose, POSE, atol=1e-9)
    pos = trilaterate(LANDMARKS[[0, 1, 3]], z[[0, 1, 3], 0], SIGMA_R)
    np.testing.assert_allclose(pos.position, POSE[:2], atol=1e-9)


def test_noisy_fixes_within_three_sigma(rng: np.random.Generator) -> None:
    z = _readings() + rng.normal(size=(5, 2)) * [SIGMA_R, SIGMA_B]
    pos = trilaterate(LANDMARKS, z[:, 0], SIGMA_R)
    assert np.all(np.abs(pos.position - POSE[:2]) < 3 * np.sqrt(np.diag(pos.cov)))
    for fix in (
        triangulate(LANDMARKS, z[:, 1], SIGMA_B),
        localize_range_bearing(LANDMARKS, z, RB_COV),
    ):
        err = fix.pose - POSE
        err[2] = np.angle(np.exp(1j * err[2]))
        assert np.all(np.abs(err) < 3 * np.sqrt(np.diag(fix.cov)))
        assert fix.converged and fix.iterations < 20


def _sample_check(fixes: np.ndarray, truth: np.ndarray, cov: np.ndarray) -> None:
    err = fixes - truth
    if err.shape[1] == 3:
        err[:, 2] = np.angle(np.exp(1j * err[:, 2]))
    assert np.all(np.abs(err.mean(axis=0)) < 3 * np.sqrt(np.diag(cov) / len(err)))
    sample = np.cov(err.T)
    ratio = np.diag(sample) / np.diag(cov)
    assert np.all(np.abs(ratio - 1.0) < 0.15), ratio
    # Correlations too: the sample and predicted correlation matrices agree to 0.1.
    d = np.sqrt(np.diag(cov))
    ds = np.sqrt(np.diag(sample))
    np.testing.assert_allclose(sample / np.outer(ds, ds), cov / np.outer(d, d), atol=0.1)


def test_fix_covariance_matches_monte_carlo(rng: np.random.Generator) -> None:
    n = 500
    z0 = _readings()
    pos_fixes, tri_fixes, rb_fixes = [], [], []
    for _ in range(n):
        z = z0 + rng.normal(size=(5, 2)) * [SIGMA_R, SIGMA_B]
        pos_fixes.append(trilaterate(LANDMARKS, z[:, 0], SIGMA_R).position)
        tri_fixes.append(triangulate(LANDMARKS, z[:, 1], SIGMA_B).pose)
        rb_fixes.append(localize_range_bearing(LANDMARKS, z, RB_COV).pose)
    # Covariances at the noise-free readings (the linearisation point of the prediction).
    _sample_check(np.array(pos_fixes), POSE[:2], trilaterate(LANDMARKS, z0[:, 0], SIGMA_R).cov)
    _sample_check(np.array(tri_fixes), POSE, triangulate(LANDMARKS, z0[:, 1], SIGMA_B).cov)
    _sample_check(np.array(rb_fixes), POSE, localize_range_bearing(LANDMARKS, z0, RB_COV).cov)


def test_noise_arguments_sigma_vector_and_matrix_agree() -> None:
    z = _readings() + 0.01
    sig = np.array([0.1, 0.2, 0.1, 0.3, 0.2])
    a = trilaterate(LANDMARKS, z[:, 0], sig)
    b = trilaterate(LANDMARKS, z[:, 0], np.diag(sig**2))
    np.testing.assert_allclose(a.position, b.position, atol=1e-12)
    np.testing.assert_allclose(a.cov, b.cov, atol=1e-12)


# --------------------------------------------------------------------------- refusals
def test_too_few_landmarks_are_refused() -> None:
    z = _readings()
    with pytest.raises(GeometryError, match="at least 3"):
        trilaterate(LANDMARKS[:2], z[:2, 0], SIGMA_R)
    with pytest.raises(GeometryError, match="at least 3"):
        triangulate(LANDMARKS[:2], z[:2, 1], SIGMA_B)
    with pytest.raises(GeometryError, match="at least 2"):
        localize_range_bearing(LANDMARKS[:1], z[:1], RB_COV)


@pytest.mark.parametrize("offset", [0.0, 1e-7])
def test_collinear_landmarks_refused_for_trilateration(offset: float) -> None:
    lm = np.array([[0.0, 0.0], [5.0, offset], [10.0, 0.0], [7.0, -offset]])
    z = RangeOnly().predict(POSE, lm)[:, 0]
    with pytest.raises(GeometryError, match="collinear"):
        trilaterate(lm, z, SIGMA_R)


def test_triangulation_refuses_indeterminate_geometry() -> None:
    # Robot on the circle through the landmarks: every point of the arc sees them under the
    # same angles (inscribed angle theorem).
    ang = np.array([0.3, 1.9, 3.5, 4.4])
    lm = 5.0 * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    pose = np.array([5.0 * np.cos(5.5), 5.0 * np.sin(5.5), 0.4])
    with pytest.raises(GeometryError):
        triangulate(lm, BearingOnly().predict(pose, lm)[:, 0], SIGMA_B)
    # Robot on the line through collinear landmarks: all bearings equal.
    lm_line = np.array([[1.0, 0.0], [3.0, 0.0], [6.0, 0.0]])
    with pytest.raises(GeometryError):
        triangulate(lm_line, BearingOnly().predict([-2.0, 0.0, 0.2], lm_line)[:, 0], SIGMA_B)
    # Collinear landmarks seen from off the line are fine for bearings.
    fix = triangulate(lm_line, BearingOnly().predict([2.0, 4.0, 0.2], lm_line)[:, 0], SIGMA_B)
    np.testing.assert_allclose(fix.pose, [2.0, 4.0, 0.2], atol=1e-9)


def test_nan_input_raises_non_finite() -> None:
    z = _readings()
    z[1, 0] = z[2, 1] = np.nan
    with pytest.raises(NonFiniteError):
        trilaterate(LANDMARKS, z[:, 0], SIGMA_R)
    with pytest.raises(NonFiniteError):
        triangulate(LANDMARKS, z[:, 1], SIGMA_B)
    with pytest.raises(NonFiniteError):
        localize_range_bearing(LANDMARKS, z, RB_COV)
    bad = LANDMARKS.copy()
    bad[0, 0] = np.inf
    with pytest.raises(NonFiniteError):
        trilaterate(bad, _readings()[:, 0], SIGMA_R)


# ------------------------------------------------------------------------- dispatcher
def test_localize_from_readings_dispatches_and_filters_ids() -> None:
    lmap = LandmarkMap(LANDMARKS, np.array([10, 11, 12, 13, 14]))
    z = _readings()
    ids = np.array([10, 11, -1, 13, 14])  # one reading of unknown identity is ignored
    rb = localize_from_readings(z, ids, LandmarkSensorSpec("range-bearing", RB_COV), lmap)
    np.testing.assert_allclose(rb.pose, POSE, atol=1e-9)
    assert rb.residuals.shape == (4, 2)
    br = localize_from_readings(
        z[:, 1:], ids, LandmarkSensorSpec("bearing", np.array([[SIGMA_B**2]])), lmap
    )
    np.testing.assert_allclose(br.pose, POSE, atol=1e-9)
    rg = localize_from_readings(
        z[:, :1], ids, LandmarkSensorSpec("range", np.array([[SIGMA_R**2]])), lmap
    )
    np.testing.assert_allclose(rg.pose, [POSE[0], POSE[1], 0.0], atol=1e-9)
    assert rg.cov[2, 2] == pytest.approx(np.pi**2 / 3) == UNIFORM_HEADING_VARIANCE
    assert np.all(rg.cov[2, :2] == 0.0)
    with pytest.raises(InputError, match=r"\[99\]"):
        localize_from_readings(
            z, np.array([10, 11, 99, 13, 14]), LandmarkSensorSpec("range-bearing", RB_COV), lmap
        )
    with pytest.raises(GeometryError, match="at least 3"):
        localize_from_readings(
            z[:, :1],
            np.array([10, -1, -1, -1, 14]),
            LandmarkSensorSpec("range", np.array([[0.01]])),
            lmap,
        )


# -------------------------------------------------------------------------- estimator
def _hand_dataset() -> Dataset:
    lmap = LandmarkMap.from_positions(LANDMARKS)
    z = _readings()
    events = (
        LandmarkReadings(1.0, z[:3], np.array([0, 1, 2])),
        LandmarkReadings(2.0, z[:1], np.array([0])),  # too few
        LandmarkReadings(3.0, np.vstack([z[:1], z[:1]]), np.array([0, 0])),  # degenerate
        LandmarkReadings(4.0, z, np.arange(5)),
    )
    return Dataset(
        "hand",
        events,
        landmark_sensor=LandmarkSensorSpec("range-bearing", RB_COV),
        known_landmarks=lmap,
        truth=GroundTruth(np.array([1.0, 2.0, 3.0, 4.0]), np.tile(POSE, (4, 1))),
    )


def test_estimator_counts_fixes_and_refusals(rng: np.random.Generator) -> None:
    ds = _hand_dataset()
    est = LeastSquaresLocalization(ds, LeastSquaresConfig(), rng)
    assert est.estimate().cov is not None and est.estimate().cov[0, 0] == pytest.approx(1e6)
    est.handle(ds.events[0])
    first = est.estimate()
    np.testing.assert_allclose(first.pose, POSE, atol=1e-9)
    ref = localize_range_bearing(LANDMARKS[:3], _readings()[:3], RB_COV)
    np.testing.assert_allclose(first.cov, ref.cov, atol=1e-15)
    for ev in ds.events[1:3]:  # neither changes the estimate
        est.handle(ev)
        np.testing.assert_array_equal(est.estimate().cov, first.cov)
    est.handle(ds.events[3])
    diag = est.finish().diagnostics
    assert (diag["fixes"], diag["too_few_readings"], diag["refused"]) == (2, 1, 1)
    assert diag["not_converged"] == 0


def test_estimator_predicts_between_fixes(rng: np.random.Generator) -> None:
    ds = load_dataset("five-features", seed=3)
    assert ds.motion is not None
    est = LeastSquaresLocalization(ds, LeastSquaresConfig(), rng)
    hold = LeastSquaresLocalization(ds, LeastSquaresConfig(predict_between=False), rng)
    readings = next(i for i, e in enumerate(ds.events) if isinstance(e, LandmarkReadings))
    control = next(i for i, e in enumerate(ds.events) if i > readings and isinstance(e, Control))
    for ev in ds.events[: control + 1]:
        est.handle(ev)
        hold.handle(ev)
    ev_c = ds.events[control]
    assert isinstance(ev_c, Control)
    ev_r = ds.events[readings]
    assert isinstance(ev_r, LandmarkReadings)
    assert ds.landmark_sensor is not None and ds.known_landmarks is not None
    fix = localize_from_readings(ev_r.z, ev_r.ids, ds.landmark_sensor, ds.known_landmarks)
    expected = predict(
        GaussianBelief(fix.pose, fix.cov), ev_c.u, ev_c.dt, ds.motion.model, ds.motion.noise_cov
    )
    np.testing.assert_allclose(est.estimate().pose, expected.pose, atol=1e-12)
    np.testing.assert_allclose(hold.estimate().pose, fix.pose, atol=1e-12)


@pytest.mark.parametrize(
    ("name", "max_median_error"),
    # Measured with seed 1: median position error 0.080 m (range-bearing), 0.169 m
    # (bearing-only, 3-4 landmarks in view), 0.101 m (range-only); median NEES 2.6, 2.5, 3.1.
    [("five-features", 0.10), ("five-features-bearing", 0.21), ("five-features-range", 0.13)],
)
def test_estimator_through_runner(name: str, max_median_error: float) -> None:
    # A full 360° view: single-shot fixes need three landmarks in sight (the registered
    # range/bearing variants default to a 120° view, where that never happens).
    ds = load_dataset(name, seed=1, options={"fov_deg": 360.0})
    entry = EstimatorEntry(
        "least-squares",
        "static fix at every landmark event",
        "slamkit.localization.least_squares:LeastSquaresLocalization",
        "slamkit.localization.least_squares:LeastSquaresConfig",
        requires=("landmark_sensor", "known_landmarks"),
    )
    res = run(entry, ds, config={"predict_between": False})
    diag = res.output.diagnostics
    events = diag["fixes"] + diag["too_few_readings"] + diag["refused"] + diag["not_converged"]
    n_events = sum(1 for _ in ds.of_type(LandmarkReadings))
    assert events == n_events
    se = snapshot_errors(ds)
    assert se.times.size == diag["fixes"]
    assert se.refused_times.size == n_events - diag["fixes"]
    # The runner's estimate at a fix time is that fix.
    ia, ib = associate(se.times, res.times, 0.0)
    it, jt = associate(se.times, ds.truth.times, 0.0)
    assert ia.size == it.size == se.times.size
    np.testing.assert_allclose(
        pose_errors(res.poses[ib], ds.truth.poses[jt]), se.errors, atol=1e-12
    )
    assert float(np.median(se.position_errors)) < max_median_error
    # Median of χ²(3) is 2.37: the fix covariances are about right.
    assert 1.7 < float(np.median(se.nees)) < 3.9


def test_relative_position_readings() -> None:
    try:
        sensor = LandmarkSensorSpec("position", np.diag([0.01, 0.02]))  # type: ignore[arg-type]
    except InputError:
        pytest.skip("this checkout has no 'position' landmark sensor")
    lmap = LandmarkMap.from_positions(LANDMARKS)
    c, s = np.cos(POSE[2]), np.sin(POSE[2])
    z = (LANDMARKS - POSE[:2]) @ np.array([[c, -s], [s, c]])  # R(θ)ᵀ (l − p), row-wise
    fix = localize_from_readings(z[:2], np.array([0, 1]), sensor, lmap)
    np.testing.assert_allclose(fix.pose, POSE, atol=1e-9)
    with pytest.raises(GeometryError, match="at least 2"):
        localize_from_readings(z[:1], np.array([0]), sensor, lmap)


def test_estimator_counts_refusals_when_too_few_landmarks_are_in_view() -> None:
    # With the 120° view of the registered bearing-only variant, never three landmarks are in
    # sight: every event is counted as too few readings, none is forced into a fix.
    ds = load_dataset("five-features-bearing", seed=1)
    res = run("least-squares", ds, config={"predict_between": False})
    diag = res.output.diagnostics
    assert diag["fixes"] == 0
    assert diag["too_few_readings"] == sum(1 for _ in ds.of_type(LandmarkReadings))
