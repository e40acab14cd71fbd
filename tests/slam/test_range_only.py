"""Range-only SLAM (:mod:`slamkit.slam.range_only`) on a simulated world with known truth.

The world: four beacons around a 40 m x 20 m rectangle driven once at 1 m/s, ranges every
second (σ = 0.3 m, no range limit), odometry noise 0.05 m/s and 1 deg/s, the start known to
5 cm and 1 deg. Beacon 0 stands 6 m to the left of the first, straight, 40 m leg: until the
turn its mirror image 6 m to the right fits the ranges as well as itself.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from slamkit.cli.main import app
from slamkit.datasets import Dataset
from slamkit.datasets.stream import LandmarkReadings
from slamkit.errors import ConfigError, InputError
from slamkit.eval.trajectory import absolute_trajectory_error
from slamkit.maps import LandmarkMap
from slamkit.optim.robust import RobustKernel
from slamkit.pipeline import run
from slamkit.pipeline.evaluate import evaluate
from slamkit.sim.scenarios import LandmarkScenarioConfig, build_five_features, landmark_dataset
from slamkit.slam.range_only import (
    MIRROR_GAP,
    ODOMETRY_FLOOR,
    RangeOnlySlamConfig,
    locate_beacon,
    mirror_seeds,
    odometry_information,
)

BEACONS = np.array([[20.0, 6.0], [35.0, -8.0], [45.0, 25.0], [5.0, 30.0]])
CHI2_2_999 = 13.8155
"""The 99.9 % point of χ² with 2 degrees of freedom."""
CAUCHY = RobustKernel("cauchy", 1.0)


def _world(seed: int) -> Dataset:
    cfg = LandmarkScenarioConfig(
        dt=0.2, speed=1.0, sigma_v=0.05, sigma_omega_deg=1.0, sensor="range",
        sigma_range=0.3, max_range=100.0, min_range=0.0, observe_every=5,
    )  # fmt: skip
    route = np.array([[40.0, 0.0], [40.0, 20.0], [0.0, 20.0], [0.0, 0.0]])
    world = LandmarkMap(BEACONS.copy(), np.arange(4))
    return landmark_dataset(
        "range-only-world", "test", cfg, world, np.zeros(3), route, np.random.default_rng(seed)
    )


def _with_outliers(ds: Dataset, share: float, seed: int) -> tuple[Dataset, int]:
    """``share`` of the ranges lengthened by U(2, 10) m (a UWB reading off a reflection)."""
    rng = np.random.default_rng(seed)
    events, hits = [], 0
    for e in ds.events:
        if isinstance(e, LandmarkReadings):
            z = e.z.copy()
            hit = rng.random(z.shape[0]) < share
            z[hit, 0] += rng.uniform(2.0, 10.0, int(hit.sum()))
            hits += int(hit.sum())
            e = LandmarkReadings(e.t, z, e.ids)
        events.append(e)
    return dataclasses.replace(ds, events=tuple(events)), hits


# ------------------------------------------------------------------ beacon initialisation
def test_a_straight_path_gives_both_mirror_images_exactly() -> None:
    x = np.linspace(0.0, 30.0, 61)
    pts = np.column_stack([x, 0.5 * x])  # a straight line, not along an axis
    beacon = np.array([12.0, 14.0])
    r = np.hypot(*(beacon - pts).T)
    seeds = mirror_seeds(pts, r)
    # the mirror image of the beacon across the line y = x / 2
    n = np.array([-0.5, 1.0]) / np.hypot(0.5, 1.0)
    mirror = beacon - 2.0 * (beacon @ n) * n
    found = sorted(map(tuple, np.round(seeds, 9)))
    assert found == sorted([tuple(np.round(beacon, 9)), tuple(np.round(mirror, 9))])


def test_the_mirror_is_kept_on_the_straight_leg_and_rejected_after_the_turn() -> None:
    rng = np.random.default_rng(3)
    leg = np.column_stack([np.linspace(0.0, 30.0, 31), np.zeros(31)])
    turn = np.column_stack([np.full(10, 30.0), np.linspace(1.0, 10.0, 10)])
    for side in (1.0, -1.0):
        beacon = np.array([15.0, 6.0 * side])
        r_leg = np.hypot(*(beacon - leg).T) + rng.normal(0.0, 0.3, 31)
        fix = locate_beacon(leg, r_leg, 0.3, CAUCHY, max_sigma=1.0)
        assert not fix.resolved and fix.reason.startswith("ambiguous")
        gap = fix.hypotheses[1].cost - fix.hypotheses[0].cost
        assert gap < MIRROR_GAP
        # both hypotheses are there, one near the beacon and one near its mirror image
        ys = sorted(h.position[1] for h in fix.hypotheses)
        assert ys[0] == pytest.approx(-6.0, abs=0.5) and ys[1] == pytest.approx(6.0, abs=0.5)
        pts = np.vstack([leg, turn])
        r = np.concatenate([r_leg, np.hypot(*(beacon - turn).T) + rng.normal(0.0, 0.3, 10)])
        fix = locate_beacon(pts, r, 0.3, CAUCHY, max_sigma=1.0)
        assert fix.resolved
        assert np.hypot(*(fix.best.position - beacon)) < 0.5


def test_an_imprecise_fix_is_not_taken() -> None:
    pts = np.column_stack([np.linspace(0.0, 1.0, 11), np.zeros(11)])  # 1 m of path
    r = np.hypot(*(np.array([15.0, 20.0]) - pts).T)
    fix = locate_beacon(pts, r + 0.3 * np.random.default_rng(0).normal(size=11), 0.3, CAUCHY, 1.0)
    assert not fix.resolved and fix.reason.startswith("imprecise")


def test_odometry_information_is_rotated_into_the_measurement_frame() -> None:
    cov = np.diag([0.04, 0.01, 0.0025])[None]
    info = odometry_information(np.array([[1.0, 0.0, np.pi / 2]]), cov)
    # e_t = R_zᵀ (d - t_z) with θ_z = 90°: x and y swap roles
    floor = np.diag(ODOMETRY_FLOOR)
    expected = np.diag(1.0 / (np.array([0.01, 0.04, 0.0025]) + floor[[1, 0, 2]]))
    np.testing.assert_allclose(info[0], expected, atol=1e-9)


# ------------------------------------------------------------------------- the estimator
@pytest.fixture(scope="module")
def solved() -> list[tuple[Dataset, object]]:
    return [(ds, run("range-only-slam", ds, seed=0)) for ds in map(_world, range(3))]


def test_beacons_are_recovered_within_their_own_uncertainty(solved) -> None:
    """Each beacon's error, unaligned, under the marginal covariance the solve reports: the
    squared Mahalanobis distance is χ² with 2 dof if the model is right; every one of the
    12 must lie below its 99.9 % point (measured: at most 4.6). Aligned, the beacons' RMS
    error stays below 0.15 m (measured 0.05–0.06 m: ~120 ranges per beacon at σ = 0.3 m
    give ~0.04 m)."""
    for ds, res in solved:
        est = res.output.landmarks
        assert est is not None and est.covariances is not None
        np.testing.assert_array_equal(est.landmarks.ids, np.arange(4))
        err = est.landmarks.positions - BEACONS
        d2 = np.einsum("ki,kij,kj->k", err, np.linalg.inv(est.covariances), err)
        assert (d2 < CHI2_2_999).all(), d2
        m = evaluate(res, ds).metrics
        assert m["landmarks"]["rmse"] < 0.15


def test_the_path_is_recovered(solved) -> None:
    # measured: aligned ATE 0.065-0.086 m over the three seeds, dead reckoning 0.32-0.76 m
    for ds, res in solved:
        m = evaluate(res, ds).metrics
        dr = evaluate(run("dead-reckoning", ds), ds).metrics
        assert m["ate"]["rmse"] < 0.15
        assert m["ate"]["rmse"] < dr["ate"]["rmse"] / 3.0


def test_the_beacon_beside_the_straight_leg_starts_on_the_right_side(solved) -> None:
    for _, res in solved:
        start = res.output.diagnostics["beacon_starts"]["0"]
        assert start["ambiguous_attempts"] >= 3  # kept both images along the leg
        assert start["time_s"] > 40.0  # decided only after the turn at 40 s
        assert start["reason"].startswith("mirror rejected")
        found = res.output.landmarks.landmarks.positions[0]
        assert found[1] > 0.0 and np.hypot(*(found - BEACONS[0])) < 2.0


def test_outlier_ranges_do_not_move_the_result(solved) -> None:
    """10 % of the ranges lengthened by 2–10 m: with the default Cauchy kernel the beacons
    move by less than 0.15 m from the clean solution (measured 0.03–0.12 m); without a kernel
    they move by more than 0.3 m (measured 0.77–1.32 m), so the test can see the difference."""
    ds, clean = solved[1]
    bad, hits = _with_outliers(ds, 0.10, seed=7)
    assert hits > 30
    robust = run("range-only-slam", bad, seed=0)
    plain = run("range-only-slam", bad, config={"robust_kernel": "none"}, seed=0)
    ref = clean.output.landmarks.landmarks.positions
    moved = np.hypot(*(robust.output.landmarks.landmarks.positions - ref).T)
    assert moved.max() < 0.15
    moved_plain = np.hypot(*(plain.output.landmarks.landmarks.positions - ref).T)
    assert moved_plain.max() > 0.3
    m = evaluate(robust, bad).metrics
    assert m["ate"]["rmse"] < 0.15


# ------------------------------------------------------------------------- bad input
def test_a_data_set_without_ranges_is_refused() -> None:
    ds = build_five_features({}, seed=0)  # range-bearing readings
    with pytest.raises(InputError, match="needs range readings"):
        run("range-only-slam", ds)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("init_max_sigma", 0.0),
        ("robust_width", -1.0),
        ("max_iterations", 0),
        ("resolve_every_s", -1.0),
    ],
)
def test_bad_settings_are_refused(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=field):
        RangeOnlySlamConfig(**{field: value})


def test_a_beacon_seen_only_from_a_straight_path_is_left_out_with_a_warning() -> None:
    """Driven along the x axis only, a beacon beside the line is never resolved (its mirror
    fits as well): its readings are left out, counted, and the run says so."""
    cfg = LandmarkScenarioConfig(
        dt=0.2, speed=1.0, sigma_v=0.0, sigma_omega_deg=0.0, sensor="range",
        sigma_range=0.3, max_range=100.0, min_range=0.0, observe_every=5,
        initial_sigma_theta_deg=0.0, initial_sigma_xy=0.0,
    )  # fmt: skip
    world = LandmarkMap(np.array([[15.0, 6.0]]), np.array([0]))
    ds = landmark_dataset(
        "line", "test", cfg, world, np.zeros(3), np.array([[30.0, 0.0]]),
        np.random.default_rng(0),
    )  # fmt: skip
    res = run("range-only-slam", ds, seed=0)
    d = res.output.diagnostics
    assert d["beacons_started"] == 0 and d["readings_of_unstarted_beacons"] > 20
    assert [w.kind for w in res.output.warnings] == ["beacons_not_started"]
    assert res.output.landmarks is None


def test_periodic_solves_track_online_and_end_at_the_batch_optimum(solved) -> None:
    """``resolve_every_s = 20``: seven warm-started solves along the run. Online, the
    estimate is the latest solution with the odometry since (aligned ATE measured 0.58-0.66
    of dead reckoning's); at the end, the same optimum as the single batch solve (measured
    within 2.2 mm)."""
    for ds, batch in solved:
        res = run("range-only-slam", ds, config={"resolve_every_s": 20.0}, seed=0)
        assert res.output.diagnostics["solves"] == 7
        dr = run("dead-reckoning", ds)
        assert res.online_poses is not None
        online = absolute_trajectory_error(res.online_poses, ds.truth.poses, align="se2")
        dead = absolute_trajectory_error(dr.poses, ds.truth.poses, align="se2")
        assert online.rmse < 0.75 * dead.rmse
        np.testing.assert_allclose(res.poses, batch.poses, atol=0.01)
        np.testing.assert_allclose(
            res.output.landmarks.landmarks.positions,
            batch.output.landmarks.landmarks.positions,
            atol=0.01,
        )


def test_slamkit_run_range_only_slam_writes_a_scored_run(tmp_path) -> None:
    """The registered estimator through the command line, on the registered range-only
    world (8 m range, 120° view): the standard files, the beacons scored against the truth
    (measured seed 1: ATE 0.130 m aligned, 5 of 5 beacons, 0.107 m)."""
    out = tmp_path / "run"
    res = CliRunner().invoke(
        app,
        ["run", "range-only-slam", "--data", "five-features-range", "--seed", "1",
         "--out", str(out), "--no-plots"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["ate"]["rmse"] < 0.2
    assert metrics["landmarks"]["n_matched"] == 5 and metrics["landmarks"]["rmse"] < 0.15
    assert metrics["diagnostics"]["beacons_started"] == 5
    assert (out / "landmarks.csv").exists() and (out / "trajectory.tum").exists()
