"""Monte Carlo localization: the likelihood field, the filter steps, the estimator, and its
global-localization and kidnapped-robot behaviour over seeded runs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import chi2, multivariate_normal

import slamkit.localization.mcl.core as mcl_core
from slamkit.config import config_from_mapping, config_to_dict
from slamkit.datasets import load_dataset
from slamkit.datasets.stream import Dataset, LandmarkReadings, LaserScan, group_by_time
from slamkit.errors import ConfigError, ConvergenceError, InputError
from slamkit.estimation.particles import ParticleSet, effective_sample_size
from slamkit.geometry import angle_diff
from slamkit.localization import GaussianBelief
from slamkit.localization.ekf import ekf_update
from slamkit.localization.mcl import (
    Augmentation,
    AugmentedConfig,
    KldConfig,
    MclConfig,
    MonteCarloLocalization,
    SnapshotConfig,
    StartConfig,
    kld_resample_predict,
    kld_sample_size,
    landmark_innovations,
    landmark_log_likelihood,
    mcl_predict,
    mcl_resample,
    mcl_update_landmarks,
    mcl_update_laser,
    reweight,
)
from slamkit.maps import LandmarkMap, OccupancyGrid
from slamkit.maps.likelihood_field import (
    LikelihoodField,
    beam_log_likelihood,
    log_likelihood,
    usable_beams,
)
from slamkit.models import RangeBearing, UnicycleEuler
from slamkit.pipeline.registry import EstimatorEntry
from slamkit.pipeline.runner import run

POS_TOL = 0.5  # m: "converged" means position error below this ...
HEADING_TOL = np.deg2rad(10.0)  # ... and heading error below this


@pytest.fixture(scope="module")
def rooms() -> Dataset:
    return load_dataset("rooms-laser", seed=3)


@pytest.fixture(scope="module")
def field(rooms: Dataset) -> LikelihoodField:
    assert rooms.known_grid is not None and rooms.laser is not None
    return LikelihoodField.from_grid(rooms.known_grid, 0.2, 0.9, 0.1, rooms.laser.max_range)


def _scans(dataset: Dataset) -> list[LaserScan]:
    return [ev for ev in dataset.events if isinstance(ev, LaserScan)]


# -- likelihood field -----------------------------------------------------------------------


def _loop_log_likelihood(
    f: LikelihoodField,
    pose: np.ndarray,
    ranges: np.ndarray,
    angles: np.ndarray,
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    stride: int = 1,
) -> float:
    """The model written out beam by beam with math, straight from its definition."""
    x, y, th = (float(v) for v in pose)
    xs = x + math.cos(th) * offset[0] - math.sin(th) * offset[1]
    ys = y + math.sin(th) * offset[0] + math.cos(th) * offset[1]
    g = f.grid
    rows, cols = g.shape
    total = 0.0
    for b in range(0, len(ranges), stride):
        r = float(ranges[b])
        if r >= f.max_range:
            continue  # no return: no information
        a = th + offset[2] + float(angles[b])
        ex, ey = xs + r * math.cos(a), ys + r * math.sin(a)
        col = math.floor((ex - g.origin_xy[0]) / g.resolution)
        row = math.floor((ey - g.origin_xy[1]) / g.resolution)
        inside = 0 <= row < rows and 0 <= col < cols
        d = float(f.distances[row, col]) if inside else float(f.distances.max())
        s = f.sigma_hit
        p_hit = math.exp(-0.5 * (d / s) ** 2) / (s * math.sqrt(2 * math.pi))
        total += math.log(f.z_hit * p_hit + f.z_rand / f.max_range)
    return total


def test_distance_map_hand_values() -> None:
    prob = np.zeros((5, 7))
    prob[2, 3] = 1.0
    prob[0, 6] = 0.5  # unknown: gets the largest distance
    grid = OccupancyGrid(prob, 0.1, np.array([0.0, 0.0]))
    f = LikelihoodField.from_grid(grid, sigma_hit=0.1, z_hit=0.8, z_rand=0.2, max_range=4.0)
    assert f.distances[2, 3] == 0.0
    assert f.distances[2, 5] == pytest.approx(0.2)
    assert f.distances[4, 5] == pytest.approx(0.1 * np.hypot(2, 2))
    assert f.distances[0, 6] == pytest.approx(f.distances.max())
    # log p(0) = log(z_hit / (σ √(2π)) + z_rand / max_range)
    expected = np.log(0.8 / (0.1 * np.sqrt(2 * np.pi)) + 0.2 / 4.0)
    assert f.log_p(0.0) == pytest.approx(expected, rel=1e-12)
    # far away only the random component is left
    assert f.log_p(100.0) == pytest.approx(np.log(0.2 / 4.0), rel=1e-12)


def test_vectorised_log_likelihood_equals_a_per_beam_loop(
    rooms: Dataset, field: LikelihoodField
) -> None:
    assert rooms.laser is not None and rooms.truth.poses is not None
    rng = np.random.default_rng(5)
    scan = _scans(rooms)[40]
    truth = rooms.truth.poses[40]
    poses = np.concatenate(
        [
            truth + rng.normal(0.0, [0.3, 0.3, 0.2], (40, 3)),  # near the truth
            np.column_stack(  # anywhere, including outside the map
                [rng.uniform(-5, 25, 40), rng.uniform(-5, 17, 40), rng.uniform(-4, 4, 40)]
            ),
            [[1000.0, -2000.0, 1.0], [-0.49, 6.0, np.pi], [20.49, 12.49, 0.0]],
        ]
    )
    angles = rooms.laser.beam_angles
    ranges = scan.ranges.copy()
    ranges[::7] = rooms.laser.max_range  # some beams without a return
    for offset, stride in (((0.0, 0.0, 0.0), 1), ((0.25, -0.1, 0.05), 3)):
        fast = log_likelihood(field, poses, ranges, angles, offset, beam_stride=stride)
        slow = [_loop_log_likelihood(field, p, ranges, angles, offset, stride) for p in poses]
        np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-9)
        per_beam = beam_log_likelihood(field, poses[0], ranges, angles, offset, stride)
        assert per_beam.sum() == pytest.approx(fast[0], abs=1e-9)


def test_max_range_readings_carry_no_information(rooms: Dataset, field: LikelihoodField) -> None:
    assert rooms.laser is not None
    angles = rooms.laser.beam_angles
    ranges = np.full(angles.size, rooms.laser.max_range)
    poses = np.array([[5.0, 6.0, 0.0], [15.0, 3.0, 2.0]])
    np.testing.assert_array_equal(log_likelihood(field, poses, ranges, angles), [0.0, 0.0])
    ranges[:10] = 2.0
    assert usable_beams(field, ranges, angles) == 10
    assert usable_beams(field, ranges, angles, beam_stride=4) == 3  # beams 0, 4, 8
    with pytest.raises(InputError):
        log_likelihood(field, poses, -ranges, angles)
    with pytest.raises(InputError):
        log_likelihood(field, poses, ranges, angles, beam_stride=0)


def test_true_pose_scores_higher_than_displaced_poses(
    rooms: Dataset, field: LikelihoodField
) -> None:
    assert rooms.laser is not None and rooms.truth.poses is not None
    angles = rooms.laser.beam_angles
    d = 0.5
    t = np.deg2rad(10.0)
    offsets = np.array(
        [[d, 0, 0], [-d, 0, 0], [0, d, 0], [0, -d, 0], [0, 0, t], [0, 0, -t]], dtype=float
    )
    margins = []
    for k in range(0, 450, 25):
        truth = rooms.truth.poses[k]
        ranges = _scans(rooms)[k].ranges
        ll = log_likelihood(field, np.vstack([truth, truth + offsets]), ranges, angles)
        margins.append(ll[0] - ll[1:])
    # Measured (seed 3, every 25th of the first 450 scans, all 181 beams): the true pose wins
    # all 108 comparisons; median margin 254 nats, smallest 0.28 nats — ±0.5 m along the
    # corridor while looking down it (scan 400), where only the door frames tell the
    # positions apart (the far end is beyond the 12 m range).
    m = np.asarray(margins)
    assert m.min() > 0.0
    assert np.median(m) > 100.0
    assert np.mean(m > 10.0) > 0.9  # measured 0.96: 4 of 108 below 0.5 nats, the rest > 39


# -- filter steps -----------------------------------------------------------------------------


def test_predict_moves_particles_with_their_own_noise() -> None:
    model = UnicycleEuler()
    Q = np.diag([0.1**2, 0.05**2])
    poses = np.tile([1.0, 2.0, 0.3], (500, 1))
    ps = ParticleSet.from_log_weights(poses, np.linspace(0, 1, 500))
    out = mcl_predict(ps, [1.0, 0.2], 0.5, model, Q, np.random.default_rng(4))
    expected = model.sample(poses, [1.0, 0.2], 0.5, Q, np.random.default_rng(4))
    np.testing.assert_array_equal(out.poses, expected)
    np.testing.assert_array_equal(out.log_weights, ps.log_weights)
    assert np.all(ps.poses == [1.0, 2.0, 0.3])  # the input is untouched
    assert np.std(out.poses[:, 0]) > 0.01


def test_landmark_likelihood_hand_values() -> None:
    lms = LandmarkMap(np.array([[3.0, 4.0], [-2.0, 0.0]]), np.array([7, 9]))
    model = RangeBearing()
    R = np.array([[0.04, 0.001], [0.001, 0.01]])
    poses = np.array([[0.0, 0.0, 0.0], [0.5, -0.2, 3.0]])
    z = np.array([[5.1, 0.95], [2.2, -3.1], [1.0, 0.0]])
    ids = np.array([7, 9, 42])  # 42 is not in the map: skipped
    ll, n = landmark_log_likelihood(poses, z, ids, lms, model, R)
    assert n == 2
    for i, pose in enumerate(poses):
        expected = 0.0
        for zk, pos in ((z[0], lms.positions[0]), (z[1], lms.positions[1])):
            nu = model.residual(zk, model.predict(pose, pos))  # bearing wrapped
            expected += multivariate_normal(np.zeros(2), R).logpdf(nu)
        assert ll[i] == pytest.approx(expected, abs=1e-10)
    none, n0 = landmark_log_likelihood(poses, z[2:], ids[2:], lms, model, R)
    assert n0 == 0 and np.all(none == 0.0)
    update = mcl_update_landmarks(ParticleSet.uniform_weights(poses), z, ids, lms, model, R)
    assert update.n_readings == 2
    np.testing.assert_allclose(update.particles.weights, np.exp(ll) / np.exp(ll).sum())


def test_reweight_is_bayes_rule_with_the_evidence() -> None:
    ps = ParticleSet.from_log_weights(np.zeros((3, 3)), np.log([0.5, 0.3, 0.2]))
    lik = np.array([0.1, 0.2, 0.7])
    out = reweight(ps, np.log(lik))
    evidence = 0.5 * 0.1 + 0.3 * 0.2 + 0.2 * 0.7
    np.testing.assert_allclose(out.particles.weights, np.array([0.05, 0.06, 0.14]) / evidence)
    assert out.log_evidence == pytest.approx(np.log(evidence))
    with pytest.raises(ConvergenceError, match="all 3 particle weights are zero"):
        reweight(ps, np.full(3, -np.inf))


def test_resample_with_random_particles() -> None:
    ps = ParticleSet.from_log_weights(np.arange(12.0).reshape(4, 3), np.log([0.7, 0.1, 0.1, 0.1]))

    def far_away(n: int, rng: np.random.Generator) -> np.ndarray:
        return np.column_stack([np.full(n, 100.0), rng.random(n), np.zeros(n)])

    out = mcl_resample(ps, np.random.default_rng(0), 10, n_random=3, sampler=far_away)
    assert len(out) == 10
    assert np.sum(out.poses[:, 0] == 100.0) == 3
    assert np.sum(out.poses[:, 0] == 0.0) == 5  # 7 draws by weight: 0.7·7 = 4.9 -> 4 or 5
    np.testing.assert_allclose(out.weights, 0.1)
    with pytest.raises(InputError):
        mcl_resample(ps, np.random.default_rng(0), 4, n_random=2)  # no sampler


def test_augmentation_averages_hand_values() -> None:
    a = Augmentation.start(np.log(0.5))
    assert a.injection_probability == 0.0
    b = a.update(np.log(0.1), alpha_slow=0.1, alpha_fast=0.5)
    # w_slow = 0.9·0.5 + 0.1·0.1 = 0.46; w_fast = 0.5·0.5 + 0.5·0.1 = 0.3
    assert np.exp(b.log_w_slow) == pytest.approx(0.46)
    assert np.exp(b.log_w_fast) == pytest.approx(0.3)
    assert b.injection_probability == pytest.approx(1 - 0.3 / 0.46)
    c = b.update(np.log(2.0), 0.1, 0.5)  # the fit improves: no injection
    assert c.injection_probability == 0.0
    # works far outside the float range: likelihoods of e^-2000 per reading
    d = Augmentation.start(-2000.0).update(-2010.0, 0.1, 0.5)
    assert np.isfinite(d.log_w_slow) and 0 < d.injection_probability < 1


def test_kld_bound_matches_the_chi_square_quantile() -> None:
    eps, q = 0.05, 0.99
    # Measured relative differences to χ²_{k-1, 0.99} / (2ε) (ceil included): -0.53 % for
    # k = 2, +0.39 % for 11, +0.07 % for 101, +0.003 % for 1001.
    for k, rel in ((2, 0.01), (11, 0.006), (101, 0.001), (1001, 1e-4)):
        exact = chi2.ppf(q, k - 1) / (2 * eps)
        assert kld_sample_size(k, eps, q) == pytest.approx(exact, rel=rel)
    assert kld_sample_size(1, eps, q) == 1
    assert np.all(np.diff(kld_sample_size(np.arange(1, 50), eps, q)) >= 0)


def test_kld_sampling_adapts_the_number_of_particles() -> None:
    model = UnicycleEuler()
    Q = np.diag([1e-6, 1e-6])
    rng = np.random.default_rng(1)
    concentrated = ParticleSet.uniform_weights(np.tile([0.25, 0.25, 0.05], (1000, 1)))
    out, n_rand = kld_resample_predict(
        concentrated, [0.0, 0.0], 0.1, model, Q, rng, min_particles=50, max_particles=5000
    )
    assert len(out) == 50 and n_rand == 0  # one bin: the minimum suffices
    heading = np.full(5000, 0.05)  # inside one 10° bin (0 would sit on a bin edge)
    spread = ParticleSet.uniform_weights(
        np.column_stack([rng.uniform(0, 20, 5000), rng.uniform(0, 10, 5000), heading])
    )
    out, _ = kld_resample_predict(
        spread, [0.0, 0.0], 0.1, model, Q, rng, min_particles=50, max_particles=100_000
    )
    # 40 × 20 position bins in one heading bin: once all 800 are occupied the bound is
    # χ²_{799, 0.99} / 0.1 = 8,949. Measured over 10 draws: 8,833-8,939.
    assert 8500 < len(out) <= 8950
    out, _ = kld_resample_predict(
        spread, [0.0, 0.0], 0.1, model, Q, rng, min_particles=50, max_particles=1000
    )
    assert len(out) == 1000


# -- the estimator ------------------------------------------------------------------------------


def _errors(dataset: Dataset, est: MonteCarloLocalization, max_t: float = np.inf) -> np.ndarray:
    """(position error, |heading error|) after each time stamp up to ``max_t``."""
    assert dataset.truth.times is not None and dataset.truth.poses is not None
    out = []
    for t, group in group_by_time(dataset.events):
        if t > max_t:
            break
        for ev in group:
            est.handle(ev)
        pose = est.estimate().pose
        k = int(np.searchsorted(dataset.truth.times, t))
        truth = dataset.truth.poses[k]
        out.append([np.hypot(*(pose[:2] - truth[:2])), abs(float(angle_diff(pose[2], truth[2])))])
    return np.asarray(out)


def _converged_from(errors: np.ndarray) -> int | None:
    """The first step from which the error stays within the tolerances to the end."""
    ok = (errors[:, 0] < POS_TOL) & (errors[:, 1] < HEADING_TOL)
    bad = np.flatnonzero(~ok)
    if bad.size == 0:
        return 0
    return None if bad[-1] == ok.size - 1 else int(bad[-1] + 1)


def test_constructor_checks_what_the_data_set_provides(rooms: Dataset) -> None:
    scans_only = dataclasses.replace(rooms, events=tuple(_scans(rooms)), motion=None)
    with pytest.raises(InputError, match="needs a motion model"):
        MonteCarloLocalization(scans_only, MclConfig(), np.random.default_rng(0))
    with pytest.raises(InputError, match="laser with a known grid map or a landmark sensor"):
        MonteCarloLocalization(
            dataclasses.replace(rooms, known_grid=None), MclConfig(), np.random.default_rng(0)
        )
    with pytest.raises(ConfigError):
        MclConfig(augmented=AugmentedConfig(alpha_slow=0.5, alpha_fast=0.1))
    with pytest.raises(ConfigError):
        MclConfig(kld=KldConfig(min_particles=500, max_particles=100))


def test_weight_underflow_is_reported_not_silently_reset(
    rooms: Dataset, monkeypatch: pytest.MonkeyPatch
) -> None:
    est = MonteCarloLocalization(
        rooms, MclConfig(kld=KldConfig(enabled=False)), np.random.default_rng(0)
    )
    scans = _scans(rooms)
    est.handle(scans[0])
    before = est.particles

    def nothing_fits(field: object, poses: np.ndarray, *args: object) -> np.ndarray:
        return np.full(len(poses), -np.inf)

    monkeypatch.setattr(mcl_core, "log_likelihood", nothing_fits)
    est.handle(scans[1])
    est.handle(scans[2])
    assert est.particles is before  # the weights are kept, not reset to uniform
    diag = est.finish().diagnostics
    assert diag["weight_underflows"] == 2
    assert diag["first_underflow_update"] == 2
    assert diag["first_underflow_t"] == scans[1].t

    strict = MonteCarloLocalization(
        rooms, MclConfig(on_weight_underflow="raise"), np.random.default_rng(0)
    )
    with pytest.raises(ConvergenceError, match=r"step 1: mcl at t = 0\.0"):
        strict.handle(scans[0])


def test_tracking_snapshots_and_reproducibility(rooms: Dataset) -> None:
    cfg = MclConfig(
        kld=KldConfig(enabled=False),
        n_particles=500,
        snapshots=SnapshotConfig(every=100, times=(10.0,)),
    )
    est = MonteCarloLocalization(rooms, cfg, np.random.default_rng(2))
    errors = _errors(rooms, est, max_t=40.0)
    # Measured: RMS position error 0.047 m, largest 0.12 m, largest heading error 1.2°.
    assert np.sqrt(np.mean(errors[:, 0] ** 2)) < 0.09
    assert errors[:, 0].max() < 0.25 and errors[:, 1].max() < np.deg2rad(5.0)
    out = est.finish()
    snaps = out.particle_snapshots
    assert [s.t for s in snaps] == pytest.approx([0.0, 10.0, 19.8, 39.8])
    for s in snaps:
        assert s.particles.shape == (500, 3)
        assert s.weights.sum() == pytest.approx(1.0)
    assert out.diagnostics["weight_underflows"] == 0
    assert out.diagnostics["resamplings"] > 0
    again = MonteCarloLocalization(rooms, cfg, np.random.default_rng(2))
    np.testing.assert_array_equal(_errors(rooms, again, max_t=5.0), errors[:26])


def test_runs_through_the_pipeline_runner() -> None:
    data = load_dataset("five-features", seed=1)
    entry = EstimatorEntry(
        "mcl",
        "Monte Carlo localization",
        "slamkit.localization.mcl:MonteCarloLocalization",
        "slamkit.localization.mcl:MclConfig",
        requires=("motion",),
    )
    config = {"n_particles": 300, "kld": {"enabled": False}}
    result = run(entry, data, config=config, seed=4, frames=5)
    assert data.truth.poses is not None
    assert result.covariances is not None and result.poses.shape == data.truth.poses.shape
    err = np.hypot(*(result.poses[:, :2] - data.truth.poses[:, :2]).T)
    # Measured: RMS 0.029 m (largest 0.07 m) with 300 particles.
    assert np.sqrt(np.mean(err**2)) < 0.06
    assert result.output.diagnostics["measurement_updates"] == data.counts()["LandmarkReadings"]
    assert result.config["n_particles"] == 300
    # Animation frames carry the particle cloud; its unweighted centre is the estimate's
    # neighbour (the weights after a scan are close to even with 300 particles).
    assert 5 <= len(result.frames) <= 7
    for f in result.frames:
        assert f.particles is not None and f.particles.shape == (300, 3)
        assert np.hypot(*(f.particles[:, :2].mean(axis=0) - f.pose[:2])) < 0.1


# -- global localization, kidnapping, wrong prior (seeded Monte Carlo runs) --------------------


@pytest.mark.slow
def test_global_localization_converges_in_95_percent_of_seeds() -> None:
    """20 seeds of "rooms-laser-global" (no prior), 200 steps (40 s) each, default config:
    454,147 particles uniform over the 267 m² of free space (1700 per m²), 46 of 181 beams
    tempered to 4.5 independent ones, KLD-sampling down to 500 particles.

    Converged = position error < 0.5 m and heading error < 10° from that step to the end of
    the 40 s. The corridor looks the same from both of its ends (the building is symmetric
    under a half turn except for the pillars in the rooms). Measured for seeds 0-19,
    converged from step (sorted): 5 5 6 6 6 6 7 7 7 7 7 8 8 8 9 10 10 11 12 15. With the
    former defaults (20,000 start particles, no tempering, 200 after convergence): 0 0 0 0
    0 0 1 1 19 20 20 23 23 25 25 26 39 81 87 87, the slow ones waiting for the robot to
    enter a room or a second one. The test asks for 19 of 20 within 120 steps, as before.
    """
    limit = 120  # steps (24 s)
    converged, shrunk = [], []
    for seed in range(20):
        data = load_dataset("rooms-laser-global", seed=seed)
        est = MonteCarloLocalization(data, MclConfig(), np.random.default_rng(seed))
        assert est.global_start
        step = _converged_from(_errors(data, est, max_t=40.0))
        converged.append(step is not None and step <= limit)
        counts = est.particle_counts
        shrunk.append((counts[0], max(counts[-20:])))
    assert sum(converged) >= 19, converged
    # KLD adapts: 454,147 particles at the uniform start; measured 500 (kld.min_particles)
    # over the last 20 steps in every seed.
    assert all(start == 454_147 and end <= 1_000 for start, end in shrunk), shrunk


@pytest.mark.slow
def test_augmented_mcl_recovers_from_kidnapping() -> None:
    """Scenario "rooms-laser-kidnapped": just after t = 30 s (step 150) the robot is carried
    40 s along its route, with ~170 steps left. With augmented MCL (default config) the error
    must return below 0.5 m / 10° within 60 steps (12 s) and stay there; without augmentation
    it must not recover: the mechanism is what matters.

    Measured, seeds 0-7: with augmentation recovered 4 8 11 11 5 7 8 13 steps after
    t = 30 s (injection only once the fast average is 8 natural spreads below the slow
    one, see ``AugmentedConfig.injection_sigmas``; Thrun's rule: 3 15 15 8 24 3 16 5); without it
    none recovered. Largest error before the kidnapping 0.15 m.
    """
    with_aug, without = [], []
    for seed in range(8):
        data = load_dataset("rooms-laser-kidnapped", seed=seed)
        for augmented, out in ((True, with_aug), (False, without)):
            cfg = MclConfig(augmented=AugmentedConfig(enabled=augmented))
            errors = _errors(data, MonteCarloLocalization(data, cfg, np.random.default_rng(seed)))
            k = round(30.0 / 0.2)  # time stamps are 0, 0.2, 0.4, ... s: step 150 is t = 30 s
            assert errors[:k, 0].max() < POS_TOL  # tracking before the kidnapping
            out.append(_converged_from(errors[k:]))
    assert sum(s is not None and s <= 60 for s in with_aug) >= 7, with_aug
    assert sum(s is None for s in without) >= 6, without


@pytest.mark.slow
def test_wrong_prior_is_corrected_at_the_first_features() -> None:
    """Scenario "five-features-kidnapped": the prior is 3.6 m and 60° off (σ 5 cm, 1°).
    Landmarks 0 and 4 are in view from t = 0. A broad prior (σ × 60: 3 m, 60°) or a global
    start lets the first readings pull the particles onto the true pose.

    Measured, seeds 0-9, converged (to the end of the run) from step: broad prior 13 14 2 6 0
    0 0 6 0 0 (the same without augmentation: here the broad prior does the work); global
    start (368,900 particles over the landmarks' box) 0 in all ten. With the prior as given,
    105 114 108 118 106 115 101 117 119 103: augmentation cannot help there, it detects a
    *change* in how well the particles fit, not a prior that is wrong from the start.
    """
    for seed in range(5):
        data = load_dataset("five-features-kidnapped", seed=seed)
        for cfg, limit in (
            (MclConfig(start=StartConfig(prior_cov_scale=3600.0)), 40),
            (MclConfig(start=StartConfig(uniform=True)), 20),
        ):
            est = MonteCarloLocalization(data, cfg, np.random.default_rng(seed))
            step = _converged_from(_errors(data, est, max_t=15.0))
            assert step is not None and step <= limit, (cfg, step)


def test_landmark_readings_without_ids_are_counted() -> None:
    data = load_dataset("five-features", seed=0)
    est = MonteCarloLocalization(data, MclConfig(n_particles=200), np.random.default_rng(0))
    reading = next(ev for ev in data.events if isinstance(ev, LandmarkReadings))
    est.handle(LandmarkReadings(reading.t, reading.z, np.full(reading.ids.size, -1)))
    diag = est.finish().diagnostics
    assert diag["readings_skipped"] == reading.ids.size
    assert diag["measurement_updates"] == 0


# -- augmentation on range-only readings, KLD with the ESS trigger, fast kernels -------------


def test_injection_waits_for_a_drop_beyond_the_natural_spread() -> None:
    a = Augmentation.start(0.0).update(np.log(0.2), alpha_slow=0.1, alpha_fast=0.5)
    # w_slow = 0.9 + 0.1·0.2 = 0.92, w_fast = 0.5 + 0.5·0.2 = 0.6: ratio 0.652
    ratio = 0.6 / 0.92
    assert a.injection_probability == pytest.approx(1 - ratio)  # Thrun's rule: ratio 1
    assert a.injection_probability_below(1.0) == pytest.approx(1 - ratio)
    assert a.injection_probability_below(0.8) == pytest.approx(1 - ratio / 0.8)
    assert a.injection_probability_below(0.5) == 0.0  # not yet below half the slow average
    with pytest.raises(InputError):
        a.injection_probability_below(0.0)
    # Mean and variance of log w (West's update): d = log 0.2, m = 0.1 d, v = 0.9·0.1 d².
    d = np.log(0.2)
    assert a.mean_log_w == pytest.approx(0.1 * d)
    assert a.var_log_w == pytest.approx(0.9 * 0.1 * d * d)
    # Bias-corrected (one deviation averaged: divide by 1 - 0.9), times α_f / (2 - α_f).
    assert a.tolerance(0.1, 0.5) == pytest.approx(np.sqrt(0.9 * d * d * 0.5 / 1.5))
    assert Augmentation.start(-3.0).tolerance(0.1, 0.5) == 0.0
    # A long run of equal values: no spread, so the tolerance is 0 (Thrun's rule).
    b = Augmentation.start(-1.0)
    for _ in range(50):
        b = b.update(-1.0, 0.01, 0.2)
    assert b.tolerance(0.01, 0.2) == 0.0 and b.injection_probability == pytest.approx(0.0)
    # Values of standard deviation 1: the bias-corrected spread estimate is near 1 · 1/3.
    c = Augmentation.start(0.0)
    for x in np.random.default_rng(0).normal(0.0, 1.0, 3000):
        c = c.update(float(x), 0.01, 0.2)
    assert c.tolerance(0.01, 0.2) == pytest.approx(np.sqrt(0.2 / 1.8), rel=0.15)


def test_range_only_tracking_injects_no_particles_by_default() -> None:
    """Why Thrun's rule (inject ``1 - w_fast/w_slow`` whenever the fast average is below the
    slow one) fails on range-only readings: one 1-dof reading's evidence ``N(ν; 0, S)``
    varies by a factor e^±1 from reading to reading for a filter that tracks perfectly, so
    the fast average spends half its time below the slow one. Measured on
    "five-features-range" (seeds 0-4, ~315 updates each): Thrun's rule
    (``augmented.injection_sigmas = 0``) injected at 175 166 82 26 172 updates (up to 1.35 M
    random particles; position ATE 0.81 1.91 0.09 0.12 1.40 m); the default (3 natural
    spreads) at none (ATE 0.13 0.10 0.09 0.11 0.12 m). Seed 0 here."""
    for seed in (0,):
        data = load_dataset("five-features-range", seed=seed)
        assert data.truth.poses is not None
        res = run("mcl", data, seed=seed)
        assert res.output.diagnostics["injected_particles"] == 0
        err = np.hypot(*(res.poses[:, :2] - data.truth.poses[:, :2]).T)
        assert np.sqrt(np.mean(err**2)) < 0.2
        thrun = run("mcl", data, config={"augmented": {"injection_sigmas": 0.0}}, seed=seed)
        assert thrun.output.diagnostics["injection_events"] > 100


def test_mcl_nis_on_the_five_feature_world_is_chi_square() -> None:
    """MCL's innovation log (each reading against the particle mean and covariance before
    the update, S = H Σ Hᵀ + R) behaves like an EKF's on a simulated world whose noise
    the filter knows: measured NIS per dof, seeds 0-9 (~890 range-bearing readings each),
    0.990 1.032 1.002 1.023 1.005 1.018 1.015 1.029 1.067 1.023 (mean 1.020). Each of seeds
    0-2 must lie in the two-sided 99 % χ² band of its own mean."""
    from slamkit.eval import chi2_bounds

    for seed in range(3):
        data = load_dataset("five-features", seed=seed)
        res = run("mcl", data, seed=seed)
        log = res.output.innovations
        assert log is not None and len(log) > 800
        assert np.all(log.dof == 2) and np.all(log.nis >= 0)
        lo, hi = chi2_bounds(2, len(log), probability=0.99)
        assert lo <= log.nis.mean() <= hi, (seed, log.nis.mean(), lo, hi)
        d = res.output.diagnostics
        assert d["mean_nis_per_dof"] == pytest.approx(log.nis.mean() / 2)


def test_landmark_innovations_equal_an_ekf_update() -> None:
    lms = LandmarkMap(np.array([[3.0, 4.0], [-2.0, 0.0]]), np.array([7, 9]))
    model = RangeBearing()
    R = np.diag([0.04, 0.01])
    mean = np.array([0.2, -0.1, 0.0])
    cov = np.array([[0.09, 0.01, 0.0], [0.01, 0.04, 0.002], [0.0, 0.002, 0.01]])
    z = np.array([[5.3, 0.9], [2.1, -3.1], [1.0, 0.0]])
    ids = np.array([7, 9, 42])  # 42 is not in the map
    out = landmark_innovations(mean, cov, z, ids, lms, model, R)
    np.testing.assert_array_equal(out.landmark_ids, [7, 9])
    for k, lm in enumerate(lms.positions):
        _, info = ekf_update(GaussianBelief(mean, cov), z[k], lm, model, R)
        np.testing.assert_allclose(out.nu[k], info.innovation, atol=1e-12)
        np.testing.assert_allclose(out.S[k], info.S, atol=1e-12)
        assert out.nis[k] == pytest.approx(info.nis, rel=1e-12)
    # Landmark 9 lies behind the robot at bearing atan2(0.1, -2.2) = π - 0.0454: the
    # reading's -3.1 is 0.087 rad past it, not -6.196.
    assert out.nu[1, 1] == pytest.approx(-3.1 - (np.pi - np.arctan2(0.1, 2.2)) + 2 * np.pi)


def test_kld_resamples_only_when_the_ess_drops() -> None:
    """KLD-sampling resizes the set when it resamples, and it resamples only when the ESS
    trigger (or an injection) asks for it: not at every prediction, which with 1-3
    predictions per measurement (Plaza 1) redrew a set of equal weights each time and
    lost particles for nothing (first 300 s of Plaza 1, seed 0: ATE 0.313 m → 0.263 m)."""
    data = load_dataset("five-features", seed=0)
    est = MonteCarloLocalization(data, MclConfig(), np.random.default_rng(0))
    controls = [ev for ev in data.events if not isinstance(ev, LandmarkReadings)]
    for ev in controls[:5]:  # predictions without a measurement: no resampling
        est.handle(ev)
    assert est.finish().diagnostics["resamplings"] == 0
    assert est.particle_counts == (2000,) * 6
    # The first real reading concentrates the weights: the next prediction resamples.
    reading = next(ev for ev in data.events if isinstance(ev, LandmarkReadings))
    est.handle(reading)
    est.handle(controls[6])
    d = est.finish().diagnostics
    assert d["resamplings"] == 1 and est.particle_counts[-1] < 2000
    # With the ESS trigger off (threshold 0) and no augmentation, KLD never resamples.
    never = MonteCarloLocalization(
        data,
        MclConfig(resample_threshold=0.0, augmented=AugmentedConfig(enabled=False)),
        np.random.default_rng(0),
    )
    for ev in data.events[:200]:
        never.handle(ev)
    d = never.finish().diagnostics
    assert d["measurement_updates"] > 50 and d["resamplings"] == 0


def test_fast_prediction_draws_what_the_model_samples() -> None:
    from slamkit.localization.mcl.core import control_noise_root, mcl_predict_unchecked
    from slamkit.models import OdometryModel, UnicycleArc

    rng = np.random.default_rng(3)
    poses = rng.normal(size=(300, 3))
    for model, u, Q in (
        (UnicycleArc(), np.array([1.0, 0.3]), np.diag([0.05**2, 0.017**2])),
        (UnicycleEuler(), np.array([0.5, -0.2]), np.diag([0.01, 0.0])),  # singular Q
        (OdometryModel(), np.array([0.1, 0.4, -0.05]), np.diag([1e-4, 4e-4, 1e-4])),
    ):
        fast = mcl_predict_unchecked(
            poses, u, 0.2, model, control_noise_root(Q), np.random.default_rng(9)
        )
        slow = model.sample(poses, u, 0.2, Q, np.random.default_rng(9))
        np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)


def test_tempered_scan_likelihood(rooms: Dataset, field: LikelihoodField) -> None:
    assert rooms.laser is not None and rooms.truth.poses is not None
    scan = _scans(rooms)[10]
    poses = rooms.truth.poses[10] + np.random.default_rng(1).normal(0, 0.2, (50, 3))
    ps = ParticleSet.uniform_weights(poses)
    angles = rooms.laser.beam_angles
    full = mcl_update_laser(ps, scan.ranges, field, angles, beam_stride=4)
    half = mcl_update_laser(ps, scan.ranges, field, angles, beam_stride=4, exponent=0.5)
    np.testing.assert_allclose(half.log_likelihood, 0.5 * full.log_likelihood, rtol=1e-12)
    assert effective_sample_size(half.particles.weights) > effective_sample_size(
        full.particles.weights
    )
    with pytest.raises(InputError):
        mcl_update_laser(ps, scan.ranges, field, angles, exponent=0.0)


def test_a_global_start_is_sized_by_area_and_not_moved_before_the_first_scan() -> None:
    data = load_dataset("rooms-laser-global", seed=0)
    assert data.known_grid is not None
    cfg = MclConfig()
    est = MonteCarloLocalization(data, cfg, np.random.default_rng(0))
    area = np.count_nonzero(data.known_grid.free()) * data.known_grid.resolution**2
    assert len(est.particles) == int(np.ceil(cfg.start.particles_per_m2 * area))
    start = est.particles.poses
    first_scan = next(i for i, ev in enumerate(data.events) if isinstance(ev, LaserScan))
    for ev in data.events[:first_scan]:
        est.handle(ev)
    assert est.particles.poses is start or np.array_equal(est.particles.poses, start)
    fixed = MonteCarloLocalization(
        data, MclConfig(start=StartConfig(n_particles=5000)), np.random.default_rng(0)
    )
    assert len(fixed.particles) == 5000


def test_config_sections_round_trip_and_old_names_are_refused_with_their_place() -> None:
    cfg = config_from_mapping(
        MclConfig,
        {"n_particles": 300, "kld": {"epsilon": 0.1}, "laser": {"sigma_hit": None}},
    )
    assert cfg.kld == KldConfig(epsilon=0.1) and cfg.laser.sigma_hit is None
    assert config_from_mapping(MclConfig, config_to_dict(cfg)) == cfg
    with pytest.raises(ConfigError, match=r"kld_epsilon \(MCL: now kld.epsilon"):
        config_from_mapping(MclConfig, {"kld_epsilon": 0.1})
    with pytest.raises(ConfigError, match=r"kld.quantile: expected a number in \(0, 1\)"):
        config_from_mapping(MclConfig, {"kld": {"quantile": 1.0}})
    with pytest.raises(ConfigError, match="kld: expected a KldConfig"):
        MclConfig(kld=False)  # type: ignore[arg-type]
