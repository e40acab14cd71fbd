"""Evaluation: association, ATE, RPE, NEES/NIS consistency and landmark-map error."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from slamkit.errors import (
    ConfigError,
    CovarianceError,
    GeometryError,
    InputError,
    NonFiniteError,
    ShapeError,
)
from slamkit.eval import (
    absolute_trajectory_error,
    associate,
    chi2_bounds,
    consistency_report,
    landmark_map_error,
    nees,
    nis,
    pose_errors,
    relative_pose_error,
)
from slamkit.geometry.alignment import Similarity
from slamkit.maps.types import LandmarkMap


def curvy_path(n: int = 60) -> np.ndarray:
    t = np.linspace(0.0, 6.0, n)
    x, y = 5.0 * np.cos(t) + t, 3.0 * np.sin(1.3 * t)
    theta = np.arctan2(np.gradient(y), np.gradient(x))
    return np.column_stack([x, y, theta])


# ------------------------------------------------------------------------ associate
def test_associate_hand_case_with_unsorted_b() -> None:
    times_a = np.array([0.0, 1.0, 2.0, 3.0, 10.0])
    times_b = np.array([2.9, 0.05, 2.2, 0.9])  # not sorted
    ia, ib = associate(times_a, times_b, max_dt=0.15)
    np.testing.assert_array_equal(ia, [0, 1, 3])  # 2.0 is 0.2 from 2.2; 10.0 has no partner
    np.testing.assert_array_equal(ib, [1, 3, 0])
    assert ia.dtype == np.int64 and ib.dtype == np.int64


def test_associate_ties_sharing_and_empty() -> None:
    ia, ib = associate([1.0], [0.5, 1.5], max_dt=1.0)
    np.testing.assert_array_equal(ib, [0])  # exact tie: the earlier b
    ia, ib = associate([0.0, 0.1], [0.05], max_dt=0.1)
    np.testing.assert_array_equal(ia, [0, 1])
    np.testing.assert_array_equal(ib, [0, 0])  # a dense stream may share one b
    ia, ib = associate([], [1.0, 2.0], max_dt=0.1)
    assert ia.size == 0 and ib.size == 0
    with pytest.raises(InputError, match="max_dt"):
        associate([0.0], [0.0], max_dt=-1.0)
    with pytest.raises(ShapeError):
        associate([[0.0]], [0.0], max_dt=1.0)


# ----------------------------------------------------------------------- pose errors
def test_pose_errors_hand_value_and_batch() -> None:
    err = pose_errors([1.0, 2.0, -3.0], [0.5, 2.5, 3.0])
    np.testing.assert_allclose(err, [0.5, -0.5, 2 * np.pi - 6.0], atol=1e-15)
    batch = pose_errors(np.zeros((4, 5, 3)), np.ones((4, 5, 3)))
    assert batch.shape == (4, 5, 3)
    with pytest.raises(ShapeError):
        pose_errors(np.zeros((4, 3)), np.zeros((5, 3)))


# ------------------------------------------------------------------------------- ATE
def test_ate_se2_removes_a_rigid_offset_and_none_measures_it() -> None:
    truth = curvy_path()
    offset = Similarity.from_pose([2.0, -1.0, np.deg2rad(30.0)])
    est = offset.apply_to_poses(truth)

    se2 = absolute_trajectory_error(est, truth, align="se2")
    assert se2.rmse < 1e-10 and se2.max < 1e-10 and se2.heading_rmse < 1e-12
    np.testing.assert_allclose(se2.alignment.as_pose(), offset.inverse().as_pose(), atol=1e-10)

    none = absolute_trajectory_error(est, truth, align="none")
    expected = np.linalg.norm(est[:, :2] - truth[:, :2], axis=1)
    np.testing.assert_allclose(none.translation_errors, expected, rtol=1e-12)
    assert none.rmse == pytest.approx(np.sqrt(np.mean(expected**2)), rel=1e-12)
    assert none.rmse > 1.0
    np.testing.assert_allclose(none.heading_errors, np.deg2rad(30.0), atol=1e-12)
    assert none.heading_rmse == pytest.approx(np.pi / 6, abs=1e-12)


def test_ate_origin_hand_case() -> None:
    truth = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    # The same start heading 90° off and 1 m too far on the second step.
    est = np.array([[1.0, 1.0, np.pi / 2], [1.0, 2.0, np.pi / 2], [1.0, 4.0, np.pi / 2]])
    ate = absolute_trajectory_error(est, truth, align="origin")
    np.testing.assert_allclose(ate.aligned_estimate, [[0, 0, 0], [1, 0, 0], [3, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(ate.translation_errors, [0.0, 0.0, 1.0], atol=1e-12)
    assert ate.rmse == pytest.approx(np.sqrt(1 / 3))
    assert ate.mean == pytest.approx(1 / 3)
    assert ate.median == pytest.approx(0.0, abs=1e-12)
    assert ate.max == pytest.approx(1.0)
    assert ate.std == pytest.approx(np.sqrt(2 / 9))
    assert ate.heading_rmse == pytest.approx(0.0, abs=1e-12)
    assert ate.alignment.angle == pytest.approx(-np.pi / 2)


def test_ate_weights_and_json() -> None:
    truth = curvy_path(20)
    est = truth.copy()
    est[5, :2] += [30.0, -40.0]  # one outlier
    w = np.ones(20)
    w[5] = 0.0
    ate = absolute_trajectory_error(est, truth, weights=w)
    np.testing.assert_allclose(ate.translation_errors[np.arange(20) != 5], 0.0, atol=1e-10)
    assert ate.translation_errors[5] == pytest.approx(50.0, abs=1e-9)
    d = ate.as_dict()
    assert json.loads(json.dumps(d)) == d
    assert d["count"] == 20 and d["align"] == "se2"
    assert all(isinstance(v, float | int | str) for v in d.values())


def test_ate_bad_inputs() -> None:
    truth = curvy_path(10)
    with pytest.raises(ConfigError, match="align"):
        absolute_trajectory_error(truth, truth, align="sim3")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="weights"):
        absolute_trajectory_error(truth, truth, align="none", weights=np.ones(10))
    with pytest.raises(ShapeError, match="associate"):
        absolute_trajectory_error(truth, truth[:9])
    with pytest.raises(NonFiniteError):
        absolute_trajectory_error(np.full((10, 3), np.nan), truth)
    with pytest.raises(GeometryError):
        absolute_trajectory_error(truth[:1], truth[:1], align="se2")
    one = absolute_trajectory_error(truth[:1], truth[:1] + 1.0, align="origin")
    assert one.rmse == pytest.approx(0.0, abs=1e-12)


# ------------------------------------------------------------------------------- RPE
def test_rpe_is_zero_for_a_global_rigid_offset() -> None:
    truth = curvy_path()
    est = Similarity.from_pose([-3.0, 7.0, 2.0]).apply_to_poses(truth)
    for delta, unit in [(1, "frames"), (7, "frames"), (2.5, "meters")]:
        rpe = relative_pose_error(est, truth, delta=delta, unit=unit)  # type: ignore[arg-type]
        assert rpe.translation_max < 1e-10 and rpe.rotation_max < 1e-12


def test_rpe_scale_error_per_step() -> None:
    k = np.arange(11.0)
    truth = np.column_stack([k, np.zeros(11), np.zeros(11)])  # 1 m per step along x
    est = np.column_stack([1.1 * k, np.zeros(11), np.zeros(11)])  # 10 % too long
    one = relative_pose_error(est, truth, delta=1)
    assert one.count == 10
    np.testing.assert_allclose(one.translation_errors, 0.1, atol=1e-12)
    assert one.translation_rmse == pytest.approx(0.1)
    assert one.rotation_rmse == 0.0
    two = relative_pose_error(est, truth, delta=2)
    np.testing.assert_allclose(two.translation_errors, 0.2, atol=1e-12)
    # 2.5 m along the true path: the first j with travelled distance >= 2.5 is i + 3.
    metres = relative_pose_error(est, truth, delta=2.5, unit="meters")
    np.testing.assert_array_equal(metres.pairs[:, 1] - metres.pairs[:, 0], 3)
    assert metres.count == 8
    np.testing.assert_allclose(metres.translation_errors, 0.3, atol=1e-12)
    d = metres.as_dict()
    assert json.loads(json.dumps(d)) == d and d["unit"] == "meters" and d["count"] == 8


def test_rpe_heading_drift() -> None:
    k = np.arange(8.0)
    truth = np.column_stack([k, np.zeros(8), np.zeros(8)])
    est = truth.copy()
    est[:, 2] = 0.01 * k  # 0.01 rad of heading drift per step
    rpe = relative_pose_error(est, truth, delta=3)
    np.testing.assert_allclose(rpe.rotation_errors, 0.03, atol=1e-14)
    assert rpe.rotation_max == pytest.approx(0.03)


def test_rpe_bad_inputs() -> None:
    truth = curvy_path(10)
    with pytest.raises(InputError, match="whole number"):
        relative_pose_error(truth, truth, delta=1.5)
    with pytest.raises(InputError, match="whole number"):
        relative_pose_error(truth, truth, delta=0)
    with pytest.raises(InputError, match="metres"):
        relative_pose_error(truth, truth, delta=-1.0, unit="meters")
    with pytest.raises(ConfigError, match="unit"):
        relative_pose_error(truth, truth, unit="seconds")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="no pose pair"):
        relative_pose_error(truth, truth, delta=10)
    with pytest.raises(InputError, match="no pose pair"):
        relative_pose_error(truth, truth, delta=1e6, unit="meters")


# ----------------------------------------------------------------------- consistency
def test_nees_hand_values_and_broadcasting() -> None:
    assert nees([1.0, 2.0], np.diag([1.0, 4.0])) == pytest.approx(2.0)
    # P = [[2, 1], [1, 2]], P⁻¹ = [[2, -1], [-1, 2]] / 3, e = (1, 1): (2 - 1 - 1 + 2) / 3.
    assert nees([1.0, 1.0], [[2.0, 1.0], [1.0, 2.0]]) == pytest.approx(2 / 3)
    rng = np.random.default_rng(0)
    e = rng.normal(size=(4, 6, 3))
    A = rng.normal(size=(6, 3, 3))
    P = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(3)
    out = nees(e, P)  # (4, 6, 3) against (6, 3, 3)
    assert out.shape == (4, 6)
    direct = np.einsum("rti,rti->rt", e, np.linalg.solve(P[None], e[..., None])[..., 0])
    np.testing.assert_allclose(out, direct, rtol=1e-10)
    np.testing.assert_allclose(nis(e, P), out)
    assert nees(e[0], P[0]).shape == (6,)


def test_nees_rejects_bad_covariances() -> None:
    with pytest.raises(CovarianceError, match="positive definite"):
        nees([1.0, 1.0], [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(CovarianceError, match="symmetric"):
        nees([1.0, 1.0], [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ShapeError):
        nees([1.0, 1.0, 1.0], np.eye(2))
    with pytest.raises(ShapeError, match="broadcast"):
        nees(np.zeros((4, 2)), np.broadcast_to(np.eye(2), (3, 2, 2)))
    with pytest.raises(NonFiniteError):
        nis([np.nan, 0.0], np.eye(2))


def test_chi2_bounds_against_scipy() -> None:
    lo, hi = chi2_bounds(3, n_runs=50, probability=0.95)
    assert lo == pytest.approx(stats.chi2.ppf(0.025, 150) / 50, rel=1e-12)
    assert hi == pytest.approx(stats.chi2.ppf(0.975, 150) / 50, rel=1e-12)
    assert (lo, hi) == pytest.approx((2.3597, 3.7160), abs=1e-4)
    # One run of a 3-D state: the familiar (0.216, 9.348).
    assert chi2_bounds(3) == pytest.approx((0.2158, 9.3484), abs=1e-4)
    for bad in [dict(dof=0), dict(dof=3, n_runs=0), dict(dof=3, probability=1.0)]:
        with pytest.raises(InputError):
            chi2_bounds(**bad)  # type: ignore[arg-type]


def test_monte_carlo_nees_is_consistent() -> None:
    """Errors drawn from N(0, P): average NEES over runs stays in the χ² band, mean ≈ dim."""
    rng = np.random.default_rng(42)
    runs, steps, dim = 50, 200, 3
    A = rng.normal(size=(steps, dim, dim))
    P = A @ np.swapaxes(A, -1, -2) + 0.05 * np.eye(dim)  # a different P at every step
    L = np.linalg.cholesky(P)
    e = np.einsum("tij,rtj->rti", L, rng.normal(size=(runs, steps, dim)))
    values = nees(e, P)
    assert values.shape == (runs, steps)
    report = consistency_report(values, dof=dim)
    assert (report.lower, report.upper) == pytest.approx(chi2_bounds(dim, runs))
    assert report.mean == pytest.approx(dim, abs=0.05)  # sd of the mean: sqrt(6/1e4) ≈ 0.024
    assert report.mean_inside
    assert report.fraction_inside >= 0.9  # expected 0.95, binomial sd ≈ 0.015
    assert report.per_step.shape == (steps,)
    d = report.as_dict()
    assert json.loads(json.dumps(d)) == d and d["n_runs"] == runs

    # A filter claiming a covariance 4x too small is caught.
    over = consistency_report(nees(e, P / 4.0), dof=dim)
    assert over.mean == pytest.approx(4 * dim, rel=0.05)
    assert not over.mean_inside and over.fraction_inside == 0.0


def test_consistency_report_single_run_and_bad_input() -> None:
    rep = consistency_report([1.0, 2.0, 3.0, 100.0], dof=2, probability=0.9)
    lo, hi = chi2_bounds(2, 1, 0.9)
    assert (rep.lower, rep.upper) == (lo, hi)
    assert rep.n_runs == 1 and rep.n_steps == 4
    assert rep.fraction_inside == pytest.approx(0.75)  # 100 is far above hi ≈ 5.99
    assert rep.mean == pytest.approx(26.5)
    assert (rep.mean_lower, rep.mean_upper) == chi2_bounds(2, 4, 0.9)
    with pytest.raises(InputError, match="negative"):
        consistency_report([1.0, -1.0], dof=1)
    with pytest.raises(ShapeError):
        consistency_report(np.ones((2, 2, 2)), dof=1)
    with pytest.raises(ShapeError):
        consistency_report(np.ones((0,)), dof=1)


# ------------------------------------------------------------------------- landmarks
def test_landmark_error_with_permuted_ids_and_rigid_transform() -> None:
    rng = np.random.default_rng(5)
    true_ids = np.array([10, 3, 7, 42, 5])
    truth = LandmarkMap(rng.uniform(-10, 10, size=(5, 2)), true_ids)
    moved = Similarity.from_pose([1.0, -2.0, 0.8])
    # Estimate: ids in another order, landmark 5 missing, a spurious landmark 99.
    order = [3, 0, 2, 1]  # 42, 10, 7, 3
    est_pos = moved.apply_to_points(truth.positions[order])
    est = LandmarkMap(np.vstack([est_pos, [[0.0, 0.0]]]), np.append(true_ids[order], 99))

    err = landmark_map_error(est, truth)
    np.testing.assert_array_equal(err.ids, [3, 7, 10, 42])
    assert err.n_matched == 4 and err.n_missing == 1 and err.n_spurious == 1
    np.testing.assert_array_equal(err.missing_ids, [5])
    np.testing.assert_array_equal(err.spurious_ids, [99])
    assert err.rmse < 1e-10 and err.max < 1e-10
    np.testing.assert_allclose(err.alignment.as_pose(), moved.inverse().as_pose(), atol=1e-10)

    raw = landmark_map_error(est, truth, align=False)
    expected = np.linalg.norm(
        moved.apply_to_points(truth.position_of(raw.ids)) - truth.position_of(raw.ids), axis=1
    )
    np.testing.assert_allclose(raw.errors, expected, rtol=1e-12)
    assert raw.rmse == pytest.approx(np.sqrt(np.mean(expected**2)))
    d = err.as_dict()
    assert json.loads(json.dumps(d)) == d and d["n_matched"] == 4


def test_landmark_error_with_scale() -> None:
    truth = LandmarkMap.from_positions([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0], [5.0, 5.0]])
    est = LandmarkMap.from_positions(
        Similarity.from_pose([1.0, 1.0, -0.4], scale=2.0).apply_to_points(truth.positions)
    )
    assert landmark_map_error(est, truth, with_scale=True).rmse < 1e-10
    assert landmark_map_error(est, truth).rmse > 0.5


def test_landmark_error_bad_inputs() -> None:
    a = LandmarkMap.from_positions([[0.0, 0.0], [1.0, 0.0]])
    b = LandmarkMap(np.array([[0.0, 0.0], [1.0, 1.0]]), np.array([7, 8]))
    with pytest.raises(InputError, match="no landmark id"):
        landmark_map_error(a, b)
    with pytest.raises(ConfigError, match="with_scale"):
        landmark_map_error(a, a, align=False, with_scale=True)
    one = LandmarkMap(np.array([[0.0, 0.0]]), np.array([0]))
    with pytest.raises(GeometryError):
        landmark_map_error(one, a)
    assert landmark_map_error(one, a, align=False).rmse == 0.0
    with pytest.raises(InputError, match="LandmarkMap"):
        landmark_map_error(a.positions, a)  # type: ignore[arg-type]
